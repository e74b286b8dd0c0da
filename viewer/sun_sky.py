"""The Sun & sky panel's state and what it does each frame (issue 38); the widgets are in
:mod:`viewer.sun_panel`.

The panel edits a :class:`~iat.lighting.daylight_default.Daylight` (place, true north, date, hour,
sun on/off, sky model, turbidity, sky brightness), starting from the one the open model got
(:func:`iat.lighting.sun_study.daylight_of`: its IfcSite, ``--sun`` / ``--sky``, the default). A
change is taken up at the next frame (:func:`apply_pending`):

- the sun and sky of the new setting become a lighting state (:func:`iat.lighting.sun_study.daylight_state`)
  applied to the light editor (:meth:`iat.lighting.editor.LightEditor.apply_state`), and the
  viewer's background re-solve (:class:`viewer.relight.ProgressRelighter`) is handed the scene:
  progress, ETA and Cancel as for a light edit. First a preview of the new light on the mesh on
  screen replaces the solution shown (:func:`iat.lighting.relight.preview`: the direct sun and sky
  with fewer rays, the bounces mostly from the ambient term; the open house in about 2 s). Then a
  sun that moved (or came on), which needs a new mesh for its shadows, is solved afresh
  (``remesh``: one adaptive solve, whose first stage is the meshing on the new direct light); a sky
  or a sun's brightness alone re-solves on the mesh;
- while a sun study is shown (the day cycle), the time slider moves the time of day instead:
  the study's states are blended at once, with no solve.

Each frame :func:`sync_sky` puts the sky of what is shown behind the model (the solution's scene,
or the study's key state nearest the slider), and :func:`sun_marker` says where the sun stands:
the setting's sun (or the study's at the slider), its azimuth and elevation (NOAA's, from true
north), its W/m², its direction in the scene.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iat.errors import IATError
from iat.io.scene import Sky
from iat.lighting.daylight_default import Daylight
from iat.lighting.sun_study import daylight_of, daylight_state, parse_hours, sun_study_states
from viewer.daylight import key_states, stated_angles, sun_at, towards_sun
from viewer.state import AppState

log = logging.getLogger(__name__)

#: the panel's key in ``state.lighting.__dict__`` (the panel's state travels with the lighting's)
KEY = "sun_sky"
#: the mesh the sun study's states share (:func:`iat.lighting.solution_set.solve_set`): the mesh of
#: every hour's sun at once (N + 1 solves; "merge" would take 2 N)
STUDY_MESH = "union"


@dataclass
class SunSky:
    """What the Sun & sky panel shows and asks for.

    editor : the light editor this belongs to (a new model starts afresh)
    daylight : the setting in the panel (what is solved, or being solved)
    given : the model got daylight when opened (else it has lamps of its own: sun off, no sky)
    pending : a change not yet handed to the re-solve (:func:`apply_pending` takes it up)
    solved : {id(scene): (scene, setting)} of the scenes handed to the re-solve (what is on screen)
    hours : the sun study's hours (``--hours`` text); study : the study's hours and names once
      started ({"hours": [...], "names": [...], "date": date})
    sky_shown : the sky last put behind the model (:func:`sync_sky`)
    events : (time, what) of this panel's work, for a look at what happened when (tests, bench)
    """

    editor: Any = None
    daylight: Daylight | None = None
    given: bool = False
    pending: Daylight | None = None
    solved: dict = field(default_factory=dict)
    hours: str = "8-18"
    study: dict | None = None
    sky_shown: Any = None
    opened: Daylight | None = None
    error: str = ""
    events: list = field(default_factory=list)

    def daylight_given(self) -> Daylight | None:
        """The light the model opened with, as a setting (None: its own lamps, nothing added)."""
        return self.opened if self.given else None

    def note(self, what: str) -> None:
        self.events.append((time.perf_counter(), what))
        del self.events[:-200]


def sun_sky(state: AppState) -> SunSky:
    """The panel's state for the model open now (made from the model's own setting on first use)."""
    lt = state.lighting
    ss = lt.__dict__.get(KEY)
    ed = lt.editor
    if ss is None or ss.editor is not ed:
        ss = SunSky(editor=ed)
        lt.__dict__[KEY] = ss
        scene = ed.base if ed is not None else state.model.scene
        if scene is not None:
            try:
                ss.daylight, ss.given = daylight_of(scene, state.model.daylight_request)
                ss.opened = ss.daylight
            except IATError as e:  # (an IFC site that cannot be read: the default place)
                ss.error = str(e)
            ss.sky_shown = state.model.scene.sky if state.model.scene is not None else None
            if ed is not None and ss.daylight is not None:
                ss.solved[id(ed.scene)] = (ed.scene, ss.daylight if ss.given else None)
    return ss


def study_shown(state: AppState) -> bool:
    """The day cycle on screen is this panel's sun study."""
    ss = sun_sky(state)
    lt = state.lighting
    return bool(
        ss.study is not None
        and lt.day_cycle
        and lt.solution_set is not None
        and list(lt.solution_set.names) == ss.study["names"]
    )


