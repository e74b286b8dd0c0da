"""The viewer's controls: keyboard, mouse and gamepad into camera moves, divider and light drags.

Every frame the app calls :func:`navigate` (the camera: a path being played, else the
:class:`~viewer.navigation.Navigator` fed by :func:`read_input`) and :func:`shortcuts`. The mouse
in the 3D view drags the split divider, a light marker (:func:`drag_light`) or looks around.
"""

from __future__ import annotations

import time

import imgui_bundle  # noqa: F401  # before glfw: points pyGLFW at imgui-bundle's own libglfw
import numpy as np
from imgui_bundle import hello_imgui, imgui

import glfw  # isort: skip

from viewer import panels
from viewer.navigation import InputState
from viewer.picking import drag_on_plane, pick_light
from viewer.state import AppState

#: keyboard keys the navigator understands, and the imgui keys that press them
NAV_KEYS = {
    "w": ("w",),
    "a": ("a",),
    "s": ("s",),
    "d": ("d",),
    "q": ("q",),
    "e": ("e",),
    "up": ("up_arrow",),
    "down": ("down_arrow",),
    "left": ("left_arrow",),
    "right": ("right_arrow",),
    "shift": ("left_shift", "right_shift"),
}
#: GLFW gamepad button index -> navigator button name
PAD_BUTTONS = {
    glfw.GAMEPAD_BUTTON_A: "a",
    glfw.GAMEPAD_BUTTON_B: "b",
    glfw.GAMEPAD_BUTTON_X: "x",
    glfw.GAMEPAD_BUTTON_Y: "y",
    glfw.GAMEPAD_BUTTON_LEFT_BUMPER: "lb",
    glfw.GAMEPAD_BUTTON_RIGHT_BUMPER: "rb",
    glfw.GAMEPAD_BUTTON_BACK: "back",
    glfw.GAMEPAD_BUTTON_START: "start",
}
DIVIDER_GRAB_PX = 16.0  # half the width of the divider's grab zone


def read_gamepad() -> tuple[tuple[float, ...], frozenset[str]]:
    """Axes (triggers mapped to 0..1) and held buttons of the first connected gamepad, or rest."""
    for jid in range(glfw.JOYSTICK_1, glfw.JOYSTICK_LAST + 1):
        try:
            if not glfw.joystick_is_gamepad(jid):
                continue
            st = glfw.get_gamepad_state(jid)
        except Exception:  # no joystick support in this GLFW build / platform
            return (0.0,) * 6, frozenset()
        if st is None:
            continue
        ax = [float(a) for a in st.axes]
        ax[4] = (ax[4] + 1.0) * 0.5  # GLFW triggers rest at -1
        ax[5] = (ax[5] + 1.0) * 0.5
        held = frozenset(name for i, name in PAD_BUTTONS.items() if i < len(st.buttons) and st.buttons[i])
        return tuple(ax), held
    return (0.0,) * 6, frozenset()


def drag_light(s: AppState, mx: float, my: float, pressed: bool, down: bool, over: bool) -> bool:
    """Select and drag a light marker in the view with the mouse at (``mx``, ``my``) window pixels
    (``pressed`` this frame, held ``down``, ``over`` the view); True when the mouse is busy with a
    light."""
    ed, cam = s.lighting.editor, s.view.camera
    if ed is None or cam is None or not s.lighting.show_lights or s.lighting.day_cycle:
        s.lighting.dragging_light = False
        return False
    if pressed and over:
        k = pick_light(cam, ed.lights, s.view.rect, (mx, my))
        if k >= 0:
            s.lighting.selected_light, s.lighting.dragging_light = k, True
            return True
    if s.lighting.dragging_light:
        if not down:
            s.lighting.dragging_light = False
            return True
        k = s.lighting.selected_light
        if 0 <= k < len(ed.lights):
            lt = ed.lights[k]
            p = drag_on_plane(cam, s.view.rect, (mx, my), float(lt.position[1]), ed.scene.bounds)
            if p is not None and not np.allclose(p, lt.position):
                ed.move(k, p)
        return True
    return False


