"""Quad-tree → texture tile per patch (report §3.3, §3.6, §5.1, §5.2).

A patch of depth ``d`` (its deepest leaf level) gets a square tile of
``n = 2**d + 1`` texels per side, ``(n, n, 3) float32`` linear RGB.

Axis convention (image-like): ``tile[b, a]`` is the texel at lattice point
``(i, j) = (a << (D - d), b << (D - d))``, ``D = max_depth``: **row = j (v),
column = i (u)**. Every mesh vertex of the patch is a texel (all leaves have
level <= d, so their corners sit on multiples of ``2**(D - d)``).

Texel centres sit on the polygon corners (report §3.4): texel ``a`` of a tile
``W`` texels wide is centred on ``u = a / (W - 1)``; in texture coordinates of
the tile alone, ``s = u * (W - 1) / W + 0.5 / W``. The texture therefore reaches
half a texel beyond the polygon on every side.

Methods
-------
``bilinear``
    the report's §3.3: each leaf fills the texels it covers by bilinear
    interpolation of its corners (triangle leaves: linear), coarse leaves first
    so that finer leaves own shared edges (an edge with a hanging vertex follows
    the anchored mesh); then every texel that is a mesh vertex (hanging ones
    included) takes the vertex value.
``scan``
    the report's §5.1: the anchored mesh triangles (``solution.tri_vertices``)
    are scan-converted; every texel centre inside a triangle takes the
    barycentric interpolation of its corners, with exact integer edge functions.
    The tile equals the mesh at every texel centre.
``bicubic``
    the report's §5.2: a smooth (C1, cubic-reproducing inside, quadratic at the
    borders) fit through the *vertex values only*: hierarchical Catmull-Rom
    refinement, level by level; at each level the new lattice points are the
    Catmull-Rom midpoints of the coarser grid (weights -1/16, 9/16, 9/16, -1/16;
    at the borders the ghost point is the quadratic extrapolation
    ``3 p0 - 3 p1 + p2``), and points that are mesh vertices keep the vertex
    value. The same Catmull-Rom kernel samples the tile at any resolution
    (:func:`scale_tiles`), so the fitted surface is one continuous function.
    A field quadratic in (u, v) is reproduced exactly on quad patches.

Triangle roots occupy the lower-left half of their square (``a + b <= n - 1``).
The other half is filled by the parallelogram rule
``v(a, b) = v(a-1, b) + v(a, b-1) - v(a-1, b-1)`` (closed form in
:func:`extend_triangle`): exact for fields linear in (u, v), and a bilinear
lookup in a cell cut by the diagonal then equals the linear interpolation of
the cell's three inside texels, so filtering at the hypotenuse is exact.

Scaling (report §3.6): :func:`scale_tiles` with ``mode="clamped"`` resamples the
tile's own interpolant (bilinear for bilinear/scan, Catmull-Rom for bicubic) at
``m = max(2, floor((n - 1) * scale + 0.5) + 1)`` new lattice positions
``k (n - 1) / (m - 1)``: texel centres stay on the polygon corners, edge texels
depend on edge texels only, so corners stay exact and neighbours with equal
edges still agree. ``mode="naive"`` is a PIL image resize of the whole tile
(texel centres move by a fraction of a texel: the report's correspondence
errors), kept for comparison. Both are separable and linear: one ``(m, n)`` float32
weight matrix ``W`` per (n, m) (Pillow's own coefficients for naive), applied to every
tile of that size at once as ``W @ tile @ W.T`` (two float32 products per chunk of tiles,
block-diagonal sparse ones for the usual 2-6 taps; the per-tap float64 gathers they
replace took 6-10x longer). Neighbours of *different* sizes describe a shared edge by
different polylines (and sample it at different points once scaled); the baker matches
them after scaling (:mod:`iat.bake.seams`: the coarser side's edge polyline is copied onto the
finer side's edge texels, exact when sides are ``2**k + 1``), for clamped scaling and
scale 1 only.

Every fill is vectorised over groups of leaves / triangles of equal size; no
Python loop runs per leaf or per texel.
"""

from __future__ import annotations

import mmap

import numpy as np

from iat.errors import OptionError
from iat.geometry import quadtree as qt

__all__ = [
    "METHODS",
    "SCALE_MODES",
    "SolutionIndex",
    "TileCache",
    "extend_triangle",
    "flatten",
    "sample_tile",
    "scale_tile",
    "scale_tiles",
    "scaled_side",
    "tile_side",
    "tile_uv",
]

METHODS = ("bilinear", "scan", "bicubic")
SCALE_MODES = ("clamped", "naive")

#: elements per vectorised chunk (bounds temporary memory to a few tens of MB)
_CHUNK = 1 << 21


