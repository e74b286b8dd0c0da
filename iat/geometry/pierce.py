"""Faces cut where other geometry pierces them (issue 36: no leaks through intersecting geometry).

Real BIM exports pass walls up through a ceiling into the sun. A root patch that straddles the
ceiling has vertices above it (sunlit) and below it (the room): its elements interpolate across the
ceiling line and, as a shooter, its field carries the sunlight into the room. So the loader
(:func:`iat.io.load.load_scene`, ``cut=True``, the default) cuts the triangles along the lines where
other objects pierce them, after welding and the sides classification and before quads and panels
are made:

1. :func:`pierced_pairs`: pairs of triangles of *different* objects (IFC elements, glTF primitives,
   OBJ groups) that cross properly: each has corners strictly on both sides of the other's plane
   (beyond :data:`PIERCE_TOL` x the scene diagonal) and the two crossing intervals on the planes'
   common line overlap by more than that. Touching is not piercing: a box standing on a floor, a
   slab that ends on a wall's face, coplanar overlaps are left as they are (a sample model with no
   crossing loads exactly as before). A sweep over the triangles' boxes along the axis with the
   fewest overlaps, compiled with numba.
2. :func:`cut_faces`: each pierced triangle is cut by the plane of every face that pierces it (the
   whole triangle, restricted to the faces that really cross it, and to planes whose faces cross it
   along at least :data:`MIN_CROSSING` of its chord there), convex piece by convex piece;
   the pieces are fanned into triangles, their vertices welded, their uvs interpolated. The piece
   edges that lie on a cut are **barriers**.
3. :func:`region_labels`: patches may merge only within a side of every barrier. Coplanar,
   same-material faces joined by non-barrier edges form regions; a region that holds both sides of
   a barrier (it joins around the cut's end) gives each of its faces a region of its own. The
   loader passes (material, region) pairs as the materials :func:`iat.geometry.mesh.merge_quads`
   and :func:`iat.geometry.panels.make_panels` see (so no quad, no panel and no panel cell spans
   a cut) and maps them back after.
4. :func:`refan_regions`: a region holding pieces, flat, on one uv map, whose outline is one convex
   polygon once its straight vertices are dropped, is made again as a fan of that polygon (a wall's
   rectangle between two slabs: two triangles, one quad, where the pieces' fans made many); else
   as fans of the convex cells :mod:`iat.geometry.decompose` cuts it into (a wall with a door: three).

:func:`cut_pierced` runs the four; its :class:`PierceReport` is ``Scene.pierce`` (``iat info``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from iat.geometry.decompose import boundary_half_edges, decompose_regions, region_plane
from iat.geometry.mesh import QUAD_SKEW_TOL, degenerate_faces, quad_twist, weld_vertices

#: the loader's choices (``load_scene(cut=...)``, ``--cut``): ``crossings`` (``True``): faces cut
#: where faces of other objects cross them;
#: ``all``: also where a face of another object rests on them (a slab ending on a wall's face, a wall
#: standing on a slab, a box on a floor: contacts); ``none`` (``False``): nothing cut (the crossings
#: are still counted); ``auto`` (default): ``all`` for a model taken as built (IFC, or ``sides="both"``),
#: ``crossings`` for the rest
CUTS = ("auto", "crossings", "all", "none")
#: faces pierce each other when each has corners beyond this fraction of the scene diagonal on both
#: sides of the other's plane and their crossing overlaps by more than that (0.1 mm in a 10 m house)
PIERCE_TOL = 1e-5
#: a face is cut along a plane only where the faces in that plane cross (or touch) it along at least
#: this fraction of its chord on the plane (a bolt through a steel plate does not slice the plate
#: from edge to edge; a slab through a wall's face crosses all of it)
MIN_CROSSING = 0.25
#: faces are coplanar neighbours of one region when their normals are within this (radians; as panels)
REGION_ANGLE_TOL = 1e-3
#: a region's outline vertex within this fraction of the scene diagonal of its neighbours' chord is
#: straight (dropped from its fan), and its faces within it of one plane are flat (:func:`refan_regions`)
STRAIGHT_TOL = 1e-8
#: a region's faces follow one affine uv map when their corners' uvs are within this of it (relative
#: to the uvs' size, at least 1: as merge_quads)
UV_TOL = 1e-6


@dataclass
class PierceReport:
    """What :func:`cut_pierced` found and did (``iat info``).

    cut : whether the loader cut (``load_scene(cut=...)``); the counts are found either way
    mode : what the loader cut (crossings, all or none: :data:`CUTS`, ``auto`` resolved)
    pairs : pairs of triangles of different objects that pierce each other
    contacts : triangles that rest on a triangle of another object (counted with ``contacts``)
    objects : objects (IFC elements, glTF primitives, OBJ groups) with a face in such a pair
    faces_cut : triangles cut (0 when ``cut`` is False; a crossing shorter than
      :data:`MIN_CROSSING` of the face's chord cuts nothing)
    pieces : triangles they were cut into
    joined_regions : regions that joined around a cut's end (their faces merge no further)
    fanned_regions : regions of pieces made again as fans: of their convex outline, or of the convex
      cells they are cut into (:func:`refan_regions`)
    decomposed_regions : of those, the regions cut into convex cells (an outline not convex, or holes)
    triangles : triangles out, cut or not, after the fans (the input's when nothing is cut)
    """

    cut: bool = True
    mode: str = "crossings"
    pairs: int = 0
    contacts: int = 0
    objects: int = 0
    faces_cut: int = 0
    pieces: int = 0
    joined_regions: int = 0
    fanned_regions: int = 0
    decomposed_regions: int = 0
    triangles: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


@njit(cache=True, nogil=True)
def _interval(t, dist, tri, line, tol):
    """(lo, hi) of triangle ``t``'s crossing of a plane along unit ``line``; dist (3,): its
    corners' signed distances to that plane (within ``tol``: on it)."""
    lo, hi = np.inf, -np.inf
    for i in range(3):
        j = (i + 1) % 3
        di, dj = dist[i], dist[j]
        si = 0 if abs(di) <= tol else (1 if di > 0 else -1)
        sj = 0 if abs(dj) <= tol else (1 if dj > 0 else -1)
        if si == 0:
            s = tri[t, i, 0] * line[0] + tri[t, i, 1] * line[1] + tri[t, i, 2] * line[2]
            lo, hi = min(lo, s), max(hi, s)
        if si * sj < 0:
            f = di / (di - dj)
            s = 0.0
            for c in range(3):
                s += (tri[t, i, c] + (tri[t, j, c] - tri[t, i, c]) * f) * line[c]
            lo, hi = min(lo, s), max(hi, s)
    return lo, hi


@njit(cache=True, nogil=True)
def _straddle(a, b, tri, normal, offset, tol, dist):
    """Fill ``dist`` (3,) with triangle a's corners' distances to b's plane; True when a has
    corners beyond ``tol`` on both sides."""
    lo, hi = np.inf, -np.inf
    for i in range(3):
        d = tri[a, i, 0] * normal[b, 0] + tri[a, i, 1] * normal[b, 1] + tri[a, i, 2] * normal[b, 2]
        d -= offset[b]
        dist[i] = d
        lo, hi = min(lo, d), max(hi, d)
    return lo < -tol and hi > tol


@njit(cache=True, nogil=True)
def _chords(a, b, tri, normal, tol, da, db, line, span):
    """The chords of triangles a and b (their signed distances ``da``, ``db`` (3,) from each other's
    plane) along the planes' common ``line`` (3,): ``span`` (3,) gets a's, b's and their overlap;
    True when they overlap by more than ``tol`` (False for parallel planes)."""
    line[0] = normal[a, 1] * normal[b, 2] - normal[a, 2] * normal[b, 1]
    line[1] = normal[a, 2] * normal[b, 0] - normal[a, 0] * normal[b, 2]
    line[2] = normal[a, 0] * normal[b, 1] - normal[a, 1] * normal[b, 0]
    n = np.sqrt(line[0] ** 2 + line[1] ** 2 + line[2] ** 2)
    if n < 1e-12:
        return False
    line /= n
    lo_a, hi_a = _interval(a, da, tri, line, tol)
    lo_b, hi_b = _interval(b, db, tri, line, tol)
    span[0], span[1], span[2] = hi_a - lo_a, hi_b - lo_b, min(hi_a, hi_b) - max(lo_a, lo_b)
    return span[2] > tol


@njit(cache=True, nogil=True)
def _crossing(a, b, tri, normal, offset, tol, da, db, line, span):
    """True when triangles a and b pierce each other (see :func:`pierced_pairs`); ``span`` (3,) gets
    the lengths of a's and b's chords along the planes' common line and of their overlap."""
    if not _straddle(a, b, tri, normal, offset, tol, da):
        return False
    if not _straddle(b, a, tri, normal, offset, tol, db):
        return False
    return _chords(a, b, tri, normal, tol, da, db, line, span)


@njit(cache=True, nogil=True)
def _rests_on(a, b, tri, normal, offset, tol, da, db, line, span):
    """True when triangle b rests on triangle a: an edge of b lies in a's plane across a's inside,
    b stays on one side of that plane, and a has corners beyond ``tol`` on both sides of b's plane
    (a slab ending on a wall's face, a box on a floor; see :func:`pierced_pairs`)."""
    if not _straddle(a, b, tri, normal, offset, tol, da):
        return False
    if _straddle(b, a, tri, normal, offset, tol, db):
        return False
    on = 0
    for i in range(3):
        on += abs(db[i]) <= tol
    if on != 2:
        return False
    return _chords(a, b, tri, normal, tol, da, db, line, span)


@njit(cache=True, nogil=True)
def _sweep(tri, normal, offset, lo, hi, obj, order, axis, tol, contacts):
    """Rows (i, j, kind) int64 and spans (chord of i, chord of j, overlap) float64 of the pairs of a
    sweep along ``axis`` over the boxes ``lo``, ``hi`` (T, 3) in ``order`` (sorted by
    ``lo[:, axis]``): kind 0, i < j cross each other; kind 1 (with ``contacts``), j rests on i."""
    cap = 1024
    rows = np.empty((cap, 3), np.int64)
    spans = np.empty((cap, 3))
    k = 0
    da = np.empty(3)
    db = np.empty(3)
    line = np.empty(3)
    span = np.empty(3)
    n = len(order)
    for ii in range(n):
        i0 = order[ii]
        for jj in range(ii + 1, n):
            j0 = order[jj]
            if lo[j0, axis] > hi[i0, axis]:
                break
            if obj[i0] == obj[j0]:
                continue
            if (
                lo[j0, 0] > hi[i0, 0]
                or lo[i0, 0] > hi[j0, 0]
                or lo[j0, 1] > hi[i0, 1]
                or lo[i0, 1] > hi[j0, 1]
                or lo[j0, 2] > hi[i0, 2]
                or lo[i0, 2] > hi[j0, 2]
            ):
                continue
            i, j = min(i0, j0), max(i0, j0)
            for kind in range(3):  # a crossing, else j resting on i, else i resting on j
                if kind == 0:
                    found = _crossing(i, j, tri, normal, offset, tol, da, db, line, span)
                elif not contacts:
                    break
                elif kind == 1:
                    found = _rests_on(i, j, tri, normal, offset, tol, da, db, line, span)
                else:
                    found = _rests_on(j, i, tri, normal, offset, tol, da, db, line, span)
                if not found:
                    continue
                if k == cap:
                    cap *= 2
                    r2, s2 = np.empty((cap, 3), np.int64), np.empty((cap, 3))
                    r2[:k], s2[:k] = rows[:k], spans[:k]
                    rows, spans = r2, s2
                rows[k, 0], rows[k, 1], rows[k, 2] = (j, i, 1) if kind == 2 else (i, j, min(kind, 1))
                spans[k] = span
                k += 1
                break
    return rows[:k], spans[:k]


@dataclass
class Pairs:
    """:func:`pierced_pairs`'s result.

    a, b : (k,) int64, a < b, sorted: triangles that cross each other; span : (k, 3) float64 the
      lengths of a's and b's chords along the line where their planes meet, and of the crossing
    c, d : (m,) int64 sorted: triangle d rests on triangle c (an edge of d lies in c's plane across
      c, d on one side of it, c on both sides of d's plane: c is cut by d's plane, d is not cut);
      contact_span : (m, 3) float64 likewise (c's chord, d's edge, their overlap). Empty unless asked.
    """

    a: np.ndarray
    b: np.ndarray
    span: np.ndarray
    c: np.ndarray
    d: np.ndarray
    contact_span: np.ndarray


def pierced_pairs(tri: np.ndarray, objects: np.ndarray, tol: float, contacts: bool = False) -> Pairs:
    """Pairs of triangles of different objects that pierce each other (and, with ``contacts``, that
    rest on each other): :class:`Pairs`.

    tri : (T, 3, 3) float64 world corners; objects : (T,) int64; tol : scene units (corners within
    it of a plane are on it, crossings no longer than it do not count).
    """
    tri = np.ascontiguousarray(tri, dtype=np.float64)
    none = np.zeros(0, np.int64)
    if len(tri) < 2:
        return Pairs(none, none, np.zeros((0, 3)), none, none, np.zeros((0, 3)))
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    offset = (n * tri[:, 0]).sum(axis=1)
    lo, hi = tri.min(axis=1) - tol, tri.max(axis=1) + tol
    counts = []
    for axis in range(3):  # the axis along which the fewest boxes overlap
        s = np.sort(lo[:, axis])
        counts.append(int((np.searchsorted(s, hi[:, axis], side="right")).sum()))
    axis = int(np.argmin(counts))
    order = np.argsort(lo[:, axis], kind="stable")
    obj = np.ascontiguousarray(objects, dtype=np.int64)
    rows, spans = _sweep(tri, n, offset, lo, hi, obj, order, axis, float(tol), bool(contacts))
    cross, touch = rows[:, 2] == 0, rows[:, 2] == 1
    o = np.lexsort((rows[cross, 1], rows[cross, 0]))
    oc = np.lexsort((rows[touch, 1], rows[touch, 0]))
    return Pairs(
        rows[cross, 0][o],
        rows[cross, 1][o],
        spans[cross][o],
        rows[touch, 0][oc],
        rows[touch, 1][oc],
        spans[touch][oc],
    )


@njit(cache=True, nogil=True)
def _cut_one(t, tri, start, pn, pd, tol, maxv):
    """Convex pieces of triangle ``t`` cut by its planes ``pn[start[t]:start[t + 1]]``, ``pd``.

    Returns (pieces (q, maxv, 3), count (q,), barrier (q, maxv) bool: edge k, corner k to k + 1,
    lies on a cut)."""
    cap = 8
    P = np.zeros((cap, maxv, 3))
    C = np.zeros(cap, np.int64)
    B = np.zeros((cap, maxv), np.bool_)
    P[0, :3] = tri[t]
    C[0] = 3
    q = 1
    s = np.empty(maxv, np.int64)
    d = np.empty(maxv)
    pts = np.empty((2, maxv, 3))
    on = np.empty((2, maxv), np.bool_)
    fl = np.empty((2, maxv), np.bool_)
    m = np.zeros(2, np.int64)
    for k in range(start[t], start[t + 1]):
        for p in range(q):
            n = C[p]
            pos = neg = False
            for i in range(n):
                d[i] = P[p, i, 0] * pn[k, 0] + P[p, i, 1] * pn[k, 1] + P[p, i, 2] * pn[k, 2] - pd[k]
                s[i] = 0 if abs(d[i]) <= tol else (1 if d[i] > 0 else -1)
                pos |= s[i] > 0
                neg |= s[i] < 0
            if not (pos and neg):
                continue
            m[:] = 0
            for i in range(n):  # Sutherland-Hodgman on a convex polygon, both sides at once
                j = (i + 1) % n
                for side in range(2):
                    sg = 1 if side == 0 else -1
                    if s[i] * sg >= 0:
                        pts[side, m[side]] = P[p, i]
                        on[side, m[side]] = s[i] == 0
                        fl[side, m[side]] = B[p, i]
                        m[side] += 1
                    if s[i] * s[j] < 0:
                        f = d[i] / (d[i] - d[j])
                        pts[side, m[side]] = P[p, i] + (P[p, j] - P[p, i]) * f
                        on[side, m[side]] = True
                        fl[side, m[side]] = B[p, i]
                        m[side] += 1
            if q == cap:
                cap *= 2
                P2, C2, B2 = (
                    np.zeros((cap, maxv, 3)),
                    np.zeros(cap, np.int64),
                    np.zeros((cap, maxv), np.bool_),
                )
                P2[:q], C2[:q], B2[:q] = P[:q], C[:q], B[:q]
                P, C, B = P2, C2, B2
            for side in range(2):
                slot = p if side == 0 else q
                mm = m[side]
                C[slot] = mm
                for e in range(mm):
                    P[slot, e] = pts[side, e]
                    B[slot, e] = (on[side, e] and on[side, (e + 1) % mm]) or fl[side, e]
            q += 1
    return P[:q], C[:q], B[:q]


@njit(cache=True, nogil=True)
def _cut_all(faces, tri, start, pn, pd, tol, maxv):
    """:func:`_cut_one` of every triangle ``faces`` (m,), as fans: (parent (r,), corners (r, 3, 3),
    barrier (r, 3) bool per edge k, corner k to k + 1)."""
    cap = 4 * len(faces) + 16
    par = np.empty(cap, np.int64)
    cor = np.empty((cap, 3, 3))
    bar = np.zeros((cap, 3), np.bool_)
    r = 0
    for f in faces:
        P, C, B = _cut_one(f, tri, start, pn, pd, tol, maxv)
        for p in range(len(C)):
            n = C[p]
            for k in range(1, n - 1):  # fan from corner 0: edges (0, k), (k, k + 1), (k + 1, 0)
                if r == cap:
                    cap *= 2
                    par2, cor2, bar2 = (
                        np.empty(cap, np.int64),
                        np.empty((cap, 3, 3)),
                        np.zeros((cap, 3), np.bool_),
                    )
                    par2[:r], cor2[:r], bar2[:r] = par[:r], cor[:r], bar[:r]
                    par, cor, bar = par2, cor2, bar2
                par[r] = f
                cor[r, 0], cor[r, 1], cor[r, 2] = P[p, 0], P[p, k], P[p, k + 1]
                bar[r, 0] = B[p, 0] if k == 1 else False
                bar[r, 1] = B[p, k]
                bar[r, 2] = B[p, n - 1] if k + 1 == n - 1 else False
                r += 1
    return par[:r], cor[:r], bar[:r]


def _plane_keys(face, by, normal, offset, tol, step=1e-7):
    """(k, 5) int64 keys of (face, plane of ``by``): coplanar faces ``by`` (either orientation) share
    one (normals rounded to ``step``, offsets to ``tol``); and (k, 3) normals, (k,) offsets of those
    planes, oriented alike."""
    n, d = normal[by], offset[by]
    flip = np.where(
        np.abs(n[:, 0]) > 1e-9, n[:, 0] < 0, np.where(np.abs(n[:, 1]) > 1e-9, n[:, 1] < 0, n[:, 2] < 0)
    )
    n = np.where(flip[:, None], -n, n)
    d = np.where(flip, -d, d)
    key = np.concatenate([face[:, None], np.round(n / step), np.round(d / tol)[:, None]], axis=1)
    return key.astype(np.int64), n, d


def _normals(V: np.ndarray, F: np.ndarray):
    """(f, 3) unit normals and (f,) plane offsets of triangles F."""
    tri = V[F]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    return normal, (normal * tri[:, 0]).sum(axis=1)


def _face_planes(face: np.ndarray, by: np.ndarray, normal: np.ndarray, offset: np.ndarray, tol: float):
    """Each cut face's distinct cutting planes: (face (k,) sorted, normal (k, 3), offset (k,)), the
    planes of the faces ``by`` that cut it (coplanar ones once)."""
    key, n, d = _plane_keys(face, by, normal, offset, tol)
    _, first = np.unique(key, axis=0, return_index=True)
    o = first[np.argsort(face[first], kind="stable")]
    return face[o], n[o], d[o]


def _long_crossings(F, V, face, by, chord, overlap, tol):
    """The (face, by) pairs whose plane crosses (or touches) the face along at least
    :data:`MIN_CROSSING` of the face's chord on it, the overlaps of all coplanar ``by`` summed: a
    bolt through a plate does not slice the plate, a slab through a wall's face does."""
    if len(face) == 0:
        return face, by
    normal, offset = _normals(V, F)
    key, _, _ = _plane_keys(face, by, normal, offset, 10.0 * tol, step=1e-4)  # near-coplanar: one plane
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.reshape(-1)
    total = np.bincount(group, weights=overlap)
    longest = np.zeros(len(total))
    np.maximum.at(longest, group, chord)
    keep = (total >= MIN_CROSSING * longest)[group]
    return face[keep], by[keep]


def cut_faces(V: np.ndarray, F: np.ndarray, face: np.ndarray, by: np.ndarray, tol: float):
    """Cut faces ``face`` (k,) by the planes of faces ``by`` (k,) (from :func:`pierced_pairs`: a pair
    (a, b) that crosses gives (a, b) and (b, a), a contact (c, d) gives (c, d)).

    V (n, 3) float64, F (f, 3) int64. Returns (vertices (n', 3), faces (f', 3), parent (f',) int64:
    the input face each output face comes from (uncut faces first, in place; pieces in place of
    their parent), barrier (k, 2) int64 sorted vertex pairs of the edges on a cut, n_cut).
    """
    tri = V[F]
    normal, offset = _normals(V, F)
    face, pn, pd = _face_planes(face, by, normal, offset, tol)
    cut, per = np.unique(face, return_counts=True)
    start = np.zeros(len(F) + 1, np.int64)
    start[cut + 1] = per
    start = np.cumsum(start)
    maxv = 3 + int(per.max())
    par, cor, bar = _cut_all(cut, np.ascontiguousarray(tri), start, np.ascontiguousarray(pn), pd, tol, maxv)
    keep = np.ones(len(F), bool)
    keep[cut] = False
    nv = len(V)
    allV = np.concatenate([V, cor.reshape(-1, 3)])
    newF = (nv + np.arange(3 * len(cor))).reshape(-1, 3)
    allF = np.concatenate([F[keep], newF])
    parent = np.concatenate([np.flatnonzero(keep), par])
    o = np.argsort(parent, kind="stable")
    allF, parent = allF[o], parent[o]
    allV, allF = weld_vertices(allV, allF)
    bad = degenerate_faces(allV, allF)
    piece = np.concatenate([np.zeros(int(keep.sum()), bool), np.ones(len(cor), bool)])[o]
    e = np.stack([allF, np.roll(allF, -1, axis=1)], axis=2)[piece]  # (r, 3, 2) edges of the pieces
    flags = np.concatenate([np.zeros((int(keep.sum()), 3), bool), bar])[o][piece]
    barrier = np.sort(e[flags & ~bad[piece][:, None]], axis=1)
    barrier = np.unique(barrier, axis=0) if len(barrier) else np.zeros((0, 2), np.int64)
    return allV, allF[~bad], parent[~bad], barrier, len(cut)


def _coplanar_neighbours(V: np.ndarray, F: np.ndarray, group: np.ndarray):
    """Faces sharing an edge: (fa, fb (e,) int64, edge key (e,) ``lo * n + hi`` of its vertices, ok
    (e,) bool: same ``group`` (f,) and normals within :data:`REGION_ANGLE_TOL`)."""
    normal, _ = _normals(V, F)
    e = np.sort(np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(len(F)), 3)
    key = e[:, 0] * len(V) + e[:, 1]
    o = np.argsort(key, kind="stable")
    ks, fo = key[o], owner[o]
    same = ks[1:] == ks[:-1]  # consecutive half-edges on one edge (pairs of a non-manifold edge chain)
    fa, fb, kk = fo[:-1][same], fo[1:][same], ks[1:][same]
    ok = (group[fa] == group[fb]) & ((normal[fa] * normal[fb]).sum(axis=1) >= np.cos(REGION_ANGLE_TOL))
    return fa, fb, kk, ok


def _spread(V, F, group, face, by, tol):
    """Each cut (face, by) carried to the whole flat surface of the face (faces joined by edges within
    one ``group`` (f,): object and material, coplanar) wherever it crosses the plane of ``by``: the
    cut line runs across the surface, not only across the triangles the other face meets (their
    neighbours would keep the whole edge, a T-junction, and stay apart from the pieces)."""
    if len(face) == 0:
        return face, by
    nf = len(F)
    fa, fb, _, ok = _coplanar_neighbours(V, F, group)
    g = coo_matrix((np.ones(int(ok.sum())), (fa[ok], fb[ok])), shape=(nf, nf))
    k, surface = connected_components(g, directed=False)
    normal, offset = _normals(V, F)
    key, _, _ = _plane_keys(surface[face], by, normal, offset, tol)
    _, first = np.unique(key, axis=0, return_index=True)
    s_of, by_of = surface[face[first]], by[first]  # one representative per (surface, plane)
    members = np.argsort(surface, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(surface, minlength=k))])
    size = start[s_of + 1] - start[s_of]
    rep = np.repeat(np.arange(len(s_of)), size)
    f = members[start[s_of][rep] + np.arange(len(rep)) - np.repeat(np.cumsum(size) - size, size)]
    d = np.einsum("fkc,fc->fk", V[F[f]], normal[by_of[rep]]) - offset[by_of[rep]][:, None]
    cross = (d.max(axis=1) > tol) & (d.min(axis=1) < -tol)
    return np.concatenate([face, f[cross]]), np.concatenate([by, by_of[rep][cross]])