def change(state: AppState, **fields) -> None:
    """The panel changed the setting: shown at once in the panel, solved from the next frame."""
    ss = sun_sky(state)
    if ss.daylight is None:
        return
    try:
        ss.daylight = ss.daylight.with_changes(**fields)
    except IATError as e:
        ss.error = str(e)
        return
    ss.error = ""
    if study_shown(state) and set(fields) == {"hour"}:
        study_time(state, float(fields["hour"]))
        return
    ss.pending = ss.daylight


def study_time(state: AppState, hour: float) -> None:
    """Move the day cycle's slider to ``hour`` of the sun study shown."""
    hours = sun_sky(state).study["hours"]
    t = (float(hour) - hours[0]) / (hours[-1] - hours[0])
    state.lighting.day_time = float(min(max(t, 0.0), 1.0))


def study_hour(state: AppState) -> float | None:
    """The clock hour at the day cycle's slider, when the sun study is shown."""
    if not study_shown(state):
        return None
    hours = sun_sky(state).study["hours"]
    return hours[0] + float(state.lighting.day_time) * (hours[-1] - hours[0])


def _moves_shadows(old: Daylight | None, new: Daylight) -> bool:
    """A new sun (moved, or switched on): its shadows need a mesh of their own."""
    if new.sun() is None:
        return False
    if old is None or old.sun() is None:
        return True
    return float(np.dot(old.to_sun(), new.to_sun())) < np.cos(np.radians(0.05))


def apply_pending(state: AppState) -> bool:
    """Hand the panel's change to the light editor and the background re-solve (once a frame, on
    the UI thread). True when something was submitted."""
    ss = sun_sky(state)
    lt = state.lighting
    ed, rl = lt.editor, lt.relighter
    if ss.pending is None or ed is None or rl is None or lt.day_cycle:
        return False
    new, ss.pending = ss.pending, None
    if light_key(new) == light_key(_setting(ss, ed.scene) or ss.daylight_given()):  # the same light
        ss.solved[id(ed.scene)] = (ed.scene, new)  # (e.g. the hour moved with the sun off, no sky)
        ss.note(f"{new.clock_text()}: the same light, nothing to solve")
        return False
    remesh = _moves_shadows(_setting(ss, rl.base_scene), new)  # against the last solution solved
    scene = ed.apply_state(daylight_state(new))
    ss.solved[id(scene)] = (scene, new)
    rl.submit(scene, ed.version, remesh=remesh)
    lt.relight_version, lt.relight_submitted = ed.version, time.perf_counter()
    ss.note(f"submitted {new.clock_text()} ({'afresh' if remesh else 'on the mesh'})")
    return True


def light_key(d: Daylight | None) -> str:
    """What of ``d`` reaches the solve (its sun when up and on, its sky), as text to compare; None:
    no daylight (a model's own lamps alone)."""
    if d is None:
        return json.dumps({"sky": None, "sun": None}, sort_keys=True)
    st = daylight_state(d)
    st.pop("azimuth"), st.pop("elevation")
    if float(st["sun"].get("intensity", 0.0)) <= 0:
        st["sun"] = None
    return json.dumps(st, sort_keys=True)


def shown_daylight(state: AppState) -> Daylight | None:
    """The setting of the solution on screen (None: not one this panel made, e.g. the model's own)."""
    return _setting(sun_sky(state), state.model.scene)


def _setting(ss: SunSky, scene) -> Daylight | None:
    hit = ss.solved.get(id(scene)) if scene is not None else None
    return hit[1] if hit is not None and hit[0] is scene else None


