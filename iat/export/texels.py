"""8-bit page texels placed so that a client's picture is our renderer's.

Our renderer filters the float page and clips the pixel; a client filters the 8-bit texels, which
the file holds clipped to [0, 1] (``radiance / radiance_scale``): between a texel above 1 (by a
light) and one below, the client's ramp starts lower and the surface is darker (and tinted where
the channels clip at different places). :func:`place_texels` chooses the stored texels of such
cells by bounded least squares so that bilinear filtering of them matches clip(bilinear filtering
of the float texels) at sample points over every cell that uses them; texels of cells entirely
below 1 stay as they are unless a neighbouring cell needs them. Gutters are re-replicated after.

Tiles (:func:`tile_boxes`) are read from the textured part's atlas uv: each patch's vertices are
consecutive and its slots 0, 1, 2 span the tile's first row and column (texel centres on the
polygon's corners).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.optimize import lsq_linear

__all__ = ["RGBM_RANGE", "place_texels", "rgbm_decode", "rgbm_encode", "scale_tiles", "tile_boxes"]

#: sample points per cell side for the fit
SAMPLES = 4


def tile_boxes(baked) -> dict[str, np.ndarray]:
    """Each textured patch's tile: ``patch, layer, x0, y0, side`` (k,) int64 (texel column and row
    of its first texel, texels per side) and ``tri`` (k,) bool (triangle: texels with
    ``a + b <= side - 1`` are its own), ``area`` (k,) float64 world area, ``vertices`` (k,) int64,
    ``first`` (k,) int64 its first textured-part vertex."""
    tp = np.asarray(getattr(baked, "tex_patch", np.zeros(0)), dtype=np.int64)
    pages = np.asarray(baked.pages)
    _, H, W, _ = pages.shape
    ps, first, nv = np.unique(tp, return_index=True, return_counts=True)
    uv = np.asarray(baked.tex_uv, dtype=np.float64)
    pos = np.asarray(baked.tex_positions, dtype=np.float64)
    layer = np.asarray(baked.tex_layer, dtype=np.int64)
    span = np.stack([uv[first + k] for k in range(3)], axis=1) if len(first) else np.zeros((0, 3, 2))
    e = np.cross(pos[first + 1] - pos[first], pos[first + 2] - pos[first]) if len(first) else np.zeros((0, 3))
    return {
        "patch": ps,
        "layer": layer[first],
        "x0": np.rint(span[:, :, 0].min(axis=1) * W - 0.5).astype(np.int64),
        "y0": np.rint(span[:, :, 1].min(axis=1) * H - 0.5).astype(np.int64),
        "side": np.rint(np.ptp(span[:, :, 0], axis=1) * W).astype(np.int64) + 1,
        "tri": nv == 3,
        "area": np.linalg.norm(e, axis=1) * np.where(nv == 3, 0.5, 1.0),
        "vertices": nv,
        "first": first,
    }


def _cells(x0, y0, side, tri):
    """All cells of the tiles: (origin column, origin row, side, tri) per cell, (c,) each."""
    cx, cy, cs, ct = [], [], [], []
    for m in np.unique(side).tolist():
        if m < 2:
            continue
        sel = side == m
        a, b = np.meshgrid(np.arange(m - 1), np.arange(m - 1))
        a, b = a.ravel(), b.ravel()
        k = int(sel.sum())
        keep_tri = (a + b) <= m - 2
        t = np.repeat(tri[sel], len(a))
        ok = ~t | np.tile(keep_tri, k)
        cx.append((np.repeat(x0[sel], len(a)) + np.tile(a, k))[ok])
        cy.append((np.repeat(y0[sel], len(a)) + np.tile(b, k))[ok])
        cs.append(np.tile(a + b, k)[ok])  # a + b, for the triangle's diagonal cells
        ct.append(np.stack([t, np.repeat(np.full(k, m), len(a))], 1)[ok])
    if not cx:
        z = np.zeros(0, np.int64)
        return z, z, z, np.zeros((0, 2), np.int64)
    return np.concatenate(cx), np.concatenate(cy), np.concatenate(cs), np.concatenate(ct)


def place_texels(page: np.ndarray, boxes: dict, gutter: int, align: int = 1) -> tuple[np.ndarray, int]:
    """The texels to store for one page: ``(texels (H, W, 3) float64 in [0, 1], changed)``.

    page : (H, W, 3) float linear values at the file's exposure (1 = white), unclipped
    boxes : :func:`tile_boxes` of the tiles on this page; gutter, align : the packing's
    ``changed`` counts the texels moved from their clipped value.
    """
    t = np.asarray(page, np.float64)
    out = np.clip(t, 0.0, 1.0)
    H, W, _ = t.shape
    cx, cy, cab, cinfo = _cells(boxes["x0"], boxes["y0"], boxes["side"], boxes["tri"])
    if not len(cx):
        return out, 0
    corners = np.stack([cy * W + cx, cy * W + cx + 1, (cy + 1) * W + cx, (cy + 1) * W + cx + 1], 1)
    flat = t.reshape(-1, 3)
    ct = flat[corners]  # (c, 4, 3)
    mixed = ((ct.min(axis=1) < 1.0) & (ct.max(axis=1) > 1.0)).any(axis=1)
    if not mixed.any():
        return out, 0
    var = np.unique(corners[mixed])
    col = np.full(H * W, -1, np.int64)
    col[var] = np.arange(len(var))
    use = (col[corners] >= 0).any(axis=1)  # every cell that reads a texel being placed
    corners, cab, cinfo = corners[use], cab[use], cinfo[use]
    f = (np.arange(SAMPLES) + 0.5) / SAMPLES
    fx, fy = (g.ravel() for g in np.meshgrid(f, f))
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)  # (S, 4)
    n, S = len(corners), len(fx)
    inside = ~cinfo[:, :1].astype(bool) | ((cab[:, None] + fx + fy) <= cinfo[:, 1:2] - 1)  # (n, S)
    rows = np.repeat(np.arange(n * S), 4).reshape(n, S, 4)
    wt = np.broadcast_to(w, (n, S, 4))
    cc = np.broadcast_to(corners[:, None, :], (n, S, 4))
    keep = np.broadcast_to(inside[:, :, None], (n, S, 4))
    is_var = col[cc] >= 0
    sel = keep & is_var
    B = sparse.csr_matrix((wt[sel], (rows[sel], col[cc][sel])), shape=(n * S, len(var)))
    fixed = keep & ~is_var
    changed = 0
    for k in range(3):
        target = np.clip(np.einsum("nsj,nj->ns", wt, flat[corners, k]), 0.0, 1.0).ravel()
        const = np.zeros(n * S)
        np.add.at(const, rows[fixed], wt[fixed] * out.reshape(-1, 3)[cc[fixed], k])
        rows_in = inside.ravel()
        r = lsq_linear(B[rows_in], (target - const)[rows_in], bounds=(0.0, 1.0), lsmr_tol="auto")
        x = np.clip(r.x, 0.0, 1.0)
        o = out.reshape(-1, 3)
        changed += int((np.abs(o[var, k] - x) > 0.5 / 255).sum())
        o[var, k] = x
    _repad(out, boxes, var, W, gutter, align)
    return out, changed


def _repad(out, boxes, var, W, gutter, align):
    """Re-replicate the edges of the tiles that hold a placed texel into their gutters."""
    H = out.shape[0]
    vy, vx = var // W, var % W
    x0, y0, side = boxes["x0"], boxes["y0"], boxes["side"]
    if gutter <= 0:
        return
    hit = (
        (vx[None] >= x0[:, None])
        & (vx[None] < (x0 + side)[:, None])
        & (vy[None] >= y0[:, None])
        & (vy[None] < (y0 + side)[:, None])
    ).any(axis=1)
    for i in np.flatnonzero(hit).tolist():  # the tiles touched: a handful, by the lights
        m = int(side[i])
        box = -(-(m + 2 * gutter) // align) * align
        far = box - m - gutter
        tile = out[y0[i] : y0[i] + m, x0[i] : x0[i] + m]
        padded = np.pad(tile, ((gutter, far), (gutter, far), (0, 0)), mode="edge")
        ya, xa = y0[i] - gutter, x0[i] - gutter
        yb, xb = min(ya + padded.shape[0], H), min(xa + padded.shape[1], out.shape[1])
        out[max(ya, 0) : yb, max(xa, 0) : xb] = padded[max(-ya, 0) : yb - ya, max(-xa, 0) : xb - xa]


def scale_tiles(
    texels: np.ndarray, boxes: dict, factor: np.ndarray, gutter: int, align: int = 1
) -> np.ndarray:
    """``texels`` (H, W, C) with each tile's box (the tile, its gutter ring and alignment padding)
    multiplied by ``factor`` (k,) (one per tile of ``boxes``); returns a new array."""
    out = np.array(texels, dtype=np.float64)
    H, W = out.shape[:2]
    scale = np.ones((H, W))
    x0, y0, side = boxes["x0"], boxes["y0"], boxes["side"]
    box = -(-(side + 2 * gutter) // align) * align
    for b in np.unique(box).tolist():  # a few distinct box sides: one scatter each
        sel = np.flatnonzero(box == b)
        a = np.arange(b)
        ys = np.clip(y0[sel][:, None, None] - gutter + a[None, :, None], 0, H - 1)
        xs = np.clip(x0[sel][:, None, None] - gutter + a[None, None, :], 0, W - 1)
        scale[ys, xs] = np.broadcast_to(factor[sel][:, None, None], ys.shape[:1] + (b, b))
    return out * scale[:, :, None]


#: the brightest value (times the file's white) an RGBM lightmap holds: 4 stops above white
RGBM_RANGE = 16.0


def rgbm_encode(values: np.ndarray, value_range: float = RGBM_RANGE) -> np.ndarray:
    """(h, w, 4) uint8 RGBM of linear ``values`` (h, w, 3) >= 0 (clipped at ``value_range``):
    alpha = m, the smallest multiple of 1/255 with max(values) <= m x range; rgb = sRGB 8-bit of
    values / (m x range). Decoded (:func:`rgbm_decode`) as sRGB-decoded rgb x alpha x range, which a
    GPU does after filtering an sRGB RGBA texture (alpha stays linear)."""
    from iat.color import srgb_encode

    v = np.clip(np.asarray(values, np.float64), 0.0, value_range)
    m = np.ceil(np.clip(v.max(axis=-1) / value_range, 1.0 / 255.0, 1.0) * 255.0) / 255.0
    rgb = np.clip(v / (m[..., None] * value_range), 0.0, 1.0)
    out = np.empty(v.shape[:-1] + (4,), np.uint8)
    out[..., :3] = np.round(srgb_encode(rgb) * 255.0)
    out[..., 3] = np.round(m * 255.0)
    return out


def rgbm_decode(rgbm: np.ndarray, value_range: float = RGBM_RANGE) -> np.ndarray:
    """(h, w, 3) float64 linear values of (h, w, 4) uint8 RGBM (:func:`rgbm_encode`)."""
    from iat.color import srgb_decode

    x = np.asarray(rgbm, np.float64) / 255.0
    return srgb_decode(x[..., :3]) * x[..., 3:4] * value_range
