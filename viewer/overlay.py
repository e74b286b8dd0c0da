"""What the viewer draws over the 3D view with imgui (its background draw list, no GL): the mode's
label, the split divider, the light markers and their names (on a dark plate, readable on bright
surfaces), the HUD lines (:func:`viewer.panels.hud_lines`), REC / PLAY, and, in the middle of the
view, why it shows nothing (:func:`view_notices`): no light in the model, no light reaching its
surfaces, the camera outside the model (:func:`outside_model`) or the model outside the camera's
view (:func:`nothing_in_view`), each with what to do.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from imgui_bundle import ImVec2, ImVec4, imgui

from viewer.daylight import angles, model_north, shown_sun
from viewer.panels import RED, hud_lines
from viewer.state import MODE_LABELS, AppState


def view_overlay(state: AppState) -> None:
    """Labels and the split divider over the 3D view (imgui background draw list, no GL), clipped to
    the view: the panels beside it may keep last frame's pixels (:mod:`viewer.panel_cache`), and a
    label drawn over them every frame would pile up."""
    state.view.notices = ()
    x, y, w, h = state.view.rect
    if w <= 0 or h <= 0:
        return
    dl = imgui.get_background_draw_list()
    dl.push_clip_rect(ImVec2(x, y), ImVec2(x + w, y + h), True)
    try:
        _view_overlay(state, dl)
    finally:
        dl.pop_clip_rect()


def _view_overlay(state: AppState, dl) -> None:
    x, y, w, h = state.view.rect
    white = imgui.get_color_u32(ImVec4(1, 1, 1, 0.9))
    shadow = imgui.get_color_u32(ImVec4(0, 0, 0, 0.7))

    def label(px: float, text: str) -> None:
        dl.add_text(ImVec2(px + 9, y + 9), shadow, text)
        dl.add_text(ImVec2(px + 8, y + 8), white, text)

    if not state.model.loaded:
        if not state.view.kept:  # (a kept view still shows it)
            label(x, empty_label(state))
        return
    shown = state.view.mode
    if state.view.mode == "split":
        sx = x + state.view.split * w
        col = imgui.get_color_u32(ImVec4(1.0, 0.85, 0.2, 1.0 if state.view.dragging_split else 0.8))
        dl.add_line(ImVec2(sx, y), ImVec2(sx, y + h), col, 3.0 if state.view.dragging_split else 2.0)
        dl.add_circle_filled(ImVec2(sx, y + h * 0.5), 7.0, col)
        label(x, "Mesh")
        label(sx, "IAT")
    else:
        label(
            x, MODE_LABELS.get(shown, shown) + (f"  x{state.view.diff_gain:.0f}" if shown == "diff" else "")
        )
    light_markers(state, dl)
    sun_compass(state, dl)
    state.view.notices = tuple(view_notices(state))
    for k, text in enumerate(state.view.notices):  # on a dark plate, one under the other
        size = imgui.calc_text_size(text)
        p = ImVec2(x + 0.5 * (w - size.x), y + 0.5 * h + 28 * k)
        dl.add_rect_filled(ImVec2(p.x - 8, p.y - 6), ImVec2(p.x + size.x + 8, p.y + size.y + 6), shadow, 4.0)
        dl.add_text(p, imgui.get_color_u32(NOTICE), text)
    hud = hud_lines(state)
    for k, line in enumerate(hud):
        yy = y + h - 10 - 16 * (len(hud) - k)
        dl.add_text(ImVec2(x + 9, yy + 1), shadow, line)
        dl.add_text(ImVec2(x + 8, yy), white, line)
    if state.paths.recorder is not None:
        dl.add_text(ImVec2(x + w - 60, y + 8), imgui.get_color_u32(RED), "REC")
    if state.paths.player is not None:
        dl.add_text(ImVec2(x + w - 60, y + 8), white, "PLAY")


#: the colour of the notices in the middle of the view
NOTICE = ImVec4(1.0, 0.6, 0.3, 1.0)
NO_LIGHT = "no light: the model has no lamp, sky or emissive material (Lighting: Add point light)"
NO_LIGHT_REACHES = "no light reaches the model's surfaces: the solution is black"
OUTSIDE = "outside the model: press R (or View: Reset view) to go back"
NOT_IN_VIEW = "nothing in view: the model is outside the camera's view (R: reset view)"


def view_notices(state: AppState) -> list[str]:
    """Why the 3D view of the open model shows nothing (black or empty), each line with what to do;
    [] when it shows the model."""
    scene = state.model.scene
    if scene is None:
        return []
    out = []
    if not scene.has_light_sources:
        out.append(NO_LIGHT)
    elif solution_is_black(state.model.solution):
        out.append(NO_LIGHT_REACHES)
    if outside_model(state):
        out.append(OUTSIDE)
    elif nothing_in_view(state):
        out.append(NOT_IN_VIEW)
    return out


_BLACK: list = [None, False]  # [solution, whether its radiance is all zero]: the last one asked about


def solution_is_black(sol) -> bool:
    """Every vertex of ``sol`` (a Solution or None) has zero radiance (kept for the last solution)."""
    if sol is None:
        return False
    if _BLACK[0] is not sol:
        rad = getattr(sol, "vert_radiance", None)
        _BLACK[0], _BLACK[1] = sol, rad is not None and len(rad) > 0 and not np.any(np.asarray(rad) > 0)
    return bool(_BLACK[1])


def nothing_in_view(state: AppState) -> bool:
    """The model's box lies wholly outside the camera's view frustum (all 8 corners beyond one clip
    plane): everything is culled, the view shows only the background."""
    cam, scene = state.view.camera, state.model.scene
    x, y, w, h = state.view.rect
    if cam is None or scene is None or w <= 0 or h <= 0:
        return False
    lo, hi = scene_bounds(scene)
    corners = np.array([[(lo, hi)[(k >> a) & 1][a] for a in range(3)] + [1.0] for k in range(8)])
    clip = corners @ np.asarray(cam.clip_from_world(w / h), dtype=np.float64).T  # (8, 4)
    cw = clip[:, 3]
    beyond = [clip[:, a] > cw for a in range(3)] + [clip[:, a] < -cw for a in range(3)]
    return bool(any(b.all() for b in beyond))


def empty_label(state: AppState) -> str:
    """The text over the 3D view while no model is shown."""
    job = state.jobs.open_job
    return f"opening {Path(job.path).name}: {job.message}" if job and not job.done else "nothing open"


_BOUNDS: list = [None, None]  # [scene, {home: (lo, hi)}]: the last scene's boxes


def scene_bounds(scene, home: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``scene.bounds`` (with ``home``: grown to take in its home camera), kept for the last scene
    asked about (a scene's box walks all its vertices: 0.2 ms a frame on the house)."""
    if _BOUNDS[0] is not scene:
        _BOUNDS[0], _BOUNDS[1] = scene, {}
    boxes = _BOUNDS[1]
    if home not in boxes:
        lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.bounds)
        if home:
            eye = np.asarray(scene.default_camera().eye, dtype=np.float64)
            lo, hi = np.minimum(lo, eye), np.maximum(hi, eye)
        boxes[home] = (lo, hi)
    return boxes[home]