def region_labels(V: np.ndarray, F: np.ndarray, material: np.ndarray, barrier: np.ndarray):
    """(f,) int64 region of each face and the number of regions that joined around a cut.

    Regions: faces joined by edges shared with a face of the same material whose normal is within
    :data:`REGION_ANGLE_TOL`, except ``barrier`` (k, 2) edges. Every face of a region holding both
    sides of a barrier edge gets a region of its own (label ``-1 - face``); the others keep their
    region's number (>= 0). V (n, 3), F (f, 3) int64, material (f,) int64.
    """
    nf, nv = len(F), len(V)
    fa, fb, kk, ok = _coplanar_neighbours(V, F, material)
    on_barrier = np.isin(kk, barrier[:, 0] * nv + barrier[:, 1]) if len(barrier) else np.zeros(len(kk), bool)
    link = ok & ~on_barrier
    g = coo_matrix((np.ones(int(link.sum())), (fa[link], fb[link])), shape=(nf, nf))
    _, region = connected_components(g, directed=False)
    region = region.astype(np.int64)
    across = ok & on_barrier & (region[fa] == region[fb])
    joined = np.unique(region[fa[across]])
    lone = np.isin(region, joined)
    region[lone] = -1 - np.flatnonzero(lone)
    return region, len(joined)


