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


def angles(to_sun: np.ndarray) -> tuple[float, float]:
    """(azimuth, elevation) in degrees of a unit vector towards the sun."""
    el = math.degrees(math.asin(float(np.clip(np.dot(to_sun, UP), -1.0, 1.0))))
    az = math.degrees(math.atan2(float(np.dot(to_sun, EAST)), float(np.dot(to_sun, NORTH)))) % 360.0
    return az, el


def sun_at(app_state: AppState) -> np.ndarray | None:
    """(3,) unit vector towards the sun at the day-cycle slider's time, or None (no day cycle shown,
    or its states have no sun)."""
    lt = app_state.lighting
    sset = lt.solution_set
    if sset is None or not lt.day_cycle:
        return None
    a, b, w = lt.day_blend()
    names = sset.names
    da, db = (towards_sun(lt.states.get(names[k], {})) for k in (a, b))
    if da is None and db is None:
        return None
    if da is None or db is None:  # sunrise or sunset: the side that has a sun
        return da if da is not None else db
    d = (1.0 - w) * da + w * db
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-9 else da


def sun_label(app_state: AppState) -> str:
    """'sun: azimuth 135 deg, elevation 32 deg' at the slider's time, or ''."""
    d = sun_at(app_state)
    if d is None:
        return ""
    az, el = angles(d)
    return f"sun: azimuth {az:.0f} deg, elevation {el:.0f} deg"
