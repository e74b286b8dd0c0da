"""The bake's result: :class:`Baked` (one state: the mesh part, the textured part and its atlas
pages) and :class:`BakedSet` (several lighting states with one shared atlas layout)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iat.bake.formats import GPU_DTYPES, quantise_rgb9e5, quantise_rgba8
from iat.bake.memory import MemoryReport
from iat.bake.policy import BakePolicy
from iat.errors import OptionError


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
    patch_twin : (P,) bool, patches with a coincident twin facing the other way (a back face of its
      own, :func:`iat.geometry.sides.twin_patches`): the renderer draws them from their front only
    patch_textured : (P,) bool; memory : MemoryReport; policy : the policy baked (budget resolved)
    timings : seconds per stage
    lod : the :class:`~iat.bake.lod.LodChain` of every textured tile's levels (None unless the
      policy asked for LOD); the renderer then draws the textured part from its pages
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
    patch_twin: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    gpu_pages: np.ndarray | None = field(default=None, repr=False, compare=False)
    gpu_format: str | None = field(default=None, repr=False, compare=False)
    pages_source: Any = field(default=None, repr=False, compare=False)
    lod: Any = field(default=None, repr=False, compare=False)

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
        "patch_twin",
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
        in [0, 1]); see :func:`iat.lighting.solution_set.blend_weights`."""
        from iat.lighting.solution_set import blend_weights, even_times

        times = even_times(self.n_states) if times is None else times
        return self.blend(*blend_weights(times, t))
