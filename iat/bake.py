"""Solution → Baked: a vertex-coloured mesh part and one textured polygon per deep patch.

``Baker(solution, scene).bake(policy)`` keeps what does not change between
policies (flattened tiles per method and scale, padded and quantised boxes, the
packing when the tile sizes are unchanged, the mesh part per textured set), so a
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
"""

from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from . import atlas
from .errors import BakeError, Cancelled, OptionError
from .flatten import METHODS, SCALE_MODES, SolutionIndex, TileCache, sample_tile, scaled_side, tile_side

__all__ = [
    "BYTES_PER_TEXEL",
    "BakePolicy",
    "Baked",
    "BakedSet",
    "Baker",
    "MemoryReport",
    "bake",
    "choose_policy",
    "cost_model",
    "quantise_rgb9e5",
    "quantise_rgba8",
    "seam_error",
]

#: bytes per texel on the GPU for each pixel format
BYTES_PER_TEXEL = {"rgba16f": 8, "rgba8": 4, "rgb9e5": 4}
#: largest texture side we accept (GL_MAX_TEXTURE_SIZE of current desktop GPUs and llvmpipe)
GL_MAX_TEXTURE_SIZE = 16384
#: vertex attribute bytes the renderer uploads: mesh = position 12 + colour 12
MESH_VERTEX_BYTES = 24
#: textured = position 12 + uv 8 + layer 4 + detail uv 8 + flags 4
TEX_VERTEX_BYTES = 36
#: uint32 indices per triangle
INDEX_BYTES = 12
#: cost model: one triangle's transform/setup cost, in byte-equivalents (Myszkowski-style weight)
TRIANGLE_COST_BYTES = 64
#: the budget search never scales below base scale x this
MIN_SCALE_FACTOR = 0.25
MIB = 1 << 20


@dataclass
class BakePolicy:
    """How to bake. Each field: range, typical value, trade-off.

    threshold : int >= 0, typical 2. Patches whose tree depth >= threshold become one
        textured polygon. 0 textures all; higher = fewer, larger-payoff textures and
        more mesh triangles.
    scale : float > 0, typical 1.0. Texture side factor ((n-1) scale + 1 texels).
        < 1 saves texture memory (blur, seams with "naive"); > 1 costs memory, gains nothing
        for bilinear/scan, smooths bicubic.
    method : "bilinear" | "scan" | "bicubic", typical "bilinear". bilinear = report §3.3;
        scan = exact copy of the mesh at texel centres (§5.1); bicubic = smooth C1 fit (§5.2),
        not identical to the mesh but without its subdivision artefacts.
    scale_mode : "clamped" | "naive", typical "clamped". clamped keeps corners/edges exact so
        neighbours agree; naive resizes images (the report's correspondence errors), for comparison.
    budget_mb : float >= 0 or None, typical None. Texture memory budget in MiB (2**20 bytes);
        when set, threshold and scale are chosen by :func:`choose_policy` (0 = all mesh).
    gutter : int >= 0, typical 2. Edge-replicated texels around each tile. Larger = more mip
        levels usable (1 + floor(log2 gutter)) and less bleeding, more atlas waste.
    page_size : int, power of two in [64, 16384], typical 2048. Atlas page side; a tile
        larger than a page is an error. Larger = fewer pages, coarser memory steps.
    pixel_format : "rgba16f" (8 B/texel, exact) | "rgba8" (4 B, sRGB 8-bit of radiance /
        page_scale) | "rgb9e5" (4 B, shared exponent). Typical "rgba16f".
    mipmaps : bool, typical True. Build the mip levels the gutter allows (less aliasing far
        away; costs 25 % more texture memory with gutter 2).
    detail : bool, typical True. Store incoming light on patches with a detail texture so the
        shader combines both in one pass (§3.7); False stores radiance everywhere.
    """

    threshold: int = 2
    scale: float = 1.0
    method: str = "bilinear"
    scale_mode: str = "clamped"
    budget_mb: float | None = None
    gutter: int = 2
    page_size: int = 2048
    pixel_format: str = "rgba16f"
    mipmaps: bool = True
    detail: bool = True

    def validate(self) -> BakePolicy:
        """Raise OptionError naming the bad field; returns self."""
        if not isinstance(self.threshold, (int, np.integer)) or self.threshold < 0:
            raise OptionError(f"threshold must be an integer >= 0, got {self.threshold!r}")
        if not (
            isinstance(self.scale, (int, float, np.number)) and np.isfinite(self.scale) and self.scale > 0
        ):
            raise OptionError(f"scale must be a finite number > 0, got {self.scale!r}")
        if self.method not in METHODS:
            raise OptionError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.scale_mode not in SCALE_MODES:
            raise OptionError(f"scale_mode must be one of {', '.join(SCALE_MODES)}, got {self.scale_mode!r}")
        if self.budget_mb is not None and not (np.isfinite(self.budget_mb) and self.budget_mb >= 0):
            raise OptionError(f"budget_mb must be >= 0 or None, got {self.budget_mb!r}")
        if not isinstance(self.gutter, (int, np.integer)) or not 0 <= self.gutter <= 64:
            raise OptionError(f"gutter must be an integer in 0..64, got {self.gutter!r}")
        ps = self.page_size
        if not isinstance(ps, (int, np.integer)) or ps < 64 or ps > GL_MAX_TEXTURE_SIZE or ps & (ps - 1):
            raise OptionError(
                f"page_size must be a power of two in 64..{GL_MAX_TEXTURE_SIZE}, got {self.page_size!r}"
            )
        if self.pixel_format not in BYTES_PER_TEXEL:
            raise OptionError(
                f"pixel_format must be one of {', '.join(BYTES_PER_TEXEL)}, got {self.pixel_format!r}"
            )
        return self

    @property
    def mip_levels(self) -> int:
        return atlas.mip_levels(self.gutter, self.mipmaps)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass
