"""Panels (the report's §6.1): connected coplanar patches of one material, one surface each.

:func:`find_panels` groups root patches that share an edge, a material and a plane, and
fits each group an oriented bounding rectangle in its own plane (the root a panel's
quad-tree would have). ``iat info`` reports them, and the slivers (CAD fans) among the patches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from iat.geometry.mesh import corner_positions, patch_areas, patch_normals

#: patches are coplanar when their normals are within this (radians) ...
PANEL_ANGLE_TOL = 1e-3
#: ... and each one's centre lies within this times the scene's diagonal of the other's plane
PANEL_PLANE_TOL = 1e-6
#: a patch is a sliver when its longest edge squared exceeds this times twice its area
SLIVER_ASPECT = 20.0


@dataclass
class Panels:
    """Panels of a scene's patches.

    panel : (p,) int64 panel index per patch
    normal : (k, 3) float64 unit normal per panel
    axes : (k, 2, 3) float64 in-plane unit axes of the bounding rectangle
    origin : (k, 3) float64 world corner of the rectangle (``origin + s a0 + t a1``, s, t in the extent)
    extent : (k, 2) float64 side lengths of the rectangle (scene units)
    area : (k,) float64 summed patch area
    """

    panel: np.ndarray
    normal: np.ndarray
    axes: np.ndarray
    origin: np.ndarray
    extent: np.ndarray
    area: np.ndarray

    @property
    def n_panels(self) -> int:
        return len(self.area)

    @property
    def fill(self) -> np.ndarray:
        """(k,) float64 panel area over its rectangle's (1 for a rectangle, less for holes, L shapes)."""
        rect = self.extent.prod(axis=1)
        return np.divide(self.area, rect, out=np.ones_like(self.area), where=rect > 0)


def _edges(corners: np.ndarray):
    """(e,) patch index and (e, 2) sorted vertex pairs of every patch edge."""
    c = np.asarray(corners, dtype=np.int64)
    n = np.where(c[:, 3] >= 0, 4, 3)
    patch, a, b = [], [], []
    for k in range(4):
        has = k < n
        nxt = np.where((k + 1) % n == 0, 0, (k + 1) % 4)
        p = np.flatnonzero(has)
        patch.append(p)
        a.append(c[p, k])
        b.append(c[p, nxt[p]])
    patch, a, b = np.concatenate(patch), np.concatenate(a), np.concatenate(b)
    return patch, np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)