def outside_model(state: AppState, margin: float = 0.02) -> bool:
    """The camera is outside the box of the model and its home camera (grown by ``margin`` of its
    diagonal): walked through a wall into the void (a model seen from outside, such as the Cornell
    box, counts its home camera in)."""
    cam, scene = state.view.camera, state.model.scene
    if cam is None or scene is None:
        return False
    lo, hi = scene_bounds(scene, home=True)
    pad = margin * float(np.linalg.norm(hi - lo))
    eye = np.asarray(cam.eye, dtype=np.float64)
    return bool(np.any(eye < lo - pad) or np.any(eye > hi + pad))


_MARKERS: list = [None, None]  # [(editor, version, scene), per-light data]: the lights last drawn


def _marker_data(ed) -> dict:
    """What the markers of ``ed``'s lights need besides the camera (kept until the lights change):
    their points and spot tips (one projection a frame), colours, kinds and names."""
    key = (ed, getattr(ed, "version", None), ed.scene)
    old = _MARKERS[0]
    if old is None or old[0] is not ed or old[1] != key[1] or old[2] is not ed.scene:
        lights = ed.lights
        lo, hi = scene_bounds(ed.scene)
        reach = 0.06 * float(np.linalg.norm(hi - lo))
        pos = np.array([lt.position for lt in lights], dtype=np.float64).reshape(-1, 3)
        tips = np.array([lt.position + reach * lt.direction for lt in lights], dtype=np.float64).reshape(
            -1, 3
        )
        cols = []
        for lt in lights:
            c = np.clip(np.asarray(lt.color, dtype=np.float64) / max(float(np.max(lt.color)), 1e-9), 0.0, 1.0)
            cols.append(imgui.get_color_u32(ImVec4(float(c[0]), float(c[1]), float(c[2]), 1.0)))
        _MARKERS[0] = key
        _MARKERS[1] = {
            "points": np.concatenate([pos, tips]),
            "colors": cols,
            "spot": [lt.kind == "spot" for lt in lights],
            "sun": [lt.kind == "directional" for lt in lights],
            "names": [lt.name for lt in lights],
        }
    return _MARKERS[1]


