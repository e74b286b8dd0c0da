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
"""

from __future__ import annotations

import dataclasses
import mmap
import os
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iat.bake import atlas
from iat.bake.flatten import (
    METHODS,
    SCALE_MODES,
    SolutionIndex,
    TileCache,
    extend_triangle,
    populated_empty,
    sample_tile,
    scaled_side,
    tile_side,
)
from iat.errors import BakeError, Cancelled, OptionError

__all__ = [
    "BYTES_PER_TEXEL",
    "GPU_DTYPES",
    "BakePolicy",
    "Baked",
    "BakedSet",
    "Baker",
    "MemoryReport",
    "bake",
    "choose_policy",
    "cost_model",
    "from_gpu",
    "host_bytes",
    "host_memory_bytes",
    "quantise_rgb9e5",
    "quantise_rgba8",
    "seam_error",
    "to_gpu",
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
      rgb9e5 values are already rounded; the GPU value of rgba8 is sRGB8(page / page_scale);
      rgba16f values are exact, the GPU holds them as float16); (0, 1, 1, 3) when nothing is
      textured. Made on first access when the Baker baked it (read-only, cached)
    page_scale : float, 1.0 except rgba8, where the GPU texel is sRGB8(page / page_scale) and the
      shader multiplies by page_scale (one scale for all pages: the largest stored vertex value)
    gpu_pages : (n_pages, H, W, 4) in ``GPU_DTYPES[gpu_format]``: the pages as uploaded (float16 for
      rgba16f and rgb9e5, sRGB8 codes for rgba8), built by the Baker and written to GL as they are;
      ``pages`` is then made on first access (``pages_source``). :meth:`gpu_form` says when it applies.
    mip_levels : mip levels the renderer may use (GL_TEXTURE_MAX_LEVEL = mip_levels - 1)
    detail_textures : {material index: (h, w, 3) float32 linear albedo}
    mesh_patch : (M,) int32, the patch of each mesh-part vertex. The mesh part is sorted by patch
      depth (stable), so each threshold's mesh part is a prefix of the same read-only arrays
    patch_emissive : (P,) bool, patches whose material emits (empty when baked without a scene)
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
    mesh_patch: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    patch_emissive: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    gpu_pages: np.ndarray | None = field(default=None, repr=False, compare=False)
    gpu_format: str | None = field(default=None, repr=False, compare=False)
    pages_source: Any = field(default=None, repr=False, compare=False)

    @property
    def n_pages(self) -> int:
        return int(self.memory.pages)

    def gpu_form(self) -> np.ndarray | None:
        """The pages as the GPU stores them, ``(n_pages, H, W, 4)`` in :data:`GPU_DTYPES`
        ``[policy.pixel_format]`` (read-only, cached by the Baker), or None when there is none or
        ``pages`` was given explicitly (then the renderer converts ``pages``)."""
        g = self.gpu_pages
        if g is None or self.__dict__.get("_pages_explicit"):
            return None
        fmt = getattr(self.policy, "pixel_format", None)
        if self.gpu_format != fmt or fmt not in GPU_DTYPES or g.dtype != GPU_DTYPES[fmt] or g.ndim != 4:
            return None
        return g


def _baked_pages_get(self) -> np.ndarray:
    p = self.__dict__.get("_pages")
    if p is None:
        src = self.__dict__.get("pages_source")
        if src is None:
            return None
        p = self.__dict__["_pages"] = src()
    return p


def _baked_pages_set(self, value) -> None:
    # the Baker passes pages=None and a pages_source (float32 pages made on demand from its cache)
    self.__dict__["_pages"] = value
    self.__dict__["_pages_explicit"] = value is not None


#: ``Baked.pages``: (n_pages, H, W, 3) float32, made on first access when the Baker left it to
#: ``pages_source`` (the renderer uploads ``gpu_pages`` and never needs it)
Baked.pages = property(_baked_pages_get, _baked_pages_set, doc=_baked_pages_get.__doc__)


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
        "mesh_patch",
        "patch_emissive",
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
        return dataclasses.replace(
            base,
            pages=pages,
            mesh_radiance=mesh,
            timings={},
            gpu_pages=None,
            gpu_format=None,
            pages_source=None,
        )

    def at(self, t: float, times=None) -> Baked:
        """The blend at time ``t`` between the neighbouring key times (default: evenly spaced
        in [0, 1]); see :func:`iat.solution_set.blend_weights`."""
        from iat.lighting.solution_set import blend_weights, even_times

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
    return (_srgb_decode(_rgba8_codes(x, scale) / 255.0) * scale).astype(np.float32)


#: host dtype of each pixel format's GPU form: ``(..., 4)`` arrays the renderer writes as they are
#: (rgba8: sRGB8 codes of ``page / page_scale``, alpha 255; rgb9e5: the 9e5-rounded values as half
#: floats, which hold them exactly and which GL packs into GL_RGB9_E5; float formats: alpha 1)
GPU_DTYPES = {"rgba16f": np.float16, "rgba32f": np.float32, "rgba8": np.uint8, "rgb9e5": np.float16}
#: largest finite half float; brighter radiance is clamped to it, never turned into inf
HALF_MAX = 65504.0


def to_gpu(
    x: np.ndarray, pixel_format: str, page_scale: float = 1.0, out: np.ndarray | None = None
) -> np.ndarray:
    """``(..., 3)`` linear values -> their GPU form ``(..., 4)`` of dtype ``GPU_DTYPES[pixel_format]``.

    rgba8: ``rint(sRGB(clip(x / page_scale, 0, 1)) x 255)`` (GL_SRGB8_ALPHA8 decodes it before
    filtering); rgb9e5: :func:`quantise_rgb9e5` then float16 (exact); rgba16f: clamped to
    +-:data:`HALF_MAX`; rgba32f: as is.
    out : an array of that shape and dtype to write into (returned), or None for a new one.
    """
    if pixel_format not in GPU_DTYPES:
        raise OptionError(f"unknown pixel format {pixel_format!r} (known: {', '.join(GPU_DTYPES)})")
    x = np.asarray(x)[..., :3]
    dt = GPU_DTYPES[pixel_format]
    if out is None:
        out = np.empty(x.shape[:-1] + (4,), dtype=dt)
    if pixel_format == "rgba8":
        out[..., 3] = 255
        out[..., :3] = _rgba8_codes(x, page_scale)
        return out
    out[..., 3] = 1.0
    if pixel_format == "rgb9e5":
        out[..., :3] = quantise_rgb9e5(x)
    elif pixel_format == "rgba16f":
        np.clip(x, -HALF_MAX, HALF_MAX, out=out[..., :3], casting="unsafe")
    else:
        out[..., :3] = x
    return out


def from_gpu(g: np.ndarray, pixel_format: str, page_scale: float = 1.0) -> np.ndarray:
    """Inverse of :func:`to_gpu`: ``(..., 4)`` GPU form -> ``(..., 3)`` float32 linear values
    (what the shader reads, times ``page_scale`` for rgba8)."""
    g = np.asarray(g)[..., :3]
    if pixel_format == "rgba8":
        return (_srgb_decode(g.astype(np.float64) / 255.0) * page_scale).astype(np.float32)
    return g.astype(np.float32)


def _rgba8_codes(x: np.ndarray, scale: float) -> np.ndarray:
    return np.round(_srgb_encode(np.clip(np.asarray(x, np.float64) / scale, 0.0, 1.0)) * 255.0).astype(
        np.uint8
    )


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
# host memory


def host_memory_bytes() -> int:
    """Memory this process may still use: ``MemAvailable`` of /proc/meminfo, else the physical
    memory (``os.sysconf``), else 2**62 (unknown: no refusal); at most the address-space limit
    (``ulimit -v``) when one is set."""
    have = 1 << 62
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    have = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        try:
            have = int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            pass
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            have = min(have, int(soft))
    except (ImportError, OSError, ValueError):
        pass
    return have


def host_bytes(sides: np.ndarray, packing: atlas.Packing, policy: BakePolicy, align: int) -> int:
    """Host bytes a bake allocates for its textures (estimate, made before any texel exists):
    the tiles (float32), their padded boxes (float32 and GPU form), the GPU pages, and the
    float64 temporaries of resampling the largest group of equal-sized tiles (two arrays).
    An upper bound since the boxes keep only their GPU form and scaling and boxing run in
    float32 chunks of a few MB (float32 boxes are made again only for ``Baked.pages``)."""
    sides = np.asarray(sides, dtype=np.int64)
    if not len(sides):
        return 0
    isz = np.dtype(GPU_DTYPES[policy.pixel_format]).itemsize
    box = -(-(sides + 2 * policy.gutter) // align) * align
    tiles = int((sides.astype(np.float64) ** 2).sum()) * 12
    boxes = int((box.astype(np.float64) ** 2).sum()) * (12 + 4 * isz)
    pages = int(packing.n_pages) * int(packing.width) * int(packing.height) * 4 * isz
    u, c = np.unique(sides, return_counts=True)
    temporaries = int((c * u.astype(np.float64) ** 2).max()) * 3 * 8 * 2
    return tiles + boxes + pages + temporaries


# ---------------------------------------------------------------------------
# baker


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


class _PageEntry:
    """One cached set of pages: the GPU form (built by the bake) and the float32 pages, made on
    first use (export, seams, tests) and kept: from the GPU form for the quantised formats (it
    holds exactly the stored values), else blitted from the boxes' sources (:func:`_box_source`)."""

    def __init__(self, gpu: np.ndarray, sources: list, packing: atlas.Packing, policy, align: int, scale8):
        self.gpu = gpu
        self._sources, self._packing, self._align = sources, packing, align
        self._fmt, self._gutter, self._scale8 = policy.pixel_format, policy.gutter, scale8
        self._float32: np.ndarray | None = None

    def float32(self) -> np.ndarray:
        if self._float32 is None:
            n, h, w = self.gpu.shape[:3]
            if self._fmt in ("rgba8", "rgb9e5"):
                pages = np.ascontiguousarray(from_gpu(self.gpu, self._fmt, self._scale8))
            else:
                pages = np.zeros((n, h, w, 3), dtype=np.float32)
                if self._sources:
                    tiles = [_box_source_tile(src) for src in self._sources]
                    atlas.blit(pages, tiles, self._packing.placements, self._gutter, self._align)
            pages.flags.writeable = False
            self._float32 = pages
        return self._float32