def min_area_rectangle(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The smallest-area rectangle around 2-D ``points`` (m, 2) (rotating calipers over the hull).

    Returns (origin (2,), axes (2, 2) unit rows, extent (2,)); points are
    ``origin + s axes[0] + t axes[1]`` with ``0 <= s <= extent[0]``, ``0 <= t <= extent[1]``.
    """
    pts = np.asarray(points, dtype=np.float64)
    try:
        hull = pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):  # collinear or too few points
        hull = pts
    e = np.roll(hull, -1, axis=0) - hull
    length = np.linalg.norm(e, axis=1)
    e = e[length > 0] / length[length > 0, None]
    if len(e) == 0:
        return pts.min(axis=0), np.eye(2), np.zeros(2)
    normal = np.stack([-e[:, 1], e[:, 0]], axis=1)
    s = hull @ e.T  # (h, candidates)
    t = hull @ normal.T
    area = (s.max(axis=0) - s.min(axis=0)) * (t.max(axis=0) - t.min(axis=0))
    k = int(np.argmin(area))
    axes = np.stack([e[k], normal[k]])
    lo = np.array([s[:, k].min(), t[:, k].min()])
    hi = np.array([s[:, k].max(), t[:, k].max()])
    return lo @ axes, axes, hi - lo


def patch_geometry(vertices: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(p, 4, 3) corner positions (a triangle's 4th repeats its 3rd), (p, 3) unit normals and
    (p,) areas of root patches ``corners`` (p, 4) int64 (-1 in column 3 for triangles), as a
    :class:`~iat.io.scene.Scene` of them has them."""
    pos = corner_positions(vertices, corners)
    is_quad = np.asarray(corners)[:, 3] >= 0
    return pos, patch_normals(pos, is_quad), patch_areas(pos, is_quad)


def group_panels(vertices: np.ndarray, corners: np.ndarray, material: np.ndarray, fit: str = "all") -> Panels:
    """Group root patches into panels: edge-connected, same material, coplanar
    (:data:`PANEL_ANGLE_TOL`, :data:`PANEL_PLANE_TOL`); each gets its minimal bounding
    rectangle, with ``axes[0] x axes[1]`` along the panel's normal.

    vertices : (n, 3) float64; corners : (p, 4) int64; material : (p,) int64
    fit : which panels get their rectangle (a convex hull each: the slow part): ``"all"``,
      ``"triangles"`` (groups of two or more patches holding a triangle: what
      :func:`make_panels` may turn into cells) or ``"none"``; the others keep extent 0.
    """
    corners = np.asarray(corners, dtype=np.int64)
    n_p = len(corners)
    cpos, normal, p_area = patch_geometry(vertices, corners)
    centre = cpos.mean(axis=1)
    used = np.asarray(vertices)[np.unique(corners[corners >= 0])] if n_p else np.zeros((1, 3))
    tol = PANEL_PLANE_TOL * max(float(np.linalg.norm(used.max(axis=0) - used.min(axis=0))), 1e-12)
    patch, edge = _edges(corners)
    order = np.lexsort((edge[:, 1], edge[:, 0]))
    patch, edge = patch[order], edge[order]
    same = (edge[1:] == edge[:-1]).all(axis=1)  # consecutive half-edges on one edge
    a, b = patch[:-1][same], patch[1:][same]
    material = np.asarray(material, dtype=np.int64)
    ok = (material[a] == material[b]) & ((normal[a] * normal[b]).sum(axis=1) >= np.cos(PANEL_ANGLE_TOL))
    ok &= np.abs(((centre[b] - centre[a]) * normal[a]).sum(axis=1)) <= tol
    a, b = a[ok], b[ok]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n_p, n_p))
    k, panel = connected_components(graph, directed=False)
    panel = panel.astype(np.int64)
    area = np.bincount(panel, weights=p_area, minlength=k)
    pn = np.zeros((k, 3))
    np.add.at(pn, panel, normal * p_area[:, None])
    pn /= np.maximum(np.linalg.norm(pn, axis=1, keepdims=True), 1e-300)
    axes = np.zeros((k, 2, 3))
    origin = np.zeros((k, 3))
    extent = np.zeros((k, 2))
    members = members_of(panel, k)
    if fit == "all":
        todo = range(k)
    elif fit == "triangles":
        size = np.bincount(panel, minlength=k)
        with_tri = np.bincount(panel, weights=corners[:, 3] < 0, minlength=k) > 0
        todo = np.flatnonzero((size >= 2) & with_tri)
    else:
        todo = []
    for q in todo:  # one small hull per panel
        idx = members[q]
        helper = np.array([1.0, 0.0, 0.0]) if abs(pn[q, 0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = np.cross(pn[q], helper)
        u /= np.linalg.norm(u)
        frame = np.stack([u, np.cross(pn[q], u)])
        pts = cpos[idx].reshape(-1, 3)
        o2, ax2, ext = min_area_rectangle(pts @ frame.T)
        ax = ax2 @ frame
        if np.cross(ax[0], ax[1]) @ pn[q] < 0:  # right-handed about the normal
            o2, ax[1] = o2 + ext[1] * ax2[1], -ax[1]
        axes[q] = ax
        origin[q] = o2 @ frame + (pts @ pn[q]).mean() * pn[q]
        extent[q] = ext
    return Panels(panel=panel, normal=pn, axes=axes, origin=origin, extent=extent, area=area)


def members_of(label: np.ndarray, k: int) -> list[np.ndarray]:
    """Indices of each of ``k`` labels in ``label`` (n,), ascending within a label."""
    return np.split(np.argsort(label, kind="stable"), np.cumsum(np.bincount(label, minlength=k))[:-1])


def find_panels(scene, fit: str = "all") -> Panels:
    """:func:`group_panels` of a :class:`~iat.io.scene.Scene`'s root patches."""
    return group_panels(scene.vertices, scene.patch_corners, scene.patch_material, fit)


def sliver_count(scene) -> int:
    """Patches whose longest edge squared exceeds :data:`SLIVER_ASPECT` x twice their area (CAD fans)."""
    c = scene.corner_positions
    e = np.linalg.norm(np.roll(c, -1, axis=1) - c, axis=2)
    tri = ~scene.patch_is_quad
    e[tri, 2] = np.linalg.norm(c[tri, 0] - c[tri, 2], axis=1)
    return int((e.max(axis=1) ** 2 > SLIVER_ASPECT * 2.0 * np.maximum(scene.patch_area, 1e-300)).sum())


#: a group becomes a panel only when its area fills at least this much of its rectangle
PANEL_MIN_FILL = 0.2
#: panel cells are at most this times the square root of the scene's area a side (with the
#: solver's default depth and minimum element, a finer root would not refine further)
PANEL_CELL_FRACTION = 0.2
#: a cell covered to within this fraction is a plain rectangle root (no clip triangles)
FULL_COVER = 1.0 - 1e-9


@dataclass
class PanelRoots:
    """Root patches after panels (:func:`make_panels`).

    vertices : (n', 3) float64 (the input's, then the panels' cell corners)
    corners : (p', 4) int64; material : (p',) int64; uv : (p', 4, 2) float64 detail uv
    clip_uv : (C, 3, 2) float64 clip triangles in their patch's lattice (u, v), sorted by patch
    clip_patch : (C,) int64
    n_panels : groups turned into panels
    """

    vertices: np.ndarray
    corners: np.ndarray
    material: np.ndarray
    uv: np.ndarray
    clip_uv: np.ndarray
    clip_patch: np.ndarray
    n_panels: int


def _affine_uv(st: np.ndarray, uv: np.ndarray) -> np.ndarray | None:
    """(3, 2) affine map ``[s, t, 1] -> uv`` fitting (m, 2) points exactly, or None."""
    X = np.concatenate([st, np.ones((len(st), 1))], axis=1)
    M, *_ = np.linalg.lstsq(X, uv, rcond=None)
    err = np.abs(X @ M - uv).max() if len(uv) else 0.0
    return M if err <= 1e-6 * max(1.0, float(np.abs(uv).max(initial=0.0))) else None


def make_panels(
    vertices: np.ndarray,
    corners: np.ndarray,
    material: np.ndarray,
    uv: np.ndarray,
    has_detail: np.ndarray,
    cell_max: float | None = None,
) -> PanelRoots:
    """Turn groups of coplanar patches that hold triangles into panels (report §6.1).

    A group (:func:`group_panels`) of two or more patches of which one is a triangle, filling
    at least :data:`PANEL_MIN_FILL` of its rectangle, with detail uvs affine over it (or a
    material without a detail texture), becomes a grid of rectangle roots over its bounding
    rectangle, cells of at most :data:`PANEL_CELL_FRACTION` x sqrt(scene area) a side: a
    cell the group covers is a plain quad root, a cell it covers in part a root with *clip
    triangles* (the group's triangles cut to the cell, in the cell's lattice (u, v)), a cell
    it misses is dropped. Groups of parallelogram quads (already good roots) stay as they are.

    vertices (n, 3) float64, corners (p, 4) int64, material (p,) int64, uv (p, 4, 2) float64,
    has_detail (materials,) bool; cell_max : cells no longer than this either (scene units).
    Patches come back in order: kept patches first (input
    order), then the panels' cells.
    """
    from iat.geometry.clip import clip_to_boxes, fan, triangle_area

    V = np.asarray(vertices, dtype=np.float64)
    corners = np.asarray(corners, dtype=np.int64)
    material = np.asarray(material, dtype=np.int64)
    uv = np.asarray(uv, dtype=np.float64)
    empty = PanelRoots(V, corners, material, uv, np.zeros((0, 3, 2)), np.zeros(0, dtype=np.int64), 0)
    if not (corners[:, 3] < 0).any():  # no triangle: no group can become a panel
        return empty
    pan = group_panels(V, corners, material, fit="triangles")
    is_tri = corners[:, 3] < 0
    k = pan.n_panels
    size = np.bincount(pan.panel, minlength=k)
    with_tri = np.bincount(pan.panel, weights=is_tri, minlength=k) > 0
    cand = np.flatnonzero((size >= 2) & with_tri & (pan.fill >= PANEL_MIN_FILL))
    if len(cand) == 0:
        return empty
    _, _, p_area = patch_geometry(V, corners)
    cell_max = min(PANEL_CELL_FRACTION * np.sqrt(float(p_area.sum())), cell_max or np.inf)
    members = members_of(pan.panel, k)
    tri_of_quad = np.array([[0, 1, 2], [0, 2, 3]])
    keep = np.ones(len(corners), dtype=bool)
    new_v, new_c, new_m, new_uv, clip_uv, clip_patch = [], [], [], [], [], []
    n_v, n_p = len(V), int(len(corners))
    n_done = 0
    for q in cand:
        idx = members[q]
        c = corners[idx]
        tris = np.concatenate([c[~is_tri[idx]][:, tri_of_quad].reshape(-1, 3), c[is_tri[idx], :3]])
        tri_uv = np.concatenate(
            [uv[idx][~is_tri[idx]][:, tri_of_quad].reshape(-1, 3, 2), uv[idx][is_tri[idx], :3]]
        )
        o, ax, ext = pan.origin[q], pan.axes[q], pan.extent[q]
        st = np.einsum("tkc,ac->tka", V[tris] - o, ax)  # (t, 3, 2) panel-plane coordinates
        M = np.zeros((3, 2))
        if has_detail[material[idx[0]]]:
            M = _affine_uv(st.reshape(-1, 2), tri_uv.reshape(-1, 2))
            if M is None:
                continue
        n0, n1 = (max(1, int(np.ceil(e / cell_max - 1e-9))) for e in ext)
        d0, d1 = ext[0] / n0, ext[1] / n1
        gi, gj = np.meshgrid(np.arange(n0), np.arange(n1), indexing="ij")
        cell_lo = np.stack([gi.ravel() * d0, gj.ravel() * d1], axis=1)
        cell_hi = cell_lo + [d0, d1]
        # every (triangle, cell) pair whose boxes overlap, clipped to the cell
        tlo, thi = st.min(axis=1), st.max(axis=1)
        a0 = np.clip(np.floor(tlo[:, 0] / max(d0, 1e-300)), 0, n0 - 1).astype(int)
        a1 = np.clip(np.floor(thi[:, 0] / max(d0, 1e-300)), 0, n0 - 1).astype(int)
        b0 = np.clip(np.floor(tlo[:, 1] / max(d1, 1e-300)), 0, n1 - 1).astype(int)
        b1 = np.clip(np.floor(thi[:, 1] / max(d1, 1e-300)), 0, n1 - 1).astype(int)
        ti, ci = [], []
        for t in range(len(st)):
            ii, jj = np.meshgrid(np.arange(a0[t], a1[t] + 1), np.arange(b0[t], b1[t] + 1), indexing="ij")
            ci.append((ii * n1 + jj).ravel())
            ti.append(np.full(ci[-1].size, t))
        ti, ci = np.concatenate(ti), np.concatenate(ci)
        P, _, cnt = clip_to_boxes(st[ti], cell_lo[ci], cell_hi[ci])
        T, _, poly = fan(P, np.zeros(P.shape[:2] + (1,)), cnt, min_area=1e-12 * d0 * d1)
        cell_of = ci[poly]
        cover = np.bincount(cell_of, weights=triangle_area(T), minlength=n0 * n1) / (d0 * d1)
        grid = o + (
            np.arange(n0 + 1)[:, None, None] * d0 * ax[0] + np.arange(n1 + 1)[None, :, None] * d1 * ax[1]
        )
        gid = n_v + np.arange((n0 + 1) * (n1 + 1)).reshape(n0 + 1, n1 + 1)
        new_v.append(grid.reshape(-1, 3))
        n_v += (n0 + 1) * (n1 + 1)
        for cell in np.flatnonzero(cover > 1e-9):
            i, j = divmod(int(cell), n1)
            quad = [gid[i, j], gid[i + 1, j], gid[i + 1, j + 1], gid[i, j + 1]]
            st_c = np.array(
                [
                    [i * d0, j * d1],
                    [(i + 1) * d0, j * d1],
                    [(i + 1) * d0, (j + 1) * d1],
                    [i * d0, (j + 1) * d1],
                ]
            )
            new_c.append(quad)
            new_m.append(material[idx[0]])
            new_uv.append(np.concatenate([st_c, np.ones((4, 1))], axis=1) @ M)
            if cover[cell] < FULL_COVER:
                sel = cell_of == cell
                clip_uv.append((T[sel] - cell_lo[cell]) / [d0, d1])
                clip_patch.append(np.full(int(sel.sum()), n_p))
            n_p += 1
        keep[idx] = False
        n_done += 1
    if n_done == 0:
        return empty
    kept = np.flatnonzero(keep)
    remap = np.full(len(corners), -1)
    remap[kept] = np.arange(len(kept))
    shift = len(corners) - len(kept)  # cells were numbered after all input patches
    cp = np.concatenate(clip_patch) - shift if clip_patch else np.zeros(0, dtype=np.int64)
    return PanelRoots(
        vertices=np.concatenate([V, *new_v]),
        corners=np.concatenate([corners[kept], np.asarray(new_c, dtype=np.int64).reshape(-1, 4)]),
        material=np.concatenate([material[kept], np.asarray(new_m, dtype=np.int64)]),
        uv=np.concatenate([uv[kept], np.asarray(new_uv, dtype=np.float64).reshape(-1, 4, 2)]),
        clip_uv=np.concatenate(clip_uv) if clip_uv else np.zeros((0, 3, 2)),
        clip_patch=cp.astype(np.int64),
        n_panels=n_done,
    )
