"""T-junctions: vertices that lie inside another triangle's edge, and splitting them away.

A rasteriser fills two triangles without a gap only where they share both ends of an edge; where a
vertex of one lies inside the other's edge (a *T-junction*: a subdivided patch next to a coarser
one) a client shows see-through pixels along it. :func:`split_tjunctions` makes such a mesh
watertight: every triangle edge is split at the welded points lying strictly inside it and the
triangle is re-triangulated (fanned from the opposite corner when one side is split, from its
centroid when several are). New vertices are affine combinations of a triangle's own vertices, so
any attribute interpolated linearly over the triangle (colour, uv) is unchanged on screen:
:meth:`Split.interpolate` carries attributes over.

Everything is vectorised: candidate points come from a k-d tree around pieces of the edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["Split", "edge_points", "split_tjunctions", "tjunction_edges", "weld_tolerance"]

#: points within this times the bounding-box diagonal of an edge count as on it (and weld)
REL_TOL = 1e-6


def weld_tolerance(*positions: np.ndarray, rel_tol: float = REL_TOL) -> float:
    """``rel_tol`` x the bounding-box diagonal of all ``positions`` ((n, 3) arrays); > 0."""
    p = np.concatenate([np.asarray(x, np.float64).reshape(-1, 3) for x in positions])
    if not len(p):
        return 1e-12
    return max(float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) * rel_tol, 1e-12)


def _weld(points: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """(ids (n,) int64, unique (u, 3) float64): points on one ``tol`` grid cell share an id; the
    representative is the first such point."""
    key = np.floor(points / tol).astype(np.int64)
    _, first, ids = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return ids.reshape(-1), points[first]


def edge_points(
    positions: np.ndarray, triangles: np.ndarray, points: np.ndarray | None = None, tol: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The points lying strictly inside triangle sides.

    positions : (n, 3) float vertex positions; triangles : (t, 3) int indices into them
    points : (m, 3) float candidate points (default ``positions``); they are welded within ``tol``
    tol : distance to the edge and from its ends (default :func:`weld_tolerance` of both arrays)
    Returns ``(tri, side, point, t, where)``, (k,) each, sorted by triangle, side, then t: side
    ``s`` of triangle ``tri`` runs from its vertex ``s`` to vertex ``(s + 1) % 3``, ``t`` in (0, 1)
    is the point's parameter along it, ``where`` (k, 3) float64 the welded point's position, and
    ``point`` its welded id (the same for coincident points).
    """
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    pts = pos if points is None else np.asarray(points, np.float64).reshape(-1, 3)
    empty = (np.zeros(0, np.int64),) * 3 + (np.zeros(0), np.zeros((0, 3)))
    if not len(tri) or not len(pts):
        return empty
    if tol is None:
        tol = weld_tolerance(pos, pts)
    ids, uniq = _weld(np.concatenate([pts, pos]), tol)
    vid = ids[len(pts) :]  # welded id of each vertex
    # the triangles' sides as undirected edges of welded ids (each edge once)
    a = tri.ravel()
    b = tri[:, [1, 2, 0]].ravel()
    wa, wb = vid[a], vid[b]
    edges, side_edge = np.unique(
        np.stack([np.minimum(wa, wb), np.maximum(wa, wb)], axis=1), axis=0, return_inverse=True
    )
    side_edge = side_edge.reshape(-1)
    keep = edges[:, 0] != edges[:, 1]
    p0, p1 = uniq[edges[:, 0]], uniq[edges[:, 1]]
    d = p1 - p0
    length = np.linalg.norm(d, axis=1)
    if not keep.any():
        return empty
    # pieces of length <= h along each edge; a sphere of radius h / 2 + tol around each piece's
    # centre holds every point within tol of it
    h = max(float(np.median(length[keep])), 4 * tol)
    n_pieces = np.where(keep, np.ceil(length / h).astype(np.int64), 0)
    piece_edge = np.repeat(np.arange(len(edges)), n_pieces)
    k = np.arange(len(piece_edge)) - np.repeat(np.cumsum(n_pieces) - n_pieces, n_pieces)
    frac = (k + 0.5) / n_pieces[piece_edge]
    centres = p0[piece_edge] + frac[:, None] * d[piece_edge]
    r = 0.5 * length[piece_edge] / n_pieces[piece_edge] + 2 * tol
    pairs = cKDTree(centres).sparse_distance_matrix(cKDTree(uniq), float(r.max()), output_type="ndarray")
    pe, pj = piece_edge[pairs["i"]], pairs["j"].astype(np.int64)
    ok = pairs["v"] <= r[pairs["i"]]
    pe, pj = pe[ok], pj[ok]
    ok = (pj != edges[pe, 0]) & (pj != edges[pe, 1])
    pe, pj = pe[ok], pj[ok]
    rel = uniq[pj] - p0[pe]
    s = (rel * d[pe]).sum(axis=1) / length[pe] ** 2
    dist = np.linalg.norm(rel - s[:, None] * d[pe], axis=1)
    ok = (dist <= tol) & (s * length[pe] > tol) & ((1 - s) * length[pe] > tol)
    pe, pj, s = pe[ok], pj[ok], s[ok]
    pe_pj = np.unique(np.stack([pe, pj], axis=1), axis=0)  # a point found from two pieces once
    if not len(pe_pj):
        return empty
    pe, pj = pe_pj[:, 0], pe_pj[:, 1]
    rel = uniq[pj] - p0[pe]
    s = (rel * d[pe]).sum(axis=1) / length[pe] ** 2
    # back to triangle sides: every side on an edge with points gets them, t along the side
    order = np.argsort(side_edge, kind="stable")
    first = np.searchsorted(side_edge[order], pe, side="left")
    last = np.searchsorted(side_edge[order], pe, side="right")
    count = last - first
    rows = np.repeat(np.arange(len(pe)), count)
    side_id = order[
        np.repeat(first, count) + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
    ]
    forward = wa[side_id] == edges[pe[rows], 0]
    t = np.where(forward, s[rows], 1.0 - s[rows])
    tri_id, side = side_id // 3, side_id % 3
    o = np.lexsort((t, side, tri_id))
    return tri_id[o], side[o], pj[rows][o], t[o], uniq[pj[rows][o]]


