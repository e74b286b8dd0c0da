"""The Sun & sky panel (issue 38) and the sun's disc over the 3D view.

**Sun & sky** (a tab beside Stats, top right; the state and what a change does are in
:mod:`viewer.sun_sky`): the place (latitude, longitude; true north as a slider and a compass drawn
with the camera's heading up: N and the sun), the date, a time slider (clock hours in the
longitude's zone), sun on/off, the sky model (clear: Preetham with its turbidity; overcast: CIE;
uniform; none) and the sky's brightness; the sun's azimuth, elevation and W/m²; the re-solve's
progress, time left and Cancel (a preview of the new light is shown within seconds, while the full
solve goes on: :func:`iat.lighting.relight.preview`). Under it the sun study: hours (``8-18``),
*Solve sun study* (the hours as lighting states on one mesh; progress, time left, Cancel), then the
time slider plays it. Artificial lights stay in the Lighting panel.

:func:`frame` is the app's per-frame call: it hands the panel's change to the re-solve
(:func:`viewer.sun_sky.apply_pending`), puts the shown sky behind the model and draws the sun's
disc where it stands in the view (when it is in view) with its azimuth, elevation and W/m².
"""

from __future__ import annotations

import datetime

import numpy as np
from imgui_bundle import ImVec2, ImVec4, imgui

from iat.lighting.daylight_default import DEFAULT_TURBIDITY
from viewer import sun_sky
from viewer.eta import JobEta
from viewer.panels import DIM, RED
from viewer.state import AppState

SKY_CHOICES = (
    ("clear", "clear (Preetham)"),
    ("overcast", "overcast (CIE)"),
    ("uniform", "uniform"),
    ("none", "none"),
)
STUDY_ETA = JobEta()
SUN_GOLD = ImVec4(1.0, 0.85, 0.2, 1.0)


def help_mark(text: str) -> None:
    imgui.same_line()
    imgui.text_disabled("(?)")
    imgui.set_item_tooltip(text)


def bar(fraction: float, text: str) -> None:
    imgui.progress_bar(float(min(max(fraction, 0.0), 1.0)), ImVec2(-1, 0), text)


def seconds(s: float | None) -> str:
    if s is None:
        return "..."
    return f"{s * 1000:.0f} ms" if s < 1 else f"{s:.1f} s"


def _clock(hour: float) -> str:
    m = int(round(float(hour) * 60))
    return f"{m // 60:02d}:{m % 60:02d}"


