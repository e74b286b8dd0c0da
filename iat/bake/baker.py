"""Solution → Baked: a vertex-coloured mesh part and one textured polygon per deep patch.

``Baker(solution, scene).bake(policy)`` keeps what does not change between
policies (flattened tiles per method and scale, padded and quantised boxes, the
packing when the tile sizes are unchanged, the pages per textured set, and the mesh
sorted by patch depth, whose prefixes are the mesh parts of every threshold), so a
slider change re-does only the page blit and the small vertex arrays.

Threshold semantics (report §3.5): a patch whose tree depth is ``>= threshold``
becomes one textured polygon; the others stay a mesh of anchored triangles.
``threshold = 0`` textures every patch; ``threshold > deepest tree`` keeps all as mesh.

Texture coordinates: a textured patch's tile of ``m x m`` texels sits at
``[page, x, y]``; the polygon corner at lattice ``(i, j)`` (``i, j`` in ``{0, N}``)
gets ``uv = ((x + a + 0.5) / W, (y + b + 0.5) / H)`` with ``a = i / N (m - 1)``,
``b = j / N (m - 1)``: texel centres on the corners, half a texel of texture
beyond the polygon (report §3.4). Page row ``y + b`` is texture row ``b`` counted
from ``v = 0`` (upload rows in array order, GL and glTF alike). Quads: corners in
patch order, triangles ``(0, 1, 2), (0, 2, 3)`` (the diagonal of the anchored
mesh); triangles: the lower-left half of the tile, corners ``(0,0), (m-1,0), (0,m-1)``.

The textured polygon is drawn as triangles with affinely interpolated uv, while the
lattice is bilinear in the patch corners: the two agree exactly on parallelograms
(and triangles); on other planar quads the texture is slightly displaced inside the
polygon (never on its edges), an error of the same kind as the mesh's own bilinear
vertex placement.

Detail textures (report §3.7): on a patch whose material has a detail texture
(and no emission, albedo > 0 in every channel) with ``policy.detail``, the texels
hold the incoming light ``radiance / albedo`` and ``tex_detail`` is 1.0: the
shader multiplies by the material's detail texture (``detail_textures``) at
``tex_detail_uv``. The mesh part always holds radiance.

The bake is a pipeline of stages over arrays, each with its own cache on the Baker:
policy (budget resolved, :func:`~iat.bake.budget.resolve_budget`) -> textured set and tile
sides -> packing (:meth:`Baker.pack`) -> scaled tiles (:class:`~iat.bake.flatten.TileCache`)
-> harmonised rings (:mod:`iat.bake.seams`, :class:`SeamCache`) -> boxes
(:func:`~iat.bake.boxes.build_boxes`) -> pages (:class:`~iat.bake.boxes.PageEntry`) ->
:class:`~iat.bake.baked.Baked` (mesh prefix, textured polygons, memory report); with
``policy.lod`` / ``lod_stream``, the pages' finest tiles -> their level-of-detail chain
(:func:`~iat.bake.lod.build_chain`, cached per pages entry) in ``Baked.lod``.
"""

from __future__ import annotations

import mmap
import sys
import time
from collections import OrderedDict

import numpy as np

from iat.bake import atlas, seams
from iat.bake.baked import Baked, BakedSet
from iat.bake.boxes import PageEntry, build_boxes
from iat.bake.budget import resolve_budget
from iat.bake.flatten import SolutionIndex, TileCache, scaled_side, tile_side
from iat.bake.formats import GPU_DTYPES, rgba8_page_scale
from iat.bake.lod import LodChain, build_chain, finest_tiles
from iat.bake.memory import MIB, check_host_memory, lod_report, memory_report, set_budget, states_report
from iat.bake.policy import BakePolicy
from iat.bake.polygons import depth_sorted_mesh, mesh_prefix, textured_polygons
from iat.errors import BakeError, Cancelled
from iat.geometry.sides import twin_patches

__all__ = ["CACHE_BYTES", "Baker", "SeamCache", "bake"]

