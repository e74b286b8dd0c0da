"""Geometry helpers shared by the render tests: where pixel rays meet a plane."""

from __future__ import annotations

import numpy as np


def pixel_centres_on_plane_z0(cam, w, h):
    """(h, w, 3) world points where the rays through the pixel centres meet z = 0 (row 0 at the top)."""
    m = np.linalg.inv(cam.clip_from_world(w / h))
    px, py = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    nx, ny = px / w * 2 - 1, 1 - py / h * 2

    def unproject(z):
        p = np.stack([nx, ny, np.full_like(nx, z), np.ones_like(nx)], -1) @ m.T
        return p[..., :3] / p[..., 3:]

    a, b = unproject(-1.0), unproject(1.0)
    t = -a[..., 2] / (b[..., 2] - a[..., 2])
    return a + t[..., None] * (b - a)