def tjunction_edges(
    positions: np.ndarray, triangles: np.ndarray, points: np.ndarray | None = None, tol: float | None = None
) -> int:
    """How many distinct triangle edges (undirected, by vertex index) have a point strictly inside
    them (see :func:`edge_points`): 0 for a watertight mesh."""
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    tid, side, _, _, _ = edge_points(positions, tri, points, tol)
    if not len(tid):
        return 0
    a, b = tri[tid, side], tri[tid, (side + 1) % 3]
    return int(len(np.unique(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1), axis=0)))


@dataclass
class Split:
    """A mesh with its T-junctions split.

    positions : (n', 3) float64; the first n are the input's, then split points and centroids
    triangles : (t', 3) int64, each input triangle's pieces in its place (input order kept)
    source, weights : (n', 3) int64 and float64: vertex v is ``sum_k weights[v, k] x
    input_vertex[source[v, k]]`` (all three from one input triangle)
    triangle_source : (t',) int64, the input triangle of each output triangle
    split_triangles : how many input triangles were re-triangulated
    """

    positions: np.ndarray
    triangles: np.ndarray
    source: np.ndarray
    weights: np.ndarray
    triangle_source: np.ndarray
    split_triangles: int

    def interpolate(self, values: np.ndarray) -> np.ndarray:
        """(n', ...) per-vertex ``values`` (n, ...) carried to the output vertices (affine: exact for
        anything linear over a triangle), in ``values``' dtype."""
        v = np.asarray(values)
        w = self.weights.reshape(self.weights.shape + (1,) * (v.ndim - 1))
        out = (v[self.source].astype(np.float64) * w).sum(axis=1)
        return out.astype(v.dtype)

    def pick(self, values: np.ndarray) -> np.ndarray:
        """(n', ...) per-vertex ``values`` that are constant over a triangle (page, material,
        patch): each output vertex takes its first source vertex's."""
        return np.asarray(values)[self.source[:, 0]]


