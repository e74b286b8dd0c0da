"""Noise in smooth regions: what is left of an image after a quadratic trend, against what a
path-traced reference says is real.

A window of ``w x w`` pixels lying wholly on one patch, away from edges, is fitted by a quadratic in
its pixel coordinates; the standard deviation of the rest over the window's mean is its *residual*.
A reference's residual holds the light's real non-quadratic structure plus the path tracer's
noise, estimated from a second, noisier reference of another seed (``var(a - b) = s_a^2 + s_b^2``).
The *excess* of a render is the residual of (render - reference) beyond the reference's noise: the
grain, blotches and mesh creases that are in the render and not in the light.

Images are ``(h, w, 3)`` float linear radiance (row 0 at the top), as
:func:`iat.measure.reference.render_reference` and
:func:`iat.measure.reference.box_filtered_render` return them.
"""

from __future__ import annotations

import numpy as np

from iat.camera import Camera
from iat.color import LUMINANCE_WEIGHTS

__all__ = ["NOISE_SPP", "patch_image", "wall_noise"]

#: samples a pixel of the reference the excess is measured against, the other reference having
#: ``NOISE_SPP // 8``. The excess is the square root of a difference of squares, the reference's noise
#: taken out: at 4 096 spp the Cornell box's ceiling has ~2 % noise a pixel, its estimate is known to
#: +-6 %, and a 0.5 % excess could read anywhere from 0 to 0.9 %; at 65 536 spp (~0.5 %) it reads to
#: about +-0.05 %.
NOISE_SPP = 65536


def patch_image(scene, camera: Camera, size: tuple[int, int]) -> np.ndarray:
    """(h, w) int64 the patch seen through each pixel's centre (-1: none), by one ray a pixel.

    size : (w, h) pixels (:meth:`iat.camera.Camera.pixel_rays`)."""
    from iat.radiosity.visibility import Visibility

    w, h = int(size[0]), int(size[1])
    d = camera.pixel_rays((w, h)).reshape(-1, 3)
    with Visibility.of_scene(scene) as vis:
        tri = vis.first_hit(np.broadcast_to(camera.eye, d.shape), d, np.full(len(d), 1e30))
        tri_patch = scene.world_triangle_patch()[vis.opaque]
    return np.where(tri >= 0, tri_patch[np.maximum(tri, 0)], -1).reshape(h, w)


def wall_noise(
    img,
    reference,
    other_reference,
    patches: np.ndarray,
    which: dict,
    mask=None,
    spp_ratio: float = 8.0,
    window: int = 12,
    step: int = 4,
) -> dict:
    """Per named patch, the medians over its windows of the render's residual, its excess and the
    reference's real structure (its residual with its noise taken out), as fractions of the mean.

    img, reference, other_reference : (h, w, 3) the render and two references of other seeds
    (``other_reference`` has ``spp_ratio`` times fewer samples a pixel: 512 against 4096 is 8);
    patches : (h, w) :func:`patch_image`; which : {name: patch index}; mask : (h, w) bool pixels a
    window may use (default all); window, step : the windows' side and spacing in pixels.
    Returns ``{name: {"windows", "residual", "excess", "real"}}`` (a name with no window: omitted).
    """
    a, r, o = (np.asarray(x, dtype=np.float64) @ LUMINANCE_WEIGHTS for x in (img, reference, other_reference))
    ok = np.ones(a.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    y, x = np.mgrid[0:window, 0:window]
    x, y = x.ravel() / window, y.ravel() / window
    basis = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
    rest = np.eye(window * window) - basis @ np.linalg.pinv(basis)  # what no quadratic explains
    h, w = a.shape

    def spread(v: np.ndarray, mean: float) -> float:
        return float(np.std(rest @ v.ravel())) / mean

    out = {}
    for name, p in which.items():
        rows = []
        for y0 in range(0, h - window + 1, step):
            for x0 in range(0, w - window + 1, step):
                sl = (slice(y0, y0 + window), slice(x0, x0 + window))
                if not ((patches[sl] == p).all() and ok[sl].all()):
                    continue
                m = float(r[sl].mean())
                # var(o - r) = s_o^2 + s_r^2 with s_o^2 = spp_ratio s_r^2: the reference's own noise
                noise = spread(o[sl] - r[sl], m) / np.sqrt(1.0 + spp_ratio)
                real = np.sqrt(max(spread(r[sl], m) ** 2 - noise**2, 0.0))
                excess = np.sqrt(max(spread(a[sl] - r[sl], m) ** 2 - noise**2, 0.0))
                rows.append((spread(a[sl], m), excess, real))
        if rows:
            v = np.asarray(rows)
            out[name] = {
                "windows": len(rows),
                "residual": float(np.median(v[:, 0])),
                "excess": float(np.median(v[:, 1])),
                "real": float(np.median(v[:, 2])),
            }
    return out
