"""Regions of cut pieces made again as few convex cells (issue 36): a wall with a door cut out, a
facade with a row of windows.

:func:`iat.geometry.pierce.refan_regions` makes a region whose outline is one convex loop one fan of
it. The other regions (an outline that is not convex, or one with holes) come here:
:func:`decompose_regions` takes each one's boundary loops (:func:`boundary_loops`: the outline and its
holes), drops their straight vertices and, in the region's plane with axes along its longest edge,
cuts it along the lines across one axis through its corners (slabs). Each slab holds trapezoids
between a bottom and a top edge; a trapezoid joins its neighbour in the previous slab when they
share the whole side and the union stays convex (:func:`_slabs`). So a cut runs from a corner only
as far as the boundary and a rectilinear region comes back as rectangles (a wall with a door: three).
Both axes are tried, the one with fewer cells kept. Each cell is fanned (a rectangle: two triangles,
one quad for :func:`iat.geometry.mesh.merge_quads`). A region that is not flat, whose boundary is
not simple loops (a pinched outline), whose slabs do not pair into trapezoids, or whose cells are not
strictly convex, do not cover its area or make more triangles than it had, keeps its pieces.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.typed import Dict


@njit(cache=True, nogil=True)
def boundary_half_edges(F, faces, nv):
    """The half-edges of faces ``faces`` (m,) of F (f, 3) (nv vertices), ``3 i + j`` the one of
    ``faces[i]`` from its corner j, that no face uses the other way: (b,) int64, by start vertex, and
    their keys ``start * nv + end`` (b,); both empty when a half-edge repeats (an edge used twice the
    same way) or there is none."""
    m, none = 3 * len(faces), (np.zeros(0, np.int64), np.zeros(0, np.int64))
    key = np.empty(m, np.int64)
    for h in range(m):
        key[h] = F[faces[h // 3], h % 3] * nv + F[faces[h // 3], (h % 3 + 1) % 3]
    o = np.argsort(key)
    ks = key[o]
    rev = ks % nv * nv + ks // nv
    rim = ks[np.minimum(np.searchsorted(ks, rev), m - 1)] != rev
    if (ks[1:] == ks[:-1]).any() or not rim.any():
        return none
    return o[rim], ks[rim]


@njit(cache=True, nogil=True)
def boundary_loops(F, faces, nv):
    """The boundary of faces ``faces`` (m,) of F (f, 3) (nv vertices) as loops (the faces on their
    left): vertex ids (b,) int64 along each loop and the loops' starts in it (l + 1,) int64; both
    empty unless each edge is used once per direction and each boundary vertex starts and ends one
    boundary edge (no pinched outline)."""
    none = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    b = boundary_half_edges(F, faces, nv)[1]
    if len(b) == 0:
        return none
    src, dst = b // nv, b % nv
    if (src[1:] == src[:-1]).any() or (np.sort(dst) != src).any():
        return none
    verts, starts = np.empty(len(b), np.int64), np.zeros(len(b) + 1, np.int64)
    seen, k, n = np.zeros(len(b), np.bool_), 0, 0
    for e0 in range(len(b)):
        e = e0
        while not seen[e]:
            seen[e], verts[k] = True, src[e]
            k, e = k + 1, np.searchsorted(src, dst[e])
        if k > starts[n]:
            n += 1
            starts[n] = k
    return verts, starts[: n + 1]


@njit(cache=True, nogil=True)
def _cross(x, y, a, b, c):
    """Twice the signed area of the triangle of points a, b, c (indices of x, y (k,))."""
    return (x[b] - x[a]) * (y[c] - y[b]) - (y[b] - y[a]) * (x[c] - x[b])


@njit(cache=True, nogil=True)
def _turn(x, y, a, b, c):
    """Distance of point b from the chord from a to c (indices of x, y (k,)), positive where a, b, c
    turn left."""
    return _cross(x, y, a, b, c) / max(np.sqrt((x[c] - x[a]) ** 2 + (y[c] - y[a]) ** 2), 1e-300)


@njit(cache=True, nogil=True)
def _corners(x, y, starts, tol):
    """(b,) bool the loop vertices (coordinates x, y (b,), loops ``starts`` (l + 1,)) that are
    corners: they turn (or turn back) by more than ``tol``; all False unless every loop keeps three
    and each dropped vertex lies within ``tol`` of the edge replacing it."""
    keep = np.zeros(len(x), np.bool_)
    for s in range(len(starts) - 1):
        a, k = starts[s], starts[s + 1] - starts[s]
        for i in range(k):
            p, c, q = a + (i - 1) % k, a + i, a + (i + 1) % k
            back = (x[c] - x[p]) * (x[q] - x[c]) + (y[c] - y[p]) * (y[q] - y[c]) <= 0
            keep[c] = back or abs(_turn(x, y, p, c, q)) > tol
        kept = np.flatnonzero(keep[a : a + k])
        if len(kept) < 3:
            return np.zeros(len(x), np.bool_)
        for j in range(len(kept)):
            i0, i1 = kept[j], kept[(j + 1) % len(kept)]
            for i in range(i0 + 1, i0 + (i1 - i0) % k):
                if abs(_turn(x, y, a + i0, a + i % k, a + i1)) > tol:
                    return np.zeros(len(x), np.bool_)
    return keep


@njit(cache=True, nogil=True)
def _lines(X, tol):
    """The lines across the axis through points at X (k,): each point's line (k,) int64 and the lines'
    positions (m,) ascending (a line takes the points within ``tol`` past its first)."""
    line, at, m = np.empty(len(X), np.int64), np.empty(len(X)), 0
    for i in np.argsort(X):
        if m == 0 or X[i] - at[m - 1] > tol:
            at[m] = X[i]
            m += 1
        line[i] = m - 1
    return line, at[:m]


@njit(cache=True, nogil=True)
def _edge_y(Y, line, at, u, v, s):
    """Y where the edge from point u to point v (coordinates Y (k,), lines ``line`` (k,), line
    positions ``at`` (m,)) crosses line s."""
    return Y[u] + (at[s] - at[line[u]]) / (at[line[v]] - at[line[u]]) * (Y[v] - Y[u])


@njit(cache=True, nogil=True)
def _slabs(X, Y, nxt, tol):
    """Convex cells of the region bounded by the edges from point i to ``nxt[i]`` (coordinates X, Y
    (k,), the region on each edge's left), cut along the lines across X through the points, the
    trapezoids of neighbouring slabs joined where they share a whole side and stay convex.

    Returns each cell's corners, counter-clockwise, as (edge, line) pairs ((p,) int64 each: where the
    edge from point ``edge`` meets that line), the cells' starts in them (c + 1,) int64 (just [0]
    when the slabs do not pair into trapezoids: crossing or tangled edges), the points' lines (k,)
    int64 and the lines' positions (m,)."""
    line, at = _lines(X, tol)
    m, k = len(at), len(X)
    none = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(1, np.int64), line, at)
    lo, hi = np.minimum(line, line[nxt]), np.maximum(line, line[nxt])
    first = np.zeros(m + 1, np.int64)  # the edges across each slab: slot[first[s]:first[s + 1]]
    for e in range(k):
        first[lo[e] + 1 : hi[e] + 1] += 1
    first = np.cumsum(first)
    slot, fill = np.empty(first[m], np.int64), first[:m].copy()
    for e in range(k):
        for s in range(lo[e], hi[e]):
            slot[fill[s]] = e
            fill[s] += 1
    nt = first[m] // 2
    eb, et = np.empty(nt, np.int64), np.empty(nt, np.int64)  # bottom, top edge
    ts, cell = np.empty(nt, np.int64), np.empty(nt, np.int64)  # slab, cell (its first trapezoid)
    yb, yt = np.empty((nt, 2)), np.empty((nt, 2))  # bottom, top edge at the slab's left, right line
    t, prev = 0, 0  # prev: the previous slab's first trapezoid
    for s in range(m - 1):
        es = slot[first[s] : first[s + 1]]
        if len(es) % 2:
            return none
        y0, y1 = np.empty(len(es)), np.empty(len(es))
        for i in range(len(es)):
            y0[i] = _edge_y(Y, line, at, es[i], nxt[es[i]], s)
            y1[i] = _edge_y(Y, line, at, es[i], nxt[es[i]], s + 1)
        o = np.argsort(y0 + y1)
        for i in range(len(es)):  # bottom (rightward) and top edges in turn, not crossing in the slab
            if (line[es[o[i]]] < line[nxt[es[o[i]]]]) != (i % 2 == 0):
                return none
            if i and (y0[o[i]] < y0[o[i - 1]] - tol or y1[o[i]] < y1[o[i - 1]] - tol):
                return none
        j, cur = prev, t
        for i in range(0, len(es), 2):
            b, c = o[i], o[i + 1]
            eb[t], et[t], ts[t], cell[t] = es[b], es[c], s, t
            yb[t, 0], yb[t, 1], yt[t, 0], yt[t, 1] = y0[b], y1[b], y0[c], y1[c]
            while j < cur and yb[j, 1] < yb[t, 0] - tol:
                j += 1
            side = j < cur and abs(yb[j, 1] - yb[t, 0]) <= tol and abs(yt[j, 1] - yt[t, 0]) <= tol
            if side and yt[t, 0] - yb[t, 0] > tol and _joins(at, yb, yt, j, t, s, tol):
                cell[t] = cell[j]
            t += 1
        prev = cur
    return _cell_corners(eb[:t], et[:t], ts[:t], cell[:t]) + (line, at)


