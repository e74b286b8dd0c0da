"""What the viewer draws over the 3D view with imgui (its background draw list, no GL): the mode's
label, the split divider, the light markers and their names (on a dark plate, readable on bright
surfaces), the HUD lines (:func:`viewer.panels.hud_lines`), REC / PLAY, and a notice when the camera
has left the model (:func:`outside_model`) with the way back (R).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from imgui_bundle import ImVec2, ImVec4, imgui

from viewer.daylight import angles, sun_at
from viewer.panels import RED, hud_lines
from viewer.state import MODE_LABELS, AppState


def view_overlay(state: AppState) -> None:
    """Labels and the split divider over the 3D view (imgui background draw list, no GL)."""
    x, y, w, h = state.view.rect
    if w <= 0 or h <= 0:
        return
    dl = imgui.get_background_draw_list()
    white = imgui.get_color_u32(ImVec4(1, 1, 1, 0.9))
    shadow = imgui.get_color_u32(ImVec4(0, 0, 0, 0.7))

    def label(px: float, text: str) -> None:
        dl.add_text(ImVec2(px + 9, y + 9), shadow, text)
        dl.add_text(ImVec2(px + 8, y + 8), white, text)

    if not state.model.loaded:
        job = state.jobs.open_job
        label(x, f"opening {Path(job.path).name}: {job.message}" if job and not job.done else "nothing open")
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
    if outside_model(state):
        text = "outside the model: press R (or View: Reset view) to go back"
        size = imgui.calc_text_size(text)
        p = ImVec2(x + 0.5 * (w - size.x), y + 0.5 * h)
        dl.add_rect_filled(ImVec2(p.x - 8, p.y - 6), ImVec2(p.x + size.x + 8, p.y + size.y + 6), shadow, 4.0)
        dl.add_text(p, imgui.get_color_u32(ImVec4(1.0, 0.6, 0.3, 1.0)), text)
    hud = hud_lines(state)
    for k, line in enumerate(hud):
        yy = y + h - 10 - 16 * (len(hud) - k)
        dl.add_text(ImVec2(x + 9, yy + 1), shadow, line)
        dl.add_text(ImVec2(x + 8, yy), white, line)
    if state.paths.recorder is not None:
        dl.add_text(ImVec2(x + w - 60, y + 8), imgui.get_color_u32(RED), "REC")
    if state.paths.player is not None:
        dl.add_text(ImVec2(x + w - 60, y + 8), white, "PLAY")


def outside_model(state: AppState, margin: float = 0.02) -> bool:
    """The camera is outside the box of the model and its home camera (grown by ``margin`` of its
    diagonal): walked through a wall into the void (a model seen from outside, such as the Cornell
    box, counts its home camera in)."""
    cam, scene = state.view.camera, state.model.scene
    if cam is None or scene is None:
        return False
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.bounds)
    home = np.asarray(scene.default_camera().eye, dtype=np.float64)
    lo, hi = np.minimum(lo, home), np.maximum(hi, home)
    pad = margin * float(np.linalg.norm(hi - lo))
    eye = np.asarray(cam.eye, dtype=np.float64)
    return bool(np.any(eye < lo - pad) or np.any(eye > hi + pad))


def light_markers(state: AppState, dl) -> None:
    """A circle per light (filled for the selected one), its name, and a spot light's direction."""
    from viewer.picking import project_points

    ed, cam = state.lighting.editor, state.view.camera
    if not state.lighting.show_lights or ed is None or cam is None or not ed.lights:
        return
    lights = ed.lights
    px, ok = project_points(cam, [lt.position for lt in lights], state.view.rect)
    plate = imgui.get_color_u32(ImVec4(0.0, 0.0, 0.0, 0.65))
    white = imgui.get_color_u32(ImVec4(1.0, 1.0, 1.0, 1.0))
    lo, hi = ed.scene.bounds
    reach = 0.06 * float(np.linalg.norm(hi - lo))
    tips, tok = project_points(cam, [lt.position + reach * lt.direction for lt in lights], state.view.rect)
    for k, lt in enumerate(lights):
        if not ok[k]:
            continue
        c = np.clip(np.asarray(lt.color, dtype=np.float64) / max(float(np.max(lt.color)), 1e-9), 0.0, 1.0)
        col = imgui.get_color_u32(ImVec4(float(c[0]), float(c[1]), float(c[2]), 1.0))
        sel = k == state.lighting.selected_light
        edge = imgui.get_color_u32(ImVec4(1.0, 0.85, 0.2, 1.0) if sel else ImVec4(0, 0, 0, 0.9))
        p = ImVec2(float(px[k, 0]), float(px[k, 1]))
        if lt.kind == "spot" and tok[k]:
            dl.add_line(p, ImVec2(float(tips[k, 0]), float(tips[k, 1])), edge, 2.0)
        dl.add_circle_filled(p, 7.0, col)
        dl.add_circle(p, 8.0, edge, 0, 3.0 if k == state.lighting.selected_light else 1.5)
        if lt.name:  # on a dark plate: readable on bright surfaces too
            size = imgui.calc_text_size(lt.name)
            dl.add_rect_filled(
                ImVec2(p.x + 8, p.y - 9), ImVec2(p.x + 12 + size.x, p.y - 5 + size.y), plate, 3.0
            )
            dl.add_text(ImVec2(p.x + 10, p.y - 7), edge if sel else white, lt.name)


def sun_compass(state: AppState, dl, radius: float = 26.0) -> None:
    """A compass in the view's top right corner: the arrow points where the sun stands, seen from
    above with the camera's heading up; its length is the cosine of the elevation (a short arrow:
    the sun is high)."""
    d = sun_at(state)
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
    az, el = angles(d)
    dl.add_text(ImVec2(c.x - radius, c.y + radius + 4), ring, f"sun {az:.0f}/{el:.0f} deg")
