"""Power that mesh elements receive from a point light, integrated over their area.

The irradiance of a point light of intensity ``I`` at distance ``r`` is ``I cos / r^2``: exact at
a vertex, but a light ``d`` from a wall puts a peak of ``I / d^2`` on the vertex at its foot, and
a mesh that interpolates vertex values spreads that peak over whole elements (a 12 cm element
under a light 0.1 mm away would re-emit 10^4 times the light the wall received: defect D3).

What an element really receives is the integral of the irradiance over its area, which is the
intensity times the solid angle the element subtends from the light,

    Phi = I * Omega,   Omega = integral of cos / r^2 dA,

finite even when the light touches the element (at most 2 pi per side). :func:`lumped_light`
computes ``Omega`` per element analytically (Van Oosterom & Strackee's formula for triangles; a
quad element is two triangles), weighs it by the element's visible fraction (its corners'
visibility, weighted by their unoccluded irradiance), and turns the elements' powers into vertex
values by lumped projection: a vertex gets the power of its elements (a ``1/k`` share of each
element with ``k`` corners) over their area (the same shares). The shooting matrix averages a
patch's vertex values the same way (area-weighted leaf-corner means), so the power a patch
shoots is exactly the sum of its elements' ``I * Omega * visible``.
"""

from __future__ import annotations

import numpy as np


def solid_angle_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(n,) unsigned solid angle of triangles (a, b, c) (each (n, 3)) seen from the point p (3,)
    (Van Oosterom & Strackee 1983); 0 for a degenerate triangle or p on its plane."""
    ra, rb, rc = a - p, b - p, c - p
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (ra, rb, rc))
    num = np.abs(np.einsum("nc,nc->n", ra, np.cross(rb, rc)))
    den = (
        la * lb * lc
        + np.einsum("nc,nc->n", ra, rb) * lc
        + np.einsum("nc,nc->n", ra, rc) * lb
        + np.einsum("nc,nc->n", rb, rc) * la
    )
    return 2.0 * np.arctan2(num, den)


def element_solid_angle(
    p: np.ndarray, corners: np.ndarray, normal: np.ndarray, is_quad: np.ndarray
) -> np.ndarray:
    """(L,) solid angle of planar elements (corners (L, 4, 3); triangles repeat corner 2 in slot 3)
    from p, counting only elements whose front (``normal`` (L, 3)) faces p."""
    om = solid_angle_triangles(p, corners[:, 0], corners[:, 1], corners[:, 2])
    q = np.asarray(is_quad, dtype=bool)
    if q.any():
        om[q] += solid_angle_triangles(p, corners[q, 0], corners[q, 2], corners[q, 3])
    front = np.einsum("lc,lc->l", p - corners.mean(axis=1), normal) > 0
    return np.where(front, om, 0.0)


def lumped_light(
    position: np.ndarray,
    leaf_world: np.ndarray,
    leaf_normal: np.ndarray,
    leaf_is_quad: np.ndarray,
    corner_idx: np.ndarray,
    leaf_area: np.ndarray,
    k: np.ndarray,
    free: np.ndarray,
    n_vertices: int,
) -> np.ndarray:
    """(V,) element-integrated irradiance per unit intensity, as vertex values.

    leaf_world (L, 4, 3), leaf_normal (L, 3), leaf_is_quad (L,): the elements; corner_idx (L, 4)
    their corners' indices into the vertex arrays; leaf_area (L,); k (V,) the exact irradiance per
    unit intensity at the vertices (with visibility and cone); free (V,) the same without
    visibility or cone. An element receives ``Omega * sum(k) / sum(free)`` over its corners (its
    solid angle times its visible fraction). A vertex that is no element's corner (a hanging
    midpoint, which the shooting matrix does not read) keeps ``k``.
    """
    q = np.asarray(leaf_is_quad, dtype=bool)
    valid = np.ones(corner_idx.shape, dtype=bool)
    valid[~q, 3] = False
    omega = element_solid_angle(np.asarray(position, dtype=np.float64), leaf_world, leaf_normal, q)
    kc = np.where(valid, k[corner_idx], 0.0).sum(axis=1)
    fc = np.where(valid, free[corner_idx], 0.0).sum(axis=1)
    power = omega * np.where(fc > 0, kc / np.where(fc > 0, fc, 1.0), 0.0)  # per unit intensity
    share = np.where(q, 0.25, 1.0 / 3.0)
    rows = corner_idx[valid]
    num = np.bincount(
        rows, weights=np.broadcast_to((power * share)[:, None], valid.shape)[valid], minlength=n_vertices
    )
    den = np.bincount(
        rows, weights=np.broadcast_to((leaf_area * share)[:, None], valid.shape)[valid], minlength=n_vertices
    )
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), k)
