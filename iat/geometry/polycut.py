"""Convex polygons in a patch's plane cut along lines, and the pieces made roots again.

Used by :mod:`iat.geometry.discontinuity`. Polygons are (k, 2) float64 counter-clockwise in the
patch's 2-D frame (:func:`plane_frame`, right-handed about its normal), lengths in scene units.
"""

from __future__ import annotations

import numpy as np

from iat.geometry.mesh import quad_twist


def plane_frame(corners: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(origin (3,), axes (2, 3)) of a patch's plane: corner 0, its first edge and ``normal x`` it."""
    t1 = corners[1] - corners[0]
    t1 = t1 / max(float(np.linalg.norm(t1)), 1e-300)
    return corners[0], np.stack([t1, np.cross(normal, t1)])


def area(poly: np.ndarray) -> float:
    """Signed area of a (k, 2) polygon (positive counter-clockwise)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def width(poly: np.ndarray) -> float:
    """Twice the area over the longest side: a sliver's is small."""
    side = np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1).max()
    return 2.0 * area(poly) / max(float(side), 1e-300)


def clip_segment(poly: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> float:
    """Length of segment p0-p1 (2,) inside convex ``poly`` (Cyrus-Beck)."""
    d = p1 - p0
    e = np.roll(poly, -1, axis=0) - poly
    inward = np.stack([-e[:, 1], e[:, 0]], axis=1)
    num = ((poly - p0) * inward).sum(axis=1)  # inside where t * den >= num
    den = (d * inward).sum(axis=1)
    lo, hi = 0.0, 1.0
    for n_, d_ in zip(num, den, strict=True):
        if abs(d_) < 1e-300:
            if n_ > 0:
                return 0.0
        elif d_ > 0:
            lo = max(lo, n_ / d_)
        else:
            hi = min(hi, n_ / d_)
    return max(hi - lo, 0.0) * float(np.linalg.norm(d))


def split(
    poly: np.ndarray, p0: np.ndarray, p1: np.ndarray, tol: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """The two convex pieces of ``poly`` on either side of the line through p0, p1 (left first), or
    None when the line misses its interior (corners within ``tol`` of the line count as on it)."""
    d = (p1 - p0) / max(float(np.linalg.norm(p1 - p0)), 1e-300)
    f = d[0] * (poly[:, 1] - p0[1]) - d[1] * (poly[:, 0] - p0[0])
    f = np.where(np.abs(f) <= tol, 0.0, f)
    if not ((f > 0).any() and (f < 0).any()):
        return None
    left, right = [], []
    k = len(poly)
    for i in range(k):
        j = (i + 1) % k
        if f[i] >= 0:
            left.append(poly[i])
        if f[i] <= 0:
            right.append(poly[i])
        if f[i] * f[j] < 0:
            x = poly[i] + (poly[j] - poly[i]) * (f[i] / (f[i] - f[j]))
            left.append(x)
            right.append(x)
    return np.array(left), np.array(right)


def simplify(poly: np.ndarray, tol: float) -> np.ndarray:
    """``poly`` without repeated corners and corners within ``tol`` of the line of their neighbours."""
    keep = list(poly)
    changed = True
    while changed and len(keep) > 3:
        changed = False
        for i in range(len(keep)):
            a, b, c = keep[i - 1], keep[i], keep[(i + 1) % len(keep)]
            ac = c - a
            dist = abs(ac[0] * (b[1] - a[1]) - ac[1] * (b[0] - a[0])) / max(float(np.linalg.norm(ac)), 1e-300)
            if dist <= tol or np.linalg.norm(b - a) <= tol:
                del keep[i]
                changed = True
                break
    return np.array(keep)


def _quality(tri: np.ndarray) -> float:
    """Area over the longest side squared (an equilateral triangle's is 0.43)."""
    return area(tri) / max(float((np.linalg.norm(np.roll(tri, -1, axis=0) - tri, axis=1) ** 2).max()), 1e-300)


def to_roots(poly: np.ndarray, skew_tol: float) -> list[list[int]]:
    """Corner indices into ``poly`` of the roots of a convex piece: itself as a triangle or a quad
    within ``skew_tol`` of a parallelogram (:func:`iat.geometry.mesh.quad_twist`), else the fan of
    triangles from the corner whose worst triangle is best."""
    k = len(poly)
    if k == 3:
        return [[0, 1, 2]]
    if k == 4:
        p3 = np.concatenate([poly, np.zeros((4, 1))], axis=1)
        if quad_twist(p3[:1], p3[1:2], p3[2:3], p3[3:]) <= skew_tol:
            return [[0, 1, 2, 3]]
    best, fan = -1.0, None
    for apex in range(k):
        tris = [[apex, (apex + i) % k, (apex + i + 1) % k] for i in range(1, k - 1)]
        q = min(_quality(poly[t]) for t in tris)
        if q > best:
            best, fan = q, tris
    return fan


def shorten(poly: np.ndarray, aspect: float, length: float) -> list[np.ndarray]:
    """``poly`` cut across its longest side, in halves and again, until each piece's longest side is
    at most ``aspect`` x its width or ``length`` (a long thin root costs a quad-tree of long thin
    elements, each split for its length)."""
    out, todo = [], [poly]
    while todo:
        p = todo.pop()
        e = np.roll(p, -1, axis=0) - p
        side = np.linalg.norm(e, axis=1)
        k = int(np.argmax(side))
        halves = None
        if side[k] > max(aspect * width(p), length):
            mid = p[k] + 0.5 * e[k]
            halves = split(p, mid, mid + np.array([-e[k, 1], e[k, 0]]), 1e-9 * side[k])
        if halves is None:
            out.append(p)
        else:
            todo.extend(halves)
    return out


def legs_on_lines(poly: np.ndarray, tri: list[int], lines: np.ndarray, tol: float) -> list[int]:
    """``tri`` (3 corner indices into ``poly`` (k, 2)) rotated so that its hypotenuse, edge 1-2 of a
    triangle root's lattice (``u + v = 1``), lies on none of ``lines`` (c, 2, 2) (within ``tol``)
    when one of its edges does not: a shadow along a leg is a function of one lattice axis, which
    a texture's bilinear lookup reproduces, while across the hypotenuse it mixes values from either
    side of the line (docs/baking.md, "Cut roots"). The winding is kept."""
    if not len(lines):
        return tri
    d = lines[:, 1] - lines[:, 0]
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)

    def on_a_line(p: np.ndarray, q: np.ndarray) -> bool:
        off = [np.abs(d[:, 0] * (x[1] - lines[:, 0, 1]) - d[:, 1] * (x[0] - lines[:, 0, 0])) for x in (p, q)]
        return bool(((off[0] <= tol) & (off[1] <= tol)).any())

    for shift in range(3):
        r = tri[shift:] + tri[:shift]
        if not on_a_line(poly[r[1]], poly[r[2]]):
            return r
    return tri