# -- the sun study -----------------------------------------------------------------------------------
def start_study(state: AppState) -> None:
    """Solve the sun study of the panel's place, date and sky at its hours on one mesh (a
    :class:`viewer.jobs.SetJob`: progress, ETA, Cancel in the panel); the app shows the set with the
    day cycle's time-of-day slider once solved."""
    from viewer.jobs import SetJob
    from viewer.relight import options_in_force

    ss = sun_sky(state)
    lt, ed = state.lighting, state.lighting.editor
    if ed is None or ss.daylight is None or state.model.solution is None:
        return
    try:
        hours = parse_hours(ss.hours)
        states = sun_study_states(ss.daylight.with_changes(sun_on=True), ss.daylight.date, hours)
    except IATError as e:
        ss.error = str(e)
        return
    ss.error = ""
    opts = options_in_force(state)
    if lt.set_job is not None and not lt.set_job.done:
        lt.set_job.cancel()
    lt.states, lt.solution_set, lt.day_cycle = states, None, False
    ss.study = {"hours": hours, "names": list(states), "date": ss.daylight.date}
    lt.set_job = SetJob(ed.base, states, opts, mesh=STUDY_MESH)
    ss.note(f"sun study of {len(hours)} hours started")
    state.messages.set_status(f"sun study: solving {len(hours)} hours of {ss.daylight.date} on one mesh")


# -- what is shown -------------------------------------------------------------------------------------
_SKIES: dict = {}  # id(state dict) -> (state dict, Sky): the study's skies, made once


def _state_sky(st: dict):
    if "sky" not in st:
        return None
    hit = _SKIES.get(id(st))
    if hit is None or hit[0] is not st:
        hit = (st, Sky.from_spec(st["sky"]))
        _SKIES[id(st)] = hit
    return hit[1]


def shown_sky(state: AppState):
    """The sky behind the model: the study's key state nearest the slider, else the shown scene's."""
    if study_shown(state):
        keys = key_states(state)
        if keys is not None:
            a, b, w = keys
            return _state_sky(b if w >= 0.5 else a)
    sc = state.model.scene
    return sc.sky if sc is not None else None


def sync_sky(state: AppState, renderer) -> bool:
    """Put :func:`shown_sky` behind the model when it changed (a GL upload of its image: call where
    GL may be used). True when it was uploaded."""
    ss = sun_sky(state)
    sky = shown_sky(state)
    if sky is ss.sky_shown or renderer is None:
        return False
    ss.sky_shown = sky
    try:
        renderer.set_sky(sky)
    except Exception as e:  # the view keeps its last sky
        log.warning("cannot draw the new sky: %s", e)
        return False
    return True


@dataclass
class SunMarker:
    """Where the sun shown stands: ``to_sun`` (3,) unit vector in the scene, ``azimuth`` (degrees
    clockwise from true north), ``elevation`` (degrees), ``irradiance`` (W/m² on a surface facing it),
    ``up`` (above the horizon and on)."""

    to_sun: np.ndarray
    azimuth: float
    elevation: float
    irradiance: float
    up: bool

    def text(self) -> str:
        if not self.up:
            return f"sun down or off (azimuth {self.azimuth:.1f} deg, elevation {self.elevation:.1f} deg)"
        return (
            f"sun: azimuth {self.azimuth:.1f} deg, elevation {self.elevation:.1f} deg, "
            f"{self.irradiance:.0f} W/m²"
        )


def sun_marker(state: AppState) -> SunMarker | None:
    """The sun to mark: the study's at the slider when it is shown, else the panel's setting (the
    view's light follows once solved); None without a setting or sun."""
    if study_shown(state):
        d = sun_at(state)
        ang = stated_angles(state)
        keys = key_states(state)
        if d is None or ang is None or keys is None:
            return None
        a, b, w = keys
        e = [float(st["sun"]["intensity"]) if towards_sun(st) is not None else 0.0 for st in (a, b)]
        return SunMarker(d, ang[0], ang[1], (1.0 - w) * e[0] + w * e[1], True)
    d = sun_sky(state).daylight
    if d is None:
        return None
    az, el = d.position()
    return SunMarker(d.to_sun(), az, el, d.illuminance(), d.illuminance() > 0)