class MemoryReport:
    """What a bake costs on the GPU.

    texture_bytes : pages x mip-chain texels (levels used) x bytes/texel
    vertex_bytes : vertex attribute bytes (mesh part 24 B/vertex + textured part 36 B/vertex)
    index_bytes : 12 bytes per triangle (uint32)
    draw_calls : 1 for the mesh part (if any) + 1 per texture state of the textured part
      (all pages are one texture array; one more per detail texture)
    utilisation : tile texels / page texels (atlas occupancy, level 0)
    mip_factor : mip-chain texels / level-0 texels, exact for the levels used
    detail_texture_bytes : the materials' detail textures (rgba8, full mip chain), not in the budget
    budget_mb, budget_fits, budget_too_small : the budget asked for (None if none), whether the
      texture bytes fit it, and whether it was smaller than any texture (then all mesh)
    solutions : lighting states baked together (:class:`BakedSet`): the texture bytes hold one
      page layer per state and page (``solutions`` x one state's bytes), the mesh part two
      colour attributes (the neighbouring states the renderer mixes); 1 for a single bake
    """

    texture_bytes: int = 0
    vertex_bytes: int = 0
    vertex_bytes_mesh: int = 0
    vertex_bytes_textured: int = 0
    index_bytes: int = 0
    triangles_mesh_part: int = 0
    triangles_textured_part: int = 0
    draw_calls: int = 0
    pages: int = 0
    page_width: int = 0
    page_height: int = 0
    mip_levels: int = 1
    mip_factor: float = 1.0
    bytes_per_texel: int = 8
    utilisation: float = 0.0
    patches_textured: int = 0
    patches_meshed: int = 0
    detail_texture_bytes: int = 0
    budget_mb: float | None = None
    budget_fits: bool | None = None
    budget_too_small: bool = False
    solutions: int = 1

    @property
    def total_bytes(self) -> int:
        """texture + vertex + index bytes."""
        return self.texture_bytes + self.vertex_bytes + self.index_bytes

    @property
    def triangles(self) -> int:
        return self.triangles_mesh_part + self.triangles_textured_part

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["total_bytes"] = self.total_bytes
        d["triangles"] = self.triangles
        return d


@dataclass
class Baked:
    """The baked model (see docs/architecture.md).

    mesh part: mesh_positions (M, 3) float32, mesh_radiance (M, 3) float32, mesh_indices (Tm, 3) uint32
    textured part: tex_positions (K, 3) float32, tex_uv (K, 2) float32 atlas UV, tex_layer (K,) float32
      page, tex_detail_uv (K, 2) float32, tex_material (K,) int32, tex_indices (Tt, 3) uint32,
      tex_detail (K,) float32 (1.0: texel = incoming light, multiply by detail_textures[material]),
      tex_patch (K,) int32 (the patch of each vertex)
    pages : (n_pages, H, W, 3) float32 linear (quantised as pixel_format stores it: rgba8 and
      rgb9e5 values are already rounded; the GPU value of rgba8 is sRGB8(page / page_scale));
      (0, 1, 1, 3) when nothing is textured
    page_scale : float, 1.0 except rgba8, where the GPU texel is sRGB8(page / page_scale) and the
      shader multiplies by page_scale (one scale for all pages: the largest stored vertex value)
    mip_levels : mip levels the renderer may use (GL_TEXTURE_MAX_LEVEL = mip_levels - 1)
    detail_textures : {material index: (h, w, 3) float32 linear albedo}
    patch_textured : (P,) bool; memory : MemoryReport; policy : the policy baked (budget resolved)
    timings : seconds per stage
    """

    mesh_positions: np.ndarray
    mesh_radiance: np.ndarray
    mesh_indices: np.ndarray
    tex_positions: np.ndarray
    tex_uv: np.ndarray
    tex_layer: np.ndarray
    tex_detail_uv: np.ndarray
    tex_material: np.ndarray
    tex_indices: np.ndarray
    pages: np.ndarray
    patch_textured: np.ndarray
    memory: MemoryReport
    policy: BakePolicy
    timings: dict = field(default_factory=dict)
    tex_detail: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    detail_textures: dict = field(default_factory=dict)
    page_scale: float = 1.0
    mip_levels: int = 1
    tex_patch: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))

    @property
    def n_pages(self) -> int:
        return int(self.memory.pages)


