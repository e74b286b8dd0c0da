"""Analytic form factors: differential area (point + normal) to polygon.

The point-to-polygon form factor is Lambert's contour integral (Hottel's form):

    F = 1/(2 pi) | sum_i  gamma_i  n . (r_i x r_{i+1}) / |r_i x r_{i+1}| |

with ``r_i = v_i - x`` and ``gamma_i`` the angle between ``r_i`` and ``r_{i+1}``.
Only the part of the polygon in front of the receiver's tangent plane counts,
so the polygon is first clipped against that plane (Sutherland-Hodgman, one
plane per receiver, vectorised over receivers with padded arrays).

The value is purely geometric: it does not know which side of the polygon
emits, and it ignores occlusion (the solver multiplies by a visible fraction).

Receivers on the polygon's plane or on one of its edges give a finite value
>= 0, but the value of a receiver lying exactly on an edge line of the clipped
polygon depends on the direction it is approached from (the edge term jumps);
callers that evaluate on shared edges (the solver does) nudge the point a tiny
distance into its own surface first.
"""

from __future__ import annotations

import numpy as np

#: receivers per vectorised block (bounds the (n, 2k, 3) temporaries)
_BLOCK = 32768


def polygon_normal(polygon: np.ndarray) -> np.ndarray:
    """(3,) float64 unit normal of a planar polygon (k, 3) by Newell's method (right-handed winding)."""
    p = np.asarray(polygon, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    n = np.cross(p, q).sum(axis=0)
    return n / max(np.linalg.norm(n), 1e-300)


def polygon_area(polygon: np.ndarray) -> float:
    """Area of a planar polygon (k, 3)."""
    p = np.asarray(polygon, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.linalg.norm(np.cross(p, q).sum(axis=0)))


def point_polygon(points: np.ndarray, normals: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Form factors from differential receivers to one convex planar polygon.

    points : (n, 3) float64 receiver positions
    normals : (n, 3) float64 unit receiver normals
    polygon : (k, 3) float64 polygon corners in order (either winding)
    returns : (n,) float64 form factors in [0, 1]; the part of the polygon
      behind a receiver's tangent plane contributes nothing.
    """
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    poly = np.asarray(polygon, dtype=np.float64).reshape(-1, 3)
    out = np.empty(len(x))
    for a in range(0, len(x), _BLOCK):
        out[a : a + _BLOCK] = _point_polygon_block(x[a : a + _BLOCK], nrm[a : a + _BLOCK], poly)
    return out


def _point_polygon_block(x: np.ndarray, nrm: np.ndarray, poly: np.ndarray) -> np.ndarray:
    n = len(x)
    if n == 0:
        return np.zeros(0)
    r = poly[None, :, :] - x[:, None, :]  # (n, k, 3)
    d = np.einsum("nkc,nc->nk", r, nrm)  # signed heights above the tangent plane
    size = np.abs(r).max(axis=(1, 2))
    d = np.where(np.abs(d) <= 1e-12 * size[:, None], 0.0, d)
    inside = d >= 0.0
    front = (d > 0.0).any(axis=1)  # a polygon lying in the tangent plane subtends nothing
    full = inside.all(axis=1) & front
    f = np.zeros(n)
    if full.any():  # nothing to clip: the plain contour sum over the k edges
        f[full] = _contour(r[full], np.roll(r[full], -1, axis=1), nrm[full])
    part = ~full & front
    if part.any():
        f[part] = _clipped(r[part], d[part], inside[part], nrm[part])
    return np.clip(f, 0.0, 1.0)


def _contour(a: np.ndarray, b: np.ndarray, nrm: np.ndarray, ok: np.ndarray | None = None) -> np.ndarray:
    """(n,) |sum over edges a->b of gamma n.(a x b)/|a x b|| / (2 pi); a, b (n, e, 3)."""
    c = np.cross(a, b)
    cn = np.sqrt(np.einsum("nkc,nkc->nk", c, c))
    gamma = np.arctan2(cn, np.einsum("nkc,nkc->nk", a, b))
    proj = np.einsum("nkc,nc->nk", c, nrm)
    good = cn > 1e-300 if ok is None else ok & (cn > 1e-300)
    term = np.where(good, gamma * proj / np.where(good, cn, 1.0), 0.0)
    return np.abs(term.sum(axis=1)) / (2.0 * np.pi)


def _clipped(r: np.ndarray, d: np.ndarray, inside: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """Form factor of the polygon (rows r (n, k, 3)) clipped to d >= 0."""
    n, k = r.shape[:2]
    # Sutherland-Hodgman against one plane: edge i emits v_i if inside, and the
    # crossing point if the edge changes side. At most 2 points per edge.
    r_next = np.roll(r, -1, axis=1)
    d_next = np.roll(d, -1, axis=1)
    in_next = np.roll(inside, -1, axis=1)
    crossing = inside != in_next
    denom = np.where(crossing, d - d_next, 1.0)
    t = np.where(crossing, d / denom, 0.0)
    cut = r + t[..., None] * (r_next - r)
    pts = np.stack([r, cut], axis=2).reshape(n, 2 * k, 3)
    valid = np.stack([inside, crossing], axis=2).reshape(n, 2 * k)
    order = np.argsort(~valid, axis=1, kind="stable")
    pts = np.take_along_axis(pts, order[..., None], axis=1)
    m = valid.sum(axis=1)  # vertices of the clipped polygon
    j = np.arange(2 * k)[None, :]
    nxt = np.where(j + 1 < m[:, None], j + 1, 0)
    b = np.take_along_axis(pts, nxt[..., None], axis=1)
    f = _contour(pts, b, nrm, j < m[:, None])
    f[m < 3] = 0.0
    return f


def _gauss_points(polygon: np.ndarray, n_quad: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes (m, 3) and weights (m,) (summing to the area) over a triangle or quad."""
    g, w = np.polynomial.legendre.leggauss(int(n_quad))
    g = 0.5 * (g + 1.0)
    w = 0.5 * w
    u, v = np.meshgrid(g, g, indexing="ij")
    wu, wv = np.meshgrid(w, w, indexing="ij")
    u, v, ww = u.ravel(), v.ravel(), (wu * wv).ravel()
    p = np.asarray(polygon, dtype=np.float64)
    if len(p) == 4:
        c0, c1, c2, c3 = p
        pos = (
            ((1 - u) * (1 - v))[:, None] * c0
            + (u * (1 - v))[:, None] * c1
            + (u * v)[:, None] * c2
            + ((1 - u) * v)[:, None] * c3
        )
        du = (1 - v)[:, None] * (c1 - c0) + v[:, None] * (c2 - c3)
        dv = (1 - u)[:, None] * (c3 - c0) + u[:, None] * (c2 - c1)
        jac = np.linalg.norm(np.cross(du, dv), axis=1)
        return pos, ww * jac
    if len(p) == 3:
        c0, c1, c2 = p
        # Duffy collapse of the unit square onto the triangle
        s, t = u, v * (1 - u)
        pos = c0 + s[:, None] * (c1 - c0) + t[:, None] * (c2 - c0)
        jac = 2.0 * polygon_area(p) * (1 - u)
        return pos, ww * jac
    raise ValueError("area_to_area integrates over triangles and quads only")


def area_to_area(poly_a: np.ndarray, poly_b: np.ndarray, n_quad: int = 16) -> float:
    """Form factor F_ab from polygon a (triangle or quad, receiver) to polygon b (any convex).

    Gauss-Legendre quadrature (``n_quad`` x ``n_quad`` nodes) over a of the analytic
    point-to-polygon form factor towards b; the normal of a is taken from its
    winding, and only the part of b in front of a counts.
    """
    pos, w = _gauss_points(poly_a, n_quad)
    nrm = np.broadcast_to(polygon_normal(poly_a), pos.shape)
    f = point_polygon(pos, nrm, poly_b)
    return float((f * w).sum() / w.sum())
