"""The bake's vertex arrays: the mesh part sorted by patch depth (:func:`depth_sorted_mesh`, whose
prefixes are the mesh parts of every threshold) and the textured polygons with their atlas uv
(:func:`textured_polygons`; the uv convention is the one in :mod:`iat.bake.baker`'s docstring)."""

from __future__ import annotations

import numpy as np

from iat.bake import atlas
from iat.bake.flatten import SolutionIndex

# lattice corner offsets (units of m - 1 texels) of the polygon corners: quads, triangles
_QUAD_OX = np.array([0, 1, 1, 0])
_QUAD_OY = np.array([0, 0, 1, 1])
_TRI_OX = np.array([0, 1, 0, 0])
_TRI_OY = np.array([0, 0, 1, 1])


def depth_sorted_mesh(index: SolutionIndex, vert_position: np.ndarray) -> tuple:
    """The solution's vertices and triangles sorted by their patch's tree depth (stable, so
    vertex-table order within a depth): ``(positions (V, 3) float32, radiance (V, 3) float32,
    indices (T, 3) uint32, vertex patch (V,) int32, vertex depth (V,), triangle depth (T,))``,
    read-only. The mesh part of threshold ``t`` (patches of depth ``< t``) is then a prefix of
    each (:func:`mesh_prefix`): views, no copy, and the renderer keeps one upload of the whole
    arrays for every threshold."""
    idx = index
    vdepth = idx.depth[idx.vert_patch]
    order_v = np.argsort(vdepth, kind="stable")
    tdepth = idx.depth[idx.tri_patch] if len(idx.tri) else np.zeros(0, np.int64)
    order_t = np.argsort(tdepth, kind="stable")
    new_of_old = np.empty(len(order_v), dtype=np.int64)
    new_of_old[order_v] = np.arange(len(order_v))
    parts = (
        np.ascontiguousarray(vert_position[order_v]),
        np.ascontiguousarray(idx.radiance[order_v], dtype=np.float32),
        new_of_old[idx.tri[order_t]].astype(np.uint32).reshape(-1, 3),
        idx.vert_patch[order_v].astype(np.int32),
        vdepth[order_v],
        tdepth[order_t],
    )
    for a in parts:
        a.flags.writeable = False  # shared by every Baked (as prefixes)
    return parts


def mesh_prefix(sorted_mesh: tuple, threshold: int) -> tuple:
    """Mesh part of the patches of depth < threshold from :func:`depth_sorted_mesh`: positions
    (M, 3), radiance (M, 3), indices (Tm, 3) uint32, vertex patch (M,)."""
    pos, rad, tri, vpatch, vdepth, tdepth = sorted_mesh
    nv = int(np.searchsorted(vdepth, threshold, side="left"))
    nt = int(np.searchsorted(tdepth, threshold, side="left"))
    return pos[:nv], rad[:nv], tri[:nt], vpatch[:nv]


def textured_polygons(
    is_quad: np.ndarray,
    corners: np.ndarray,
    patch_uv: np.ndarray,
    material: np.ndarray,
    detail: np.ndarray,
    ps: np.ndarray,
    sides: np.ndarray,
    packing: atlas.Packing,
) -> tuple:
    """One polygon per textured patch ``ps`` (k,), tile sides ``sides`` (k,), placed by ``packing``.

    is_quad (P,) bool, corners (P, 4, 3) float32, patch_uv (P, 4, 2) detail uv, material (P,),
    detail (P,) bool (texels hold incoming light). Returns ``(positions (K, 3), uv (K, 2) atlas,
    layer (K,), detail uv (K, 2), material (K,) int32, detail flag (K,) float32, patch (K,)
    int32, indices (Tt, 3) uint32)``, float32 unless said.
    """
    k = len(ps)
    q = is_quad[ps]
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
    positions = corners[ps][valid]
    uv = np.stack([u, v], axis=-1)[valid].astype(np.float32)
    layer = np.broadcast_to(pl[:, 0:1], (k, 4))[valid].astype(np.float32)
    duv = patch_uv[ps][valid].astype(np.float32)
    mat = np.broadcast_to(material[ps][:, None], (k, 4))[valid].astype(np.int32)
    det = np.broadcast_to(detail[ps][:, None], (k, 4))[valid].astype(np.float32)
    patch = np.broadcast_to(ps[:, None], (k, 4))[valid].astype(np.int32)
    tri = start[:, None, None] + np.array([[0, 1, 2], [0, 2, 3]])[None]
    tvalid = np.stack([np.ones(k, dtype=bool), q], axis=1)
    indices = tri[tvalid].astype(np.uint32).reshape(-1, 3)
    return positions, uv, layer, duv, mat, det, patch, indices
