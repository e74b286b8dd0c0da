"""A sun study: a day's hours at the model's place solved as lighting states on one mesh (issue 38).

The report's §6.2.1 moves the sun across the sky; here a :class:`~iat.lighting.daylight_default.Daylight`
(place, true north, sky model, sky brightness, sun on/off) is taken through the hours of one date:

- :func:`daylight_state`: one setting as a lighting state (:mod:`iat.lighting.states`): its ``sun``
  (the directional light ``sun``: direction, W/m², colour, disc; intensity 0 with the sun off or
  below the horizon), its ``sky`` (the spec of :meth:`Daylight.sky`, ``None`` for no sky) and the
  sun's ``azimuth`` and ``elevation`` (NOAA's, degrees, against true north);
- :func:`sun_study_states`: one such state per hour, named ``HHhMM`` ("08h00": a file name as well),
  with key times in proportion to the clock from the first hour (0) to the last (1): what
  :func:`iat.lighting.solution_set.solve_set` solves on one mesh and the viewer's time-of-day
  slider blends (``iat solve MODEL --sun-study 2026-06-21 --hours 8-18``, the viewer's Sun & sky
  panel);
- :func:`parse_hours`: ``--hours`` (``8-18``, ``8-18/2``, ``9,12,15``, ``8:30-17:30``);
- :func:`daylight_of`: the setting a model got (or would get) from ``--sun`` / ``--sky`` / the
  default, which a study and the Sun & sky panel start from.
"""

from __future__ import annotations

import datetime
import math
import re

import numpy as np

from iat.errors import OptionError
from iat.io.scene import Scene
from iat.lighting.daylight_default import Daylight, DaylightRequest, request_daylight, site_daylight
from iat.lighting.edits import copy_lighting

HOURS_FORMS = "--hours must be H-H[/STEP] or H,H,... (hours as H, H.5 or H:MM, in [0, 24])"
_RANGE = re.compile(r"^\s*([\d.:]+)\s*-\s*([\d.:]+)\s*(?:/\s*([\d.:]+))?\s*$")


def _hour(text: str) -> float:
    t = text.strip()
    try:
        if ":" in t:
            h, m = t.split(":")
            v = int(h) + int(m) / 60.0
        else:
            v = float(t)
    except ValueError:
        raise OptionError(f"{HOURS_FORMS}, got {text!r}") from None
    if not (math.isfinite(v) and 0.0 <= v <= 24.0):
        raise OptionError(f"{HOURS_FORMS}, got {text!r}")
    return v


def parse_hours(text: str) -> list[float]:
    """``8-18`` (every hour from 8 to 18), ``8-18/2`` (every 2 hours), ``9,12,15``, ``8:30-17:30`` ->
    clock hours, increasing. OptionError (one line) otherwise."""
    m = _RANGE.match(str(text))
    if m:
        a, b = _hour(m.group(1)), _hour(m.group(2))
        step = _hour(m.group(3)) if m.group(3) else 1.0
        if step <= 0 or b <= a:
            raise OptionError(f"{HOURS_FORMS}: the range must increase, got {text!r}")
        n = int(math.floor((b - a) / step + 1e-9))
        hours = [a + k * step for k in range(n + 1)]
    else:
        hours = [_hour(t) for t in str(text).split(",") if t.strip()]
    if len(hours) < 2:
        raise OptionError(f"{HOURS_FORMS}: a study needs two hours or more, got {text!r}")
    if any(b <= a for a, b in zip(hours, hours[1:], strict=False)):
        raise OptionError(f"{HOURS_FORMS}: hours must increase, got {text!r}")
    return hours


def hour_name(hour: float) -> str:
    """'08h00' for 8.0, '17h30' for 17.5 (a state's name, and the part of a file name)."""
    minutes = int(round(float(hour) * 60))
    return f"{minutes // 60:02d}h{minutes % 60:02d}"