def _split_once(
    pos: np.ndarray, tri: np.ndarray, points, tol
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """One pass of :func:`split_tjunctions`: ``(positions, triangles, triangle_source, split)``."""
    T = len(tri)
    n = len(pos)
    tid, side, pid, t, where = edge_points(pos, tri, points, tol)
    if not len(tid):
        return pos, tri, np.arange(T), 0
    va, vb = tri[tid, side], tri[tid, (side + 1) % 3]
    # one new vertex per (vertex pair, point): both triangles on a shared side use it
    key = np.stack([np.minimum(va, vb), np.maximum(va, vb), pid], axis=1)
    _, first, new_of = np.unique(key, axis=0, return_index=True, return_inverse=True)
    new_of = new_of.reshape(-1)
    n_split = len(first)
    # which triangles are split, and on how many sides
    hit = np.zeros((T, 3), bool)
    hit[tid, side] = True
    nsides = hit.sum(axis=1)
    split = np.flatnonzero(nsides > 0)
    centred = split[nsides[split] > 1]
    c_index = np.full(T, -1, np.int64)
    c_index[centred] = n + n_split + np.arange(len(centred))
    # the boundary polygon of each split triangle: corner s, the points of side s in order, ...
    # rotated so that a one-side triangle starts at its split side's first corner
    rot = np.zeros(T, np.int64)
    one = split[nsides[split] == 1]
    rot[one] = np.argmax(hit[one], axis=1)
    ct = np.repeat(split, 3)
    cs = np.tile(np.arange(3), len(split))
    items_tri = np.concatenate([ct, tid])
    items_side = np.concatenate([cs, side])
    items_t = np.concatenate([np.full(len(ct), -1.0), t])
    items_v = np.concatenate([tri[ct, cs], n + new_of])
    o = np.lexsort((items_t, (items_side - rot[items_tri]) % 3, items_tri))
    ptri, pv = items_tri[o], items_v[o]
    start = np.searchsorted(ptri, split)
    length = np.diff(np.append(start, len(ptri)))
    plen = np.repeat(length, length)
    pidx = np.arange(len(ptri)) - np.repeat(start, length)
    nxt = np.where(pidx + 1 < plen, np.arange(len(ptri)) + 1, np.arange(len(ptri)) - pidx)
    is_c = c_index[ptri] >= 0
    # centroid fans: (c, q_i, q_i+1) for every polygon edge
    fan_c = np.stack([c_index[ptri[is_c]], pv[is_c], pv[nxt[is_c]]], axis=1)
    # corner fans: (q_last, q_i, q_i+1) for i = 0 .. len - 3 (q_last: the corner opposite the side)
    sel = ~is_c & (pidx <= plen - 3)
    last = pv[np.arange(len(ptri)) - pidx + plen - 1]
    fan_o = np.stack([last[sel], pv[sel], pv[nxt[sel]]], axis=1)
    kept = np.flatnonzero(nsides == 0)
    tris = np.concatenate([tri[kept], fan_c, fan_o])
    tsrc = np.concatenate([kept, ptri[is_c], ptri[sel]])
    order = np.argsort(tsrc, kind="stable")
    new_pos = np.concatenate([pos, where[first], pos[tri[centred]].mean(axis=1)])
    return new_pos, tris[order], tsrc[order], int(len(split))


def _barycentric(p: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(k, 3) barycentric coordinates of points ``p`` (k, 3) projected onto triangles (k, 3, 3)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = d00 * d11 - d01 * d01
    den = np.where(den > 0, den, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1.0 - v - w, v, w], axis=1)


#: passes of splitting (a fan's inner edge can run through a point of an overlapping surface)
MAX_PASSES = 4


def split_tjunctions(
    positions: np.ndarray, triangles: np.ndarray, points: np.ndarray | None = None, tol: float | None = None
) -> Split:
    """Split every side of ``triangles`` at the points lying strictly inside it (see
    :func:`edge_points`; ``points`` default: the mesh's own vertices, pass the union of several
    meshes to make them watertight against each other) and re-triangulate: a triangle with points
    on one side is fanned from the opposite corner, one with points on several from its centroid.
    A point shared by several sides of the same vertex pair becomes one vertex. Repeated (at most
    :data:`MAX_PASSES` times) while a new inner edge runs through a point (one of a coplanar
    overlapping surface). Returns a :class:`Split`; with no T-junction it holds the input
    unchanged."""
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    n = len(pos)
    if tol is None:
        tol = weld_tolerance(pos, pos if points is None else points)
    if points is None:
        points = pos
    cur_pos, cur_tri, tsrc, split = pos, tri, np.arange(len(tri)), 0
    for _ in range(MAX_PASSES):
        cur_pos, cur_tri, step_src, k = _split_once(cur_pos, cur_tri, points, tol)
        if not k:
            break
        tsrc = tsrc[step_src]
        split = split or k
    source = np.repeat(np.arange(len(cur_pos))[:, None], 3, axis=1)
    weights = np.tile([1.0, 0.0, 0.0], (len(cur_pos), 1))
    if len(cur_pos) > n:  # new vertices: affine in the input triangle of a triangle that uses them
        flat = cur_tri.ravel()
        owner = np.full(len(cur_pos), -1, np.int64)
        owner[flat[::-1]] = np.repeat(tsrc, 3)[::-1]  # the first triangle using each vertex
        new = np.arange(n, len(cur_pos))
        corners = tri[owner[new]]
        source[new] = corners
        weights[new] = _barycentric(cur_pos[new], pos[corners])
    return Split(cur_pos, cur_tri, source, weights, tsrc, split)