@dataclass
class BakedSet:
    """Several solutions of one model (lighting states, e.g. times of day), solved on one mesh
    and baked with one shared atlas layout (:meth:`Baker.bake_set`).

    bakes : one :class:`Baked` per state, sharing the geometry arrays (same placements, uv,
      layers, indices, mesh part positions and triangles); ``bakes[k].pages`` is state k's
    pages : (n_states, n_pages, H, W, 3) float32, every state's pages
    mesh_radiance : (n_states, M, 3) float32, every state's mesh-part colours
    memory : :class:`MemoryReport` of the whole set (``solutions = n_states``; texture bytes are
      ``n_states`` layers per page); policy : the policy baked (budget resolved for the set)
    The shared geometry is reachable as attributes of the set too (``tex_uv``, ``mesh_indices``, ...).
    """

    bakes: list
    pages: np.ndarray
    mesh_radiance: np.ndarray
    memory: MemoryReport
    policy: BakePolicy
    timings: dict = field(default_factory=dict)

    _SHARED = (
        "mesh_positions",
        "mesh_indices",
        "tex_positions",
        "tex_uv",
        "tex_layer",
        "tex_detail_uv",
        "tex_material",
        "tex_indices",
        "tex_detail",
        "tex_patch",
        "patch_textured",
        "detail_textures",
        "page_scale",
        "mip_levels",
    )

    def __getattr__(self, name):
        if name in BakedSet._SHARED:
            return getattr(self.bakes[0], name)
        raise AttributeError(name)

    @property
    def n_states(self) -> int:
        return len(self.bakes)

    @property
    def n_pages(self) -> int:
        return int(self.pages.shape[1])

    def state(self, k: int) -> Baked:
        """State k alone, as a :class:`Baked`."""
        return self.bakes[int(k)]

    def blend(self, a: int, b: int, w: float) -> Baked:
        """A :class:`Baked` of ``(1 - w) state a + w state b`` (pages and mesh colours, linear
        radiance, computed here on the CPU: for export); ``w = 0`` is state a itself."""
        w = float(w)
        if not 0.0 <= w <= 1.0:
            raise OptionError(f"blend weight must be in [0, 1], got {w}")
        base = self.bakes[int(a)]
        if w == 0.0 or int(a) == int(b):
            return base
        other = self.bakes[int(b)]
        pages = ((1.0 - w) * base.pages + w * other.pages).astype(np.float32)
        fmt = self.policy.pixel_format
        if fmt == "rgba8":
            pages = quantise_rgba8(pages, self.page_scale)
        elif fmt == "rgb9e5":
            pages = quantise_rgb9e5(pages)
        mesh = ((1.0 - w) * base.mesh_radiance + w * other.mesh_radiance).astype(np.float32)
        return dataclasses.replace(base, pages=pages, mesh_radiance=mesh, timings={})

    def at(self, t: float, times=None) -> Baked:
        """The blend at time ``t`` between the neighbouring key times (default: evenly spaced
        in [0, 1]); see :func:`iat.solution_set.blend_weights`."""
        from .solution_set import blend_weights, even_times

        times = even_times(self.n_states) if times is None else times
        return self.blend(*blend_weights(times, t))


# ---------------------------------------------------------------------------
# pixel formats


def _srgb_encode(x):
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1 / 2.4) - 0.055)


def _srgb_decode(y):
    return np.where(y <= 0.04045, y / 12.92, np.power((np.maximum(y, 0.04045) + 0.055) / 1.055, 2.4))


def quantise_rgba8(x: np.ndarray, scale: float) -> np.ndarray:
    """Round-trip through sRGB8 of ``x / scale`` (clamped to [0, 1]); float32."""
    q = np.round(_srgb_encode(np.clip(np.asarray(x, np.float64) / scale, 0.0, 1.0)) * 255.0) / 255.0
    return (_srgb_decode(q) * scale).astype(np.float32)


def quantise_rgb9e5(x: np.ndarray) -> np.ndarray:
    """Round-trip through GL_RGB9_E5 (EXT_texture_shared_exponent); float32."""
    n_bits, bias, emax = 9, 15, 31
    vmax = (2**n_bits - 1) / 2**n_bits * 2.0 ** (emax - bias)
    c = np.clip(np.asarray(x, np.float64), 0.0, vmax)
    m = np.maximum(c.max(axis=-1, keepdims=True), 2.0 ** (-bias - 1))
    e = np.maximum(-bias - 1, np.floor(np.log2(m))) + 1 + bias
    mm = np.floor(m / 2.0 ** (e - bias - n_bits) + 0.5)
    e = np.where(mm >= 2**n_bits, e + 1, e)
    step = 2.0 ** (e - bias - n_bits)
    return (np.floor(c / step + 0.5) * step).astype(np.float32)


# ---------------------------------------------------------------------------
# budget


def _texture_bytes(depth, t, scale, policy: BakePolicy) -> float:
    """Exact texture bytes of textured set ``depth >= t`` at ``scale`` (inf if a tile cannot fit)."""
    d = depth[depth >= t]
    if not len(d):
        return 0.0
    levels = policy.mip_levels
    m = scaled_side(tile_side(d), scale)
    try:
        pk = atlas.pack(np.stack([m, m], axis=1), policy.page_size, policy.gutter, 1 << (levels - 1))
    except BakeError:
        return float("inf")
    texels = atlas.mip_chain_texels(pk.width, pk.height, levels) * pk.n_pages
    return float(texels * BYTES_PER_TEXEL[policy.pixel_format])