def sun_sky_panel(state: AppState) -> None:
    ss = sun_sky.sun_sky(state)
    d = ss.daylight
    if state.lighting.editor is None or d is None:
        imgui.text_disabled("an exported bake: lit by its textures" if state.model.path else "nothing open")
        return
    study = sun_sky.study_shown(state)
    imgui.text_wrapped(d.place_text())
    imgui.begin_disabled(study)
    changed, v = imgui.input_float("Latitude", float(d.latitude), 0.1, 1.0, "%.4f")
    if changed and -90.0 <= v <= 90.0:
        sun_sky.change(state, latitude=float(v), place="set in the panel")
    changed, v = imgui.input_float("Longitude", float(d.longitude), 0.1, 1.0, "%.4f")
    if changed and -180.0 <= v <= 180.0:
        sun_sky.change(state, longitude=float(v), place="set in the panel")
    changed, v = imgui.slider_float("North", float(d.north_deg), -180.0, 180.0, "%.1f deg")
    if changed:
        sun_sky.change(state, north_deg=float(v))
    help_mark("True north: degrees from the scene's -Z, anticlockwise seen from above (an IFC's TrueNorth).")
    compass(state, d)
    text = d.date.isoformat()
    changed, text = imgui.input_text("Date", text, imgui.InputTextFlags_.enter_returns_true)
    if changed:
        try:
            sun_sky.change(state, date=datetime.date.fromisoformat(text.strip()))
        except ValueError:
            ss.error = f"date must be YYYY-MM-DD, got {text!r}"
    imgui.end_disabled()
    hour = sun_sky.study_hour(state)
    lo, hi = (0.0, 24.0) if not study else (ss.study["hours"][0], ss.study["hours"][-1])
    shown_hour = float(d.hour) if hour is None else hour
    changed, v = imgui.slider_float(
        "Time", shown_hour, lo, hi, f"{_clock(shown_hour)} ({d.clock_text().split(' ', 2)[2]})"
    )
    if changed:
        sun_sky.change(state, hour=float(min(max(v, lo), hi)))
    help_mark("Clock time in the zone of the longitude; with the sun study shown it plays the study.")
    m = sun_sky.sun_marker(state)
    if m is not None:
        imgui.push_style_color(imgui.Col_.text, SUN_GOLD if m.up else DIM)
        imgui.text_wrapped(m.text())
        imgui.pop_style_color()
        help_mark("Azimuth clockwise from true north (NOAA's solar position); the disc in the view marks it.")
    imgui.begin_disabled(study)
    changed, on = imgui.checkbox("Sun", bool(d.sun_on))
    if changed:
        sun_sky.change(state, sun_on=bool(on))
    keys = [k for k, _ in SKY_CHOICES]
    cur = keys.index(d.sky_model) if d.custom_sky is None and d.sky_model in keys else len(keys) - 1
    if imgui.begin_combo(
        "Sky", SKY_CHOICES[cur][1] if d.custom_sky is None else f"{d.custom_sky.kind} (file)"
    ):
        for k, (key, label) in enumerate(SKY_CHOICES):
            if imgui.selectable(label, k == cur)[0] and (k != cur or d.custom_sky is not None):
                sun_sky.change(state, sky_model=key, custom_sky=None)
        imgui.end_combo()
    if d.sky_model == "clear" and d.custom_sky is None:
        changed, v = imgui.slider_float("Turbidity", float(d.turbidity), 2.0, 10.0, "%.1f")
        if changed:
            sun_sky.change(state, turbidity=float(v))
        help_mark(f"Preetham's turbidity: 2 very clear ... 10 hazy (default {DEFAULT_TURBIDITY:g}).")
    changed, v = imgui.slider_float(
        "Sky brightness", float(d.sky_scale), 0.0, 4.0, "x%.2f", imgui.SliderFlags_.logarithmic
    )
    if changed:
        sun_sky.change(state, sky_scale=max(float(v), 0.0))
    imgui.end_disabled()
    imgui.text_colored(DIM, d.sky_text())
    if ss.error:
        imgui.text_colored(RED, ss.error)
    if study:
        imgui.text_colored(DIM, "the sun study is shown: turn the day cycle off to change the rest")
    resolve_progress(state)
    study_panel(state)


def resolve_progress(state: AppState) -> None:
    """The re-solve under way (a bar, the step, the time left, Cancel) or what the last one came to."""
    rl = state.lighting.relighter
    if rl is None:
        return
    if state.lighting.relighting:
        f, eta = float(rl.fraction), rl.eta
        left = f"{seconds(eta)} left" if eta is not None else "measuring..."
        bar(f, f"solving the new light: {100 * f:.0f} %  {left}")
        if imgui.button("Cancel##sun"):
            rl.cancel()
        help_mark("Stop the solve; the view keeps the light it shows.")
        if state.lighting.relight_mode == "preview":  # (under the button, which stays where it was)
            imgui.text_colored(DIM, f"shown: a preview ({seconds(state.lighting.relight_seconds)})")
    elif getattr(rl, "cancelled", False):
        imgui.text_colored(RED, "cancelled: the view keeps the last light solved")
    elif sun_sky.sun_sky(state).daylight is not None and sun_sky.shown_daylight(state) is not None:
        shown = sun_sky.shown_daylight(state)
        imgui.text_colored(
            DIM, f"shown: {shown.clock_text()}, solved in {seconds(state.lighting.relight_seconds)}"
        )


def study_panel(state: AppState) -> None:
    ss = sun_sky.sun_sky(state)
    lt = state.lighting
    imgui.separator()
    imgui.text("Sun study")
    job = lt.set_job
    if job is not None and not job.done:
        eta = STUDY_ETA.update(job, job.fraction)
        left = f"{seconds(eta)} left" if eta is not None else "measuring..."
        bar(job.fraction, f"{100 * job.fraction:.0f} %  {left}  {job.message[:40]}")
        if imgui.button("Cancel##study"):
            job.cancel()
        return
    imgui.set_next_item_width(imgui.get_content_region_avail().x * 0.4)
    _, ss.hours = imgui.input_text("Hours", ss.hours)
    imgui.same_line()
    if imgui.button("Solve sun study"):
        sun_sky.start_study(state)
    help_mark(
        "The date's hours (8-18, 8-18/2 or 9,12,15) as lighting states on one mesh, as the day cycle;\n"
        "then the Time slider (and the Lighting panel's Time of day) plays them."
    )
    if (
        ss.study is not None
        and lt.solution_set is not None
        and list(lt.solution_set.names) == ss.study["names"]
    ):
        changed, on = imgui.checkbox("Show the sun study", lt.day_cycle)
        if changed:
            lt.day_cycle = bool(on)
        imgui.text_colored(DIM, f"{ss.study['date']}: {', '.join(ss.study['names'])}")


