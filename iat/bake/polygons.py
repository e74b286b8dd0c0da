"""The bake's vertex arrays: the mesh part sorted by patch depth (:func:`depth_sorted_mesh`, whose
prefixes are the mesh parts of every threshold) and the textured polygons with their atlas uv
(:func:`textured_polygons`; the uv convention is the one in :mod:`iat.bake.baker`'s docstring)."""

from __future__ import annotations

import numpy as np

from iat.bake import atlas
from iat.geometry.mesh import QUAD_SKEW_TOL, quad_twist
from iat.geometry.quadtree import bilinear

#: a quad root further than QUAD_SKEW_TOL from a parallelogram is drawn as this many cells a side
SKEW_GRID = 16

# lattice corner offsets (units of m - 1 texels) of the polygon corners: quads, triangles
_QUAD_OX = np.array([0, 1, 1, 0])
_QUAD_OY = np.array([0, 0, 1, 1])
_TRI_OX = np.array([0, 1, 0, 0])
_TRI_OY = np.array([0, 0, 1, 1])


def depth_sorted_mesh(patch_depth: np.ndarray, drawn, radiance: np.ndarray) -> tuple:
    """The drawn mesh's vertices and triangles sorted by their patch's tree depth (stable, so
    vertex-table order within a depth): ``(positions (V, 3) float32, radiance (V, 3) float32,
    indices (T, 3) uint32, vertex patch (V,) int32, vertex depth (V,), triangle depth (T,))``,
    read-only. The mesh part of threshold ``t`` (patches of depth ``< t``) is then a prefix of
    each (:func:`mesh_prefix`): views, no copy, and the renderer keeps one upload of the whole
    arrays for every threshold.

    patch_depth : (P,) int; drawn : :class:`iat.radiosity.solution.DrawnMesh`;
    radiance : (V, 3) its vertices' radiance (:meth:`~iat.radiosity.solution.DrawnMesh.radiance`)
    """
    tri = drawn.triangles
    vdepth = patch_depth[drawn.patch]
    order_v = np.argsort(vdepth, kind="stable")
    tdepth = patch_depth[drawn.patch[tri[:, 0]]] if len(tri) else np.zeros(0, np.int64)
    order_t = np.argsort(tdepth, kind="stable")
    new_of_old = np.empty(len(order_v), dtype=np.int64)
    new_of_old[order_v] = np.arange(len(order_v))
    parts = (
        np.ascontiguousarray(drawn.position[order_v], dtype=np.float32),
        np.ascontiguousarray(radiance[order_v], dtype=np.float32),
        new_of_old[tri[order_t]].astype(np.uint32).reshape(-1, 3),
        drawn.patch[order_v].astype(np.int32),
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
    clip_uv: np.ndarray | None = None,
    clip_start: np.ndarray | None = None,
) -> tuple:
    """One polygon per textured patch ``ps`` (k,), tile sides ``sides`` (k,), placed by ``packing``;
    a panel cell's polygon is its clip triangles (``clip_uv`` (C, 3, 2) lattice uv, patch p's rows
    ``clip_start[p]:clip_start[p + 1]``), so holes stay holes, and a quad far from a
    parallelogram (an in-memory scene; the loader makes none) a :data:`SKEW_GRID` grid, so its
    texture follows its bilinear lattice.

    is_quad (P,) bool, corners (P, 4, 3) float32, patch_uv (P, 4, 2) detail uv, material (P,),
    detail (P,) bool (texels hold incoming light). Returns ``(positions (K, 3), uv (K, 2) atlas,
    layer (K,), detail uv (K, 2), material (K,) int32, detail flag (K,) float32, patch (K,)
    int32, indices (Tt, 3) uint32)``, float32 unless said.
    """
    cut = np.zeros(len(ps), dtype=bool)
    if clip_start is not None and len(clip_uv):
        cut = np.diff(clip_start)[ps] > 0
    c = np.asarray(corners, dtype=np.float64)[ps]
    skewed = is_quad[ps] & ~cut & (quad_twist(c[:, 0], c[:, 1], c[:, 2], c[:, 3]) > QUAD_SKEW_TOL)
    out = _whole_polygons(is_quad, corners, patch_uv, material, detail, ps, sides, packing, ~cut & ~skewed)
    if not (cut.any() or skewed.any()):
        return out
    # pieces drawn through their lattice (u, v): a panel cell's clip triangles, and a grid over a
    # quad far from a parallelogram (its lattice is bilinear: affine per small triangle follows it)
    rows, tri_uv = [], []
    if cut.any():
        from iat.geometry.clip import ranges

        k, t = ranges(clip_start, ps[cut])
        rows.append(np.flatnonzero(cut)[k])
        tri_uv.append(clip_uv[t])
    if skewed.any():
        grid = _grid_triangles(SKEW_GRID)
        rows.append(np.repeat(np.flatnonzero(skewed), len(grid)))
        tri_uv.append(np.tile(grid, (int(skewed.sum()), 1, 1)))
    pieces = _piece_polygons(
        corners, patch_uv, material, detail, ps, sides, packing, np.concatenate(rows), np.concatenate(tri_uv)
    )
    n0 = len(out[0])
    return tuple(
        np.concatenate([a, b + (n0 if i == 7 else 0)])
        for i, (a, b) in enumerate(zip(out, pieces, strict=True))
    )