def _choose(depth: np.ndarray, budget_mb: float, base: BakePolicy) -> tuple[BakePolicy, dict]:
    budget = float(budget_mb) * MIB
    deepest = int(depth.max()) if len(depth) else 0
    base = dataclasses.replace(base, budget_mb=None)
    all_mesh = dataclasses.replace(base, threshold=max(base.threshold, deepest + 1))
    info = {"budget_mb": float(budget_mb), "too_small": False}
    if budget <= 0:
        return all_mesh, info
    ladder = [base.scale * 2.0 ** (-q / 4) for q in range(int(round(-4 * np.log2(MIN_SCALE_FACTOR))) + 1)]
    for t in range(int(base.threshold), deepest + 1):
        if _texture_bytes(depth, t, ladder[-1], base) > budget:
            continue  # even the smallest scale does not fit: texture fewer (deeper-only) patches
        if _texture_bytes(depth, t, ladder[0], base) <= budget:
            return dataclasses.replace(base, threshold=t), info
        lo, hi = 0, len(ladder) - 1  # ladder[lo] does not fit, ladder[hi] fits
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if _texture_bytes(depth, t, ladder[mid], base) <= budget:
                hi = mid
            else:
                lo = mid
        return dataclasses.replace(base, threshold=t, scale=float(ladder[hi])), info
    info["too_small"] = deepest >= base.threshold  # some texture was wanted and none fits
    return all_mesh, info


def choose_policy(solution, budget_mb: float | None, base_policy: BakePolicy | None = None) -> BakePolicy:
    """Threshold and scale that fit ``budget_mb`` MiB of texture memory, with the best image.

    Texturing order follows a Myszkowski-style cost model (:func:`cost_model`): a mesh costs
    its vertex bytes plus a per-triangle cost, a texture its texel bytes; the saving per texture
    byte grows with tree depth, so the deepest trees are textured first (that is the threshold).
    Search: threshold ``t`` from ``base.threshold`` upwards; at each ``t`` take the largest scale
    on the ladder ``base.scale * 2**(-q/4)``, ``q = 0..8`` (down to base.scale / 4) whose exact
    packed texture bytes fit; if even the smallest does not fit, raise ``t``. Budget 0, or a
    budget smaller than any texture, gives all mesh (threshold above the deepest tree).
    The returned policy has ``budget_mb = None`` (resolved). ``budget_mb=None`` returns the base.
    """
    base = (base_policy or BakePolicy()).validate()
    if budget_mb is None:
        return base
    if not (np.isfinite(budget_mb) and budget_mb >= 0):
        raise OptionError(f"budget_mb must be >= 0, got {budget_mb!r}")
    return _choose(solution.patch_depth().astype(np.int64), budget_mb, base)[0]


def cost_model(solution, policy: BakePolicy | None = None, index: SolutionIndex | None = None) -> dict:
    """Per-depth costs (Myszkowski-style), for the budget search and the viewer.

    Returns {depth: dict(patches, vertices, triangles, mesh_cost, texture_bytes, gain)} where
    ``mesh_cost = vertices x 24 + triangles x (12 + TRIANGLE_COST_BYTES)``, ``texture_bytes``
    is the boxes' texels x bytes/texel x mip factor at ``policy.scale`` (before atlas waste),
    plus the textured polygons' vertex/triangle costs, and ``gain = mesh_cost - texture cost``.
    """
    policy = (policy or BakePolicy()).validate()
    idx = index or SolutionIndex(solution)
    levels = policy.mip_levels
    align = 1 << (levels - 1)
    bpt = BYTES_PER_TEXEL[policy.pixel_format]
    out = {}
    for d in np.unique(idx.depth):
        sel = idx.depth == d
        k = int(sel.sum())
        v = int(idx.patch_n_vertices[sel].sum())
        t = int(idx.patch_n_triangles[sel].sum())
        m = scaled_side(tile_side(int(d)), policy.scale)
        box = int(atlas.align_up(m + 2 * policy.gutter, align))
        tex = k * atlas.mip_chain_texels(box, box, levels) * bpt
        nq = int(idx.is_quad[sel].sum())
        tex_cost = (
            tex
            + (4 * nq + 3 * (k - nq)) * TEX_VERTEX_BYTES
            + (2 * nq + (k - nq)) * (INDEX_BYTES + TRIANGLE_COST_BYTES)
        )
        mesh = v * MESH_VERTEX_BYTES + t * (INDEX_BYTES + TRIANGLE_COST_BYTES)
        out[int(d)] = dict(
            patches=k, vertices=v, triangles=t, mesh_cost=mesh, texture_bytes=tex, gain=mesh - tex_cost
        )
    return out


# ---------------------------------------------------------------------------
# baker


class _LRU(OrderedDict):
    def __init__(self, size: int):
        super().__init__()
        self.size = size

    def put(self, key, value):
        self[key] = value
        self.move_to_end(key)
        while len(self) > self.size:
            self.popitem(last=False)
        return value

    def hit(self, key):
        if key in self:
            self.move_to_end(key)
            return self[key]
        return None


_QUAD_OX = np.array([0, 1, 1, 0])
_QUAD_OY = np.array([0, 0, 1, 1])
_TRI_OX = np.array([0, 1, 0, 0])
_TRI_OY = np.array([0, 0, 1, 1])