#: most bytes the Baker keeps in cached pages (GPU form): enough for every threshold of a
#: 2048 x 2048 rgba16f atlas, so a slider dragged back and forth re-bakes nothing
CACHE_BYTES = 384 * MIB


class _LRU(OrderedDict):
    """Least-recently-used dict of at most ``size`` entries and (when ``nbytes`` is given) at most
    ``max_bytes`` bytes (the newest entry is always kept); ``on_evict(value)`` sees each dropped value."""

    def __init__(self, size: int, max_bytes: int | None = None, nbytes=None, on_evict=None):
        super().__init__()
        self.size = size
        self.max_bytes, self.nbytes, self.on_evict = max_bytes, nbytes, on_evict

    def _bytes(self) -> int:
        return sum(self.nbytes(v) for v in self.values()) if self.nbytes is not None else 0

    def put(self, key, value):
        self[key] = value
        self.move_to_end(key)
        while len(self) > 1 and (
            len(self) > self.size or (self.max_bytes is not None and self._bytes() > self.max_bytes)
        ):
            _, old = self.popitem(last=False)
            if self.on_evict is not None:
                self.on_evict(old)
        return value

    def hit(self, key):
        if key in self:
            self.move_to_end(key)
            return self[key]
        return None

    def entry(self, key) -> dict:
        """The dict stored under ``key`` (a new empty one when missing), made the newest."""
        d = self.hit(key)
        return self.put(key, {}) if d is None else d


class SeamCache:
    """A Baker's seam harmonisation state (:mod:`iat.bake.seams`).

    pairs : the :class:`~iat.bake.seams.EdgePairs` of the solution (found once)
    rings : tile key -> {patch: original boundary ring} (8 keys kept)
    boxes : box key -> {patch: (harmonised ring, box item)}, each reused while its ring is
      unchanged (4 keys kept)
    stats : runs, boxes_built, boxes_reused; last_info : the last harmonisation's info
    """

    def __init__(self, solution):
        self.pairs = seams.solution_pairs(solution)
        self.rings = _LRU(8)
        self.boxes = _LRU(4)
        self.stats = {"runs": 0, "boxes_built": 0, "boxes_reused": 0}
        self.last_info: dict = {}

    def clear(self) -> None:
        """Forget the rings and boxes (the pairs stay)."""
        self.rings.clear()
        self.boxes.clear()


def _box_key(policy: BakePolicy, align: int) -> tuple:
    """What a tile box depends on besides its patch: the scaled tile, the GPU format, the gutter,
    the alignment and whether detail textures divide it (the key of the box and page caches)."""
    tkey = TileCache.key(policy.method, policy.scale, policy.scale_mode)
    return (tkey, policy.pixel_format, policy.gutter, align, policy.detail)