def daylight_state(d: Daylight) -> dict:
    """The sun and sky of ``d`` as a lighting state (see the module docstring); JSON-ready."""
    az, el = d.position()
    to_sun = d.to_sun()
    sun = d.sun()
    if sun is None:  # off or below the horizon: the state takes the sun out
        spec = {"direction": [float(-x) for x in to_sun], "intensity": 0.0}
    else:
        spec = {
            "direction": [float(x) for x in sun.direction],
            "intensity": float(sun.intensity),
            "color": [float(x) for x in sun.color],
            "angular_diameter": float(np.degrees(sun.angular_diameter)),
        }
    state: dict = {"sun": spec, "azimuth": float(az), "elevation": float(el)}
    sky = d.sky()
    if sky is None:
        state["sky"] = None
    elif sky.kind != "hdr":  # an HDR image is no spec: the scene keeps the sky it has
        state["sky"] = sky.spec()
    return state


def sun_study_states(d: Daylight, date, hours) -> dict[str, dict]:
    """{``HHhMM``: lighting state} of ``d`` at each clock hour of ``date`` (a date or ISO text), in
    the order given; each state's ``time`` is its place on the clock between the first hour (0) and
    the last (1), ``label`` its ``HH:MM``, ``hour`` its clock hour."""
    day = date if isinstance(date, datetime.date) else _date(date)
    hours = [float(h) for h in hours]
    if len(hours) < 2 or any(b <= a for a, b in zip(hours, hours[1:], strict=False)):
        raise OptionError(f"a sun study needs two or more increasing hours, got {hours}")
    span = hours[-1] - hours[0]
    states: dict[str, dict] = {}
    for h in hours:
        st = daylight_state(d.with_changes(date=day, hour=h))
        name = hour_name(h)
        st.update(time=(h - hours[0]) / span, label=name.replace("h", ":"))
        states[name] = st
    return states


def _date(text) -> datetime.date:
    try:
        return datetime.date.fromisoformat(str(text).strip())
    except ValueError:
        raise OptionError(f"--sun-study must be a date YYYY-MM-DD, got {text!r}") from None


def without_daylight(scene: Scene) -> Scene:
    """A copy of ``scene`` lit as if no daylight had been given: no directional light, no sky."""
    out = copy_lighting(scene, lights=[lt for lt in scene.lights if lt.kind != "directional"])
    out.sky = None
    return out


def daylight_of(scene: Scene, request: DaylightRequest | None = None, today=None) -> tuple[Daylight, bool]:
    """``(setting, given)``: the :class:`Daylight` ``request`` gives ``scene`` (read on the scene
    without its suns and sky, so a scene that got the default daylight already gives the same
    setting again); ``given`` False when it gets none (``--no-daylight``, or a model with lamps of
    its own and no ``--sun`` / ``--sky``): then its site's default with the sun off and no sky."""
    d = request_daylight(without_daylight(scene), request or DaylightRequest(), today=today)
    if d is not None:
        return d, True
    return site_daylight(scene, today=today).with_changes(sun_on=False, sky_model="none"), False


def study_daylight(scene: Scene, request: DaylightRequest | None, date) -> Daylight:
    """The setting a sun study of ``scene`` on ``date`` runs through: :func:`daylight_of` with
    ``--sky``, ``--sky-scale``, ``--north`` as given (``--sun`` sets a moment, which a study does
    not take: OptionError), the sun on."""
    request = request or DaylightRequest()
    if request.sun is not None:
        raise OptionError("--sun-study takes the sun through the hours: give --hours, not --sun")
    if not request.enabled:
        raise OptionError("--sun-study goes without --no-daylight")
    d, given = daylight_of(scene, request)
    if not given:  # a model with lamps: the study adds the sun (and the sky asked for)
        d = d.with_changes(sun_on=True, sky_model="none" if request.sky is None else d.sky_model)
    return d.with_changes(date=_date(date) if not isinstance(date, datetime.date) else date)