class Baker:
    """Bakes one solution under changing policies, caching what does not change.

    solution : :class:`~iat.radiosity.solution.Solution`
    scene : the :class:`~iat.scene.Scene` it was solved from (detail textures and their UVs), or None

    Attributes: ``tiles`` (:class:`~iat.flatten.TileCache`, counters included), ``stats``
    (cache hits: ``pack_hits``, ``pages_hits``, ``mesh_hits``, ``bakes``).
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
        self._vert_pos = np.asarray(solution.vert_position, dtype=np.float32)
        self._corners = np.asarray(solution.patch_corners, dtype=np.float32)
        self._material = np.asarray(solution.patch_material, dtype=np.int64)
        albedo = np.asarray(solution.patch_albedo, dtype=np.float64)
        self._inv_albedo = np.where(albedo > 1e-4, 1.0 / np.maximum(albedo, 1e-4), 0.0)
        detail_ok = np.zeros(P, dtype=bool)
        self._patch_uv = np.zeros((P, 4, 2), dtype=np.float32)
        if scene is not None:
            self._patch_uv = np.asarray(scene.patch_uv, dtype=np.float32)
            mats = scene.materials
            has = np.array([m.detail is not None and not np.any(m.emission > 0) for m in mats], dtype=bool)
            ok_m = self._material < len(mats)
            detail_ok[ok_m] = has[self._material[ok_m]]
            detail_ok &= (albedo > 1e-4).all(axis=1)
        self._detail_ok = detail_ok
        self._quant_scale: dict[bool, float] = {}
        self._boxes = _LRU(4)  # (tile key, fmt, gutter, align, detail) -> {patch: box}
        self._packs = _LRU(32)
        self._pages = _LRU(2)
        self._mesh = _LRU(4)
        self._set_bakers = _LRU(16)  # (id(solution), rgba8 shared) -> Baker of a set member
        self.stats = {"bakes": 0, "pack_hits": 0, "pages_hits": 0, "mesh_hits": 0}

    # -- pieces ------------------------------------------------------------------
    def _detail_mask(self, policy: BakePolicy) -> np.ndarray:
        return self._detail_ok if policy.detail else np.zeros_like(self._detail_ok)

    def _rgba8_scale(self, detail: bool) -> float:
        """Global rgba8 page scale: the largest stored value at any vertex (so tiles cache per format)."""
        if detail not in self._quant_scale:
            idx = self.index
            v = idx.radiance.astype(np.float64)
            if detail:
                dm = self._detail_ok[idx.vert_patch]
                v = np.where(dm[:, None], v * self._inv_albedo[idx.vert_patch], v)
            s = float(v.max()) if v.size else 1.0
            self._quant_scale[detail] = s if s > 0 else 1.0
        return self._quant_scale[detail]

    def _box_tiles(self, ps: np.ndarray, policy: BakePolicy, align: int) -> list:
        """Padded (gutter + alignment), detail-divided, quantised boxes of patches ``ps``."""
        tkey = TileCache.key(policy.method, policy.scale, policy.scale_mode)
        key = (tkey, policy.pixel_format, policy.gutter, align, policy.detail)
        store = self._boxes.hit(key)
        if store is None:
            store = self._boxes.put(key, {})
        missing = np.array([p for p in ps.tolist() if p not in store], dtype=np.int64)
        if len(missing):
            tiles = self.tiles.get(missing, policy.method, policy.scale, policy.scale_mode)
            sides = np.array([t.shape[0] for t in tiles])
            dmask = self._detail_mask(policy)[missing]
            g = policy.gutter
            scale8 = self._rgba8_scale(policy.detail) if policy.pixel_format == "rgba8" else 1.0
            for n in np.unique(sides):
                sel = np.flatnonzero(sides == n)
                stack = np.stack([tiles[q] for q in sel])
                after = int(atlas.align_up(n + 2 * g, align)) - n - g
                box = np.pad(stack, ((0, 0), (g, after), (g, after), (0, 0)), mode="edge")
                dm = dmask[sel]
                if dm.any():
                    box[dm] *= self._inv_albedo[missing[sel][dm]][:, None, None, :].astype(np.float32)
                if policy.pixel_format == "rgba8":
                    box = quantise_rgba8(box, scale8)
                elif policy.pixel_format == "rgb9e5":
                    box = quantise_rgb9e5(box)
                store.update(zip(missing[sel].tolist(), box, strict=True))
        return [store[p] for p in ps.tolist()]

    def _pack(self, ps, sides, policy: BakePolicy, align: int) -> atlas.Packing:
        key = (sides.tobytes(), policy.page_size, policy.gutter, align)
        hit = self._packs.hit(key)
        if hit is not None:
            self.stats["pack_hits"] += 1
            return hit
        pk = atlas.pack(np.stack([sides, sides], axis=1), policy.page_size, policy.gutter, align, names=ps)
        return self._packs.put(key, pk)

    def _mesh_part(self, textured: np.ndarray):
        key = textured.tobytes()
        hit = self._mesh.hit(key)
        if hit is not None:
            self.stats["mesh_hits"] += 1
            return hit
        idx = self.index
        vm = ~textured[idx.vert_patch]
        remap = np.cumsum(vm) - 1
        tm = ~textured[idx.tri_patch]
        part = (
            np.ascontiguousarray(self._vert_pos[vm]),
            np.ascontiguousarray(idx.radiance[vm]),
            remap[idx.tri[tm]].astype(np.uint32).reshape(-1, 3),
        )
        for a in part:
            a.flags.writeable = False  # shared by every Baked with this textured set
        return self._mesh.put(key, part)

    def _textured_part(self, ps, sides, packing: atlas.Packing, dmask):
        k = len(ps)
        q = self.index.is_quad[ps]
        nv = np.where(q, 4, 3)
        valid = np.arange(4)[None, :] < nv[:, None]
        start = np.concatenate([[0], np.cumsum(nv)[:-1]]).astype(np.int64)
        m1 = (sides - 1)[:, None]
        ox = np.where(q[:, None], _QUAD_OX, _TRI_OX) * m1
        oy = np.where(q[:, None], _QUAD_OY, _TRI_OY) * m1
        pl = packing.placements
        W, H = max(packing.width, 1), max(packing.height, 1)
        u = (pl[:, 1:2] + ox + 0.5) / W
        v = (pl[:, 2:3] + oy + 0.5) / H
        positions = self._corners[ps][valid]
        uv = np.stack([u, v], axis=-1)[valid].astype(np.float32)
        layer = np.broadcast_to(pl[:, 0:1], (k, 4))[valid].astype(np.float32)
        duv = self._patch_uv[ps][valid].astype(np.float32)
        mat = np.broadcast_to(self._material[ps][:, None], (k, 4))[valid].astype(np.int32)
        det = np.broadcast_to(dmask[ps][:, None], (k, 4))[valid].astype(np.float32)
        patch = np.broadcast_to(ps[:, None], (k, 4))[valid].astype(np.int32)
        tri = start[:, None, None] + np.array([[0, 1, 2], [0, 2, 3]])[None]
        tvalid = np.stack([np.ones(k, dtype=bool), q], axis=1)
        indices = tri[tvalid].astype(np.uint32).reshape(-1, 3)
        return positions, uv, layer, duv, mat, det, patch, indices

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
        if policy.budget_mb is not None:
            t0 = time.perf_counter()
            policy, budget_info = _choose(self.index.depth, policy.budget_mb, policy)
            tm["choose"] = time.perf_counter() - t0
        idx = self.index
        textured = idx.depth >= policy.threshold
        ps = np.flatnonzero(textured).astype(np.int64)
        levels = policy.mip_levels
        align = 1 << (levels - 1)
        sides = (
            scaled_side(tile_side(idx.depth[ps]), policy.scale).astype(np.int64)
            if len(ps)
            else np.zeros(0, np.int64)
        )
        dmask = self._detail_mask(policy)

        step(0.05, "pack")
        t0 = time.perf_counter()
        packing = self._pack(ps, sides, policy, align)
        tm["pack"] = time.perf_counter() - t0
        step(0.1, "tiles")

        t0 = time.perf_counter()
        pkey = (
            TileCache.key(policy.method, policy.scale, policy.scale_mode),
            policy.pixel_format,
            policy.gutter,
            align,
            policy.detail,
            policy.page_size,
            textured.tobytes(),
        )
        pages = self._pages.hit(pkey)
        if pages is not None:
            self.stats["pages_hits"] += 1
            tm["tiles"] = 0.0
        else:
            boxes = self._box_tiles(ps, policy, align)
            tm["tiles"] = time.perf_counter() - t0
            step(0.8, "blit")
            t1 = time.perf_counter()
            if len(ps):
                pages = np.zeros((packing.n_pages, packing.height, packing.width, 3), dtype=np.float32)
                atlas.blit_boxes(pages, boxes, packing.placements, policy.gutter)
            else:
                pages = np.zeros((0, 1, 1, 3), dtype=np.float32)
            pages.flags.writeable = False
            self._pages.put(pkey, pages)
            tm["blit"] = time.perf_counter() - t1

        step(0.9, "geometry")
        t0 = time.perf_counter()
        mesh_pos, mesh_rad, mesh_idx = self._mesh_part(textured)
        tm["mesh"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        tpos, tuv, tlayer, tduv, tmat, tdet, tpatch, tidx = self._textured_part(ps, sides, packing, dmask)
        tm["textured"] = time.perf_counter() - t0

        # detail textures used
        detail_textures = {}
        if self.scene is not None and len(ps):
            for mi in np.unique(self._material[ps[dmask[ps]]]).tolist():
                detail_textures[int(mi)] = self.scene.materials[mi].detail
        n_pages = int(pages.shape[0])
        page_scale = self._rgba8_scale(policy.detail) if policy.pixel_format == "rgba8" else 1.0

        # memory
        bpt = BYTES_PER_TEXEL[policy.pixel_format]
        if n_pages:
            chain = atlas.mip_chain_texels(packing.width, packing.height, levels)
            tex_bytes = n_pages * chain * bpt
            mip_factor = chain / float(packing.width * packing.height)
        else:
            tex_bytes, mip_factor = 0, 1.0
        dbytes = 0
        for d in detail_textures.values():
            h, w = d.shape[:2]
            dbytes += atlas.mip_chain_texels(w, h, int(np.floor(np.log2(max(h, w)))) + 1) * 4
        groups = (int((~dmask[ps]).any()) if len(ps) else 0) + len(detail_textures)
        vb_mesh = len(mesh_pos) * MESH_VERTEX_BYTES
        vb_tex = len(tpos) * TEX_VERTEX_BYTES
        mem = MemoryReport(
            texture_bytes=int(tex_bytes),
            vertex_bytes=int(vb_mesh + vb_tex),
            vertex_bytes_mesh=int(vb_mesh),
            vertex_bytes_textured=int(vb_tex),
            index_bytes=int((len(mesh_idx) + len(tidx)) * INDEX_BYTES),
            triangles_mesh_part=int(len(mesh_idx)),
            triangles_textured_part=int(len(tidx)),
            draw_calls=int(len(mesh_idx) > 0) + groups,
            pages=n_pages,
            page_width=int(packing.width) if n_pages else 0,
            page_height=int(packing.height) if n_pages else 0,
            mip_levels=levels,
            mip_factor=float(mip_factor),
            bytes_per_texel=bpt,
            utilisation=float(packing.utilisation),
            patches_textured=int(len(ps)),
            patches_meshed=int(idx.n_patches - len(ps)),
            detail_texture_bytes=int(dbytes),
        )
        if budget_info is not None:
            mem.budget_mb = budget_info["budget_mb"]
            mem.budget_fits = bool(tex_bytes <= budget_info["budget_mb"] * MIB)
            mem.budget_too_small = bool(budget_info["too_small"])
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
            pages=pages,
            patch_textured=textured,
            memory=mem,
            policy=policy,
            timings=tm,
            tex_detail=tdet,
            detail_textures=detail_textures,
            page_scale=float(page_scale),
            mip_levels=levels,
            tex_patch=tpatch,
        )

    # -- sets of solutions -----------------------------------------------------------------------
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
          ``solve(..., mesh=first)`` / ``resolve``), e.g. a :class:`~iat.solution_set.SolutionSet`
        policy : as for :meth:`bake`; a budget covers the whole set: N states cost N texture
          layers per page, so the budget search runs on ``budget_mb / N`` per state and picks a
          coarser scale (or a higher threshold) for a larger set.
        Returns a :class:`BakedSet`: pages ``(n_states, n_pages, H, W, 3)``, placements, uv and
        geometry identical for every state (checked). rgba8 sets share one page scale.
        """
        from .solution_set import same_mesh

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
            policy, budget_info = _choose(self.index.depth, policy.budget_mb / n, policy)
            budget_info["budget_mb"] *= n
        shared = policy.pixel_format == "rgba8"
        members = [self._member(sol, shared) for sol in solutions]
        if shared:  # one rgba8 page scale for the set: the largest of its states'
            scale = max(_natural_rgba8_scale(b, policy.detail) for b in members)
            for b in members:
                if b._quant_scale.get(policy.detail) != scale:
                    b._quant_scale[policy.detail] = scale
                    b._boxes.clear()
                    b._pages.clear()
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
        mem = dataclasses.replace(first.memory)
        mem.solutions = n
        mem.texture_bytes = int(first.memory.texture_bytes * n)
        if n > 1:  # two colour attributes per mesh vertex (the neighbouring states)
            extra = first.memory.vertex_bytes_mesh // MESH_VERTEX_BYTES * 12
            mem.vertex_bytes_mesh += int(extra)
            mem.vertex_bytes += int(extra)
        if budget_info is not None:
            mem.budget_mb = budget_info["budget_mb"]
            mem.budget_fits = bool(mem.texture_bytes <= budget_info["budget_mb"] * MIB)
            mem.budget_too_small = bool(budget_info["too_small"])
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