def compass(state: AppState, d, radius: float = 30.0) -> None:
    """True north and the sun seen from above, the camera's heading up (as the view's corner compass)."""
    cam = state.view.camera
    fwd = np.asarray(cam.forward, dtype=np.float64) if cam is not None else np.array([0.0, 0.0, -1.0])
    heading = np.array([fwd[0], 0.0, fwd[2]])
    heading = heading / n if (n := np.linalg.norm(heading)) > 1e-9 else np.array([0.0, 0.0, -1.0])
    right = np.array([-heading[2], 0.0, heading[0]])
    p = imgui.get_cursor_screen_pos()
    c = ImVec2(p.x + radius + 4, p.y + radius + 4)
    dl = imgui.get_window_draw_list()
    ring = imgui.get_color_u32(ImVec4(1, 1, 1, 0.6))
    dl.add_circle(c, radius, ring, 0, 1.5)
    north = d.north()
    nx, ny = float(north @ right), float(north @ heading)
    tip = ImVec2(c.x + radius * nx, c.y - radius * ny)
    dl.add_line(c, tip, imgui.get_color_u32(ImVec4(0.9, 0.3, 0.3, 1.0)), 2.0)
    dl.add_text(ImVec2(tip.x - 4, tip.y - 7), ring, "N")
    m = sun_sky.sun_marker(state)
    if m is not None:
        sx, sy = float(m.to_sun @ right), float(m.to_sun @ heading)
        dl.add_circle_filled(ImVec2(c.x + radius * sx, c.y - radius * sy), 4.0, imgui.get_color_u32(SUN_GOLD))
    imgui.dummy(ImVec2(2 * radius + 8, 2 * radius + 8))


# -- every frame ---------------------------------------------------------------------------------------
def frame(app) -> None:
    """The app's per-frame call (UI thread): the panel's change to the re-solve, the shown sky
    behind the model, the sun's disc over the view."""
    s = app.state
    if s.lighting.editor is None:
        return
    sun_sky.apply_pending(s)
    if sun_sky.sync_sky(s, app.renderer) and app.view3d is not None:
        app.view3d.invalidate()
    sun_disc(s)


def disc_position(state: AppState) -> tuple[float, float] | None:
    """Window pixels of the sun's disc in the 3D view, or None when it is not in view."""
    from viewer.picking import project_points

    m, cam = sun_sky.sun_marker(state), state.view.camera
    if m is None or cam is None or not m.up:
        return None
    far = 0.5 * float(getattr(cam, "zfar", 100.0))
    px, ok = project_points(cam, [np.asarray(cam.eye, dtype=np.float64) + far * m.to_sun], state.view.rect)
    return (float(px[0, 0]), float(px[0, 1])) if ok[0] else None


def sun_disc(state: AppState) -> None:
    """The sun's disc where it stands in the view, with its azimuth, elevation and W/m²."""
    pos = disc_position(state)
    if pos is None:
        return
    m = sun_sky.sun_marker(state)
    x, y, w, h = state.view.rect
    dl = imgui.get_background_draw_list()
    dl.push_clip_rect(ImVec2(x, y), ImVec2(x + w, y + h), True)
    try:
        c = ImVec2(*pos)
        dl.add_circle_filled(c, 14.0, imgui.get_color_u32(ImVec4(1.0, 0.9, 0.4, 0.25)))
        dl.add_circle_filled(c, 9.0, imgui.get_color_u32(SUN_GOLD))
        text = f"sun {m.azimuth:.0f}/{m.elevation:.0f} deg, {m.irradiance:.0f} W/m²"
        dl.add_text(ImVec2(c.x + 15, c.y - 7), imgui.get_color_u32(ImVec4(0, 0, 0, 0.8)), text)
        dl.add_text(ImVec2(c.x + 14, c.y - 8), imgui.get_color_u32(ImVec4(1, 1, 1, 1)), text)
    finally:
        dl.pop_clip_rect()
