"""The Sun & sky panel's logic without a window (viewer/sun_sky.py): the setting it starts from, a
change handed to the light editor and the real background re-solve (afresh when the sun moves, on
the mesh when only the sky changes), the sun marker, the study's hours on the time-of-day slider."""

from __future__ import annotations

import datetime
import time

import numpy as np
import pytest

from iat.lighting.daylight_default import DaylightRequest, apply_daylight, coming_equinox
from iat.lighting.sun import day_times, solar_position
from tests.support.site_ifc import angle_deg, expected_to_sun


def opened_state(tmp_path):
    """An AppState as the app leaves it after opening a court (an OBJ: the default place, Paris) by
    the default daylight: the light editor, the re-solve on its solution."""
    from iat.io.load import load_scene
    from iat.lighting.editor import LightEditor
    from iat.radiosity import SolveOptions, solve
    from viewer.relight import ProgressRelighter
    from viewer.state import AppState

    obj = tmp_path / "court.obj"
    obj.write_text(
        "v 0 0 0\nv 0 0 4\nv 4 0 4\nv 4 0 0\nv 0 2 0\nv 0 2 4\nv 4 2 4\nv 4 2 0\n"
        "f 1 2 3 4\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\n"
    )
    scene = load_scene(obj)
    apply_daylight(scene, DaylightRequest())
    sol = solve(scene, SolveOptions(max_depth=2))
    s = AppState()
    s.model.scene, s.model.solution = scene, sol
    s.lighting.editor = LightEditor(scene)
    s.lighting.relighter = ProgressRelighter(sol, scene)
    return s


def wait_result(rl, seconds=120.0):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        r = rl.poll()
        if r is not None and (r.final or r.error):
            return r
        time.sleep(0.05)
    raise AssertionError("no re-solve result")


def test_changes_go_to_the_re_solve(tmp_path):
    from viewer import sun_sky

    s = opened_state(tmp_path)
    try:
        ss = sun_sky.sun_sky(s)
        d = ss.daylight
        assert ss.given and (d.latitude, d.longitude, d.hour, d.date) == (48.85, 2.35, 10.0, coming_equinox())
        assert sun_sky.shown_daylight(s) == d  # the solution on screen is the model's own setting
        # the time slider: the sun moves, so the scene is solved afresh (a new mesh), after a preview
        # of the new sun on the mesh on screen
        published = s.lighting.relighter.published
        sun_sky.change(s, hour=15.0, date=datetime.date(2026, 6, 21))
        assert sun_sky.apply_pending(s) and s.lighting.relight_version == s.lighting.editor.version
        (sun,) = [lt for lt in s.lighting.editor.scene.lights if lt.kind == "directional"]
        when = day_times("2026-06-21", [15.0], 0.0)[0]
        assert angle_deg(-sun.direction, expected_to_sun(48.85, 2.35, when, 0.0)) < 0.1
        m = sun_sky.sun_marker(s)  # the marker shows the new sun at once
        assert (m.azimuth, m.elevation) == pytest.approx(solar_position(48.85, 2.35, when), abs=1e-9)
        r = wait_result(s.lighting.relighter)
        assert r.error is None and (r.steps, r.mode) == (2, "solve") and r.scene is s.lighting.editor.scene
        assert s.lighting.relighter.published == published + 2  # the preview, then the new solve
        assert not sun_sky.apply_pending(s)  # nothing new
        # the sky alone: on the mesh, after a preview
        sun_sky.change(s, sky_scale=2.0)
        assert sun_sky.apply_pending(s)
        assert s.lighting.editor.scene.sky.radiance == pytest.approx(2.0 * r.scene.sky.radiance)
        r2 = wait_result(s.lighting.relighter)
        assert r2.error is None and r2.steps == 2
        assert np.array_equal(r2.solution.vert_key, r.solution.vert_key)
        s.model.scene = r2.scene
        assert sun_sky.shown_daylight(s).sky_scale == 2.0
        # the sun off and no sky: moving the hour changes no light, so nothing is solved
        sun_sky.change(s, sun_on=False, sky_model="none")
        assert sun_sky.apply_pending(s)
        wait_result(s.lighting.relighter)
        version = s.lighting.editor.version
        sun_sky.change(s, hour=9.0)
        assert not sun_sky.apply_pending(s) and s.lighting.editor.version == version
        assert sun_sky.sun_marker(s).text().startswith("sun down or off (azimuth ")
    finally:
        s.lighting.relighter.close()


def test_the_study_hours_on_the_day_slider(tmp_path):
    from types import SimpleNamespace

    from iat.lighting.solution_set import blend_weights
    from viewer import sun_sky

    s = opened_state(tmp_path)
    s.lighting.relighter.close()
    ss = sun_sky.sun_sky(s)
    ss.study = {"hours": [9.0, 13.0, 17.0], "names": ["09h00", "13h00", "17h00"], "date": ss.daylight.date}
    sset = SimpleNamespace(names=["09h00", "13h00", "17h00"], times=np.array([0.0, 0.5, 1.0]))
    sset.weights = lambda t: blend_weights(sset.times, t)
    s.lighting.solution_set, s.lighting.day_cycle = sset, True
    assert sun_sky.study_shown(s)
    sun_sky.change(s, hour=15.0)  # the slider plays the study: no re-solve
    assert s.lighting.day_time == pytest.approx(0.75) and ss.pending is None
    assert sun_sky.study_hour(s) == pytest.approx(15.0)
