"""Analytic form factors: differential area (point + normal) to polygon.

The point-to-polygon form factor is Lambert's contour integral (Hottel's form):

    F = 1/(2 pi) | sum_i  gamma_i  n . (r_i x r_{i+1}) / |r_i x r_{i+1}| |

with ``r_i = v_i - x`` and ``gamma_i`` the angle between ``r_i`` and ``r_{i+1}``.
Only the part of the polygon in front of the receiver's tangent plane counts,
so the polygon is first clipped against that plane (Sutherland-Hodgman, one
plane per receiver; compiled: :func:`iat.radiosity.kernels.point_polygon`).

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

from iat.radiosity import kernels


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
    x = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    nrm = np.ascontiguousarray(np.asarray(normals, dtype=np.float64).reshape(-1, 3))
    poly = np.ascontiguousarray(np.asarray(polygon, dtype=np.float64).reshape(-1, 3))
    return kernels.point_polygon(x, nrm, poly)


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