@njit(cache=True, nogil=True)
def _joins(at, yb, yt, j, t, s, tol):
    """Whether trapezoid j (slab s - 1) and t (slab s), sharing their side on line s, make a convex
    union: bottom (yb (n, 2)) and top (yt (n, 2)) edges turn left, or go straight, there."""
    x, back = np.array([at[s - 1], at[s], at[s + 1]]), np.array([at[s + 1], at[s], at[s - 1]])
    bottom = np.array([yb[j, 0], yb[t, 0], yb[t, 1]])
    top = np.array([yt[t, 1], yt[t, 0], yt[j, 0]])
    return _turn(x, bottom, 0, 1, 2) >= -tol and _turn(back, top, 0, 1, 2) >= -tol


@njit(cache=True, nogil=True)
def _cell_corners(eb, et, ts, cell):
    """Corners (edge, line) (p,) int64 each and starts (c + 1,) of the cells made of trapezoids with
    bottom ``eb``, top ``et`` edges in slabs ``ts`` (n,), joined in cells ``cell`` (n,) (the first
    trapezoid's index), slab by slab; counter-clockwise: the bottom rightward, the top back."""
    n = len(eb)
    o = np.argsort(cell, kind="mergesort")
    edge, at, starts = np.empty(4 * n, np.int64), np.empty(4 * n, np.int64), np.zeros(n + 1, np.int64)
    p, c, i = 0, 0, 0
    while i < n:
        j = i
        while j + 1 < n and cell[o[j + 1]] == cell[o[i]]:
            j += 1
        edge[p], at[p] = eb[o[i]], ts[o[i]]
        p += 1
        for r in range(i, j + 1):
            edge[p], at[p] = eb[o[r]], ts[o[r]] + 1
            p += 1
        for r in range(j, i - 1, -1):
            edge[p], at[p] = et[o[r]], ts[o[r]] + 1
            edge[p + 1], at[p + 1] = et[o[r]], ts[o[r]]
            p += 2
        c += 1
        starts[c] = p
        i = j + 1
    return edge[:p], at[:p], starts[: c + 1]


