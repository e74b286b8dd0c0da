"""What a bake costs: the GPU memory report (:func:`memory_report`, the one count of texture,
vertex and index bytes that the bake, the budget search and sets of states use) and the host
memory a bake needs (:func:`host_bytes`, checked by :func:`check_host_memory`)."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import numpy as np

from iat.bake import atlas
from iat.bake.formats import BYTES_PER_TEXEL, GPU_DTYPES
from iat.bake.policy import BakePolicy
from iat.errors import BakeError

#: vertex attribute bytes the renderer uploads: mesh = position 12 + colour 12
MESH_VERTEX_BYTES = 24
#: textured = position 12 + uv 8 + layer 4 + detail uv 8 + flags 4
TEX_VERTEX_BYTES = 36
#: uint32 indices per triangle
INDEX_BYTES = 12
MIB = 1 << 20


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
    lod_levels : the longest level chain of a tile (:mod:`iat.bake.lod`; 0: baked without LOD,
      and then the three ``lod_*`` fields are left out of :meth:`to_dict`)
    lod_total_bytes : texture bytes of every level of every tile packed (all resident);
      ``texture_bytes`` is then this (the renderer uploads these pages instead of the finest ones)
    lod_resident_bytes : texture bytes resident for the current view (:func:`lod_report`; the
      total until a view streams); with ``lod_stream`` the budget applies to these
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
    lod_levels: int = 0
    lod_total_bytes: int = 0
    lod_resident_bytes: int = 0

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
        if not self.lod_levels:
            for name in ("lod_levels", "lod_total_bytes", "lod_resident_bytes"):
                del d[name]
        return d


def memory_report(
    packing: atlas.Packing,
    policy: BakePolicy,
    *,
    mesh_vertices: int = 0,
    mesh_triangles: int = 0,
    tex_vertices: int = 0,
    tex_triangles: int = 0,
    patches_meshed: int = 0,
    texture_groups: int = 0,
    detail_textures: dict | None = None,
) -> MemoryReport:
    """The :class:`MemoryReport` of one state baked into ``packing`` under ``policy``.

    mesh_* / tex_* : vertex and triangle counts of the mesh and textured parts
    texture_groups : texture states the textured part draws with (one draw call each)
    detail_textures : {material: (h, w, 3) detail texture} the textured part uses (rgba8, full
      mip chain each; not in ``texture_bytes``)
    With only a packing and a policy, the texture bytes of that packing (the budget search).
    """
    levels = policy.mip_levels
    bpt = BYTES_PER_TEXEL[policy.pixel_format]
    n_pages = int(packing.n_pages)
    if n_pages:
        chain = atlas.mip_chain_texels(packing.width, packing.height, levels)
        tex_bytes = n_pages * chain * bpt
        mip_factor = chain / float(packing.width * packing.height)
    else:
        tex_bytes, mip_factor = 0, 1.0
    dbytes = 0
    for d in (detail_textures or {}).values():
        h, w = d.shape[:2]
        dbytes += atlas.mip_chain_texels(w, h, int(np.floor(np.log2(max(h, w)))) + 1) * 4
    vb_mesh = mesh_vertices * MESH_VERTEX_BYTES
    vb_tex = tex_vertices * TEX_VERTEX_BYTES
    return MemoryReport(
        texture_bytes=int(tex_bytes),
        vertex_bytes=int(vb_mesh + vb_tex),
        vertex_bytes_mesh=int(vb_mesh),
        vertex_bytes_textured=int(vb_tex),
        index_bytes=int((mesh_triangles + tex_triangles) * INDEX_BYTES),
        triangles_mesh_part=int(mesh_triangles),
        triangles_textured_part=int(tex_triangles),
        draw_calls=int(mesh_triangles > 0) + int(texture_groups),
        pages=n_pages,
        page_width=int(packing.width) if n_pages else 0,
        page_height=int(packing.height) if n_pages else 0,
        mip_levels=levels,
        mip_factor=float(mip_factor),
        bytes_per_texel=bpt,
        utilisation=float(packing.utilisation),
        patches_textured=int(len(packing.placements)),
        patches_meshed=int(patches_meshed),
        detail_texture_bytes=int(dbytes),
    )


def states_report(one: MemoryReport, n: int) -> MemoryReport:
    """The report of ``n`` states baked with one layout, from one state's: ``n`` page layers per
    page, and (``n > 1``) two colour attributes per mesh vertex (the neighbouring states)."""
    mem = dataclasses.replace(one)
    mem.solutions = n
    mem.texture_bytes = int(one.texture_bytes * n)
    if n > 1:
        extra = one.vertex_bytes_mesh // MESH_VERTEX_BYTES * 12
        mem.vertex_bytes_mesh += int(extra)
        mem.vertex_bytes += int(extra)
    return mem


def set_budget(mem: MemoryReport, budget_info: dict | None) -> MemoryReport:
    """Record the budget search's outcome (``budget_mb``, ``too_small``) in ``mem``; returns it."""
    if budget_info is not None:
        mem.budget_mb = budget_info["budget_mb"]
        mem.budget_fits = bool(mem.texture_bytes <= budget_info["budget_mb"] * MIB)
        mem.budget_too_small = bool(budget_info["too_small"])
    return mem


def lod_report(
    mem: MemoryReport, levels: int, total_bytes: int, resident_bytes: int, budget_mb: float | None = None
) -> MemoryReport:
    """A copy of ``mem`` for a bake with level-of-detail chains: ``levels`` the longest chain,
    ``total_bytes`` every level packed, ``resident_bytes`` what the view keeps on the GPU
    (``texture_bytes`` becomes it); ``budget_mb`` (streaming) is checked against the resident bytes."""
    out = dataclasses.replace(mem)
    out.lod_levels, out.lod_total_bytes = int(levels), int(total_bytes)
    out.lod_resident_bytes = out.texture_bytes = int(resident_bytes)
    out.mip_levels, out.mip_factor = 1, 1.0
    if budget_mb is not None:
        out.budget_mb = float(budget_mb)
    if out.budget_mb is not None:  # the budget holds against what the GPU holds
        out.budget_fits = bool(resident_bytes <= out.budget_mb * MIB)
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


def check_host_memory(sides: np.ndarray, packing: atlas.Packing, policy: BakePolicy, align: int) -> tuple:
    """``(need, have)`` host bytes of a bake (:func:`host_bytes`, :func:`host_memory_bytes`);
    raises BakeError when it needs more than this machine has."""
    need = host_bytes(sides, packing, policy, align) if len(sides) else 0
    have = host_memory_bytes()
    if need > have:
        raise BakeError(
            f"this bake needs {need / 2**30:.1f} GiB of texture memory ({len(sides)} tiles of up to "
            f"{int(sides.max())}x{int(sides.max())} texels on {packing.n_pages} page(s) of "
            f"{packing.width}x{packing.height}, with their scaling temporaries), more than this "
            f"machine's {have / 2**30:.1f} GiB; lower the scale, raise the threshold or set a budget"
        )
    return need, have
