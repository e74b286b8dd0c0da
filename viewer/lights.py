"""New lights of the Lighting panel: where one goes (:func:`new_light_position`) and how bright it
is (:func:`new_light_intensity`), of the order of the scene's own lighting."""

from __future__ import annotations

import math

import numpy as np

#: the point and spot lights whose intensities a new light takes after (a sun is not a lamp)
LAMP_KINDS = ("point", "spot")


def new_light_intensity(scene) -> float:
    """Radiant intensity (W/sr) for a light added to ``scene``: the median of its point and spot
    lights' intensities; with none, the emitters' power spread over a sphere (``sum(pi L A) / 4 pi``,
    L the emitted radiance's largest channel, A the emitting area: a lamp as bright as all the
    emissive surfaces together); with neither, ``diagonal**2 / 100`` (a lamp that lights a room the
    size of the bounds dimly, a tenth of the light editor's default in distance)."""
    lit = [float(lt.intensity) for lt in scene.lights if lt.kind in LAMP_KINDS and lt.intensity > 0]
    if lit:
        return float(np.median(lit))
    if len(scene.materials) and scene.n_patches:
        emission = np.array([float(np.max(m.emission)) for m in scene.materials])[scene.patch_material]
        power = float(np.sum(math.pi * emission * np.asarray(scene.patch_area, dtype=np.float64)))
        if math.isfinite(power) and power > 0:
            return power / (4.0 * math.pi)
    lo, hi = scene.bounds
    d = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
    return d * d / 100.0 if math.isfinite(d) and d > 0 else 1.0


def new_light_position(scene, camera):
    """Where a new light goes: in front of ``camera`` (one fifth of the model's size), inside the
    model's bounds (5 % in from each side); None without a camera."""
    if camera is None:
        return None
    lo, hi = scene.bounds
    p = np.asarray(camera.eye) + np.asarray(camera.forward) * 0.2 * float(np.linalg.norm(hi - lo))
    m = 0.05 * (hi - lo)
    return np.clip(p, lo + m, hi - m)
