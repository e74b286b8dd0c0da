"""Level of detail for illumination textures (report §6.2.2): per textured patch, a chain of
coarser tiles made from the quad-tree's own levels, packed into atlas pages, and the choice of
the levels a view needs (streaming by distance).

Levels. A patch of depth ``d`` has a finest tile of ``n = 2**d + 1`` texels a side (``m`` after
scaling); its level ``j`` (``j = 0`` the finest) has ``(m - 1) / 2**j + 1`` texels, while that
divides: texel ``(a, b)`` of level ``j`` is texel ``(a 2**j, b 2**j)`` of the finest, i.e. (at
scale 1) lattice point ``(a << (D - k), b << (D - k))`` of tree level ``k = d - j``, valued as the
baker samples the finest level: the vertex value where the tree has a vertex there, else the
bilinear fill of the leaf that covers it. Bilinear filtering of level ``j`` therefore draws the
tree cut at level ``k`` (every node of level ``k`` interpolating its four corners), not a box filter
of the finest texture. The chain ends at 2 texels (the patch's corners, tree level 0). Tiles are
the harmonised finest tiles (seams, :mod:`iat.bake.seams`) divided by the albedo on detail
patches, so every level keeps the seams of its neighbours at the same level; triangle tiles are
re-extended (:func:`~iat.bake.flatten.extend_triangle`) at each level.

Boxes. Each (tile, level) entry is a box with :data:`LOD_GUTTER` texels of edge replication
(no alignment: the renderer samples each level with ``textureLod(..., 0)``, never hardware mip
levels), in the policy's GPU form. :meth:`LodChain.pages` packs any subset of entries (the
resident ones) with :func:`iat.bake.atlas.pack` and returns the pages and the table the shader
reads: per tile a header texel ``(n_levels, finest resident level, m - 1, 0)`` and per level
``(x, y, page, side - 1)`` in texels (x, y of texel (0, 0)).

Choosing a level (the renderer's shader, ``iat.glsl`` with ``LOD``): ``lambda = log2(rho) +
bias``, ``rho = max(|d tc / dx|, |d tc / dy|)`` finest texels per pixel (``tc = st (m - 1)``,
``st`` the patch's lattice coordinates), clamped to ``[finest resident, n_levels - 1]``; the two
levels ``floor(lambda)`` and the next are sampled and mixed by ``fract(lambda)`` (a trilinear-like
blend in one pass; ``lambda`` is continuous across frames, so nothing pops).

Streaming (:func:`needed_levels`, :func:`resident_levels`): per tile, a lower bound of the
shader's ``lambda`` over the patch from the camera (the nearest view depth of its corners, the
largest texel of its lattice, the frustum's widest angle); levels finer than its floor are not
needed anywhere on the patch, so they need not be resident; a patch behind the camera or outside
the (slightly widened) frustum needs only its coarsest level. A budget coarsens every tile by one
more level at a time until the resident pages fit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from iat.bake import atlas
from iat.bake.boxes import build_boxes
from iat.bake.flatten import extend_triangle
from iat.bake.formats import BYTES_PER_TEXEL

__all__ = [
    "LOD_GUTTER",
    "LodChain",
    "LodPages",
    "build_chain",
    "finest_tiles",
    "fit_pages",
    "level_sides",
    "needed_levels",
    "resident_levels",
]

#: edge-replicated texels around each level's box (bilinear lookups at the polygon's edge read
#: the edge texels only; one more guards against interpolated st slightly outside [0, 1])
LOD_GUTTER = 1


def level_sides(m) -> np.ndarray:
    """(k, L) int64 sides of the levels of tiles of sides ``m`` (k,): column ``j`` is
    ``(m - 1) / 2**j + 1`` while that is an integer >= 2, else 0 (no such level)."""
    m = np.asarray(m, dtype=np.int64).reshape(-1)
    span = m - 1
    cols = [span]
    while True:
        prev = cols[-1]
        nxt = np.where((prev >= 2) & (prev % 2 == 0), prev // 2, 0)
        if not nxt.any():
            break
        cols.append(nxt)
    spans = np.stack(cols, axis=1) if len(m) else np.zeros((0, 1), np.int64)
    return np.where(spans > 0, spans + 1, 0)


@dataclass
class LodPages:
    """Pages of a set of resident entries.

    gpu : (n_pages, H, W, 4) GPU form (:data:`~iat.bake.formats.GPU_DTYPES`)
    table : (T, L + 1, 4) float32: column 0 ``(n_levels, finest resident level, m - 1, 0)``,
      column ``1 + j`` ``(x, y, page, side - 1)`` of level ``j`` (zeros where not resident)
    resident : (T,) int64 finest resident level per tile; packing : the :class:`~iat.bake.atlas.Packing`
    bytes : texture bytes of the pages (level 0 only: no hardware mip levels)
    """

    gpu: np.ndarray
    table: np.ndarray
    resident: np.ndarray
    packing: atlas.Packing
    bytes: int


@dataclass
class LodChain:
    """Every level of every textured tile of one bake (see the module docstring).

    tile_patch : (T,) int64 textured patches (the bake's ``ps`` order)
    sides : (T, L) int64 level sides (0: no such level); n_levels : (T,) int64
    tree_level : (T, L) int64 the quad-tree level each entry holds at scale 1 (``log2(side - 1)``)
    boxes : {(t, j): (bs, bs, 4) GPU-form box} (level ``j`` of tile ``t``, ``LOD_GUTTER`` ring)
    corners : (T, 4, 3) float64 world corners (triangles repeat corner 2); is_quad : (T,) bool
    texel_world : (T,) float64 the largest world length of one finest texel step (the largest
      singular value of the patch's lattice-to-world map over ``m - 1``)
    pixel_format, page_size : as baked; bytes_per_texel : of the format
    finest_placements : (T, 3) int64 ``[page, x, y]`` of the finest tiles in the bake's own pages,
      finest_size : their ``(W, H)`` (to recover each vertex's lattice coordinates from its uv)
    """

    tile_patch: np.ndarray
    sides: np.ndarray
    n_levels: np.ndarray
    tree_level: np.ndarray
    boxes: dict
    corners: np.ndarray
    is_quad: np.ndarray
    texel_world: np.ndarray
    pixel_format: str
    page_size: int
    bytes_per_texel: int
    finest_placements: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    finest_size: tuple = (1, 1)
    _full: LodPages | None = field(default=None, repr=False, compare=False)
    _stacks: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def n_tiles(self) -> int:
        return len(self.tile_patch)

    @property
    def max_levels(self) -> int:
        return int(self.sides.shape[1]) if self.n_tiles else 1

    def pages(self, resident: np.ndarray | None = None) -> LodPages:
        """The pages holding levels ``j >= resident[t]`` of every tile ``t`` (None: all levels;
        that one is cached). Packed tallest first (:func:`~iat.bake.atlas.pack`, pages of at most
        ``page_size``, shrunk when one page holds everything)."""
        if resident is None and self._full is not None:
            return self._full
        T, L = self.n_tiles, self.max_levels
        res = np.zeros(T, np.int64) if resident is None else np.asarray(resident, np.int64).reshape(T)
        res = np.clip(res, 0, np.maximum(self.n_levels - 1, 0))
        tt, jj = np.nonzero((self.sides > 0) & (np.arange(L)[None, :] >= res[:, None]))
        s = self.sides[tt, jj]
        pk = atlas.pack(np.stack([s, s], axis=1), self.page_size, LOD_GUTTER, 1, names=self.tile_patch[tt])
        stacks, row = self._stacked()
        gpu_dtype = next(iter(stacks.values())).dtype if stacks else np.float16
        gpu = np.zeros((pk.n_pages, max(pk.height, 1), max(pk.width, 1), 4), dtype=gpu_dtype)
        H, W = gpu.shape[1:3]
        per = 4 * gpu.dtype.itemsize  # one texel as one integer (8 bytes for half floats)
        tdt = np.dtype(f"u{per}") if per in (1, 2, 4, 8) else None
        flat = gpu.view(tdt).reshape(-1) if tdt is not None else gpu.reshape(-1, 4)
        for side, stack in stacks.items():  # one scatter per box size, never a loop over boxes
            sel = np.flatnonzero(s == side)
            if not len(sel):
                continue
            bs = side + 2 * LOD_GUTTER
            pl = pk.placements[sel] - [0, LOD_GUTTER, LOD_GUTTER]
            r = np.arange(bs)
            idx = (
                (pl[:, 0, None, None] * H + pl[:, 2, None, None] + r[:, None]) * W + pl[:, 1, None, None] + r
            ).ravel()
            src = np.ascontiguousarray(stack[row[tt[sel], jj[sel]]])
            flat[idx] = src.view(tdt).reshape(-1) if tdt is not None else src.reshape(-1, 4)
        gpu.flags.writeable = False
        table = np.zeros((T, L + 1, 4), np.float32)
        table[:, 0, 0] = self.n_levels
        table[:, 0, 1] = res
        table[:, 0, 2] = np.maximum(self.sides[:, 0] - 1, 0) if T else 0
        table[tt, 1 + jj, 0] = pk.placements[:, 1]
        table[tt, 1 + jj, 1] = pk.placements[:, 2]
        table[tt, 1 + jj, 2] = pk.placements[:, 0]
        table[tt, 1 + jj, 3] = s - 1
        nbytes = int(pk.n_pages) * int(pk.width) * int(pk.height) * self.bytes_per_texel
        out = LodPages(gpu, table, res, pk, nbytes)
        if resident is None:
            self._full = out
        return out

    def _stacked(self) -> tuple[dict, np.ndarray]:
        """``({side: (k, bs, bs, 4) boxes of that tile side}, (T, L) row of each entry in its
        side's stack)``, made on first use and kept."""
        if self._stacks is None:
            row = np.full(self.sides.shape, -1, np.int64)
            stacks = {}
            for side in np.unique(self.sides[self.sides > 0]).tolist():
                tt, jj = np.nonzero(self.sides == side)
                stacks[side] = np.stack(
                    [self.boxes[(t, j)] for t, j in zip(tt.tolist(), jj.tolist(), strict=True)]
                )
                row[tt, jj] = np.arange(len(tt))
            self._stacks = (stacks, row)
        return self._stacks

    def entry_bytes(self) -> np.ndarray:
        """(T, L) int64 texture bytes of each entry's box (0 where there is no level)."""
        bs = np.where(self.sides > 0, self.sides + 2 * LOD_GUTTER, 0)
        return bs * bs * self.bytes_per_texel

    def tile_st(self, tex_patch: np.ndarray, tex_uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per textured vertex: ``(st (K, 2) float32 lattice coordinates in [0, 1], tile (K,)
        float32 index)``, recovered from the finest atlas uv of the bake (``tex_uv``, texel
        ``(a, b)`` at ``((x + a + 0.5) / W, (y + b + 0.5) / H)``)."""
        placements = self.finest_placements
        width, height = self.finest_size
        t = np.searchsorted(self.tile_patch, np.asarray(tex_patch, np.int64))
        span = np.maximum(self.sides[t, 0] - 1, 1).astype(np.float64)
        uv = np.asarray(tex_uv, np.float64)
        s = (uv[:, 0] * width - 0.5 - placements[t, 1]) / span
        r = (uv[:, 1] * height - 0.5 - placements[t, 2]) / span
        return np.stack([s, r], axis=1).astype(np.float32), t.astype(np.float32)


def _texel_world(corners: np.ndarray, is_quad: np.ndarray, span: np.ndarray) -> np.ndarray:
    """(T,) largest singular value of the lattice-to-world map ``[e_u, e_v] / span``: the longest
    world step of one finest texel (an upper bound over a non-parallelogram quad's two halves)."""
    c = np.asarray(corners, np.float64)
    eu = c[:, 1] - c[:, 0]
    ev = np.where(is_quad[:, None], c[:, 3] - c[:, 0], c[:, 2] - c[:, 0])
    eu2 = np.where(is_quad[:, None], c[:, 2] - c[:, 3], eu)  # the opposite edges of a quad
    ev2 = np.where(is_quad[:, None], c[:, 2] - c[:, 1], ev)
    out = np.zeros(len(c))
    for a, b in ((eu, ev), (eu2, ev2), (eu, ev2), (eu2, ev)):
        g11, g22, g12 = (a * a).sum(1), (b * b).sum(1), (a * b).sum(1)
        tr, det = g11 + g22, g11 * g22 - g12 * g12
        lam = 0.5 * (tr + np.sqrt(np.maximum(tr * tr - 4 * det, 0.0)))
        out = np.maximum(out, np.sqrt(lam))
    return out / np.maximum(span, 1)


def finest_tiles(pages: np.ndarray, placements: np.ndarray, sides: np.ndarray) -> list:
    """The finest tiles as the bake stored them: ``pages[page, y:y+m, x:x+m]`` (float32 pages
    ``(n, H, W, 3)``, placements (T, 3) ``[page, x, y]``, sides (T,)), each ``(m, m, 3)``."""
    return [
        pages[p, y : y + m, x : x + m]
        for (p, x, y), m in zip(np.asarray(placements).tolist(), np.asarray(sides).tolist(), strict=True)
    ]


def build_chain(
    finest: list,
    ps: np.ndarray,
    corners: np.ndarray,
    is_quad: np.ndarray,
    pixel_format: str,
    page_scale: float,
    page_size: int,
    packing: atlas.Packing | None = None,
) -> LodChain:
    """The :class:`LodChain` of a bake's textured tiles.

    finest : per textured patch (``ps`` order), its finest tile ``(m, m, 3)`` float32 as stored
      (:func:`finest_tiles`: harmonised, divided by the albedo on detail patches)
    ps : (T,) int64 textured patches; corners : (P, 4, 3) world corners; is_quad : (P,) bool
    pixel_format, page_scale : the GPU form of the boxes; page_size : the largest page side
    packing : the bake's packing of the finest tiles (placements and page size kept)
    """
    ps = np.asarray(ps, np.int64)
    T = len(ps)
    m = np.array([t.shape[0] for t in finest], dtype=np.int64)
    sides = level_sides(m) if T else np.zeros((0, 1), np.int64)
    n_levels = (sides > 0).sum(axis=1).astype(np.int64)
    tri = ~np.asarray(is_quad, bool)[ps]
    boxes: dict = {}
    for j in range(sides.shape[1]):
        sel = np.flatnonzero(sides[:, j] > 0)
        if not len(sel):
            continue
        step = 1 << j
        tiles = []
        for t in sel.tolist():
            lv = np.ascontiguousarray(finest[t][::step, ::step])
            if tri[t] and j:
                lv = extend_triangle(lv[None])[0]
            tiles.append(lv)
        built = build_boxes(
            tiles, [None] * len(sel), tri[sel], [None] * len(sel), LOD_GUTTER, 1, pixel_format, page_scale
        )
        for t, (_, box) in zip(sel.tolist(), built, strict=True):
            boxes[(t, j)] = box
    tree_level = np.where(sides > 0, np.log2(np.maximum(sides - 1, 1)).round().astype(np.int64), -1)
    c = np.asarray(corners, np.float64)[ps] if T else np.zeros((0, 4, 3))
    q = np.asarray(is_quad, bool)[ps]
    return LodChain(
        tile_patch=ps,
        sides=sides,
        n_levels=n_levels,
        tree_level=tree_level,
        boxes=boxes,
        corners=c,
        is_quad=q,
        texel_world=_texel_world(c, q, m - 1) if T else np.zeros(0),
        pixel_format=pixel_format,
        page_size=int(page_size),
        bytes_per_texel=BYTES_PER_TEXEL[pixel_format],
        finest_placements=np.asarray(packing.placements, np.int64)
        if packing is not None
        else np.zeros((T, 3), np.int64),
        finest_size=(int(packing.width), int(packing.height)) if packing is not None else (1, 1),
    )


def needed_levels(
    chain: LodChain,
    clip_from_world: np.ndarray,
    size: tuple[int, int],
    bias: float = 0.0,
    znear: float = 1e-3,
    cull_margin: float | None = None,
) -> np.ndarray:
    """(T,) int64 the finest level each tile can show in this view: ``floor`` of a lower bound of
    the shader's ``lambda`` over the patch, clipped to ``[0, n_levels - 1]``.

    clip_from_world : (4, 4) the camera's perspective matrix at the viewport's aspect (row 3 gives
      the view depth, ``|row 1[:3]| = 1 / tan(yfov / 2)``); size : viewport ``(w, h)`` pixels
    bias : the shader's ``lod_bias`` (negative: finer); znear : the smallest depth considered
    A pixel at view depth ``z`` and angle ``theta`` off the axis spans at least ``z 2 tan(yfov/2)
    cos(theta) / h`` of world perpendicular to its ray; a world step ``s`` on the patch is at least
    ``s / texel_world`` finest texels. Patches entirely behind the camera take their coarsest level,
    and (``cull_margin`` not None) so do patches in front of it and entirely outside the view
    frustum widened by that fraction on every side (what a small turn will show streams in
    before it is seen; None: by distance alone).
    """
    T = chain.n_tiles
    if T == 0:
        return np.zeros(0, np.int64)
    M = np.asarray(clip_from_world, np.float64)
    w, h = (max(int(v), 1) for v in size)
    t = float(np.linalg.norm(M[1, :3]))  # 1 / tan(yfov / 2)
    aspect = w / h
    cos_max = 1.0 / np.sqrt(1.0 + (1.0 + aspect * aspect) / (t * t))
    z = chain.corners @ M[3, :3] + M[3, 3]  # (T, 4) view depth of the corners
    behind = (z <= 0).all(axis=1)
    zmin = np.maximum(z.min(axis=1), znear)
    pix = zmin * 2.0 / (t * h) * cos_max
    lam = np.log2(np.maximum(pix / np.maximum(chain.texel_world, 1e-30), 1e-30)) + float(bias)
    top = np.maximum(chain.n_levels - 1, 0)
    need = np.clip(np.floor(lam), 0, top).astype(np.int64)
    need[behind] = top[behind]
    if cull_margin is not None:
        c = chain.corners @ M[:2, :3].T + M[:2, 3]  # (T, 4, 2) clip x, y
        wm = z[..., None] * (1.0 + float(cull_margin))
        out = (z > 0).all(axis=1) & ((c > wm).all(axis=1) | (c < -wm).all(axis=1)).any(axis=1)
        need[out] = top[out]
    return need


def resident_levels(
    chain: LodChain,
    need: np.ndarray,
    budget_bytes: float | None = None,
    current: np.ndarray | None = None,
    hysteresis: int = 1,
) -> np.ndarray:
    """(T,) int64 the finest resident level per tile for the levels ``need`` (:func:`needed_levels`).

    current : the levels resident now: a tile keeps finer levels than it needs until it needs a
      level ``hysteresis`` + 1 or more coarser (fewer re-packs as the camera moves); a finer need
      is always met at once.
    budget_bytes : when set, every tile is coarsened one more level at a time (all together,
      those at their coarsest stay) until the entries' bytes fit; the coarsest levels always stay.
    """
    need = np.asarray(need, np.int64)
    res = need.copy()
    if current is not None and len(current) == len(need):
        cur = np.asarray(current, np.int64)
        res = np.where((need > cur) & (need <= cur + int(hysteresis)), cur, need)
    if budget_bytes is None:
        return res
    eb = chain.entry_bytes()
    cum = np.cumsum(eb[:, ::-1], axis=1)[:, ::-1]  # bytes of levels j.. of each tile
    top = np.maximum(chain.n_levels - 1, 0)
    for extra in range(chain.max_levels + 1):
        r = np.minimum(res + extra, top)
        if cum[np.arange(len(r)), r].sum() <= budget_bytes:
            return r
    return top


def fit_pages(chain: LodChain, resident: np.ndarray, budget_bytes: float | None = None) -> LodPages:
    """The pages of ``resident`` (:func:`resident_levels`), coarsened one more level at a time
    (every tile not at its coarsest) until the packed pages' bytes fit ``budget_bytes`` (None: no
    limit); the coarsest levels always stay, even over the budget."""
    top = np.maximum(chain.n_levels - 1, 0)
    res = np.asarray(resident, np.int64)
    pg = chain.pages(res)
    extra = 0
    while budget_bytes is not None and pg.bytes > budget_bytes and (res + extra < top).any():
        extra += 1
        pg = chain.pages(np.minimum(res + extra, top))
    return pg