def _natural_rgba8_scale(baker: Baker, detail: bool) -> float:
    """The rgba8 page scale ``baker`` would choose on its own (not cached)."""
    keep = baker._quant_scale.pop(detail, None)
    try:
        return baker._rgba8_scale(detail)
    finally:
        if keep is not None:
            baker._quant_scale[detail] = keep
        else:
            baker._quant_scale.pop(detail, None)


def bake(solution, scene=None, policy: BakePolicy | None = None, progress=None) -> Baked:
    """One-shot bake (no cache kept): ``Baker(solution, scene).bake(policy, progress)``."""
    return Baker(solution, scene).bake(policy, progress)


# ---------------------------------------------------------------------------
# seams


def _patch_normals(corners: np.ndarray, is_quad: np.ndarray) -> np.ndarray:
    n = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    tri = ~is_quad
    n[tri] = np.cross(corners[tri, 1] - corners[tri, 0], corners[tri, 2] - corners[tri, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def _sample_pages(pages: np.ndarray, layer, uv) -> np.ndarray:
    """Bilinear lookup like GL_LINEAR with clamp-to-edge: (k,) layers, (k, 2) uv -> (k, 3)."""
    _, H, W, _ = pages.shape
    x = np.clip(uv[:, 0] * W - 0.5, 0, W - 1)
    y = np.clip(uv[:, 1] * H - 0.5, 0, H - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(W - 2, 0))
    y0 = np.minimum(np.floor(y).astype(np.int64), max(H - 2, 0))
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
    p = pages.astype(np.float64) if pages.dtype != np.float64 else pages
    L = np.asarray(layer, dtype=np.int64)
    return (
        (1 - fx) * (1 - fy) * p[L, y0, x0]
        + fx * (1 - fy) * p[L, y0, x1]
        + (1 - fx) * fy * p[L, y1, x0]
        + fx * fy * p[L, y1, x1]
    )


def seam_error(
    obj, solution=None, samples: int = 17, coplanar_only: bool = True, method: str = "scan"
) -> dict:
    """Radiance mismatch along world-space edges shared by neighbouring patches.

    obj : a :class:`Baked` (its textured patches; both sides sampled bilinearly in the atlas,
      as GL_LINEAR does) or a Solution (every patch; each side is its own mesh along the edge,
      i.e. the edge row of its ``scan`` tile, or of another ``method``)
    solution : with a Baked, the solution: its albedo turns incoming light back into radiance
      on detail patches (without it, stored values are compared); ignored for a Solution
    samples : points per edge, corners included
    coplanar_only : only pairs of patches whose normals agree (a wall and a floor meeting at
      an edge differ physically)

    Shared edges are polygon edges with the same two end points (within 1e-6 of the model
    size), either direction. Returns dict(max=, mean=, edges=, samples=) of the absolute
    radiance difference (max over channels); zeros when no edge is shared.
    """
    from .radiosity.solution import Solution

    none = {"max": 0.0, "mean": 0.0, "edges": 0, "samples": 0}
    t = np.linspace(0.0, 1.0, int(samples))
    is_sol = isinstance(obj, Solution)
    if is_sol:
        sol = obj
        ps = np.arange(len(sol.patch_is_quad))
        corners = np.asarray(sol.patch_corners, dtype=np.float64)
        is_quad = np.asarray(sol.patch_is_quad, dtype=bool)
        # patch (u, v) of the corner slots
        uvc = np.where(
            is_quad[:, None, None],
            np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64),
            np.array([[0, 0], [1, 0], [0, 1], [0, 1]], dtype=np.float64),
        )
    else:
        baked, sol = obj, solution
        if not len(baked.tex_patch):
            return none
        ps, first = np.unique(baked.tex_patch, return_index=True)
        nv = np.bincount(baked.tex_patch)[ps]
        is_quad = nv == 4
        sl = first[:, None] + np.minimum(np.arange(4)[None, :], nv[:, None] - 1)
        corners = baked.tex_positions[sl].astype(np.float64)  # (k, 4, 3); triangles repeat corner 2
        uvc = baked.tex_uv[sl].astype(np.float64)  # atlas uv of the corner slots
        layer = baked.tex_layer[first].astype(np.int64)
    k = len(ps)
    if k < 2:
        return none
    # polygon edges: slot a -> slot b (triangles: 0-1, 1-2, 2-0)
    b_slot = np.where(is_quad[:, None], np.array([1, 2, 3, 0]), np.array([1, 2, 0, 0]))
    e_p, e_s = np.nonzero(np.where(is_quad[:, None], True, np.arange(4)[None, :] < 3))
    ea, eb = e_s, b_slot[e_p, e_s]
    size = float(np.ptp(corners.reshape(-1, 3), axis=0).max())
    eps = max(size, 1e-12) * 1e-6
    qa = np.round(corners[e_p, ea] / eps).astype(np.int64)
    qb = np.round(corners[e_p, eb] / eps).astype(np.int64)
    diff = qa - qb
    a_less = diff[np.arange(len(diff)), np.argmax(diff != 0, axis=1)] < 0
    keyrows = np.concatenate([np.where(a_less[:, None], qa, qb), np.where(a_less[:, None], qb, qa)], axis=1)
    _, inv = np.unique(keyrows, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    order = np.argsort(inv, kind="stable")
    same = inv[order[1:]] == inv[order[:-1]]
    e1, e2 = order[:-1][same], order[1:][same]
    keep = e_p[e1] != e_p[e2]
    if coplanar_only:
        nrm = _patch_normals(corners, is_quad)
        keep &= (nrm[e_p[e1]] * nrm[e_p[e2]]).sum(axis=1) > 1 - 1e-6
    e1, e2 = e1[keep], e2[keep]
    if not len(e1):
        return none
    same_dir = (qa[e1] == qa[e2]).all(axis=1)  # edge 2 starts where edge 1 starts
    t1 = np.broadcast_to(t, (len(e1), len(t)))
    t2 = np.where(same_dir[:, None], t1, 1.0 - t1)

    def points(e, tt):
        w = tt[..., None]
        return uvc[e_p[e], ea[e]][:, None] * (1 - w) + uvc[e_p[e], eb[e]][:, None] * w  # (E, S, 2)

    if is_sol:
        from .flatten import flatten

        used = np.unique(np.concatenate([e_p[e1], e_p[e2]]))
        tiles = flatten(sol, ps[used], method)

        def values(e, tt):
            uv = points(e, tt)
            out = np.empty(uv.shape[:2] + (3,))
            pe = e_p[e]
            for q in np.unique(pe).tolist():  # one call per patch, vectorised over its samples
                r = np.flatnonzero(pe == q)
                out[r] = sample_tile(tiles[int(ps[q])], uv[r, :, 0].ravel(), uv[r, :, 1].ravel()).reshape(
                    len(r), -1, 3
                )
            return out.reshape(-1, 3)

    else:

        def values(e, tt):
            uv = points(e, tt).reshape(-1, 2)
            q = np.repeat(e_p[e], tt.shape[1])
            val = _sample_pages(baked.pages, layer[q], uv)
            if sol is not None and len(baked.tex_detail):
                det = baked.tex_detail[first[q]] > 0
                alb = np.asarray(sol.patch_albedo, dtype=np.float64)[ps[q]]
                val = np.where(det[:, None], val * alb, val)
            return val

    d = np.abs(values(e1, t1) - values(e2, t2)).max(axis=1)
    return {"max": float(d.max()), "mean": float(d.mean()), "edges": int(len(e1)), "samples": int(len(d))}