@njit(cache=True, nogil=True)
def _corner_points(V, verts, starts, kp, loop, nxt, X, Y, edge, at, line, pos, tol):
    """The cells' corners (edge, line) ((p,) int64 each: :func:`_slabs`, its corner points ``kp`` (k,)
    positions in the loop vertices ``verts`` (b,) (ids of V (n, 3); loops ``starts``, each corner's
    ``loop`` (k,), next corner ``nxt`` (k,)) with coordinates X, Y (b,), lines ``line`` (k,) at ``pos``)
    as points: ids (p,) int64 (a vertex id: the edge's end, or a dropped vertex of it on the line;
    else ``-1 - i``: new point i, one per edge and line), their coordinates (p,), (p,) and the new
    points (q, 3), on the edges in V."""
    ids, px, py = np.empty(len(edge), np.int64), np.empty(len(edge)), np.empty(len(edge))
    P, new = np.empty((len(edge), 3)), Dict.empty(key_type=types.int64, value_type=types.int64)
    for p in range(len(edge)):
        e, s = edge[p], at[p]
        u, v = kp[e], kp[nxt[e]]
        w = u if line[e] == s else (v if line[nxt[e]] == s else -1)
        a, k = starts[loop[e]], starts[loop[e] + 1] - starts[loop[e]]
        for j in range(1, (v - u) % k):  # the edge's dropped vertices
            if w < 0 and abs(X[a + (u - a + j) % k] - pos[s]) <= tol:
                w = a + (u - a + j) % k
        if w >= 0:
            ids[p], px[p], py[p] = verts[w], X[w], Y[w]
            continue
        f = (pos[s] - pos[line[e]]) / (pos[line[nxt[e]]] - pos[line[e]])
        px[p], py[p] = X[u] + f * (X[v] - X[u]), Y[u] + f * (Y[v] - Y[u])
        key = e * len(pos) + s
        if key not in new:
            new[key] = len(new)
            P[new[key]] = V[verts[u]] + f * (V[verts[v]] - V[verts[u]])
        ids[p] = -1 - new[key]
    return ids, px, py, P[: len(new)]


