"""Viewer bugs of issue 20, each driven through the real UI by imgui-bundle's test engine (needs a
display; without one these tests skip; each runs alone in a child process, see tests/conftest.py).

1. stopping a camera-path recording raised an internal error (the panel read the recorder it had
   just cleared);
2. after opening another model, Export GLB still wrote the previous model's file;
3. a new light came in at ``diagonal**2 / 4`` W/sr, not of the order of the scene's lights;
4. the exposure stayed 1.0 at open (bright models opened white);
5. "Frames N" played N + 1 frames (the frame that started the playback was counted).

Each opens the Cornell box (or a variant of it) solved at max_depth 3 into a temporary cache.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "sample_models" / "cornell_box.glb"


def make_app(model, tmp_path, monkeypatch):
    from iat.radiosity import SolveOptions
    from viewer.app import ViewerApp

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("IAT_SCREENSHOT_DIR", str(tmp_path / "shots"))
    return ViewerApp(model, size=(1280, 800), solve_options=SolveOptions(max_depth=3), idle=False)


def settle(ctx, app, seconds: float = 300.0, frames: int = 3) -> None:
    """Wait for the model and every background job (open, bake, re-solve), then a few frames."""
    s = app.state

    def idle() -> bool:
        busy = s.jobs.rebaking or s.jobs.opening or s.lighting.relighting or s.lighting.solving_day_cycle
        return s.model.baked is not None and not busy and app.pending_relit is None

    wait_until(ctx, idle, seconds, "the model and its background work")
    ctx.yield_(frames)


def screenshot(ctx, app) -> np.ndarray:
    """F12: the 3D view as the app writes it, (h, w, 3) uint8."""
    from imgui_bundle import imgui
    from PIL import Image

    s = app.state
    s.messages.last_screenshot = ""
    ctx.key_press(imgui.Key.f12)
    wait_until(ctx, lambda: s.messages.last_screenshot, 10, "the screenshot")
    return np.asarray(Image.open(s.messages.last_screenshot).convert("RGB"))


def no_internal_error(app) -> list[str]:
    return [e for e in app.state.messages.errors if "internal error" in e]


# -- 1. recording ------------------------------------------------------------------------------------
@pytest.mark.gui
def test_stopping_a_recording_keeps_the_path_and_shows_no_error(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from imgui_bundle import ImVec2, imgui

    app = make_app(CORNELL, tmp_path, monkeypatch)
    s = app.state
    got: dict = {}

    def drive(ctx) -> None:
        settle(ctx, app)
        ctx.window_focus("//View")
        ctx.item_click("//**/Record")
        ctx.yield_(2)
        got["recording"] = s.paths.recorder is not None
        x, y, w, h = s.view.rect
        ctx.mouse_move_to_pos(ImVec2(x + 0.5 * w, y + 0.5 * h))
        ctx.mouse_down(0)  # a click in the view takes the keyboard: W walks while recording
        ctx.mouse_up(0)
        ctx.key_down(imgui.Key.w)
        ctx.yield_(6)
        ctx.key_up(imgui.Key.w)
        ctx.window_focus("//View")
        ctx.item_click("//**/Stop recording")
        ctx.yield_(3)
        got["errors"] = no_internal_error(app) + ([s.messages.error] if s.messages.error else [])
        got["recorder"] = s.paths.recorder
        got["named"] = {k: len(v) for k, v in s.paths.named.items()}
        got["selected"] = s.paths.selected
        got["play_shown"] = ctx.item_exists("//**/Play")

    run_gui(app, drive)  # (how long it takes is the bench's business, not a test's)
    assert got["recording"]
    assert got["errors"] == []
    assert got["recorder"] is None and got["play_shown"]
    assert got["selected"] in got["named"] and got["named"][got["selected"]] >= 6


# -- 2. export after opening another model -----------------------------------------------------------
@pytest.mark.gui
def test_export_after_opening_another_model_writes_that_model(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    a, b = tmp_path / "room_a.glb", tmp_path / "room_b.glb"
    shutil.copyfile(CORNELL, a)
    shutil.copyfile(CORNELL, b)
    app = make_app(a, tmp_path, monkeypatch)
    s = app.state
    got: dict = {}

    def drive(ctx) -> None:
        settle(ctx, app)
        ctx.window_focus("//Model")
        ctx.yield_(2)
        got["field_a"] = s.requests.file_fields["export"]
        ctx.item_input_value("//**/File to open", str(b))
        ctx.item_click("//**/Open")
        wait_until(ctx, lambda: Path(s.model.path) == b, 30, "model B")
        settle(ctx, app)
        got["field_b"] = s.requests.file_fields["export"]
        got["solution_field_b"] = s.requests.file_fields["solution"]
        ctx.item_click("//**/Export GLB")
        wait_until(ctx, lambda: "exported" in s.messages.status or s.messages.error, 30, "the export")
        got["status"] = s.messages.status

    run_gui(app, drive)  # (how long it takes is the bench's business, not a test's)
    assert got["field_a"] == str(tmp_path / "room_a-iat.glb")
    assert got["field_b"] == str(tmp_path / "room_b-iat.glb")
    assert got["solution_field_b"] == str(tmp_path / "room_b.npz")
    assert "room_b-iat.glb" in got["status"]
    assert (tmp_path / "room_b-iat.glb").read_bytes()[:4] == b"glTF"
    assert not (tmp_path / "room_a-iat.glb").exists()


# -- 3. a new light's intensity ----------------------------------------------------------------------
def lit_cornell(path: Path, intensities) -> Path:
    """The Cornell box with point lights of ``intensities`` W/sr."""
    from iat.io.load import load_scene
    from iat.lighting import edits, save

    scene = load_scene(CORNELL)
    for k, w in enumerate(intensities):
        scene = edits.add_light(scene, "point", [0.1 + 0.2 * k, 0.4, 0.3], intensity=w, name=f"lamp {k}")
    return save.save_gltf(scene, CORNELL, path)


@pytest.mark.gui
def test_a_new_light_is_as_bright_as_the_scenes_lights(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    model = lit_cornell(tmp_path / "cornell_lamps.glb", [0.05, 0.1, 0.3])
    app = make_app(model, tmp_path, monkeypatch)
    s = app.state
    got: dict = {}

    def drive(ctx) -> None:
        settle(ctx, app)
        ed = s.lighting.editor
        got["before"] = [lt.intensity for lt in ed.lights]
        ctx.item_click("//Lighting/Add point light")
        ctx.yield_(2)
        ctx.item_click("//Lighting/Add spot light")
        ctx.yield_(2)
        got["after"] = [(lt.kind, lt.intensity) for lt in ed.lights]
        got["selected"] = s.lighting.selected_light

    run_gui(app, drive)  # (how long it takes is the bench's business, not a test's)
    assert got["before"] == pytest.approx([0.05, 0.1, 0.3])
    assert len(got["after"]) == 5 and got["selected"] == 4
    (k1, w1), (k2, w2) = got["after"][3:]
    assert (k1, k2) == ("point", "spot")
    assert w1 == pytest.approx(0.1) and w2 == pytest.approx(0.1)  # the median of 0.05, 0.1, 0.3


def test_a_new_light_without_lamps_takes_the_emitters_power():
    """No point or spot light: the emitters' power over a sphere; neither: a dim lamp by the size."""
    import math

    from iat.io.load import load_scene
    from iat.lighting import edits
    from viewer.lights import new_light_intensity

    scene = load_scene(CORNELL)
    em = np.array([float(np.max(m.emission)) for m in scene.materials])[scene.patch_material]
    power = float(np.sum(math.pi * em * scene.patch_area))
    assert power > 0 and new_light_intensity(scene) == pytest.approx(power / (4 * math.pi))
    dark = scene
    for m in edits.emissive_materials(scene):
        dark = edits.set_emission(dark, m, np.zeros(3))
    lo, hi = scene.bounds
    assert new_light_intensity(dark) == pytest.approx(float(np.linalg.norm(hi - lo)) ** 2 / 100)