def light_markers(state: AppState, dl) -> None:
    """A circle per light (filled for the selected one), its name, and a spot light's direction."""
    from viewer.picking import project_points

    ed, cam = state.lighting.editor, state.view.camera
    if not state.lighting.show_lights or ed is None or cam is None or not ed.lights:
        return
    m = _marker_data(ed)
    n = len(m["names"])
    px, ok = project_points(cam, m["points"], state.view.rect)
    plate = imgui.get_color_u32(ImVec4(0.0, 0.0, 0.0, 0.65))
    white = imgui.get_color_u32(ImVec4(1.0, 1.0, 1.0, 1.0))
    gold, dark = imgui.get_color_u32(ImVec4(1.0, 0.85, 0.2, 1.0)), imgui.get_color_u32(ImVec4(0, 0, 0, 0.9))
    for k in range(n):
        if not ok[k] or m["sun"][k]:  # a sun is a direction: the compass shows it, no marker
            continue
        sel = k == state.lighting.selected_light
        edge = gold if sel else dark
        p = ImVec2(float(px[k, 0]), float(px[k, 1]))
        if m["spot"][k] and ok[n + k]:
            dl.add_line(p, ImVec2(float(px[n + k, 0]), float(px[n + k, 1])), edge, 2.0)
        dl.add_circle_filled(p, 7.0, m["colors"][k])
        dl.add_circle(p, 8.0, edge, 0, 3.0 if sel else 1.5)
        name = m["names"][k]
        if name:  # on a dark plate: readable on bright surfaces too
            size = imgui.calc_text_size(name)
            dl.add_rect_filled(
                ImVec2(p.x + 8, p.y - 9), ImVec2(p.x + 12 + size.x, p.y - 5 + size.y), plate, 3.0
            )
            dl.add_text(ImVec2(p.x + 10, p.y - 7), edge if sel else white, name)


def sun_compass(state: AppState, dl, radius: float = 26.0) -> None:
    """A compass in the view's top right corner: the arrow points where the sun stands, seen from
    above with the camera's heading up; its length is the cosine of the elevation (a short arrow:
    the sun is high)."""
    d = shown_sun(state)
    cam = state.view.camera
    if d is None or cam is None:
        return
    x, y, w, h = state.view.rect
    c = ImVec2(x + w - radius - 14, y + radius + 34)
    fwd = np.asarray(cam.forward, dtype=np.float64)
    heading = np.array([fwd[0], 0.0, fwd[2]])
    if np.linalg.norm(heading) < 1e-9:
        heading = np.array([0.0, 0.0, -1.0])
    heading /= np.linalg.norm(heading)
    right = np.array([-heading[2], 0.0, heading[0]])
    sx, sy = float(np.dot(d, right)), float(np.dot(d, heading))  # on screen: right, up
    ring = imgui.get_color_u32(ImVec4(1, 1, 1, 0.6))
    sun = imgui.get_color_u32(ImVec4(1.0, 0.85, 0.2, 1.0))
    dl.add_circle_filled(c, radius, imgui.get_color_u32(ImVec4(0, 0, 0, 0.45)))
    dl.add_circle(c, radius, ring, 0, 1.5)
    tip = ImVec2(c.x + radius * sx, c.y - radius * sy)
    dl.add_line(c, tip, sun, 2.5)
    dl.add_circle_filled(tip, 4.0, sun)
    az, el = angles(d, model_north(state))  # from true north
    dl.add_text(ImVec2(c.x - radius, c.y + radius + 4), ring, f"sun {az:.0f}/{el:.0f} deg")