def _affine_uv(tri: np.ndarray, uv: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(f, k, 2) uvs at points ``q`` (f, k, 3) by the affine maps of triangles ``tri`` (f, 3, 3) with
    corner uvs ``uv`` (f, 3, 2), extended over their planes (barycentric coordinates)."""
    p0 = tri[:, 0]
    e1, e2, d = tri[:, 1] - p0, tri[:, 2] - p0, q - p0[:, None]
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    det = np.maximum(d11 * d22 - d12 * d12, 1e-300)[:, None]
    q1, q2 = (d * e1[:, None]).sum(2), (d * e2[:, None]).sum(2)
    beta, gamma = (d22[:, None] * q1 - d12[:, None] * q2) / det, (d11[:, None] * q2 - d12[:, None] * q1) / det
    out = (1 - beta - gamma)[..., None] * uv[:, None, 0] + beta[..., None] * uv[:, None, 1]
    return out + gamma[..., None] * uv[:, None, 2]


@njit(cache=True, nogil=True)
def _turn(V, a, b, c, n):
    """Distance of vertex b from the chord from a to c (rows of V (n, 3)), positive where a, b, c
    turn left about the unit normal ``n`` (3,)."""
    ch = V[c] - V[a]
    return (np.cross(V[b] - V[a], V[c] - V[b]) * n).sum() / max(np.sqrt((ch * ch).sum()), 1e-300)


@njit(cache=True, nogil=True)
def _loop(F, faces, nv):
    """The outline of faces ``faces`` (m,) of F (f, 3) (nv vertices) as one loop: (k,) int64 the
    face corners ``3 f + j`` starting its edges, in order; empty unless it is one loop of edges
    that its faces use once each."""
    none = np.zeros(0, np.int64)
    b, key = boundary_half_edges(F, faces, nv)  # outline edges, by start vertex
    if len(b) == 0:
        return none
    start, out, i = key // nv, np.empty(len(b), np.int64), 0
    for s in range(len(b)):  # (a vertex starting two outline edges leaves one unvisited: none)
        out[s], v = 3 * faces[b[i] // 3] + b[i] % 3, key[i] % nv
        i = np.searchsorted(start, v)
        if i == len(b) or start[i] != v:
            return none
        if i == 0:
            return out if s + 1 == len(b) else none
    return none


@njit(cache=True, nogil=True)
def _convex(V, loop, n, tol):
    """(k',) int64 the positions in ``loop`` (k,) (vertex ids of V) left once the straight vertices
    (within ``tol`` of their neighbours' chord) are dropped, when that polygon is convex (every kept
    vertex turns left about ``n`` by more than ``tol``, every dropped one lies within ``tol`` of the
    edge replacing it); else empty."""
    k, none = len(loop), np.zeros(0, np.int64)
    corner = np.zeros(k, np.bool_)
    for i in range(k):  # (a vertex where the outline turns back is no straight one)
        back = ((V[loop[i]] - V[loop[i - 1]]) * (V[loop[(i + 1) % k]] - V[loop[i]])).sum() <= 0
        corner[i] = back or abs(_turn(V, loop[i - 1], loop[i], loop[(i + 1) % k], n)) > tol
    keep = np.nonzero(corner)[0]
    for s in range(len(keep)):
        i, j = keep[s], keep[(s + 1) % len(keep)]
        if len(keep) < 3 or _turn(V, loop[keep[s - 1]], loop[i], loop[j], n) <= tol:
            return none
        for x in range(i + 1, i + (j - i) % k):
            if abs(_turn(V, loop[i], loop[x % k], loop[j], n)) > tol:
                return none
    return keep


@njit(cache=True, nogil=True)
def _outline(F, V, faces, tol):
    """The fan of faces ``faces`` (m,) of F (f, 3), V (n, 3): the corners (k,) int64 ``3 f + j`` of
    their outline in order, its straight vertices dropped, when the faces lie within ``tol`` of one
    plane, their outline is one loop (:func:`_loop`), convex (:func:`_convex`), and its fan covers
    their area; else empty."""
    n, area = region_plane(F, V, faces, tol)  # area 0: not flat
    loop = _loop(F, faces, len(V)) if area > 0.0 else np.zeros(0, np.int64)
    keep = _convex(V, F.ravel()[loop], n, tol) if len(loop) else loop
    c = F.ravel()[loop[keep]]
    fan, rim = 0.0, 0.0
    for i in range(len(c)):
        rim += np.sqrt(((V[c[(i + 1) % len(c)]] - V[c[i]]) ** 2).sum())
        if 0 < i < len(c) - 1:
            fan += 0.5 * (np.cross(V[c[i]] - V[c[0]], V[c[i + 1]] - V[c[0]]) * n).sum()
    return loop[keep] if abs(fan - area) <= tol * rim else loop[:0]  # (not an outline winding twice)


@njit(cache=True, nogil=True)
def _fans(F, V, order, start, tol):
    """Fans (:func:`_outline`) of the regions ``order[start[r]:start[r + 1]]`` (faces of F (f, 3),
    V (n, 3)) that have one: corners (t, 3) int64 (face corners ``3 f + j``: the fan's vertex
    ``F[f, j]`` with that corner's uv), region (t,) int64 r; a fan has no more triangles than faces."""
    cor, reg, t = np.empty((len(order), 3), np.int64), np.empty(len(order), np.int64), 0
    for r in range(len(start) - 1):
        c = _outline(F, V, order[start[r] : start[r + 1]], tol)
        for i in range(1, len(c) - 1):
            cor[t, 0], cor[t, 1], cor[t, 2] = c[0], c[i], c[i + 1]
            reg[t] = r
            t += 1
    return cor[:t], reg[:t]


def _off_map(V, F, uv, region, faces):
    """(f,) bool the faces of the regions (``region`` >= 0) where a face of ``faces`` (k,) int64
    leaves the affine uv map of its region's first face by more than :data:`UV_TOL`."""
    first = np.full(len(F), len(F))
    np.minimum.at(first, region[faces], faces)
    ref = first[region[faces]]
    err = np.abs(_affine_uv(V[F[ref]], uv[ref], V[F[faces]]) - uv[faces]).max(axis=(1, 2))
    return np.isin(region, region[faces][err > UV_TOL * np.maximum(1.0, np.abs(uv[faces]).max(axis=(1, 2)))])


def refan_regions(V, F, uv, region, parent, piece, tol):
    """Each region (``region`` >= 0) holding a piece (``piece`` (f,) bool) whose faces follow one
    affine uv map is made again as fans: one of its outline when that is one convex loop once its
    straight vertices are dropped (:func:`_fans`; a rectangle cut from a wall: two triangles, one
    quad for :func:`iat.geometry.mesh.merge_quads`), else one of each convex cell
    :func:`iat.geometry.decompose.decompose_regions` cuts it into (a wall with a door: three). A
    dropped vertex or a cut's new end on the outline stays a corner of the faces across it: a
    T-junction between patches, as panels and pre-splits make.

    V (n, 3) float64; F (f, 3) int64; uv (f, 3, 2) float64; region, parent (f,) int64; tol : scene
    units. Returns (vertices (n', 3) (V, then the new corners), faces (f', 3), uv (f', 3, 2) (a
    cell's by its region's affine map), region (f',), parent (f',) (a fan triangle's: its region's
    first face's), made (f',) int8: 1 a triangle of a convex outline's fan, 2 of a cell's, 0 kept),
    each region's fans in place of its first face.
    """
    lab, real = np.maximum(region, 0), region >= 0
    size, held = np.bincount(lab[real], minlength=len(F)), np.bincount(lab[real & piece], minlength=len(F))
    cand = real & (size[lab] >= 2) & (held[lab] > 0)
    cand &= ~_off_map(V, F, uv, region, np.flatnonzero(cand))
    order = np.flatnonzero(cand)
    if len(order) == 0:
        return V, F, uv, region, parent, np.zeros(len(F), np.int8)
    order = order[np.argsort(region[order], kind="stable")]
    start = np.flatnonzero(np.r_[True, region[order][1:] != region[order][:-1], True])
    cor, reg = _fans(F, V, order, start, tol)
    rest = np.ones(len(start) - 1, bool)
    rest[reg] = False  # the regions with no convex outline
    sub = order[np.repeat(rest, np.diff(start))]
    sub_start = np.r_[0, np.cumsum(np.diff(start)[rest])]
    tri, creg, points = decompose_regions(F, V, sub, sub_start, tol)
    if len(points):  # a cut's end that regions either side of a barrier share: one vertex
        points, at = weld_vertices(points, np.arange(len(points)))
        new = tri >= len(V)
        tri[new] = len(V) + at[tri[new] - len(V)]
    head = np.r_[order[start[reg]], sub[sub_start[creg]]]  # each triangle's region's first face
    V2 = np.concatenate([V, points])
    keep = np.flatnonzero(~(cand & np.isin(region, region[head])))
    o = np.argsort(np.concatenate([keep, head]), kind="stable")
    cell_uv = _affine_uv(V[F[head[len(cor) :]]], uv[head[len(cor) :]], V2[tri])
    made = np.repeat(np.array([0, 1, 2], np.int8), [len(keep), len(cor), len(tri)])
    return (
        V2,
        np.concatenate([F[keep], F.reshape(-1)[cor], tri])[o],
        np.concatenate([uv[keep], uv.reshape(-1, 2)[cor], cell_uv])[o],
        np.concatenate([region[keep], region[head]])[o],
        np.concatenate([parent[keep], parent[head]])[o],
        made[o],
    )


def _own_regions(V, F, region, one, fanned):
    """(f,) bool faces that keep a region of their own: a joined region's (``region`` < 0) and a
    region of one parent triangle's pieces (``one`` (labels,) bool) unless it is one triangle or a
    fan of two making a parallelogram (the quad :func:`merge_quads` makes): a cut triangle of a
    curved surface becomes one patch or stays triangles, not a panel. F (f, 3), fanned (f,) bool."""
    lab = np.maximum(region, 0)
    size = np.bincount(lab[region >= 0], minlength=len(one))
    i = np.flatnonzero(fanned[:-1] & (size[lab[:-1]] == 2) & (region[1:] == region[:-1]))  # fan pairs
    twist = quad_twist(V[F[i, 0]], V[F[i, 1]], V[F[i, 2]], V[F[i + 1, 2]])
    flat = np.isin(region, region[i][twist <= QUAD_SKEW_TOL])
    return (region < 0) | (one[lab] & (size[lab] > 1) & ~flat)


@dataclass
class Pierced:
    """:func:`cut_pierced`'s result.

    vertices (n', 3) float64; faces (f', 3) int64; face_uv (f', 3, 2) float64 (interpolated);
    code (f',) int64: the materials the patch makers see, (material, region) pairs numbered;
    codes (codes,) int64: each code's material, or None when nothing was cut (then
    ``code`` is the material); parent (f',) int64 input face (a fan triangle's: one of its
    region's); cut (f,) bool the input faces cut in pieces; report :class:`PierceReport`.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_uv: np.ndarray
    code: np.ndarray
    codes: np.ndarray | None
    parent: np.ndarray
    cut: np.ndarray
    report: PierceReport


def cut_pierced(
    V: np.ndarray,
    F: np.ndarray,
    material: np.ndarray,
    face_uv: np.ndarray,
    objects: np.ndarray,
    cut: bool = True,
    contacts: bool = False,
    tol_rel: float = PIERCE_TOL,
) -> Pierced:
    """Find the faces other objects pierce (:func:`pierced_pairs`) and, when ``cut``, cut them
    (:func:`cut_faces`), label the sides of each cut (:func:`region_labels`) and fan the convex
    regions again (:func:`refan_regions`).

    V (n, 3) float64 welded; F (f, 3) int64; material (f,) int64; face_uv (f, 3, 2) float64;
    objects (f,) int64; contacts : also cut a face along the faces that rest on it (a slab ending
    on a wall's face, a box on a floor); tol_rel : :data:`PIERCE_TOL` (fraction of the used
    vertices' diagonal). With nothing to cut, or ``cut`` False, the arrays come back as they are.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    material = np.asarray(material, dtype=np.int64)
    used = V[np.unique(F)] if len(F) else np.zeros((1, 3))
    diag = max(float(np.linalg.norm(used.max(axis=0) - used.min(axis=0))), 1e-300)
    tol = tol_rel * diag
    pp = pierced_pairs(V[F], objects, tol, contacts)
    face, by = np.concatenate([pp.a, pp.b, pp.c]), np.concatenate([pp.b, pp.a, pp.d])
    chord = np.concatenate([pp.span[:, 0], pp.span[:, 1], pp.contact_span[:, 0]])
    overlap = np.concatenate([pp.span[:, 2], pp.span[:, 2], pp.contact_span[:, 2]])
    mode = ("all" if contacts else "crossings") if cut else "none"
    report = PierceReport(
        cut=cut, mode=mode, pairs=len(pp.a), contacts=len(pp.c), objects=len(np.unique(objects[face]))
    )
    face, by = _long_crossings(F, V, face, by, chord, overlap, tol)
    group = np.unique(np.stack([objects, material], axis=1), axis=0, return_inverse=True)[1].reshape(-1)
    face, by = _spread(V, F, group, face, by, tol)
    report.triangles = len(F)
    same = Pierced(V, F, face_uv, material, None, np.arange(len(F)), np.zeros(len(F), bool), report)
    if not cut or len(face) == 0:
        return same
    V2, F2, parent, barrier, n_cut = cut_faces(V, F, face, by, tol)
    was_cut = np.bincount(parent, minlength=len(F)) > 1
    uv = _affine_uv(V[F[parent]], np.asarray(face_uv, dtype=np.float64)[parent], V2[F2])
    region, joined = region_labels(V2, F2, material[parent], barrier)
    real = region >= 0  # regions of one parent's pieces
    pairs = np.unique(np.stack([region[real], parent[real]], axis=1), axis=0)
    one = np.bincount(pairs[:, 0], minlength=len(F2)) == 1
    piece = np.isin(parent, face)
    V2, F2, uv, region, parent, made = refan_regions(V2, F2, uv, region, parent, piece, STRAIGHT_TOL * diag)
    report.fanned_regions = len(np.unique(region[made > 0]))
    report.decomposed_regions = len(np.unique(region[made == 2]))
    lone = _own_regions(V2, F2, region, one, made > 0)
    region[lone] = -1 - np.flatnonzero(lone)
    used, F2 = np.unique(F2, return_inverse=True)  # the fans' dropped vertices
    V2, F2 = V2[used], F2.reshape(-1, 3)
    pairs, code = np.unique(np.stack([material[parent], region], axis=1), axis=0, return_inverse=True)
    report.faces_cut, report.pieces, report.joined_regions = int(n_cut), int(piece.sum()), int(joined)
    report.triangles = len(F2)
    code = code.reshape(-1).astype(np.int64)
    return Pierced(V2, F2, uv, code, pairs[:, 0].astype(np.int64), parent, was_cut, report)
