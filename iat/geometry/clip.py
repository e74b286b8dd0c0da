"""2-D polygon clipping and point queries on clip triangles (vectorised over many polygons).

Used by panels (:mod:`iat.geometry.panels`): a panel's root is a rectangle in lattice
coordinates ``(u, v)`` in ``[0, 1]^2`` and its *clip triangles* (C, 3, 2) say which part
of the rectangle is surface. Polygons are arrays ``(n, K, 2)`` with counts ``(n,)`` and
optional attributes ``(n, K, m)`` interpolated along clipped edges.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: corners a clipped triangle can have (a triangle cut by four half-planes has at most 7)
MAX_CORNERS = 8


def clip_half_plane(P: np.ndarray, A: np.ndarray, count: np.ndarray, normal: np.ndarray, offset: np.ndarray):
    """Keep the part of each polygon where ``p . normal <= offset`` (Sutherland-Hodgman).

    P : (n, K, 2) corners; A : (n, K, m) attributes; count : (n,) corners used
    normal : (n, 2); offset : (n,)
    Returns (P (n, MAX_CORNERS, 2), A (n, MAX_CORNERS, m), count (n,)).
    """
    n, K, _ = P.shape
    k = np.arange(K)
    valid = k[None, :] < count[:, None]
    nxt = np.where(k[None, :] + 1 < count[:, None], k[None, :] + 1, 0)
    Pn = np.take_along_axis(P, nxt[..., None], axis=1)
    An = np.take_along_axis(A, nxt[..., None], axis=1)
    d = np.einsum("nkc,nc->nk", P, normal) - offset[:, None]
    dn = np.take_along_axis(d, nxt, axis=1)
    ins, ins_n = d <= 0, dn <= 0
    den = d - dn
    t = np.where(den != 0, d / np.where(den != 0, den, 1.0), 0.0)[..., None]
    X = P + t * (Pn - P)
    AX = A + t * (An - A)
    keep = np.stack([valid & ins, valid & (ins != ins_n)], axis=2).reshape(n, 2 * K)
    Q = np.stack([P, X], axis=2).reshape(n, 2 * K, 2)
    B = np.stack([A, AX], axis=2).reshape(n, 2 * K, A.shape[2])
    order = np.argsort(~keep, axis=1, kind="stable")[:, :MAX_CORNERS]
    Q = np.take_along_axis(Q, order[..., None], axis=1)
    B = np.take_along_axis(B, order[..., None], axis=1)
    return Q, B, np.minimum(keep.sum(axis=1), MAX_CORNERS)


def _pad(P: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n, K = P.shape[:2]
    Pp = np.zeros((n, MAX_CORNERS, 2))
    Ap = np.zeros((n, MAX_CORNERS, A.shape[2]))
    Pp[:, :K], Ap[:, :K] = P, A
    return Pp, Ap


def clip_to_boxes(tri: np.ndarray, lo: np.ndarray, hi: np.ndarray, attrs: np.ndarray | None = None):
    """Triangles (n, 3, 2) clipped to axis-aligned boxes ``[lo, hi]`` (n, 2) each.

    Returns (P (n, MAX_CORNERS, 2), A (n, MAX_CORNERS, m), count (n,)); ``attrs`` (n, 3, m)
    defaults to the barycentric weights of the triangle's corners (m = 3).
    """
    n = len(tri)
    A = np.broadcast_to(np.eye(3), (n, 3, 3)) if attrs is None else attrs
    P, A = _pad(np.asarray(tri, dtype=np.float64), np.asarray(A, dtype=np.float64))
    count = np.full(n, 3)
    for axis in range(2):
        e = np.zeros((n, 2))
        e[:, axis] = 1.0
        P, A, count = clip_half_plane(P, A, count, e, hi[:, axis])
        P, A, count = clip_half_plane(P, A, count, -e, -lo[:, axis])
    return P, A, count


def clip_to_triangles(tri: np.ndarray, clip: np.ndarray, attrs: np.ndarray | None = None):
    """Triangles (n, 3, 2) clipped to triangles ``clip`` (n, 3, 2) (either winding).

    Returns (P, A, count) as :func:`clip_to_boxes`.
    """
    n = len(tri)
    A = np.broadcast_to(np.eye(3), (n, 3, 3)) if attrs is None else attrs
    P, A = _pad(np.asarray(tri, dtype=np.float64), np.asarray(A, dtype=np.float64))
    count = np.full(n, 3)
    c = np.asarray(clip, dtype=np.float64)
    sign = np.sign(_cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]))
    for k in range(3):
        a, b = c[:, k], c[:, (k + 1) % 3]
        e = b - a
        nrm = -sign[:, None] * np.stack([-e[:, 1], e[:, 0]], axis=1)  # outward
        P, A, count = clip_half_plane(P, A, count, nrm, (nrm * a).sum(axis=1))
    return P, A, count


def _cross(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]


def fan(P: np.ndarray, A: np.ndarray, count: np.ndarray, min_area: float = 0.0):
    """Convex polygons (from the clippers) as triangles: corners (t, 3, 2), attributes (t, 3, m),
    and the polygon each came from (t,); triangles of area <= ``min_area`` are dropped."""
    i = np.arange(1, MAX_CORNERS - 1)
    poly, k = np.nonzero(i[None, :] < count[:, None] - 1)
    k = k + 1
    idx = np.stack([np.zeros_like(k), k, k + 1], axis=1)
    T = P[poly[:, None], idx]
    TA = A[poly[:, None], idx]
    area = 0.5 * np.abs(_cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]))
    ok = area > min_area
    return T[ok], TA[ok], poly[ok]


def triangle_area(tri: np.ndarray) -> np.ndarray:
    """(n,) unsigned areas of 2-D triangles (n, 3, 2)."""
    return 0.5 * np.abs(_cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))


def ranges(start: np.ndarray, owners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (item k, index i) for every item with owner ``owners[k]`` and every index
    ``start[owner] <= i < start[owner + 1]`` (an owner's rows in an array sorted by owner)."""
    a, b = start[owners], start[owners + 1]
    n = b - a
    k = np.repeat(np.arange(len(owners)), n)
    off = np.repeat(a - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    return k, np.arange(int(n.sum())) + off


def _closest_on_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = b - a
    t = np.clip(((p - a) * e).sum(-1) / np.maximum((e * e).sum(-1), 1e-300), 0.0, 1.0)
    q = a + t[..., None] * e
    return q, ((p - q) ** 2).sum(-1)


def clamp_into(
    pts: np.ndarray,
    owner: np.ndarray,
    clip: np.ndarray,
    start: np.ndarray,
    margin: np.ndarray,
    block: int = 1 << 20,
) -> np.ndarray:
    """Points (n, 2) moved into the clip triangles of their owner: unchanged when inside one,
    else to the nearest point of the owner's triangles, then ``margin`` (n,) towards that
    triangle's centroid (at most half the way).

    owner : (n,) int64; clip : (C, 3, 2) sorted by owner, owner ``o``'s rows
    ``start[o]:start[o + 1]`` (an owner with none keeps its points).
    """
    pts = np.asarray(pts, dtype=np.float64)
    out = pts.copy()
    has = start[owner + 1] > start[owner]
    idx = np.flatnonzero(has)
    per = (start[owner[idx] + 1] - start[owner[idx]]).astype(np.int64)
    cum = np.cumsum(per)
    lo = 0
    while lo < len(idx):  # blocks of about `block` (point, triangle) pairs
        hi = int(np.searchsorted(cum, (cum[lo - 1] if lo else 0) + block, side="right"))
        hi = max(hi, lo + 1)
        sel = idx[lo:hi]
        k, t = ranges(start, owner[sel])
        p = pts[sel][k]
        c = clip[t]
        d0 = _cross(c[:, 1] - c[:, 0], p - c[:, 0])
        d1 = _cross(c[:, 2] - c[:, 1], p - c[:, 1])
        d2 = _cross(c[:, 0] - c[:, 2], p - c[:, 2])
        tol = 1e-12
        inside = ((d0 >= -tol) & (d1 >= -tol) & (d2 >= -tol)) | ((d0 <= tol) & (d1 <= tol) & (d2 <= tol))
        q = np.empty((len(k), 3, 2))
        dist = np.empty((len(k), 3))
        for e in range(3):
            q[:, e], dist[:, e] = _closest_on_segments(p, c[:, e], c[:, (e + 1) % 3])
        best_e = dist.argmin(axis=1)
        d_best = dist[np.arange(len(k)), best_e]
        d_best[inside] = -1.0
        q_best = q[np.arange(len(k)), best_e]
        order = np.lexsort((d_best, k))
        first = np.flatnonzero(np.r_[True, k[order][1:] != k[order][:-1]])
        win = order[first]  # per point: inside, or its nearest triangle
        rows = sel[k[win]]
        outside = d_best[win] >= 0
        r, w = rows[outside], win[outside]
        cen = clip[t[w]].mean(axis=1)
        to = cen - q_best[w]
        dl = np.linalg.norm(to, axis=1)
        step = np.minimum(margin[r], 0.5 * dl) / np.maximum(dl, 1e-300)
        out[r] = q_best[w] + step[:, None] * to
        lo = hi
    return out


@njit(cache=True, nogil=True)
def coverage_grid(clip: np.ndarray, res: int) -> np.ndarray:
    """(res, res) bool ``grid[b, a]``: cell centre ``((a + 0.5) / res, (b + 0.5) / res)`` lies in
    one of the clip triangles (C, 3, 2) float64 (lattice coordinates in [0, 1]^2), on its edge
    included."""
    grid = np.zeros((res, res), dtype=np.bool_)
    for t in range(clip.shape[0]):
        x0, y0, x1, y1, x2, y2 = (
            clip[t, 0, 0],
            clip[t, 0, 1],
            clip[t, 1, 0],
            clip[t, 1, 1],
            clip[t, 2, 0],
            clip[t, 2, 1],
        )
        lo_a = min(max(math.floor(min(x0, x1, x2) * res - 0.5), 0), res - 1)
        hi_a = min(max(math.ceil(max(x0, x1, x2) * res - 0.5), 0), res - 1)
        lo_b = min(max(math.floor(min(y0, y1, y2) * res - 0.5), 0), res - 1)
        hi_b = min(max(math.ceil(max(y0, y1, y2) * res - 0.5), 0), res - 1)
        for b in range(lo_b, hi_b + 1):
            v = (b + 0.5) / res
            for a in range(lo_a, hi_a + 1):
                u = (a + 0.5) / res
                d0 = (x1 - x0) * (v - y0) - (y1 - y0) * (u - x0)
                d1 = (x2 - x1) * (v - y1) - (y2 - y1) * (u - x1)
                d2 = (x0 - x2) * (v - y2) - (y0 - y2) * (u - x2)
                if (d0 >= 0 and d1 >= 0 and d2 >= 0) or (d0 <= 0 and d1 <= 0 and d2 <= 0):
                    grid[b, a] = True
    return grid


def clip_mesh(tri_uv: np.ndarray, tri_patch: np.ndarray, clip: np.ndarray, start: np.ndarray):
    """Mesh triangles of panel cells cut to the cells' clip triangles.

    tri_uv : (T, 3, 2) lattice (u, v) of the triangles' corners; tri_patch : (T,) int64
    clip : (C, 3, 2) clip triangles sorted by patch, patch p's rows ``start[p]:start[p + 1]``
    Returns (uv (k, 3, 2), weights (k, 3, 3), source (k,)): the pieces as triangles, each
    corner's barycentric weights of the corners of its source triangle (so anything
    interpolated over the source, radiance, interpolates the same over the piece).
    """
    k, t = ranges(start, np.asarray(tri_patch, dtype=np.int64))
    a, c = tri_uv[k], clip[t]
    overlap = (a.min(axis=1) <= c.max(axis=1)).all(axis=1) & (c.min(axis=1) <= a.max(axis=1)).all(axis=1)
    k, a, c = k[overlap], a[overlap], c[overlap]
    P, A, count = clip_to_triangles(a, c)
    T, TA, poly = fan(P, A, count, min_area=1e-14)
    return T, TA, k[poly]
