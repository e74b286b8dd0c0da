"""Random rays over a scene's patches, as the solver casts them (the ray tests and benchmarks)."""

from __future__ import annotations

import numpy as np


def surface_rays(scene, n: int, rng: np.random.Generator):
    """n rays from random points on the patches (area-weighted), off the surface by 1e-4 of the
    scene's diagonal, in cosine directions about the patch normal: ``(o, d, diag)``, o and d (n, 3)
    float64 (d unit), diag the scene's diagonal (m). Draws from ``rng`` in a fixed order: the
    patches, the points' u then v, the directions' radius then angle."""
    area = scene.patch_area
    p = rng.choice(len(area), size=n, p=area / area.sum())
    c = scene.corner_positions[p]
    u, v = rng.random(n), rng.random(n)
    tri_u = np.where(u + v > 1, 1 - u, u)
    tri_v = np.where(u + v > 1, 1 - v, v)
    pos_q = (
        c[:, 0] * ((1 - u) * (1 - v))[:, None]
        + c[:, 1] * (u * (1 - v))[:, None]
        + c[:, 2] * (u * v)[:, None]
        + c[:, 3] * ((1 - u) * v)[:, None]
    )
    pos_t = c[:, 0] + (c[:, 1] - c[:, 0]) * tri_u[:, None] + (c[:, 2] - c[:, 0]) * tri_v[:, None]
    pos = np.where(scene.patch_is_quad[p][:, None], pos_q, pos_t)
    nrm = scene.patch_normal[p]
    lo, hi = scene.bounds
    diag = float(np.linalg.norm(hi - lo))
    origin = pos + 1e-4 * diag * nrm
    r, phi = np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    helper = np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(nrm, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nrm, t1)
    d = (r * np.cos(phi))[:, None] * t1 + (r * np.sin(phi))[:, None] * t2 + np.sqrt(1 - r * r)[:, None] * nrm
    return origin, d, diag