def tile_side(depth) -> np.ndarray | int:
    """Texels per side of an unscaled tile of a patch of tree depth ``depth``: ``2**depth + 1``."""
    if np.isscalar(depth):
        return (1 << int(depth)) + 1
    return (np.int64(1) << np.asarray(depth, dtype=np.int64)) + 1


def scaled_side(n, scale: float):
    """Side after scaling: ``max(2, floor((n - 1) * scale + 0.5) + 1)`` (ints or int arrays)."""
    m = np.maximum(
        2, np.floor((np.asarray(n, dtype=np.float64) - 1) * float(scale) + 0.5).astype(np.int64) + 1
    )
    return int(m) if np.ndim(m) == 0 else m


def tile_uv(u, v, side: int) -> np.ndarray:
    """(k, 2) float64 texture coordinates inside a tile of ``side`` texels of patch points ``(u, v)``.

    ``s = u (side - 1) / side + 0.5 / side``: texel centres on the polygon corners.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    return np.stack([(u * (side - 1) + 0.5) / side, (v * (side - 1) + 0.5) / side], axis=-1)


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise OptionError(f"unknown flatten method {method!r}; expected one of {', '.join(METHODS)}")


def _check_mode(mode: str) -> None:
    if mode not in SCALE_MODES:
        raise OptionError(f"unknown scale mode {mode!r}; expected one of {', '.join(SCALE_MODES)}")


class SolutionIndex:
    """Derived arrays of a :class:`~iat.radiosity.solution.Solution` that every flatten call needs.

    Build it once per solution and pass it to :func:`flatten` (``index=``) to save
    the decoding on repeated calls. Attributes (P patches, V vertices, L leaves, T triangles):

    depth : (P,) int64 tree depth; is_quad : (P,) bool
    vert_patch, vert_i, vert_j : (V,) int64 decoded vertex keys; radiance : (V, 3) float32
    leaf_corner_vid : (L, 4) int64 vertex indices of leaf corners (triangles repeat corner 2)
    tri : (T, 3) int64 anchored triangles; tri_patch : (T,) int64
    """

    def __init__(self, solution):
        self.solution = solution
        self.D = int(solution.max_depth)
        self.N = 1 << self.D
        self.n_patches = len(solution.patch_is_quad)
        self.is_quad = np.asarray(solution.patch_is_quad, dtype=bool)
        forest = solution.forest
        self.depth = forest.patch_depth().astype(np.int64)
        keys = np.asarray(solution.vert_key, dtype=np.int64)
        self.vert_patch, self.vert_i, self.vert_j = qt.decode_key(keys, self.N)
        self.radiance = np.asarray(solution.vert_radiance, dtype=np.float32)
        self.leaf_patch = np.asarray(forest.leaf_patch, dtype=np.int64)
        self.leaf_level = np.asarray(forest.leaf_level, dtype=np.int64)
        self.leaf_i = np.asarray(forest.leaf_i, dtype=np.int64)
        self.leaf_j = np.asarray(forest.leaf_j, dtype=np.int64)
        self.leaf_flip = np.asarray(forest.leaf_flip, dtype=bool)
        self.leaf_corner_vid = qt.lookup(keys, qt.leaf_corner_keys(forest))
        if (self.leaf_corner_vid < 0).any():
            raise ValueError("solution: a leaf corner is missing from the vertex table")
        self.tri = np.asarray(solution.tri_vertices, dtype=np.int64).reshape(-1, 3)
        self.tri_patch = self.vert_patch[self.tri[:, 0]] if len(self.tri) else np.zeros(0, np.int64)
        # per-patch counts, used by the baker's cost model
        self.patch_n_vertices = np.bincount(self.vert_patch, minlength=self.n_patches)
        self.patch_n_triangles = np.bincount(self.tri_patch, minlength=self.n_patches)


# ---------------------------------------------------------------------------
# triangle fill


def extend_triangle(tiles: np.ndarray) -> np.ndarray:
    """Fill the upper-right half (``a + b > c - 1``) of triangle tiles in place; returns ``tiles``.

    tiles : (k, c, c, C) float array, ``tiles[:, b, a]``. The filled values obey the
    parallelogram rule ``v(a, b) = v(a-1, b) + v(a, b-1) - v(a-1, b-1)`` everywhere
    outside, in closed form ``v(a, b) = g(c-1-b) + H(a) - H(c-1-b)`` with
    ``g(a) = v(a, c-1-a)`` (the hypotenuse) and ``H`` the running sum of
    ``v(a, c-1-a) - v(a-1, c-1-a)``. Exact for fields linear in (a, b).
    """
    c = tiles.shape[1]
    if c < 2:
        return tiles
    a = np.arange(c)
    g = tiles[:, c - 1 - a, a]  # (k, c, C) hypotenuse, g[:, a] = v(a, c-1-a)
    h = np.zeros_like(g)
    h[:, 1:] = g[:, 1:] - tiles[:, c - 1 - a[1:], a[1:] - 1]
    H = np.cumsum(h, axis=1)
    bb, aa = np.nonzero(a[None, :] + a[:, None] > c - 1)  # rows b, columns a outside
    r = c - 1 - bb
    tiles[:, bb, aa] = g[:, r] + H[:, aa] - H[:, r]
    return tiles


# ---------------------------------------------------------------------------
# fills


def _fill_leaves(idx: SolutionIndex, pmask, slot, sh: int, d: int, work: np.ndarray) -> None:
    """Bilinear (quads) / linear (triangles) fill of every leaf, coarse levels first."""
    n = work.shape[1]
    sel = np.flatnonzero(pmask[idx.leaf_patch])
    if not len(sel):
        return
    lvl = idx.leaf_level[sel]
    flat = work.reshape(-1, 3)
    quad = idx.is_quad[idx.leaf_patch[sel]]
    kind = np.where(quad, 0, np.where(idx.leaf_flip[sel], 2, 1))  # 0 quad, 1 up, 2 down
    for level in np.unique(lvl):
        if level == d:
            continue  # leaves one texel wide: every texel they cover is a vertex (set afterwards)
        m = 1 << (d - int(level))
        db, da = np.mgrid[0 : m + 1, 0 : m + 1]
        da, db = da.ravel(), db.ravel()
        s, t = da / m, db / m
        for k in (0, 1, 2):
            g = sel[(lvl == level) & (kind == k)]
            if not len(g):
                continue
            if k == 0:
                keep = np.ones(len(da), dtype=bool)
                w = np.stack([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t], axis=1)
            elif k == 1:
                keep = da + db <= m
                w = np.stack([1 - s - t, s, t], axis=1)
            else:
                keep = da + db >= m
                w = np.stack([s + t - 1, 1 - s, 1 - t], axis=1)
            w = w[keep]
            oa, ob = da[keep], db[keep]
            nc = w.shape[1]
            step = max(1, _CHUNK // max(1, len(oa)))
            for c0 in range(0, len(g), step):
                gg = g[c0 : c0 + step]
                cv = idx.radiance[idx.leaf_corner_vid[gg, :nc]].astype(np.float64)  # (l, nc, 3)
                vals = np.einsum("gc,lcr->lgr", w, cv)
                a0 = (idx.leaf_i[gg] >> sh)[:, None]
                b0 = (idx.leaf_j[gg] >> sh)[:, None]
                sl = slot[idx.leaf_patch[gg]][:, None]
                flat[((sl * n + b0 + ob[None]) * n + a0 + oa[None]).ravel()] = vals.reshape(-1, 3)


def _fill_scan(idx: SolutionIndex, pmask, slot, sh: int, work: np.ndarray) -> None:
    """Scan-convert the anchored triangles of the selected patches (exact integer edge functions)."""
    n = work.shape[1]
    sel = np.flatnonzero(pmask[idx.tri_patch])
    if not len(sel):
        return
    tv = idx.tri[sel]
    x = idx.vert_i[tv] >> sh  # (T, 3)
    y = idx.vert_j[tv] >> sh
    # (min/max over the small axis written out: numpy's axis-1 reductions are slow here)
    x0 = np.minimum(np.minimum(x[:, 0], x[:, 1]), x[:, 2])
    y0 = np.minimum(np.minimum(y[:, 0], y[:, 1]), y[:, 2])
    ext = np.maximum(
        np.maximum(np.maximum(x[:, 0], x[:, 1]), x[:, 2]) - x0,
        np.maximum(np.maximum(y[:, 0], y[:, 1]), y[:, 2]) - y0,
    )
    # triangles one texel wide cover only their own vertices (set afterwards): skip them
    big = np.flatnonzero(ext > 1)
    sel, tv, x, y, x0, y0, ext = sel[big], tv[big], x[big], y[big], x0[big], y0[big], ext[big]
    area2 = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    ok = np.flatnonzero(area2 != 0)  # degenerate triangles are skipped
    sel, tv, x, y, x0, y0, ext, area2 = sel[ok], tv[ok], x[ok], y[ok], x0[ok], y0[ok], ext[ok], area2[ok]
    flat = work.reshape(-1, 3)
    for e in np.unique(ext):
        e = int(e)
        g = np.flatnonzero(ext == e)
        dy, dx = np.mgrid[0 : e + 1, 0 : e + 1]
        dx, dy = dx.ravel(), dy.ravel()
        step = max(1, _CHUNK // len(dx))
        for c0 in range(0, len(g), step):
            gg = g[c0 : c0 + step]
            X, Y = x[gg], y[gg]
            px = x0[gg, None] + dx[None]
            py = y0[gg, None] + dy[None]
            sgn = np.sign(area2[gg])[:, None]
            # edge functions: w_k is opposite vertex k, w0 + w1 + w2 = area2
            w0 = (X[:, 2:3] - X[:, 1:2]) * (py - Y[:, 1:2]) - (Y[:, 2:3] - Y[:, 1:2]) * (px - X[:, 1:2])
            w1 = (X[:, 0:1] - X[:, 2:3]) * (py - Y[:, 2:3]) - (Y[:, 0:1] - Y[:, 2:3]) * (px - X[:, 2:3])
            w2 = (X[:, 1:2] - X[:, 0:1]) * (py - Y[:, 0:1]) - (Y[:, 1:2] - Y[:, 0:1]) * (px - X[:, 0:1])
            inside = (w0 * sgn >= 0) & (w1 * sgn >= 0) & (w2 * sgn >= 0)
            ti, gi = np.nonzero(inside)
            cv = idx.radiance[tv[gg]].astype(np.float64)  # (t, 3, 3)
            inv = 1.0 / area2[gg][ti]
            vals = (
                (w0[ti, gi] * inv)[:, None] * cv[ti, 0]
                + (w1[ti, gi] * inv)[:, None] * cv[ti, 1]
                + (w2[ti, gi] * inv)[:, None] * cv[ti, 2]
            )
            sl = slot[idx.tri_patch[sel[gg]]]
            flat[(sl[ti] * n + py[ti, gi]) * n + px[ti, gi]] = vals


def _set_vertices(idx: SolutionIndex, pmask, slot, sh: int, work: np.ndarray, mask=None) -> None:
    v = np.flatnonzero(pmask[idx.vert_patch])
    s = slot[idx.vert_patch[v]]
    b = idx.vert_j[v] >> sh
    a = idx.vert_i[v] >> sh
    work[s, b, a] = idx.radiance[v]
    if mask is not None:
        mask[s, b, a] = True


def _cr_mid(x: np.ndarray, axis: int) -> np.ndarray:
    """Catmull-Rom midpoints along ``axis``: (..., c, ...) -> (..., c - 1, ...).

    Ghost points: quadratic extrapolation ``3 p0 - 3 p1 + p2`` (linear when c == 2).
    """
    x = np.moveaxis(x, axis, 0)
    c = x.shape[0]
    if c == 2:
        mid = 0.5 * (x[0] + x[1])[None]
    else:
        gl = 3 * x[0] - 3 * x[1] + x[2]
        gr = 3 * x[-1] - 3 * x[-2] + x[-3]
        p = np.concatenate([gl[None], x, gr[None]], axis=0)
        mid = (9.0 * (p[1:-2] + p[2:-1]) - p[:-3] - p[3:]) * (1.0 / 16.0)
    return np.moveaxis(mid, 0, axis)


def _cr_upsample(x: np.ndarray) -> np.ndarray:
    """(k, c, c, C) -> (k, 2c-1, 2c-1, C): even points kept, odd points Catmull-Rom midpoints."""
    k, c, _, ch = x.shape
    r = np.empty((k, c, 2 * c - 1, ch), dtype=x.dtype)
    r[:, :, 0::2] = x
    r[:, :, 1::2] = _cr_mid(x, 2)
    out = np.empty((k, 2 * c - 1, 2 * c - 1, ch), dtype=x.dtype)
    out[:, 0::2] = r
    out[:, 1::2] = _cr_mid(r, 1)
    return out


def _fill_bicubic(idx: SolutionIndex, pmask, slot, sh: int, d: int, work: np.ndarray, tri_slots) -> None:
    """Hierarchical Catmull-Rom refinement through the vertex values (see module docstring)."""
    k, n = work.shape[:2]
    vmask = np.zeros((k, n, n), dtype=bool)
    _set_vertices(idx, pmask, slot, sh, work, vmask)
    if len(tri_slots):
        c = work[:, :: n - 1, :: n - 1]
        c[tri_slots] = extend_triangle(c[tri_slots])
    for level in range(1, d + 1):
        s = 1 << (d - level)
        up = _cr_upsample(work[:, :: 2 * s, :: 2 * s])
        fine = work[:, ::s, ::s]
        np.copyto(fine, up, where=~vmask[:, ::s, ::s, None])
        if len(tri_slots):
            fine[tri_slots] = extend_triangle(fine[tri_slots])


def _flatten_group(idx: SolutionIndex, ps: np.ndarray, d: int, method: str) -> np.ndarray:
    """(k, n, n, 3) float32 tiles of patches ``ps`` (all of depth ``d``)."""
    n = (1 << d) + 1
    sh = idx.D - d
    k = len(ps)
    slot = np.full(idx.n_patches, -1, dtype=np.int64)
    slot[ps] = np.arange(k)
    pmask = np.zeros(idx.n_patches, dtype=bool)
    pmask[ps] = True
    tri_slots = np.flatnonzero(~idx.is_quad[ps])
    work = np.zeros((k, n, n, 3), dtype=np.float64)
    if method == "bicubic":
        _fill_bicubic(idx, pmask, slot, sh, d, work, tri_slots)
    else:
        if method == "bilinear":
            _fill_leaves(idx, pmask, slot, sh, d, work)
        else:
            _fill_scan(idx, pmask, slot, sh, work)
        _set_vertices(idx, pmask, slot, sh, work)
        if len(tri_slots):
            work[tri_slots] = extend_triangle(work[tri_slots])
    return work.astype(np.float32)


def flatten(solution, patches=None, method: str = "bilinear", *, index: SolutionIndex | None = None) -> dict:
    """Texture tiles of patches, ``{patch: (n, n, 3) float32}`` with ``n = 2**depth + 1``.

    solution : a :class:`~iat.radiosity.solution.Solution`
    patches : (k,) ints, or None for every patch
    method : "bilinear" | "scan" | "bicubic" (see the module docstring)
    index : a :class:`SolutionIndex` of ``solution`` to reuse (built when None)

    ``tile[b, a]`` holds lattice point ``(a << (D - d), b << (D - d))``. Tiles of
    patches of equal depth are views of one stacked array.
    """
    _check_method(method)
    idx = index if index is not None else SolutionIndex(solution)
    if patches is None:
        ps_all = np.arange(idx.n_patches, dtype=np.int64)
    else:
        ps_all = np.unique(np.asarray(patches, dtype=np.int64).reshape(-1))
        if len(ps_all) and (ps_all[0] < 0 or ps_all[-1] >= idx.n_patches):
            raise OptionError(f"flatten: patch index out of range 0..{idx.n_patches - 1}")
    out: dict[int, np.ndarray] = {}
    dep = idx.depth[ps_all]
    for d in np.unique(dep):
        ps = ps_all[dep == d]
        tiles = _flatten_group(idx, ps, int(d), method)
        out.update(zip(ps.tolist(), tiles, strict=True))
    return out


# ---------------------------------------------------------------------------
# sampling and scaling


def axis_weights(n: int, pos: np.ndarray, kernel: str) -> tuple[np.ndarray, np.ndarray]:
    """Taps and weights to interpolate a row of ``n`` samples at ``pos`` (texel units, [0, n-1]).

    Returns (idx (k, taps) int64 into the row, w (k, taps) float64). The cubic
    kernel is Catmull-Rom with quadratic ghost points folded into the weights.
    """
    pos = np.clip(np.asarray(pos, dtype=np.float64), 0.0, n - 1)
    i0 = np.minimum(np.floor(pos).astype(np.int64), n - 2)
    t = pos - i0
    if kernel == "bilinear" or n == 2:
        return np.stack([i0, i0 + 1], axis=1), np.stack([1 - t, t], axis=1)
    t2, t3 = t * t, t * t * t
    w = np.stack(
        [
            0.5 * (-t3 + 2 * t2 - t),
            0.5 * (3 * t3 - 5 * t2 + 2),
            0.5 * (-3 * t3 + 4 * t2 + t),
            0.5 * (t3 - t2),
        ],
        axis=1,
    )
    taps = i0[:, None] + np.arange(-1, 3)[None, :]
    # fold ghosts: p[-1] = 3 p0 - 3 p1 + p2 ; p[n] = 3 p[n-1] - 3 p[n-2] + p[n-3]
    k = len(pos)
    idx = np.zeros((k, 6), dtype=np.int64)
    ww = np.zeros((k, 6))
    idx[:, :4] = np.clip(taps, 0, n - 1)
    ww[:, :4] = w
    lo = taps[:, 0] < 0
    ww[lo, 0] = 3 * w[lo, 0]  # tap 0 -> p0 (already clipped to 0)
    idx[lo, 4], ww[lo, 4] = 1, -3 * w[lo, 0]
    idx[lo, 5], ww[lo, 5] = 2, w[lo, 0]
    hi = taps[:, 3] > n - 1
    ww[hi, 3] = 3 * w[hi, 3]  # tap 3 -> p[n-1]
    idx[hi, 4], ww[hi, 4] = n - 2, -3 * w[hi, 3]
    idx[hi, 5], ww[hi, 5] = n - 3, w[hi, 3]
    return idx, ww


def _clamped_weights(n: int, m: int, kernel: str) -> np.ndarray:
    """(m, n) float64 weights of the clamped resample of a row of ``n`` samples to ``m``.

    Row ``k`` interpolates at ``k (n - 1) / (m - 1)`` (:func:`axis_weights`): rows 0 and
    ``m - 1`` are unit vectors, so edge texels are copied exactly.
    """
    pos = np.arange(m) * ((n - 1) / (m - 1))
    pos[-1] = n - 1
    idx, w = axis_weights(n, pos, kernel)
    W = np.zeros((m, n))
    np.add.at(W, (np.repeat(np.arange(m), idx.shape[1]), idx.ravel()), w.ravel())
    return W


def _pil_filter(x: np.ndarray, kernel: str) -> np.ndarray:
    x = np.abs(x)
    if kernel == "bilinear":
        return np.where(x < 1.0, 1.0 - x, 0.0)
    a = -0.5  # Pillow's bicubic
    return np.where(
        x < 1.0,
        ((a + 2.0) * x - (a + 3.0)) * x * x + 1,
        np.where(x < 2.0, (((x - 5) * x + 8) * x - 4) * a, 0.0),
    )


def _naive_weights(n: int, m: int, kernel: str) -> np.ndarray:
    """(m, n) float64 weights of Pillow's ``Image.resize`` (BILINEAR / BICUBIC) of ``n`` -> ``m``
    samples: ``precompute_coeffs`` of Pillow's ``Resample.c`` (support widened by the
    reduction factor, taps normalised), so the naive mode is a matrix product too."""
    scale = n / m
    fs = max(scale, 1.0)
    support = (1.0 if kernel == "bilinear" else 2.0) * fs
    center = (np.arange(m) + 0.5) * scale
    xmin = np.maximum(np.trunc(center - support + 0.5).astype(np.int64), 0)
    xmax = np.minimum(np.trunc(center + support + 0.5).astype(np.int64), n)
    x = np.arange(n)[None, :]
    inside = (x >= xmin[:, None]) & (x < xmax[:, None])
    W = np.where(inside, _pil_filter((x - center[:, None] + 0.5) / fs, kernel), 0.0)
    ww = W.sum(axis=1, keepdims=True)
    return np.where(ww != 0.0, W / np.where(ww != 0.0, ww, 1.0), W)


def populated_empty(shape, dtype=np.float32) -> np.ndarray:
    """``np.empty(shape, dtype)`` whose memory the kernel has already mapped (``MAP_POPULATE``),
    for large arrays that are written once and kept (scaled tiles, GPU boxes). numpy asks for
    transparent huge pages on large allocations (``madvise``); where the kernel cannot provide
    them (this VM: ``AnonHugePages`` 0) every first touch then faults at ~2 ms per MB, 4x the
    cost of plain pages and 6x that of a populated mapping (18 MB: 37 ms, 9 ms, 6 ms)."""
    shape = tuple(int(x) for x in np.atleast_1d(shape))
    dtype = np.dtype(dtype)
    n = int(np.prod(shape)) * dtype.itemsize
    if n < 1 << 20 or not hasattr(mmap, "MAP_POPULATE"):
        return np.empty(shape, dtype=dtype)
    buf = mmap.mmap(-1, n, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | mmap.MAP_POPULATE)
    return np.frombuffer(buf, dtype=dtype).reshape(shape)


_WEIGHTS: dict = {}


def _weights(n: int, m: int, kernel: str, mode: str) -> np.ndarray:
    """(m, n) float32 resampling matrix, cached per (n, m, kernel, mode); read-only."""
    key = (int(n), int(m), kernel, mode)
    W = _WEIGHTS.get(key)
    if W is None:
        W = (_clamped_weights if mode == "clamped" else _naive_weights)(n, m, kernel).astype(np.float32)
        W.flags.writeable = False
        if len(_WEIGHTS) > 256:
            _WEIGHTS.clear()
        _WEIGHTS[key] = W
    return W


_BLOCKS: dict = {}


def _block_diag(W: np.ndarray, c: int):
    """``kron(I_c, W)`` as a scipy CSR matrix (float32), cached per (``W``, ``c``)."""
    key = (id(W), int(c))
    hit = _BLOCKS.get(key)
    if hit is not None and hit[0] is W:
        return hit[1]
    from scipy.sparse import csr_matrix

    m, n = W.shape
    r, col = np.nonzero(W)  # row-major: rows sorted
    b = np.arange(c, dtype=np.int64)[:, None]
    cols = (b * n + col[None]).ravel()
    counts = np.bincount(r, minlength=m)
    indptr = np.concatenate([[0], np.cumsum(np.tile(counts, c))])
    K = csr_matrix((np.tile(W[r, col], c), cols, indptr), shape=(c * m, c * n))
    if len(_BLOCKS) > 64:
        _BLOCKS.clear()
    _BLOCKS[key] = (W, K)
    return K


def _resample_stack(tiles, W: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``W @ tile @ W.T`` per tile and channel: (k, n, n, C) -> (k, m, m, C) float32.

    Two float32 products per chunk of tiles (temporaries near 2 MB, below numpy's huge-page
    threshold, so the heap reuses them): rows (``W`` times each tile seen as ``(n, n C)``),
    then columns (``W`` times each resampled row seen as ``(n, C)``). ``tiles`` is an array
    or a list of equal tiles (stacked a chunk at a time). When ``W`` is sparse (the bilinear
    and cubic kernels: 2-6 taps of ``n``) both products are one block-diagonal CSR matrix
    ``kron(I, W)`` times the chunk (1.5-2x faster than the dense products on 65-texel tiles);
    otherwise batched ``np.matmul``. One big dense GEMM for the columns (``kron(W, I_C)``) was
    faster on an idle machine but several times slower while another process held a core.
    """
    k = len(tiles)
    n, ch = (
        (tiles.shape[1], tiles.shape[3])
        if isinstance(tiles, np.ndarray)
        else (tiles[0].shape[0], tiles[0].shape[2])
    )
    m = W.shape[0]
    if out is None:
        out = populated_empty((k, m, m, ch), np.float32)
    step = max(1, (2 << 20) // max(1, max(m, n) * n * ch * 4))
    sparse = n >= 8 and np.count_nonzero(W) * 4 <= W.size
    for c0 in range(0, k, step):
        t = tiles[c0 : c0 + step]
        t = np.stack(t).astype(np.float32, copy=False) if isinstance(t, (list, tuple)) else t
        t = np.ascontiguousarray(t, dtype=np.float32)
        kk = len(t)
        dst = out[c0 : c0 + kk]
        if sparse:
            rows = _block_diag(W, kk) @ t.reshape(kk * n, n * ch)  # (kk m, n C)
            dst[...] = (_block_diag(W, kk * m) @ rows.reshape(kk * m * n, ch)).reshape(kk, m, m, ch)
        else:
            rows = np.matmul(W, t.reshape(kk, n, n * ch)).reshape(kk * m, n, ch)  # (k m, n, C)
            np.matmul(W, rows, out=dst.reshape(kk * m, m, ch))
    return out


def _kernel(method: str) -> str:
    return "cubic" if method == "bicubic" else "bilinear"


def scale_tiles(
    tiles: np.ndarray, scale: float, mode: str = "clamped", method: str = "bilinear", triangle=False
) -> np.ndarray:
    """Resample a stack of tiles, (k, n, n, 3) (an array or a list of equal tiles) -> (k, m, m, 3) float32.

    scale : > 0; ``m = max(2, floor((n - 1) * scale + 0.5) + 1)``
    mode : "clamped" resamples the tile's interpolant (bilinear for bilinear/scan,
      Catmull-Rom for bicubic) at ``k (n-1)/(m-1)``: corners exact, edges from
      edge texels only; "naive" resizes each tile as an image as PIL does (BILINEAR,
      or BICUBIC for bicubic: Pillow's weights, :func:`_naive_weights`), moving the texel centres.
    Both are one (m, n) float32 weight matrix ``W`` per (n, m) applied as ``W @ tile @ W.T``
    to all tiles at once (batched matrix products, :func:`_resample_stack`).
    triangle : bool or (k,) bools: triangle tiles get their outer half refilled
      (:func:`extend_triangle`) after a clamped resample.
    """
    _check_mode(mode)
    _check_method(method)
    if not scale > 0:
        raise OptionError(f"scale must be > 0, got {scale}")
    if not isinstance(tiles, (list, tuple)):
        tiles = np.asarray(tiles)
        k, n = tiles.shape[:2]
    elif not tiles:
        raise OptionError("scale_tiles: no tiles")
    else:
        k, n = len(tiles), tiles[0].shape[0]
    m = scaled_side(n, scale)
    if m == n:
        return np.array(np.stack(tiles) if isinstance(tiles, (list, tuple)) else tiles, dtype=np.float32)
    kern = _kernel(method)
    out = _resample_stack(tiles, _weights(n, m, kern, mode))
    if mode == "naive":
        return out
    tri = np.broadcast_to(np.asarray(triangle, dtype=bool), (k,))
    if tri.any():
        sel = np.flatnonzero(tri)
        out[sel] = extend_triangle(out[sel].astype(np.float64))
    return out


def scale_tile(
    tile: np.ndarray, scale: float, mode: str = "clamped", method: str = "bilinear", triangle=False
):
    """One tile (n, n, 3) -> (m, m, 3) float32; see :func:`scale_tiles`."""
    return scale_tiles(np.asarray(tile)[None], scale, mode, method, triangle)[0]


def sample_tile(tile: np.ndarray, u, v, kernel: str = "bilinear") -> np.ndarray:
    """(k, 3) float64 values of a tile at patch points ``(u, v)`` in [0, 1] (texel centres on corners).

    kernel : "bilinear" (what texture filtering shows) or "cubic" (the bicubic surface).
    """
    tile = np.asarray(tile, dtype=np.float64)
    n = tile.shape[0]
    u = np.atleast_1d(np.asarray(u, dtype=np.float64))
    v = np.atleast_1d(np.asarray(v, dtype=np.float64))
    ia, wa = axis_weights(n, u * (n - 1), kernel)
    ib, wb = axis_weights(n, v * (n - 1), kernel)
    out = np.zeros((len(u), tile.shape[2]))
    for p in range(ib.shape[1]):
        for q in range(ia.shape[1]):
            out += (wb[:, p] * wa[:, q])[:, None] * tile[ib[:, p], ia[:, q]]
    return out


# ---------------------------------------------------------------------------
# cache


class TileCache:
    """Tiles keyed by ``(patch, method, scale, mode)``, reused across re-bakes.

    ``get`` flattens (and scales) only the patches it has not seen with that key.
    Counters: ``flatten_calls`` (calls of :func:`flatten`), ``tiles_flattened``,
    ``scale_calls``, ``tiles_scaled``. Scale 1 is stored once, whatever the mode, and kept
    for good; of the scaled sets (a scale slider makes one per position) only the
    ``max_scaled_sets`` most recently used are kept. Cached tiles are read-only.
    """

    def __init__(self, solution, index: SolutionIndex | None = None, max_scaled_sets: int = 8):
        self.solution = solution
        self.index = index if index is not None else SolutionIndex(solution)
        self.max_scaled_sets = int(max_scaled_sets)
        self._store: dict[tuple, dict[int, np.ndarray]] = {}
        self.flatten_calls = 0
        self.tiles_flattened = 0
        self.scale_calls = 0
        self.tiles_scaled = 0

    @staticmethod
    def key(method: str, scale: float, mode: str) -> tuple:
        scale = float(scale)
        return (method, scale, "clamped" if scale == 1.0 else mode)

    def clear(self) -> None:
        self._store.clear()

    def __len__(self) -> int:
        return sum(len(d) for d in self._store.values())

    def get(self, patches, method: str = "bilinear", scale: float = 1.0, mode: str = "clamped") -> list:
        """Tiles of ``patches`` (in the order given), each (m, m, 3) float32."""
        _check_method(method)
        _check_mode(mode)
        if not scale > 0:
            raise OptionError(f"scale must be > 0, got {scale}")
        patches = np.asarray(patches, dtype=np.int64).reshape(-1)
        key = self.key(method, scale, mode)
        store = self._store.pop(key, None)
        if store is None:
            store = {}
        self._store[key] = store  # most recently used last
        scaled = [k for k in self._store if k[1] != 1.0]
        for k in scaled[: max(0, len(scaled) - self.max_scaled_sets)]:
            del self._store[k]
        missing = [p for p in patches.tolist() if p not in store]
        if missing:
            if key[1] == 1.0:
                self.flatten_calls += 1
                self.tiles_flattened += len(missing)
                new = flatten(self.solution, missing, method, index=self.index)
                for t in new.values():
                    t.flags.writeable = False
                store.update(new)
            else:
                base = self.get(missing, method, 1.0)
                sides = np.array([t.shape[0] for t in base])
                miss = np.asarray(missing)
                tri = ~self.index.is_quad[miss]
                self.scale_calls += 1
                self.tiles_scaled += len(missing)
                for n in np.unique(sides):
                    for is_tri in (False, True):
                        g = np.flatnonzero((sides == n) & (tri == is_tri))
                        if not len(g):
                            continue
                        out = scale_tiles([base[q] for q in g], key[1], key[2], method, triangle=is_tri)
                        out.flags.writeable = False
                        store.update(zip(miss[g].tolist(), out, strict=True))
        return [store[p] for p in patches.tolist()]
