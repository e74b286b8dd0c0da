"""Walls stop the walk (issue 20): the navigator's step clipped against the model's surfaces.

:class:`Collider` tries a step one axis at a time (x, then z, then y) and keeps each part that
does not bring the eye within ``radius`` of a surface along it, so walking into a wall at an angle
slides along it, and a door lets you through. The surfaces are the scene's triangles, glass
included, in an Embree scene built on the first step (:class:`iat.radiosity.visibility.Visibility`).
"""

from __future__ import annotations

import numpy as np

#: how near the eye may come to a surface: this fraction of the model's diagonal, at most
#: :data:`MAX_RADIUS` (scene units: 0.2 m in a model in metres)
RADIUS_FRACTION = 0.02
MAX_RADIUS = 0.2


def collision_radius(bounds: np.ndarray) -> float:
    """The eye's radius for a model with ``bounds`` ((2, 3) min/max)."""
    b = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    d = float(np.linalg.norm(b[1] - b[0]))
    return min(MAX_RADIUS, RADIUS_FRACTION * d) if np.isfinite(d) and d > 0 else MAX_RADIUS


class Collider:
    """``clip(eye, step) -> step``: the part of ``step`` ((3,) scene units) the walls allow from
    ``eye`` ((3,)). scene : an :class:`iat.io.scene.Scene`; radius : scene units."""

    def __init__(self, scene, radius: float):
        self._scene = scene
        self.radius = float(radius)
        self._vis = None

    def _visibility(self):
        if self._vis is None:
            from iat.radiosity.visibility import Visibility

            self._vis = Visibility(self._scene.world_triangles(), threads=1)  # glass blocks too
        return self._vis

    def clip(self, eye: np.ndarray, step: np.ndarray) -> np.ndarray:
        step = np.asarray(step, dtype=np.float64).reshape(3)
        p = np.asarray(eye, dtype=np.float64).reshape(3).copy()
        start = p.copy()
        vis = self._visibility()
        for axis in (0, 2, 1):
            s = float(step[axis])
            if s == 0.0:
                continue
            d = np.zeros((1, 3))
            d[0, axis] = np.sign(s)
            if not vis.occluded(p[None], d, np.array([abs(s) + self.radius]))[0]:
                p[axis] += s
        return p - start