def read_input(s: AppState, idle: bool) -> InputState:
    """This frame's keys, mouse and gamepad for the navigator. The mouse also drags the split
    divider and the light markers (changing ``s.view`` and ``s.lighting``); ``idle``: the app idles,
    so held input asks hello_imgui for the next frame."""
    io = imgui.get_io()
    keys: set[str] = set()
    if not io.want_capture_keyboard and not io.want_text_input:
        for name, ikeys in NAV_KEYS.items():
            if any(imgui.is_key_down(getattr(imgui.Key, k)) for k in ikeys):
                keys.add(name)
    x, y, w, h = s.view.rect
    mx, my = io.mouse_pos.x, io.mouse_pos.y
    over = (not io.want_capture_mouse) and w > 0 and x <= mx < x + w and y <= my < y + h
    near = s.view.mode == "split" and abs(mx - (x + s.view.split * w)) <= DIVIDER_GRAB_PX
    if over and (near or s.view.dragging_split):
        imgui.set_mouse_cursor(imgui.MouseCursor_.resize_ew)
    left_pressed = imgui.is_mouse_clicked(imgui.MouseButton_.left)
    light_busy = not s.view.dragging_split and drag_light(
        s, mx, my, left_pressed and not near, imgui.is_mouse_down(imgui.MouseButton_.left), over
    )
    if light_busy:
        left_pressed = False
        s.view.looking = False
    if over and left_pressed:
        s.view.dragging_split, s.view.looking = (True, False) if near else (False, True)
    if over and imgui.is_mouse_clicked(imgui.MouseButton_.right):
        s.view.looking = True
    if not (imgui.is_mouse_down(imgui.MouseButton_.left) or imgui.is_mouse_down(imgui.MouseButton_.right)):
        s.view.dragging_split = s.view.looking = False
    dx = dy = 0.0
    if s.view.dragging_split and w > 0:
        s.view.split = float(min(max((mx - x) / w, 0.0), 1.0))
    elif s.view.looking:
        dx, dy = io.mouse_delta.x, io.mouse_delta.y
    wheel = io.mouse_wheel if over else 0.0
    axes, buttons = read_gamepad()
    if idle and (any(abs(a) > 0.15 for a in axes) or buttons or keys):
        hello_imgui.request_refresh()
    return InputState(
        keys=keys, mouse_dx=dx, mouse_dy=dy, wheel=wheel, gamepad_axes=axes, gamepad_buttons=buttons
    )


def navigate(s: AppState, idle: bool) -> None:
    """Move the camera one frame: along the camera path being played, else by the input
    (:func:`read_input`); record the pose when a path is being recorded."""
    dt = float(imgui.get_io().delta_time)
    inp = read_input(s, idle)
    if s.view.nav is None:
        return
    if s.paths.player is not None:
        if s.paths.playback_frames:
            cam = s.paths.player.next()
        else:
            t = time.perf_counter() - s.paths.play_started
            cam = s.paths.player.pose_at(t) if t <= s.paths.player.duration else None
            s.paths.player.index += 1
        if cam is None:
            s.stop_playback()
        else:
            s.view.camera = cam
            s.paths.posed = True  # this frame shows a pose of the path: counted after its swap
            return
    s.view.camera = s.view.nav.update(dt, inp, walls=s.view.walls)
    if s.paths.recorder is not None:
        s.paths.recorder.add(s.view.camera, time.perf_counter() - s.paths.record_started)


def shortcuts(s: AppState) -> None:
    """F12 screenshot; and, when no text field has the keyboard, 1-4 modes, R reset, X auto exposure,
    Ctrl+O open."""
    io = imgui.get_io()
    if imgui.is_key_pressed(imgui.Key.f12, False):
        s.requests.screenshot = ""
    if io.want_text_input or io.want_capture_keyboard:
        return
    for k, m in zip(("_1", "_2", "_3", "_4"), ("mesh", "iat", "split", "diff"), strict=True):
        if imgui.is_key_pressed(getattr(imgui.Key, k), False):
            s.view.mode = m
    if imgui.is_key_pressed(imgui.Key.r, False) and s.view.nav is not None:
        s.view.nav.reset()
    if imgui.is_key_pressed(imgui.Key.x, False):  # E is taken: it rises
        s.requests.auto_exposure = True
    if io.key_ctrl and imgui.is_key_pressed(imgui.Key.o, False):
        if panels.has_native_dialogs():
            panels.open_dialog(s)