@njit(cache=True, nogil=True)
def _fan_cells(ids, x, y, starts, area, rim, nf, tol):
    """Fans (t, 3) int64 of the cells ``ids[starts[c]:starts[c + 1]]`` (point ids (p,), coordinates
    x, y (p,)), each cell's repeated and straight (within ``tol``) points dropped; empty unless
    every cell is strictly convex (left turns beyond ``tol``), they cover ``area`` within ``tol`` x
    ``rim`` and make no more than ``nf`` triangles."""
    none = np.zeros((0, 3), np.int64)
    tri, t, total = np.empty((len(ids), 3), np.int64), 0, 0.0
    for c in range(len(starts) - 1):
        q = np.arange(starts[c], starts[c + 1])
        q = q[ids[q] != ids[np.roll(q, 1)]]
        if len(q) < 3:
            return none
        turn = np.empty(len(q))
        for i in range(len(q)):
            turn[i] = _turn(x, y, q[i - 1], q[i], q[(i + 1) % len(q)])
        if (turn < -tol).any():
            return none
        q = q[turn > tol]
        for i in range(len(q)):
            if len(q) < 3 or _turn(x, y, q[i - 1], q[i], q[(i + 1) % len(q)]) <= tol:
                return none
        if t + len(q) - 2 > nf:
            return none
        for i in range(1, len(q) - 1):
            tri[t, 0], tri[t, 1], tri[t, 2] = ids[q[0]], ids[q[i]], ids[q[i + 1]]
            total += 0.5 * _cross(x, y, q[0], q[i], q[i + 1])
            t += 1
    return tri[:t] if abs(total - area) <= tol * rim else none


@njit(cache=True, nogil=True)
def region_plane(F, V, faces, tol):
    """The unit normal (3,) and area of faces ``faces`` (m,) of F (f, 3), V (n, 3); area 0 unless
    every corner lies within ``tol`` of their plane."""
    n = np.zeros(3)
    for f in faces:
        n += np.cross(V[F[f, 1]] - V[F[f, 0]], V[F[f, 2]] - V[F[f, 0]])
    area = 0.5 * np.sqrt((n * n).sum())
    n /= max(2.0 * area, 1e-300)
    for f in faces:
        for j in range(3):
            if abs(((V[F[f, j]] - V[F[faces[0], 0]]) * n).sum()) > tol:
                return n, 0.0
    return n, area


@njit(cache=True, nogil=True)
def _frame(V, verts, keep, starts, n):
    """Coordinates x, y (b,) of the loop vertices ``verts`` (b,) (ids of V (n, 3)) in the plane of unit
    normal n, x along the longest edge between corners (``keep`` (b,) bool; loops ``starts``), so a
    rectilinear region's edges run along the axes; (x, y, n) turn as the right hand."""
    big, e1 = -1.0, np.zeros(3)
    for s in range(len(starts) - 1):
        kept = starts[s] + np.flatnonzero(keep[starts[s] : starts[s + 1]])
        for j in range(len(kept)):
            d = V[verts[kept[(j + 1) % len(kept)]]] - V[verts[kept[j]]]
            d -= (d * n).sum() * n
            if (d * d).sum() > big:
                big, e1 = (d * d).sum(), d
    e1 /= max(np.sqrt(big), 1e-300)
    e2 = np.cross(n, e1)
    x, y = np.empty(len(verts)), np.empty(len(verts))
    for i in range(len(verts)):
        d = V[verts[i]] - V[verts[0]]
        x[i], y[i] = (d * e1).sum(), (d * e2).sum()
    return x, y