# -- 4. exposure at open -------------------------------------------------------------------------------
def bright_cornell(path: Path, factor: float = 25.0) -> Path:
    """The Cornell box with its light ``factor`` times brighter (white at exposure 1)."""
    from iat.io.load import load_scene
    from iat.lighting import edits, save

    scene = load_scene(CORNELL)
    for m in edits.emissive_materials(scene):
        scene = edits.set_emission(scene, m, factor * scene.materials[m].emission)
    return save.save_gltf(scene, CORNELL, path)


@pytest.mark.gui
def test_a_bright_model_opens_auto_exposed(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from iat.color import LUMINANCE_WEIGHTS, srgb_decode

    app = make_app(bright_cornell(tmp_path / "bright.glb"), tmp_path, monkeypatch)
    s = app.state
    got: dict = {}

    def p99(img: np.ndarray) -> float:
        """99th percentile of the linear luminance the screenshot shows (exposure x radiance)."""
        return float(np.percentile(srgb_decode(img / 255.0) @ LUMINANCE_WEIGHTS, 99))

    def drive(ctx) -> None:
        settle(ctx, app)
        got["exposure"] = s.tuning.exposure
        got["p99"] = p99(screenshot(ctx, app))
        got["white"] = float(np.percentile(screenshot(ctx, app), 99))
        s.tuning.exposure = 1.0  # then the View panel's button sets it again
        ctx.yield_(2)
        got["p99_at_1"] = p99(screenshot(ctx, app))
        ctx.window_focus("//View")
        ctx.item_click("//**/Auto exposure")
        ctx.yield_(3)
        got["again"] = s.tuning.exposure
        got["p99_again"] = p99(screenshot(ctx, app))

    run_gui(app, drive)  # (how long it takes is the bench's business, not a test's)
    assert got["exposure"] < 0.5  # a bright model is exposed down
    assert got["p99"] == pytest.approx(0.8, rel=0.05)  # auto_exposure: the 99th percentile at 0.8
    assert got["white"] < 255
    assert got["p99_at_1"] == pytest.approx(1.0)  # white at exposure 1
    assert got["again"] == pytest.approx(got["exposure"], rel=1e-6)
    assert got["p99_again"] == pytest.approx(0.8, rel=0.05)


# -- 5. playback frame count ---------------------------------------------------------------------------
@pytest.mark.gui
@pytest.mark.parametrize("frames", [7])
def test_playing_n_frames_plays_n_frames(frames, tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from iat.camera import Camera
    from viewer.navigation import CameraPath

    app = make_app(CORNELL, tmp_path, monkeypatch)
    s = app.state
    got: dict = {"shown": []}

    def count(app_) -> None:  # each frame: the pose the previous frame drew, while playing
        if app_.state.paths.player is not None and app_.state.paths.player.index:
            got["shown"].append(app_.state.view.camera.eye.copy())

    def drive(ctx) -> None:
        settle(ctx, app)
        c = s.view.camera
        a = Camera(c.eye, c.target, c.up, c.yfov, c.znear, c.zfar)
        b = Camera(c.eye + 0.1 * c.forward, c.target + 0.1 * c.forward, c.up, c.yfov, c.znear, c.zfar)
        s.paths.named["walk"] = CameraPath("walk", [a, b], [0.0, 1.0])
        s.paths.selected = "walk"
        ctx.window_focus("//View")
        ctx.item_input_value("//**/Frames", frames)
        ctx.yield_(1)
        app.frame_hook = count
        ctx.item_click("//**/Play")
        wait_until(ctx, lambda: s.paths.player is None, 10, "the end of the playback")
        app.frame_hook = None
        ctx.yield_(1)
        got["timed"] = len(s.paths.play_frame_ms)
        got["status"] = s.messages.status
        got["last"] = s.view.camera.eye.copy()
        got["ends"] = (a.eye, b.eye)

    run_gui(app, drive)  # (how long it takes is the bench's business, not a test's)
    assert got["timed"] == frames, got["status"]
    assert f": {frames} frames" in got["status"]
    shown = np.array(got["shown"])
    a, b = got["ends"]
    np.testing.assert_allclose(shown[0], a, atol=1e-9)
    np.testing.assert_allclose(shown[-1], b, atol=1e-9)
    assert len(shown) == frames