class Baker:
    """Bakes one solution under changing policies, caching what does not change.

    solution : :class:`~iat.radiosity.solution.Solution`
    scene : the :class:`~iat.io.scene.Scene` it was solved from (detail textures and their UVs), or None

    Attributes: ``tiles`` (:class:`~iat.bake.flatten.TileCache`, counters included), ``stats``
    (cache hits: ``pack_hits``, ``pages_hits``, ``mesh_hits``, ``bakes``), ``inv_albedo``
    (P, 3) float64 detail divisors (1 / albedo, 0 where the albedo is ~0).
    """

    def __init__(self, solution, scene=None):
        self.solution = solution
        self.scene = scene
        self.index = SolutionIndex(solution)
        self.tiles = TileCache(solution, self.index)
        idx = self.index
        P = idx.n_patches
        if scene is not None and scene.n_patches != P:
            raise BakeError(
                f"scene has {scene.n_patches} patches but the solution has {P}; "
                "solve the model again (or load it with the same pre-split)"
            )
        self._corners = np.asarray(solution.patch_corners, dtype=np.float32)
        self._clip_start = np.searchsorted(solution.clip_patch, np.arange(P + 1))
        tau = np.asarray(getattr(solution, "patch_transmission", np.zeros(0)), dtype=np.float64)
        self._glass = tau > 0 if len(tau) == P else np.zeros(P, dtype=bool)
        self._material = np.asarray(solution.patch_material, dtype=np.int64)
        albedo = np.asarray(solution.patch_albedo, dtype=np.float64)
        self.inv_albedo = np.where(albedo > 1e-4, 1.0 / np.maximum(albedo, 1e-4), 0.0)
        detail_ok = np.zeros(P, dtype=bool)
        self._patch_uv = np.zeros((P, 4, 2), dtype=np.float32)
        if scene is not None:
            self._patch_uv = np.asarray(scene.patch_uv, dtype=np.float32)
            detail_ok = scene.detail_patches(albedo)
        self._detail_ok = detail_ok
        self._twin = twin_patches(solution.patch_corners, solution.patch_is_quad)
        self._twin.flags.writeable = False
        self._emissive = np.zeros(0, bool)  # unknown without a scene
        if scene is not None:
            self._emissive = np.asarray(scene.patch_emission, dtype=np.float64).reshape(P, 3).max(axis=1) > 0
            self._emissive.flags.writeable = False
        self._quant_scale: dict[bool, float] = {}
        self._boxes = _LRU(4)  # (tile key, fmt, gutter, align, detail) -> {patch: box}
        self._packs = _LRU(32)
        self._free_pages: list = []  # page arrays of evicted entries, reused once nothing else holds them
        self._pages = _LRU(16, CACHE_BYTES, lambda e: e.gpu.nbytes, self._recycle)
        self._mesh_sorted: tuple | None = None  # polygons.depth_sorted_mesh, made on first use
        self._lods = _LRU(4)  # (id(pages entry), page_size) -> (entry, LodChain)
        self._seam_cache: SeamCache | None = None
        self._set_bakers = _LRU(16)  # (id(solution), rgba8 shared) -> Baker of a set member
        self.stats = {"bakes": 0, "pack_hits": 0, "pages_hits": 0, "mesh_hits": 0}

    # -- pieces ------------------------------------------------------------------
    def _recycle(self, entry) -> None:
        """An evicted pages entry: keep its (large) page array for reuse by a later bake."""
        if entry.gpu.nbytes >= 1 << 20:
            self._free_pages = [entry.gpu] + self._free_pages[:2]

    def _page_array(self, shape: tuple, dtype) -> np.ndarray:
        """Zeroed pages of ``shape``: a recycled array when one of that shape is no longer referenced
        by any Baked or renderer (fresh large arrays cost a page fault per 4 KiB on first write:
        ~40 ms for 2048 x 2048 rgba16f here, against 3 ms to clear a recycled one)."""
        for k in range(len(self._free_pages)):
            a = self._free_pages[k]
            # references: the list, `a` and getrefcount's argument; any other holder keeps it
            if a.shape == shape and a.dtype == dtype and sys.getrefcount(a) <= 3:
                del self._free_pages[k]
                a.flags.writeable = True
                a.fill(0)
                return a
        n = int(np.prod(shape)) * np.dtype(dtype).itemsize
        if n >= 4 << 20 and hasattr(mmap, "MAP_POPULATE"):
            # populated up front by the kernel: ~10 ms for 32 MiB here, against 70-100 ms of page faults
            # when a fresh np.zeros is first written (each 4 KiB page faulting on its own)
            buf = mmap.mmap(-1, n, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | mmap.MAP_POPULATE)
            return np.frombuffer(buf, dtype=dtype).reshape(shape)
        return np.zeros(shape, dtype=dtype)

    # -- per-policy inputs -------------------------------------------------------------
    def detail_mask(self, policy: BakePolicy) -> np.ndarray:
        """(P,) bool: the patches whose texels hold incoming light (radiance / albedo) under ``policy``."""
        return self._detail_ok if policy.detail else np.zeros_like(self._detail_ok)

    def natural_rgba8_scale(self, detail: bool) -> float:
        """The rgba8 page scale of this solution alone: the largest stored value at any vertex
        (radiance, divided by the albedo on detail patches when ``detail``); not cached."""
        idx = self.index
        v = idx.radiance.astype(np.float64)
        if detail:
            dm = self._detail_ok[idx.vert_patch]
            v = np.where(dm[:, None], v * self.inv_albedo[idx.vert_patch], v)
        return rgba8_page_scale(v)

    def rgba8_scale(self, detail: bool) -> float:
        """Global rgba8 page scale (:meth:`natural_rgba8_scale`, or the one a set shares), cached
        (so tiles cache per format)."""
        if detail not in self._quant_scale:
            self._quant_scale[detail] = self.natural_rgba8_scale(detail)
        return self._quant_scale[detail]

    def share_rgba8_scale(self, detail: bool, scale: float) -> None:
        """Use ``scale`` as the rgba8 page scale (a set's shared one); drops the boxes and pages
        made with another."""
        if self._quant_scale.get(detail) != scale:
            self._quant_scale[detail] = scale
            self._boxes.clear()
            self._pages.clear()

    def page_scale(self, policy: BakePolicy) -> float:
        """The page scale of ``policy``'s pixel format: :meth:`rgba8_scale` for rgba8, else 1.0."""
        return self.rgba8_scale(policy.detail) if policy.pixel_format == "rgba8" else 1.0

    def textured_set(self, policy: BakePolicy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(textured (P,) bool, ps (k,) int64 textured patches, sides (k,) int64 tile sides)``:
        the patches of depth >= ``policy.threshold`` (never glass: it is not drawn) and their
        scaled tile sides."""
        idx = self.index
        textured = (idx.depth >= policy.threshold) & ~self._glass
        ps = np.flatnonzero(textured).astype(np.int64)
        sides = (
            scaled_side(tile_side(idx.depth[ps]), policy.scale).astype(np.int64)
            if len(ps)
            else np.zeros(0, np.int64)
        )
        return textured, ps, sides

    @property
    def seam_cache(self) -> SeamCache:
        """The :class:`SeamCache` (made on the first harmonised bake)."""
        if self._seam_cache is None:
            self._seam_cache = SeamCache(self.solution)
        return self._seam_cache

    def forget_pages(self, seams: bool = False) -> None:
        """Drop the cached pages (and, with ``seams``, the harmonised rings and boxes), so the next
        bake builds them again (for timing it)."""
        self._pages.clear()
        if seams and self._seam_cache is not None:
            self._seam_cache.clear()

    # -- stages ------------------------------------------------------------------------
    def pack(self, ps: np.ndarray, sides: np.ndarray, policy: BakePolicy, align: int) -> atlas.Packing:
        """The atlas packing of tiles ``ps`` (k,) of sides ``sides`` (k,) under ``policy``, cached by
        the sides (a threshold step that keeps them reuses it)."""
        key = (sides.tobytes(), policy.page_size, policy.gutter, align)
        hit = self._packs.hit(key)
        if hit is not None:
            self.stats["pack_hits"] += 1
            return hit
        pk = atlas.pack(np.stack([sides, sides], axis=1), policy.page_size, policy.gutter, align, names=ps)
        return self._packs.put(key, pk)

    def _build(self, ps: np.ndarray, tiles: list, rings: dict, policy: BakePolicy, align: int) -> list:
        """:func:`~iat.bake.boxes.build_boxes` of patches ``ps``: rings {patch: harmonised ring}
        where harmonised, the albedo divisor on detail patches."""
        dmask = self.detail_mask(policy)[ps]
        factors = [
            self.inv_albedo[p].astype(np.float32) if dm else None
            for p, dm in zip(ps.tolist(), dmask.tolist(), strict=True)
        ]
        return build_boxes(
            tiles,
            [rings.get(p) for p in ps.tolist()],
            ~self.index.is_quad[ps],
            factors,
            policy.gutter,
            align,
            policy.pixel_format,
            self.page_scale(policy),
        )

    def _plain_boxes(self, ps: np.ndarray, policy: BakePolicy, align: int) -> tuple[list, list]:
        """Boxes of patches ``ps`` without harmonised rings, cached: ``(sources, GPU-form boxes)``."""
        store = self._boxes.entry(_box_key(policy, align))
        missing = np.array([p for p in ps.tolist() if p not in store], dtype=np.int64)
        if len(missing):
            tiles = self.tiles.get(missing, policy.method, policy.scale, policy.scale_mode)
            store.update(zip(missing.tolist(), self._build(missing, tiles, {}, policy, align), strict=True))
        pairs = [store[p] for p in ps.tolist()]
        return [a for a, _ in pairs], [b for _, b in pairs]

    def _rings(self, patches: np.ndarray, method: str, scale: float, mode: str) -> dict:
        """Original boundary rings of ``patches`` under a tile key (:attr:`SeamCache.rings`)."""
        store = self.seam_cache.rings.entry(TileCache.key(method, scale, mode))
        missing = np.array([p for p in patches.tolist() if p not in store], dtype=np.int64)
        if len(missing):
            tiles = self.tiles.get(missing, method, scale, mode)
            quad = self.index.is_quad
            store.update(
                (p, seams.tile_ring(t, not quad[p])) for p, t in zip(missing.tolist(), tiles, strict=True)
            )
        return {p: store[p] for p in patches.tolist()}

    def _harmonised_rings(self, textured: np.ndarray, ps: np.ndarray, policy: BakePolicy) -> dict:
        """{patch: harmonised ring} of the textured patches whose ring :func:`~iat.bake.seams.
        harmonise_rings` changed (mesh neighbours take part with their scale-1 rings)."""
        sc = self.seam_cache
        sc.stats["runs"] += 1
        idx = self.index
        sides = seams.ring_sides(idx.depth, ps, policy.scale)
        tex_inv, mesh_inv = seams.involved_patches(sc.pairs, textured)
        rings = self._rings(tex_inv, policy.method, policy.scale, policy.scale_mode)
        if len(mesh_inv):
            rings.update(self._rings(mesh_inv, "bilinear", 1.0, "clamped"))
        judge = None  # discontinuities judged on the solution's values (a bicubic fit overshoots)
        if policy.method != "bilinear":
            judge = {**rings, **self._rings(tex_inv, "bilinear", policy.scale, policy.scale_mode)}
        new, sc.last_info = seams.harmonise_rings(rings, sides, textured, idx.is_quad, sc.pairs, judge)
        return new

    def _boxes_of(self, textured, ps, policy: BakePolicy, align: int, tm: dict) -> tuple[list, list]:
        """``(sources, GPU-form boxes)`` of patches ``ps``: scaled tiles, harmonised rings (when
        :func:`~iat.bake.seams.applies`), boxes. Harmonised boxes are built once from the tile and
        its ring and kept per (box key, patch) while the ring is unchanged; the others come from
        :meth:`_plain_boxes`. Cached boxes are never modified. ``tm["scale"]``: seconds of
        flattening and scaling, ``tm["seams"]``: of harmonising and building harmonised boxes."""
        t0 = time.perf_counter()
        self.tiles.get(ps, policy.method, policy.scale, policy.scale_mode)  # flattened / scaled at once
        tm["scale"] = time.perf_counter() - t0
        if not seams.applies(policy) or len(ps) == 0:
            return self._plain_boxes(ps, policy, align)
        t0 = time.perf_counter()
        new = self._harmonised_rings(textured, ps, policy)
        sc = self.seam_cache
        store = sc.boxes.entry((*_box_key(policy, align), self.page_scale(policy)))  # sets share one scale
        build = [p for p, ring in new.items() if p not in store or store[p][0].tobytes() != ring.tobytes()]
        sc.stats["boxes_built"] += len(build)
        sc.stats["boxes_reused"] += len(new) - len(build)
        if build:
            b = np.array(build, dtype=np.int64)
            tiles = self.tiles.get(b, policy.method, policy.scale, policy.scale_mode)
            items = self._build(b, tiles, {p: new[p] for p in build}, policy, align)
            for p, item in zip(build, items, strict=True):
                store[p] = (new[p], item)
        t_seams = time.perf_counter() - t0
        plain = np.array([p for p in ps.tolist() if p not in new], dtype=np.int64)
        res = tuple(list(comp) for comp in self._plain_boxes(plain, policy, align))
        if new:
            order = {p: q for q, p in enumerate(plain.tolist())}
            merged = tuple([None] * len(ps) for _ in res)
            for q, p in enumerate(ps.tolist()):
                item = store[p][1] if p in new else tuple(comp[order[p]] for comp in res)
                for comp, x in zip(merged, item, strict=True):
                    comp[q] = x
            res = merged
        tm["seams"] = t_seams
        return res

    def _pages_of(self, textured, ps, sides, packing, policy: BakePolicy, align: int, tm: dict, step):
        """The :class:`~iat.bake.boxes.PageEntry` of this textured set, cached: boxes
        (:meth:`_boxes_of`) blitted into GPU-form pages. ``tm``: tiles, blit (and scale, seams)."""
        t0 = time.perf_counter()
        pkey = (*_box_key(policy, align), policy.page_size, textured.tobytes())
        entry = self._pages.hit(pkey)
        if entry is not None:
            self.stats["pages_hits"] += 1
            tm["tiles"] = 0.0
            return entry
        need, have = check_host_memory(sides, packing, policy, align)
        try:
            boxes, gpu_boxes = self._boxes_of(textured, ps, policy, align, tm)
            tm["tiles"] = time.perf_counter() - t0
            step(0.8, "blit")
            t1 = time.perf_counter()
            gdt = GPU_DTYPES[policy.pixel_format]
            if len(ps):
                gpu = self._page_array((packing.n_pages, packing.height, packing.width, 4), gdt)
                atlas.blit_boxes(gpu, gpu_boxes, packing.placements, policy.gutter)
            else:
                gpu = np.zeros((0, 1, 1, 4), dtype=gdt)
        except MemoryError as e:
            raise BakeError(
                f"out of memory while baking {len(ps)} textures ({need / 2**30:.1f} GiB estimated, "
                f"{have / 2**30:.1f} GiB available): lower the scale, raise the threshold or set a budget"
            ) from e
        gpu.flags.writeable = False
        entry = self._pages.put(pkey, PageEntry(gpu, boxes, packing, policy, align, self.page_scale(policy)))
        tm["blit"] = time.perf_counter() - t1
        return entry

    def _lod_chain(self, entry: PageEntry, ps: np.ndarray, sides: np.ndarray, packing, policy) -> LodChain:
        """The :class:`~iat.bake.lod.LodChain` of a pages entry (its finest tiles as stored),
        cached per entry (the entry is held with it, so its id is not reused)."""
        key = (id(entry), policy.page_size)
        hit = self._lods.hit(key)
        if hit is not None and hit[0] is entry:
            return hit[1]
        tiles = finest_tiles(entry.float32(), packing.placements, sides) if len(ps) else []
        chain = build_chain(
            tiles,
            ps,
            self._corners,
            self.index.is_quad,
            policy.pixel_format,
            self.page_scale(policy),
            policy.page_size,
            packing,
        )
        self._lods.put(key, (entry, chain))
        return chain

    def _mesh_part(self, threshold: int) -> tuple:
        """Mesh part of the patches of depth < threshold (:func:`~iat.bake.polygons.mesh_prefix`)."""
        self.stats["mesh_hits"] += self._mesh_sorted is not None
        if self._mesh_sorted is None:
            drawn = self.solution.drawn_mesh()
            self._mesh_sorted = depth_sorted_mesh(
                self.index.depth, drawn, drawn.radiance(self.index.radiance)
            )
        return mesh_prefix(self._mesh_sorted, threshold)

    def _detail_textures(self, ps: np.ndarray, dmask: np.ndarray) -> dict:
        """{material: (h, w, 3) detail texture} of the detail patches among ``ps``."""
        out = {}
        if self.scene is not None and len(ps):
            for mi in np.unique(self._material[ps[dmask[ps]]]).tolist():
                out[int(mi)] = self.scene.materials[mi].detail
        return out

    # -- bake ----------------------------------------------------------------------
    def bake(self, policy: BakePolicy | None = None, progress=None) -> Baked:
        """Bake under ``policy`` (default :class:`BakePolicy`); reuses every cached piece it can.

        progress : ``progress(fraction, message) -> bool`` called between stages; returning
          False raises :class:`~iat.errors.Cancelled` (caches stay valid).
        One bake at a time per Baker (it is not thread-safe); the returned Baked is independent
        of later bakes (its pages and mesh part are shared with the cache and read-only).
        """
        t_start = time.perf_counter()
        tm: dict[str, float] = {}
        policy = (policy or BakePolicy()).validate()

        def step(frac: float, msg: str) -> None:
            if progress is not None and progress(frac, msg) is False:
                raise Cancelled("bake cancelled")

        step(0.0, "policy")
        budget_info = None
        if policy.budget_mb is not None and not policy.lod_stream:  # streaming: caps the resident
            t0 = time.perf_counter()
            policy, budget_info = resolve_budget(self.index.depth, policy.budget_mb, policy)
            tm["choose"] = time.perf_counter() - t0
        textured, ps, sides = self.textured_set(policy)
        align = 1 << (policy.mip_levels - 1)

        step(0.05, "pack")
        t0 = time.perf_counter()
        packing = self.pack(ps, sides, policy, align)
        tm["pack"] = time.perf_counter() - t0
        step(0.1, "tiles")
        entry = self._pages_of(textured, ps, sides, packing, policy, align, tm, step)

        step(0.9, "geometry")
        t0 = time.perf_counter()
        mesh_pos, mesh_rad, mesh_idx, mesh_patch = self._mesh_part(policy.threshold)
        tm["mesh"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        dmask = self.detail_mask(policy)
        tpos, tuv, tlayer, tduv, tmat, tdet, tpatch, tidx = textured_polygons(
            self.index.is_quad,
            self._corners,
            self._patch_uv,
            self._material,
            dmask,
            ps,
            sides,
            packing,
            self.solution.clip_uv,
            self._clip_start,
        )
        tm["textured"] = time.perf_counter() - t0
        detail_textures = self._detail_textures(ps, dmask)
        mem = memory_report(
            packing,
            policy,
            mesh_vertices=len(mesh_pos),
            mesh_triangles=len(mesh_idx),
            tex_vertices=len(tpos),
            tex_triangles=len(tidx),
            patches_meshed=self.index.n_patches - len(ps),
            texture_groups=(int((~dmask[ps]).any()) if len(ps) else 0) + len(detail_textures),
            detail_textures=detail_textures,
        )
        set_budget(mem, budget_info)
        lod = None
        if policy.uses_lod:
            t0 = time.perf_counter()
            lod = self._lod_chain(entry, ps, sides, packing, policy)
            full = lod.pages().bytes if len(ps) else 0
            mem = lod_report(mem, lod.max_levels, full, full, policy.budget_mb if policy.lod_stream else None)
            tm["lod"] = time.perf_counter() - t0
        self.stats["bakes"] += 1
        tm["total"] = time.perf_counter() - t_start
        step(1.0, "done")
        return Baked(
            mesh_positions=mesh_pos,
            mesh_radiance=mesh_rad,
            mesh_indices=mesh_idx,
            tex_positions=tpos,
            tex_uv=tuv,
            tex_layer=tlayer,
            tex_detail_uv=tduv,
            tex_material=tmat,
            tex_indices=tidx,
            pages=None,
            patch_textured=textured,
            memory=mem,
            policy=policy,
            timings=tm,
            tex_detail=tdet,
            detail_textures=detail_textures,
            page_scale=float(self.page_scale(policy)),
            mip_levels=policy.mip_levels,
            tex_patch=tpatch,
            mesh_patch=mesh_patch,
            patch_emissive=self._emissive,
            patch_twin=self._twin,
            gpu_pages=entry.gpu,
            gpu_format=policy.pixel_format,
            pages_source=entry.float32,
            lod=lod,
        )

    def _member(self, solution, shared: bool) -> Baker:
        """The Baker of one state of a set: this one for its own solution, unless the set shares
        an rgba8 scale (then a dedicated one, so this Baker's single bakes keep their own scale).
        Members are cached, so a re-bake of the set reuses their tiles."""
        if not shared and solution is self.solution:
            return self
        key = (id(solution), shared)
        b = self._set_bakers.hit(key)
        if b is None or b.solution is not solution:
            b = self._set_bakers.put(key, Baker(solution, self.scene))
        return b

    def bake_set(self, solutions, policy: BakePolicy | None = None, progress=None) -> BakedSet:
        """Bake several solutions of this model (lighting states) with one shared atlas layout.

        solutions : solutions on the same mesh as this Baker's (same leaves and vertex keys:
          ``solve(..., mesh=first)`` / ``resolve``), e.g. a :class:`~iat.lighting.solution_set.SolutionSet`
        policy : as for :meth:`bake`; a budget covers the whole set: N states cost N texture
          layers per page, so the budget search runs on ``budget_mb / N`` per state and picks a
          coarser scale (or a higher threshold) for a larger set.
        Returns a :class:`BakedSet`: pages ``(n_states, n_pages, H, W, 3)``, placements, uv and
        geometry identical for every state (checked). rgba8 sets share one page scale.
        """
        from iat.lighting.solution_set import same_mesh

        t_start = time.perf_counter()
        solutions = list(getattr(solutions, "solutions", solutions))
        if not solutions:
            raise BakeError("bake_set needs at least one solution")
        for k, sol in enumerate(solutions):
            if sol is not self.solution and not same_mesh(sol, self.solution):
                raise BakeError(
                    f"solution {k} of the set is not on this model's mesh (solve it with "
                    "solve(scene, mesh=first) or resolve(first, scene))"
                )
        policy = (policy or BakePolicy()).validate()
        n = len(solutions)
        budget_info = None
        if policy.budget_mb is not None:
            policy, budget_info = resolve_budget(self.index.depth, policy.budget_mb / n, policy)
            budget_info["budget_mb"] *= n
        shared = policy.pixel_format == "rgba8"
        members = [self._member(sol, shared) for sol in solutions]
        if shared:  # one rgba8 page scale for the set: the largest of its states'
            scale = max(b.natural_rgba8_scale(policy.detail) for b in members)
            for b in members:
                b.share_rgba8_scale(policy.detail, scale)
        bakes = []
        for k, b in enumerate(members):
            if progress is not None and progress(k / n, f"baking state {k + 1} of {n}") is False:
                raise Cancelled("bake cancelled")
            bakes.append(b.bake(policy))
        first = bakes[0]
        for k, b in enumerate(bakes[1:], 1):
            for name in ("tex_uv", "tex_layer", "tex_indices", "mesh_indices", "tex_patch"):
                if not np.array_equal(getattr(b, name), getattr(first, name)):
                    raise BakeError(f"state {k} of the set got another atlas layout ({name} differs)")
            b.tex_positions, b.tex_uv, b.tex_layer = first.tex_positions, first.tex_uv, first.tex_layer
            b.mesh_positions, b.mesh_indices = first.mesh_positions, first.mesh_indices
        pages = np.stack([b.pages for b in bakes])
        mesh_radiance = np.stack([np.asarray(b.mesh_radiance, np.float32) for b in bakes])
        mem = set_budget(states_report(first.memory, n), budget_info)
        if progress is not None and progress(1.0, "done") is False:
            raise Cancelled("bake cancelled")
        return BakedSet(
            bakes=bakes,
            pages=pages,
            mesh_radiance=mesh_radiance,
            memory=mem,
            policy=first.policy,
            timings={
                "total": time.perf_counter() - t_start,
                "states": [b.timings.get("total", 0.0) for b in bakes],
            },
        )


def bake(solution, scene=None, policy: BakePolicy | None = None, progress=None) -> Baked:
    """One-shot bake (no cache kept): ``Baker(solution, scene).bake(policy, progress)``."""
    return Baker(solution, scene).bake(policy, progress)
