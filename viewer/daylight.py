"""The sun of the day cycle (issue 16's viewer part): where it stands at the time-of-day slider.

A model's lighting states may be sun states (:func:`iat.lighting.sun.sun_states`): each holds the
directional light ``sun`` (``"sun": {"direction": [x, y, z]}``, where the light travels) and may
give its ``azimuth`` and ``elevation`` (degrees). :func:`sun_at` returns the sun's direction at
the slider's time: the two neighbouring key states' directions blended as the day-cycle set blends
their light (:meth:`iat.lighting.solution_set.SolutionSet.weights`), renormalised. Azimuth and
elevation follow :mod:`iat.lighting.sun`: degrees clockwise from north (-Z), above the horizon
(+Y up).
"""

from __future__ import annotations

import math

import numpy as np

from viewer.state import AppState

NORTH = np.array([0.0, 0.0, -1.0])
EAST = np.array([1.0, 0.0, 0.0])  # north x up
UP = np.array([0.0, 1.0, 0.0])


def towards_sun(state: dict) -> np.ndarray | None:
    """(3,) unit vector towards the sun of one lighting state, or None (no sun, or it is off)."""
    sun = state.get("sun") if isinstance(state, dict) else None
    if not isinstance(sun, dict) or "direction" not in sun or float(sun.get("intensity", 1.0)) <= 0:
        return None
    d = -np.asarray(sun["direction"], dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(d))
    return d / n if n > 0 else None


def angles(to_sun: np.ndarray, north=None) -> tuple[float, float]:
    """(azimuth, elevation) in degrees of a unit vector towards the sun; the azimuth clockwise from
    ``north`` (a horizontal unit vector; default the scene's -Z, :func:`model_north` for true north)."""
    n = NORTH if north is None else np.asarray(north, dtype=np.float64)
    east = np.cross(n, UP)
    el = math.degrees(math.asin(float(np.clip(np.dot(to_sun, UP), -1.0, 1.0))))
    az = math.degrees(math.atan2(float(np.dot(to_sun, east)), float(np.dot(to_sun, n)))) % 360.0
    return az, el


def model_north(app_state: AppState) -> np.ndarray:
    """The open model's true north in the scene: the Sun & sky panel's (its IfcSite's TrueNorth, or
    as set there; :mod:`viewer.sun_sky`), else the scene's -Z."""
    d = getattr(getattr(app_state.lighting, "sun_sky", None), "daylight", None)
    return d.north() if d is not None else NORTH


def key_states(app_state: AppState) -> tuple[dict, dict, float] | None:
    """``(state a, state b, w)``: the two key lighting states the day-cycle set blends at the
    slider's time and the weight of b, or None when no day cycle is shown."""
    lt = app_state.lighting
    sset = lt.solution_set
    if sset is None or not lt.day_cycle:
        return None
    a, b, w = lt.day_blend()
    return lt.states.get(sset.names[a], {}), lt.states.get(sset.names[b], {}), w


def sun_at(app_state: AppState) -> np.ndarray | None:
    """(3,) unit vector towards the sun at the day-cycle slider's time, or None (no day cycle shown,
    or its states have no sun)."""
    keys = key_states(app_state)
    if keys is None:
        return None
    sa, sb, w = keys
    da, db = towards_sun(sa), towards_sun(sb)
    if da is None and db is None:
        return None
    if da is None or db is None:  # sunrise or sunset: the side that has a sun
        return da if da is not None else db
    d = (1.0 - w) * da + w * db
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-9 else da


def stated_angles(app_state: AppState) -> tuple[float, float] | None:
    """(azimuth, elevation) in degrees at the slider's time from the key states' own ``azimuth`` and
    ``elevation`` (:func:`iat.lighting.sun.sun_states` writes them, against the model's own north),
    blended as the light is (the azimuth along the shorter arc); None when the states give none."""
    keys = key_states(app_state)
    if keys is None:
        return None
    *sides, w = keys
    lit = [
        st if towards_sun(st) is not None and {"azimuth", "elevation"} <= set(st) else None for st in sides
    ]
    if lit[0] is None and lit[1] is None:
        return None
    if lit[0] is None or lit[1] is None:
        st = lit[0] if lit[0] is not None else lit[1]
        return float(st["azimuth"]) % 360.0, float(st["elevation"])
    za, zb = (math.radians(float(st["azimuth"])) for st in lit)
    s = (1.0 - w) * math.sin(za) + w * math.sin(zb)
    c = (1.0 - w) * math.cos(za) + w * math.cos(zb)
    el = (1.0 - w) * float(lit[0]["elevation"]) + w * float(lit[1]["elevation"])
    return math.degrees(math.atan2(s, c)) % 360.0, el


def sun_label(app_state: AppState) -> str:
    """'sun: azimuth 135 deg, elevation 32 deg' at the slider's time, or ''. The states' own angles
    when they give them (a model whose north is not -Z), else those of :func:`sun_at`."""
    stated = stated_angles(app_state)
    if stated is None:
        d = sun_at(app_state)
        if d is None:
            return ""
        stated = angles(d, model_north(app_state))
    az, el = stated
    return f"sun: azimuth {az:.0f} deg, elevation {el:.0f} deg"


# -- a sun of the scene itself (issue 38: the default daylight, --sun, a file's directional light) --
def scene_sun(app_state: AppState) -> np.ndarray | None:
    """(3,) unit vector towards the shown scene's first sun (a directional light with light), or
    None. The day cycle's sun (:func:`sun_at`) wins when one is shown."""
    ed = app_state.lighting.editor
    scene = ed.scene if ed is not None else app_state.model.scene
    if scene is None:
        return None
    for lt in scene.lights:
        if lt.kind == "directional" and float(np.max(lt.radiant_intensity)) > 0:
            d = -np.asarray(lt.direction, dtype=np.float64)
            n = float(np.linalg.norm(d))
            return d / n if n > 0 else None
    return None


def shown_sun(app_state: AppState) -> np.ndarray | None:
    """Towards the sun shown: the day cycle's at the slider's time, else the scene's own."""
    d = sun_at(app_state)
    return d if d is not None else scene_sun(app_state)


def sun_facts(lt, north=None) -> str:
    """What a directional light is, in words: 'azimuth 132.3 deg, elevation 38.1 deg, 826 W/m²'
    (azimuth from ``north``, default the scene's -Z, :func:`model_north` for true north; the light's
    intensity times its colour's largest channel, the irradiance on a surface facing it)."""
    d = -np.asarray(lt.direction, dtype=np.float64)
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    az, el = angles(d, north)
    lux = float(lt.intensity) * float(np.max(lt.color))
    return f"azimuth {az:.1f} deg, elevation {el:.1f} deg, {lux:.0f} W/m²"