@njit(cache=True, nogil=True)
def _cells(F, V, faces, tol):
    """The convex cells (:func:`_slabs`, along the axis giving fewer) of faces ``faces`` (m,) of F
    (f, 3), V (n, 3) fanned: triangles (t, 3) int64 (a vertex id, or ``-1 - i`` for new point i) and
    the new points (q, 3) on the boundary edges; no triangles unless the region is flat, its boundary
    simple loops, the cells strictly convex (straight corners dropped) and covering the faces' area
    within ``tol`` times its rim, in no more triangles than faces."""
    none = (np.zeros((0, 3), np.int64), np.zeros((0, 3)))
    n, area = region_plane(F, V, faces, tol)
    verts, starts = boundary_loops(F, faces, len(V))
    if area == 0.0 or len(verts) == 0:
        return none
    x, y = _frame(V, verts, np.ones(len(verts), np.bool_), starts, n)
    keep = _corners(x, y, starts, tol)
    if not keep.any():
        return none
    x, y = _frame(V, verts, keep, starts, n)
    kp = np.flatnonzero(keep)  # corners: positions in verts
    loop = np.searchsorted(starts, kp, side="right") - 1
    nxt = np.empty(len(kp), np.int64)
    for i in range(len(kp)):  # the next corner along its loop
        nxt[i] = i + 1 if i + 1 < len(kp) and loop[i + 1] == loop[i] else np.searchsorted(loop, loop[i])
    rim = 0.0
    for i in range(len(kp)):
        rim += np.sqrt((x[kp[nxt[i]]] - x[kp[i]]) ** 2 + (y[kp[nxt[i]]] - y[kp[i]]) ** 2)
    across_x = _slabs(x[kp], y[kp], nxt, tol)
    across_y = _slabs(y[kp], -x[kp], nxt, tol)  # the coordinates turned a quarter right
    nx, ny = len(across_x[2]), len(across_y[2])  # cells + 1 (1: the slabs failed)
    if nx == 1 and ny == 1:
        return none
    # the axis with fewer cells, then fewer corners
    turned = nx == 1 or (ny > 1 and (ny, len(across_y[0])) < (nx, len(across_x[0])))
    X, Y = (y, -x) if turned else (x, y)
    edge, at, cs, line, pos = across_y if turned else across_x
    ids, px, py, P = _corner_points(V, verts, starts, kp, loop, nxt, X, Y, edge, at, line, pos, tol)
    tri = _fan_cells(ids, px, py, cs, area, rim, len(faces), tol)
    return _used_points(tri, P) if len(tri) else none


@njit(cache=True, nogil=True)
def _used_points(tri, P):
    """Triangles (t, 3) int64 (vertex ids, ``-1 - i`` for new point i of P (q, 3)) and the new points
    they use, renumbered (a cell's corner dropped as straight is no point)."""
    new = np.full(len(P), -1, np.int64)
    out, q = tri.copy(), 0
    for i in range(len(tri)):
        for j in range(3):
            if tri[i, j] < 0:
                if new[-1 - tri[i, j]] < 0:
                    new[-1 - tri[i, j]], q = q, q + 1
                out[i, j] = -1 - new[-1 - tri[i, j]]
    keep = np.empty((q, 3))
    for i in range(len(P)):
        if new[i] >= 0:
            keep[new[i]] = P[i]
    return out, keep


@njit(cache=True, nogil=True)
def decompose_regions(F, V, order, start, tol):
    """Convex cells (:func:`_cells`) of the regions ``order[start[r]:start[r + 1]]`` (faces of
    F (f, 3), V (n, 3); ``tol`` scene units) that have them, fanned: triangles (t, 3) int64 (vertex
    ids; ``n + i`` for new point i), their region r (t,) int64 and the new points (q, 3) on the
    regions' boundary edges; a region's triangles are no more than its faces (its new points, than
    three times them)."""
    tri, reg = np.empty((len(order), 3), np.int64), np.empty(len(order), np.int64)
    P, t, q = np.empty((3 * len(order), 3)), 0, 0
    for r in range(len(start) - 1):
        cells, new = _cells(F, V, order[start[r] : start[r + 1]], tol)
        for i in range(len(cells)):
            for j in range(3):
                c = cells[i, j]
                tri[t, j] = c if c >= 0 else len(V) + q - 1 - c
            reg[t] = r
            t += 1
        P[q : q + len(new)] = new
        q += len(new)
    return tri[:t], reg[:t], P[:q]