def _box_source_tile(src) -> np.ndarray:
    """The float32 tile a box was padded from: ``src = (tile, ring or None, is_tri, factor or
    None)`` (the scaled tile, its harmonised boundary ring, and the detail divisor)."""
    tile, ring, is_tri, factor = src
    t = np.array(tile, dtype=np.float32, copy=True)
    if ring is not None:
        from iat.bake.seams import ring_index

        rows, cols = ring_index(t.shape[0], is_tri)
        t[rows, cols] = ring
        if is_tri:
            extend_triangle(t[None])
    if factor is not None:
        t *= factor
    return t


#: tiles per chunk when boxes are built (float32 temporaries of a few MB, reused)
_BOX_CHUNK_BYTES = 2 << 20


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
        self._emissive = np.zeros(0, bool)  # unknown without a scene
        if scene is not None:
            self._emissive = np.asarray(scene.patch_emission, dtype=np.float64).reshape(P, 3).max(axis=1) > 0
            self._emissive.flags.writeable = False
        self._quant_scale: dict[bool, float] = {}
        self._boxes = _LRU(4)  # (tile key, fmt, gutter, align, detail) -> {patch: box}
        self._packs = _LRU(32)
        self._free_pages: list = []  # page arrays of evicted entries, reused once nothing else holds them
        self._pages = _LRU(16, CACHE_BYTES, lambda e: e.gpu.nbytes, self._recycle)
        self._mesh_sorted: tuple | None = None  # see _mesh_order
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

    def _box_tiles(self, ps: np.ndarray, policy: BakePolicy, align: int) -> tuple[list, list]:
        """Padded (gutter + alignment), detail-divided, quantised boxes of patches ``ps``, cached:
        ``(sources, GPU-form (h, w, 4) boxes)`` (:meth:`_build_boxes`)."""
        tkey = TileCache.key(policy.method, policy.scale, policy.scale_mode)
        key = (tkey, policy.pixel_format, policy.gutter, align, policy.detail)
        store = self._boxes.hit(key)
        if store is None:
            store = self._boxes.put(key, {})
        missing = np.array([p for p in ps.tolist() if p not in store], dtype=np.int64)
        if len(missing):
            tiles = self.tiles.get(missing, policy.method, policy.scale, policy.scale_mode)
            store.update(
                zip(missing.tolist(), self._build_boxes(missing, tiles, None, policy, align), strict=True)
            )
        pairs = [store[p] for p in ps.tolist()]
        return [a for a, _ in pairs], [b for _, b in pairs]

    def _build_boxes(
        self, ps: np.ndarray, tiles: list, rings: dict | None, policy: BakePolicy, align: int
    ) -> list:
        """``[(source, GPU-form box)]`` of patches ``ps`` from their (scaled) ``tiles``.

        A box is the tile with its boundary ring replaced by ``rings[p]`` when given (the seam
        harmonisation; triangles re-extended), divided by the albedo on detail patches, padded
        by edge replication to ``gutter`` + alignment and converted by :func:`to_gpu`. Tiles of
        one side are done together, in chunks whose float32 temporary is reused; only the GPU
        form is kept. ``source = (tile, ring, is_tri, factor)`` rebuilds the float32 box.
        """
        from iat.bake.seams import ring_index

        rings = rings or {}
        out: list = [None] * len(ps)
        if not len(ps):
            return out
        sides = np.array([t.shape[0] for t in tiles], dtype=np.int64)
        dmask = self._detail_mask(policy)[ps]
        is_tri = ~self.index.is_quad[ps]
        g = policy.gutter
        fmt = policy.pixel_format
        scale8 = self._rgba8_scale(policy.detail) if fmt == "rgba8" else 1.0
        gdt = GPU_DTYPES[fmt]
        factors = [
            self._inv_albedo[p].astype(np.float32) if dm else None
            for p, dm in zip(ps.tolist(), dmask.tolist(), strict=True)
        ]
        has_ring = np.array([p in rings for p in ps.tolist()], dtype=bool)
        for n in np.unique(sides).tolist():
            sel = np.flatnonzero(sides == n)
            bs = int(atlas.align_up(n + 2 * g, align))
            gpu = populated_empty((len(sel), bs, bs, 4), gdt)
            step = max(1, _BOX_CHUNK_BYTES // (bs * bs * 12))
            buf = np.empty((min(step, len(sel)), bs, bs, 3), dtype=np.float32)
            for c0 in range(0, len(sel), step):
                chunk = sel[c0 : c0 + step]
                b = buf[: len(chunk)]
                inner = b[:, g : g + n, g : g + n]
                for j, q in enumerate(chunk.tolist()):
                    inner[j] = tiles[q]
                for tri in (False, True):  # harmonised rings, one scatter per kind
                    js = np.flatnonzero(has_ring[chunk] & (is_tri[chunk] == tri))
                    if not len(js):
                        continue
                    rows, cols = ring_index(n, tri)
                    inner[js[:, None], rows[None], cols[None]] = np.stack(
                        [rings[p] for p in ps[chunk[js]].tolist()]
                    )
                    if tri:
                        inner[js] = extend_triangle(inner[js])
                dj = np.flatnonzero(dmask[chunk])
                if len(dj):
                    inner[dj] *= np.stack([factors[q] for q in chunk[dj].tolist()])[:, None, None, :]
                if g or bs > n:  # edge replication, as np.pad(mode="edge")
                    b[:, :g, g : g + n] = inner[:, :1]
                    b[:, g + n :, g : g + n] = inner[:, -1:]
                    b[:, :, :g] = b[:, :, g : g + 1]
                    b[:, :, g + n :] = b[:, :, g + n - 1 : g + n]
                to_gpu(b, fmt, scale8, out=gpu[c0 : c0 + len(chunk)])
            for j, q in enumerate(sel.tolist()):
                p = int(ps[q])
                out[q] = ((tiles[q], rings.get(p), bool(is_tri[q]), factors[q]), gpu[j])
        return out

    def _pack(self, ps, sides, policy: BakePolicy, align: int) -> atlas.Packing:
        key = (sides.tobytes(), policy.page_size, policy.gutter, align)
        hit = self._packs.hit(key)
        if hit is not None:
            self.stats["pack_hits"] += 1
            return hit
        pk = atlas.pack(np.stack([sides, sides], axis=1), policy.page_size, policy.gutter, align, names=ps)
        return self._packs.put(key, pk)

    def _mesh_order(self):
        """The solution's vertices and triangles sorted by their patch's tree depth (stable, so
        vertex-table order within a depth): ``(positions, radiance, indices, vertex patch, vertex
        depth, triangle depth)``, read-only. The mesh part of threshold ``t`` (patches of depth
        ``< t``) is then a prefix of each: views, no copy, and the renderer keeps one upload of
        the whole arrays for every threshold."""
        if self._mesh_sorted is None:
            idx = self.index
            vdepth = idx.depth[idx.vert_patch]
            order_v = np.argsort(vdepth, kind="stable")
            tdepth = idx.depth[idx.tri_patch] if len(idx.tri) else np.zeros(0, np.int64)
            order_t = np.argsort(tdepth, kind="stable")
            new_of_old = np.empty(len(order_v), dtype=np.int64)
            new_of_old[order_v] = np.arange(len(order_v))
            parts = (
                np.ascontiguousarray(self._vert_pos[order_v]),
                np.ascontiguousarray(idx.radiance[order_v], dtype=np.float32),
                new_of_old[idx.tri[order_t]].astype(np.uint32).reshape(-1, 3),
                idx.vert_patch[order_v].astype(np.int32),
                vdepth[order_v],
                tdepth[order_t],
            )
            for a in parts:
                a.flags.writeable = False  # shared by every Baked (as prefixes)
            self._mesh_sorted = parts
        return self._mesh_sorted

    def _mesh_part(self, threshold: int):
        """Mesh part of the patches of depth < threshold: positions (M, 3), radiance (M, 3),
        indices (Tm, 3) uint32, vertex patch (M,): prefixes of :meth:`_mesh_order`."""
        self.stats["mesh_hits"] += self._mesh_sorted is not None
        pos, rad, tri, vpatch, vdepth, tdepth = self._mesh_order()
        nv = int(np.searchsorted(vdepth, threshold, side="left"))
        nt = int(np.searchsorted(tdepth, threshold, side="left"))
        return pos[:nv], rad[:nv], tri[:nt], vpatch[:nv]

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
        entry = self._pages.hit(pkey)
        if entry is not None:
            self.stats["pages_hits"] += 1
            tm["tiles"] = 0.0
        else:
            need = host_bytes(sides, packing, policy, align) if len(ps) else 0
            have = host_memory_bytes()
            if need > have:
                raise BakeError(
                    f"this bake needs {need / 2**30:.1f} GiB of texture memory ({len(ps)} tiles of up to "
                    f"{int(sides.max())}x{int(sides.max())} texels on {packing.n_pages} page(s) of "
                    f"{packing.width}x{packing.height}, with their scaling temporaries), more than this "
                    f"machine's {have / 2**30:.1f} GiB; lower the scale, raise the threshold or set a budget"
                )
            try:
                from iat.bake.seams import harmonised_boxes

                boxes, gpu_boxes = harmonised_boxes(self, ps, policy, align, tm)
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
            scale8 = self._rgba8_scale(policy.detail) if policy.pixel_format == "rgba8" else 1.0
            entry = self._pages.put(pkey, _PageEntry(gpu, boxes, packing, policy, align, scale8))
            tm["blit"] = time.perf_counter() - t1

        step(0.9, "geometry")
        t0 = time.perf_counter()
        mesh_pos, mesh_rad, mesh_idx, mesh_patch = self._mesh_part(policy.threshold)
        tm["mesh"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        tpos, tuv, tlayer, tduv, tmat, tdet, tpatch, tidx = self._textured_part(ps, sides, packing, dmask)
        tm["textured"] = time.perf_counter() - t0

        # detail textures used
        detail_textures = {}
        if self.scene is not None and len(ps):
            for mi in np.unique(self._material[ps[dmask[ps]]]).tolist():
                detail_textures[int(mi)] = self.scene.materials[mi].detail
        n_pages = int(entry.gpu.shape[0])
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
            pages=None,
            patch_textured=textured,
            memory=mem,
            policy=policy,
            timings=tm,
            tex_detail=tdet,
            detail_textures=detail_textures,
            page_scale=float(page_scale),
            mip_levels=levels,
            tex_patch=tpatch,
            mesh_patch=mesh_patch,
            patch_emissive=self._emissive,
            gpu_pages=entry.gpu,
            gpu_format=policy.pixel_format,
            pages_source=entry.float32,
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
    from iat.radiosity.solution import Solution

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
        from iat.bake.flatten import flatten

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