def _grid_triangles(n: int) -> np.ndarray:
    """(2 n², 3, 2) triangles of an n x n grid over the unit square."""
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    o = np.stack([a.ravel(), b.ravel()], axis=1)[:, None, :]
    t1 = o + np.array([[0, 0], [1, 0], [1, 1]])
    t2 = o + np.array([[0, 0], [1, 1], [0, 1]])
    return np.concatenate([t1, t2]).astype(np.float64) / n


def _piece_polygons(corners, patch_uv, material, detail, ps, sides, packing, r, tri_uv):
    """Triangles ``tri_uv`` (n, 3, 2) in the lattices of patches ``ps[r]``, in
    :func:`textured_polygons`' layout (positions and detail uvs blended bilinearly)."""
    p = ps[r]
    u = tri_uv[:, :, 0].reshape(-1)
    v = tri_uv[:, :, 1].reshape(-1)
    rr, pp = np.repeat(r, 3), np.repeat(p, 3)
    pl = packing.placements
    W, H = max(packing.width, 1), max(packing.height, 1)
    m1 = (sides[rr] - 1).astype(np.float64)
    auv = np.stack([(pl[rr, 1] + u * m1 + 0.5) / W, (pl[rr, 2] + v * m1 + 0.5) / H], axis=1)
    n = len(u)
    return (
        bilinear(np.asarray(corners, np.float64)[pp], u, v).astype(np.float32),
        auv.astype(np.float32),
        pl[rr, 0].astype(np.float32),
        bilinear(np.asarray(patch_uv, np.float64)[pp], u, v).astype(np.float32),
        material[pp].astype(np.int32),
        detail[pp].astype(np.float32),
        pp.astype(np.int32),
        np.arange(n, dtype=np.uint32).reshape(-1, 3),
    )


def _whole_polygons(is_quad, corners, patch_uv, material, detail, ps, sides, packing, sel) -> tuple:
    """The polygons (quads, triangles) of the whole patches ``ps[sel]``."""
    pl_all = packing.placements
    ps, sides = ps[sel], sides[sel]
    k = len(ps)
    q = is_quad[ps]
    nv = np.where(q, 4, 3)
    valid = np.arange(4)[None, :] < nv[:, None]
    start = np.concatenate([[0], np.cumsum(nv)[:-1]]).astype(np.int64)
    m1 = (sides - 1)[:, None]
    ox = np.where(q[:, None], _QUAD_OX, _TRI_OX) * m1
    oy = np.where(q[:, None], _QUAD_OY, _TRI_OY) * m1
    pl = pl_all[sel]
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
