"""The Sun & sky panel end to end (issue 38): the real viewer driven by imgui-bundle's test engine
(needs a display; the GUI part runs in a child process, see tests/conftest.py).

The model is an IFC written with ifcopenshell's API (tests/support/site_ifc.py): a 10 x 10 m hall at
Boulder (IfcSite), TrueNorth turned 30 degrees, a 1 x 1 m skylight in its roof; opened as
``iat view hall.ifc --sun 2026-06-21T09:00`` would (its site's place, the longitude's zone, UTC-7).

1. the first view is lit (median luminance above 0), and the sun's patch on the floor stands
   where the 9:00 sun through the skylight puts it;
2. the panel's Time slider to 17:00: the progress of the re-solve shows (with the 9:00 light still
   on screen) before the first view lit by the new sun, a preview on the 9:00 mesh, then the new
   solve; the sun marker's azimuth and elevation are NOAA's for 17:00, its direction the site's (true
   north applied), and the lit patch has moved across the floor against the sun's move, where the
   17:00 sun puts it;
3. 13:00, then Cancel: the solve stops; the 17:00 light stays, or the 13:00 preview if it came first;
4. the sun study from the panel (9-17/4): three hours on one mesh; the Time slider then plays it
   (no solve): at 17:00 the marker and the lit patch are those of the 17:00 state.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until
from tests.support import gui
from tests.support.site_ifc import HALL_WALL, LAT, LON, NORTH_DEG, ROOF, SKYLIGHT, TZ_HOURS, expected_to_sun

DATE = "2026-06-21"
#: how far the sun's patch on the floor may stand from where the skylight and the sun put it, m
#: (its vertices are the adaptive mesh's, 0.16 m apart at max_depth 4 on 2.5 m panel cells)
PATCH_TOL = 0.45


def lit_patch(sol) -> np.ndarray:
    """(x, z) centroid of the floor's sunlit vertices (radiance above half the floor's brightest)."""
    n1 = (1 << int(sol.max_depth)) + 1
    patch = np.asarray(sol.vert_key) // (n1 * n1)
    c = np.asarray(sol.patch_corners)
    nrm = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    pos = sol.vert_position
    floor = (nrm[patch, 1] > 0.9) & (np.abs(pos[:, 1]) < 1e-6)
    lum = np.asarray(sol.vert_radiance, dtype=np.float64) @ [0.2126, 0.7152, 0.0722]
    lit = floor & (lum > 0.5 * lum[floor].max())
    return pos[lit][:, [0, 2]].mean(axis=0)


def predicted_patch(to_sun: np.ndarray) -> np.ndarray:
    """Where the sun through the skylight lands on the floor (the middle of the roof's thickness)."""
    x0, x1, y0, y1 = SKYLIGHT
    mid = np.array([(x0 + x1) / 2, HALL_WALL + ROOF / 2, -(y0 + y1) / 2])  # IFC (x, y, z) -> (x, z, -y)
    p = mid - mid[1] / to_sun[1] * to_sun
    return p[[0, 2]]


@pytest.mark.gui
def test_sun_and_sky_panel(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    pytest.importorskip("ifcopenshell")
    from imgui_bundle.immapp import testing

    from iat.camera import Camera
    from iat.lighting.daylight_default import DaylightRequest
    from iat.lighting.sun import day_times, solar_position
    from iat.radiosity import SolveOptions
    from tests.support.site_ifc import site_ifc
    from viewer import sun_panel, sun_sky
    from viewer.app import ViewerApp
    from viewer.daylight import model_north, sun_facts

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("IAT_SCREENSHOT_DIR", str(tmp_path / "shots"))
    model = site_ifc(tmp_path, skylight=True)
    frames: list[tuple] = []  # per frame: (relighting, fraction, solution shown, its mode)

    def hook(app):
        st = app.state
        rl = st.lighting.relighter
        shown = (st.model.solution, st.lighting.relight_mode)
        frames.append((st.lighting.relighting, float(getattr(rl, "fraction", 0.0)), *shown))

    app = ViewerApp(
        model,
        size=(1280, 800),
        solve_options=SolveOptions(max_depth=4),
        idle=False,
        daylight=DaylightRequest(sun=f"{DATE}T09:00"),
        frame_hook=hook,
    )
    s = app.state
    got: dict = {}

    def noaa(hour: float):
        when = day_times(DATE, [hour], TZ_HOURS)[0]
        return solar_position(LAT, LON, when), expected_to_sun(LAT, LON, when, NORTH_DEG)

    def settle(ctx):
        gui.settle(ctx, app, 300)

    def shot(ctx, name: str) -> np.ndarray:
        return gui.screenshot(ctx, app, name) / 255.0

    def marker(hour_label: str):
        m = sun_sky.sun_marker(s)
        return {
            "az": m.azimuth,
            "el": m.elevation,
            "to_sun": m.to_sun.copy(),
            "W": m.irradiance,
            "at": hour_label,
        }

    def drive(ctx) -> None:
        wait_until(ctx, lambda: s.model.baked is not None and s.lighting.editor is not None, 300, "the model")
        settle(ctx)
        cam = Camera(eye=[0.8, 1.5, -0.8], target=[6.0, 0.0, -6.0], up=[0.0, 1.0, 0.0], yfov=75.0, zfar=80.0)
        s.view.nav.set_camera(cam)
        s.view.camera = s.view.nav.camera
        s.requests.auto_exposure = True
        ctx.item_click("//**/IAT")
        ctx.yield_(4)
        got["first"] = shot(ctx, "first")
        got["m9"], got["patch9"] = marker("09:00"), lit_patch(s.model.solution)
        got["sol9"] = s.model.solution
        got["text9"] = sun_sky.sun_marker(s).text()

        n0 = len(frames)
        ctx.item_input_value("//Sun & sky/Time", 17.0)
        wait_until(
            ctx,
            lambda: sun_sky.shown_daylight(s) is not None and sun_sky.shown_daylight(s).hour == 17.0,
            300,
            "the 17:00 light",
        )
        settle(ctx)
        got["after"] = frames[n0:]
        got["m17"], got["patch17"] = marker("17:00"), lit_patch(s.model.solution)
        got["sol17"] = s.model.solution
        got["disc_away"] = sun_panel.disc_position(s)  # the camera looks down into the hall
        m = sun_sky.sun_marker(s)  # look at the sun: its disc in the middle of the view
        eye = np.asarray(s.view.camera.eye)
        s.view.camera = Camera(eye=eye, target=eye + m.to_sun, up=[0.0, 1.0, 0.0], yfov=75.0, zfar=80.0)
        x, y, w, h = s.view.rect
        got["disc"] = (sun_panel.disc_position(s), (x + w / 2, y + h / 2))
        s.view.nav.set_camera(cam)
        s.view.camera = s.view.nav.camera
        ctx.yield_(2)
        (sun,) = [lt for lt in s.lighting.editor.lights if lt.kind == "directional"]
        got["facts17"] = sun_facts(sun, model_north(s))  # the Lighting panel's words, from true north
        got["seventeen"] = shot(ctx, "17")
        testing.capture(ctx, str(tmp_path / "window-17.png"))  # (docs/screenshots/viewer-sun-sky.png)

        rl = s.lighting.relighter  # a 13:00 solve long enough that the click lands in it on a busy machine
        opts, rl.options = rl.options, dataclasses.replace(rl.options, max_depth=7, tolerance=0.02)
        ctx.item_input_value("//Sun & sky/Time", 13.0)
        wait_until(ctx, lambda: s.lighting.relighting, 60, "the 13:00 solve to start")
        ctx.item_click("//Sun & sky/Cancel##sun")
        wait_until(ctx, lambda: not s.lighting.relighting, 60, "the cancelled solve to stop")
        ctx.yield_(30)
        kept = "17:00" if s.model.solution is got["sol17"] else s.lighting.relight_mode  # (or its preview)
        got["cancelled"] = (s.lighting.relighter.cancelled, kept, sun_sky.shown_daylight(s).hour)
        rl.options = opts  # (the sun study below solves at the model's options)

        ctx.item_input_value("//Sun & sky/Hours", "9-17/4")
        ctx.item_click("//Sun & sky/Solve sun study")
        ctx.yield_(2)
        got["study_progress"] = s.lighting.solving_day_cycle
        wait_until(
            ctx, lambda: s.lighting.day_cycle and s.lighting.solution_set is not None, 600, "the sun study"
        )
        settle(ctx)
        ctx.item_input_value("//Sun & sky/Time", 17.0)
        ctx.yield_(3)
        sset = s.lighting.solution_set
        got["study"] = (list(sset.names), s.lighting.day_time, marker("study 17:00"), lit_patch(sset.at(1.0)))
        ctx.item_input_value("//Sun & sky/Time", 9.0)
        ctx.yield_(3)
        got["study9"] = (s.lighting.day_time, marker("study 09:00"), lit_patch(sset.at(0.0)))

    run_gui(app, drive)

    # 1. the first view is lit, the patch where the 9:00 sun puts it
    lum = got["first"] @ np.array([0.2126, 0.7152, 0.0722])
    assert np.median(lum) > 0, "the first view is black"
    (az9, el9), to9 = noaa(9.0)
    m9 = got["m9"]
    assert (m9["az"], m9["el"]) == pytest.approx((az9, el9), abs=0.1)
    assert np.degrees(np.arccos(np.clip(m9["to_sun"] @ to9, -1, 1))) < 0.1
    assert got["text9"].startswith(f"sun: azimuth {az9:.1f} deg, elevation {el9:.1f} deg, ")
    assert np.linalg.norm(got["patch9"] - predicted_patch(to9)) < PATCH_TOL, (
        got["patch9"],
        predicted_patch(to9),
    )

    # 2. 17:00: progress first (old light on screen), then a preview of the new light on the old mesh,
    # then the new light; marker and patch moved
    after = got["after"]
    first_new = next(k for k, f in enumerate(after) if f[2] is not got["sol9"])
    assert any(f[0] for f in after[:first_new]), "no progress shown before the first view of the new sun"
    assert all(f[2] is got["sol9"] for f in after[:first_new])  # the old light stays until then
    assert max(f[1] for f in after if f[0]) > 0  # the bar moved (the preview may come before it does)
    preview = after[first_new][2]
    assert after[first_new][3] == "preview" and np.array_equal(preview.vert_key, got["sol9"].vert_key)
    assert got["sol17"].stats["mode"] == "solve" and got["sol17"] is not preview
    (az17, el17), to17 = noaa(17.0)
    m17 = got["m17"]
    assert (m17["az"], m17["el"]) == pytest.approx((az17, el17), abs=0.1)
    assert np.degrees(np.arccos(np.clip(m17["to_sun"] @ to17, -1, 1))) < 0.1
    assert m17["az"] - m9["az"] > 150  # from the east to the west, by the south
    disc, middle = got["disc"]
    assert got["disc_away"] is None and disc is not None and np.allclose(disc, middle, atol=1.0)
    assert got["facts17"].startswith(f"azimuth {az17:.1f} deg, elevation {el17:.1f} deg, ")
    assert np.linalg.norm(got["patch17"] - predicted_patch(to17)) < PATCH_TOL, (
        got["patch17"],
        predicted_patch(to17),
    )
    move = got["patch17"] - got["patch9"]
    sun_move = (to17 - to9)[[0, 2]]
    assert np.linalg.norm(move) > 3.0 and move @ sun_move < -0.8 * np.linalg.norm(move) * np.linalg.norm(
        sun_move
    )
    assert np.median(got["seventeen"] @ np.array([0.2126, 0.7152, 0.0722])) > 0

    # 3. cancel: the solve stopped; the 17:00 light stayed, or the 13:00 preview if it came first
    assert got["cancelled"] in ((True, "17:00", 17.0), (True, "preview", 13.0)), got["cancelled"]

    # 4. the sun study from the panel, played by the Time slider
    assert got["study_progress"]
    names, t17, ms17, patch_s17 = got["study"]
    assert names == ["09h00", "13h00", "17h00"] and t17 == pytest.approx(1.0)
    assert (ms17["az"], ms17["el"]) == pytest.approx((az17, el17), abs=0.1)
    assert np.linalg.norm(patch_s17 - predicted_patch(to17)) < PATCH_TOL
    t9, ms9, patch_s9 = got["study9"]
    assert t9 == pytest.approx(0.0) and (ms9["az"], ms9["el"]) == pytest.approx((az9, el9), abs=0.1)
    assert np.linalg.norm(patch_s9 - predicted_patch(to9)) < PATCH_TOL
