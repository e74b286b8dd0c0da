"""Light picking and dragging in the 3D view: pure geometry, testable without a window.

Window pixels are measured from the view's top left; a view ``rect`` is (x, y, w, h) in
window pixels. :func:`project_points` places world points in the view, :func:`pick_light`
finds the light marker under the mouse, :func:`drag_on_plane` moves a light at its height.
"""

from __future__ import annotations

import numpy as np

from iat.camera import Camera


def project_points(camera: Camera, points, rect) -> tuple[np.ndarray, np.ndarray]:
    """Window pixel positions of world ``points`` (k, 3) seen by ``camera`` in the view ``rect``
    (x, y from the top left, w, h): (k, 2) float64 and (k,) bool in front of the camera and inside."""
    x, y, w, h = (float(v) for v in rect)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if w <= 0 or h <= 0 or not len(p):
        return np.zeros((len(p), 2)), np.zeros(len(p), dtype=bool)
    c = np.concatenate([p, np.ones((len(p), 1))], axis=1) @ np.asarray(camera.clip_from_world(w / h)).T
    front = c[:, 3] > 1e-9
    ndc = c[:, :3] / np.where(front, c[:, 3], 1.0)[:, None]
    px = np.stack([x + (ndc[:, 0] + 1) * 0.5 * w, y + (1 - ndc[:, 1]) * 0.5 * h], axis=1)
    inside = front & (np.abs(ndc[:, :2]) <= 1.0).all(axis=1) & (np.abs(ndc[:, 2]) <= 1.0)
    return px, inside


def pick_light(camera: Camera, lights, rect, mouse, radius: float = 12.0) -> int:
    """Index of the light whose marker is nearest to ``mouse`` (window pixels) within ``radius``, or -1."""
    if not lights:
        return -1
    px, ok = project_points(camera, [lt.position for lt in lights], rect)
    d = np.linalg.norm(px - np.asarray(mouse, dtype=np.float64)[None, :], axis=1)
    d[~ok] = np.inf
    k = int(np.argmin(d))
    return k if d[k] <= radius else -1


def mouse_ray(camera: Camera, rect, mouse) -> tuple[np.ndarray, np.ndarray]:
    """World origin and unit direction of the ray through window pixel ``mouse``."""
    x, y, w, h = (float(v) for v in rect)
    nx = (float(mouse[0]) - x) / w * 2.0 - 1.0
    ny = 1.0 - (float(mouse[1]) - y) / h * 2.0
    inv = np.linalg.inv(np.asarray(camera.clip_from_world(w / h), dtype=np.float64))
    a = inv @ np.array([nx, ny, -1.0, 1.0])
    b = inv @ np.array([nx, ny, 1.0, 1.0])
    a, b = a[:3] / a[3], b[:3] / b[3]
    d = b - a
    return a, d / max(float(np.linalg.norm(d)), 1e-300)


def drag_on_plane(camera: Camera, rect, mouse, height: float, bounds=None, margin: float = 0.02):
    """Where the ray through ``mouse`` meets the horizontal plane ``y = height`` (a light dragged at
    its height), kept inside ``bounds`` (2, 3) shrunk by ``margin`` of its size; None when the ray
    runs away from the plane (or parallel to it)."""
    o, d = mouse_ray(camera, rect, mouse)
    if abs(d[1]) < 1e-9:
        return None
    t = (float(height) - o[1]) / d[1]
    if t <= 0:
        return None
    p = o + t * d
    if bounds is not None:
        lo, hi = np.asarray(bounds, dtype=np.float64)
        m = margin * (hi - lo)
        p = np.clip(p, lo + m, hi - m)
        p[1] = float(height)
    return p
