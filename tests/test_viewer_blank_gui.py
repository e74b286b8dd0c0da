"""A 3D view with nothing to show says why, in the view itself (issue 42): a model with no light
source, a solution no light reaches, the camera outside the model, the model outside the camera's
view. The GUI test opens a model with no light (and daylight off: by default such a model gets the
sun and a clear sky) in the real viewer (imgui test engine, needs a
display; it runs alone in a child process, see tests/conftest.py) and finds the notice's pixels in
the middle of the 3D view; the others check :func:`viewer.overlay.view_notices` on real scenes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pygltflib import GLTF2

from tests.conftest import run_gui, wait_until

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "sample_models" / "cornell_box.glb"


def unlit_cornell(path: Path) -> Path:
    """The Cornell box with its lamp's emission taken out: no light source at all."""
    g = GLTF2().load(str(CORNELL))
    for m in g.materials:
        m.emissiveFactor = [0.0, 0.0, 0.0]
        (m.extensions or {}).pop("KHR_materials_emissive_strength", None)
    g.extensionsUsed = [e for e in g.extensionsUsed or [] if e != "KHR_materials_emissive_strength"]
    g.save(str(path))
    return path


def notice_pixels(img: np.ndarray, rect) -> np.ndarray:
    """(n, 2) rows, cols of window image ``img`` (h, w, 3) uint8 in the notice's colour, inside the
    3D view's rectangle ``rect`` (x, y, w, h)."""
    from viewer.overlay import NOTICE

    x, y, w, h = rect
    want = np.array([NOTICE.x, NOTICE.y, NOTICE.z]) * 255
    close = (np.abs(img.astype(np.float64) - want) <= 12).all(axis=-1)
    inside = np.zeros_like(close)
    inside[y : y + h, x : x + w] = True
    return np.argwhere(close & inside)


@pytest.mark.gui
def test_a_model_with_no_light_opens_with_the_reason_in_the_3d_view(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from imgui_bundle import imgui
    from imgui_bundle.immapp import testing
    from PIL import Image

    from iat.lighting.daylight_default import DaylightRequest
    from iat.radiosity import SolveOptions
    from viewer.app import ViewerApp
    from viewer.overlay import NO_LIGHT

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("IAT_SCREENSHOT_DIR", str(tmp_path / "shots"))
    model = unlit_cornell(tmp_path / "dark_box.glb")
    app = ViewerApp(
        model,
        size=(1280, 800),
        solve_options=SolveOptions(max_depth=3),
        daylight=DaylightRequest(enabled=False),  # iat view --no-daylight: else the sun and sky light it
        idle=False,
    )
    s = app.state
    got: dict = {}

    def drive(ctx) -> None:
        wait_until(
            ctx,
            lambda: s.model.baked is not None and not s.jobs.rebaking and not s.jobs.opening,
            300,
            "the model",
        )
        ctx.yield_(5)
        got["notices"] = s.view.notices
        got["rect"] = s.view.rect
        got["scale"] = s.view.framebuffer_scale
        testing.capture(ctx, str(tmp_path / "window.png"))
        s.messages.last_screenshot = ""
        ctx.key_press(imgui.Key.f12)  # the 3D view alone, as the app writes it
        wait_until(ctx, lambda: s.messages.last_screenshot, 10, "the screenshot")
        got["view"] = np.asarray(Image.open(s.messages.last_screenshot).convert("RGB"))

    run_gui(app, drive)
    assert got["notices"] == (NO_LIGHT,)
    assert got["scale"] == (1.0, 1.0)
    assert got["view"].max() <= 2  # the model itself is black: the notice is all there is to see
    window = np.asarray(Image.open(tmp_path / "window.png").convert("RGB"))
    px = notice_pixels(window, got["rect"])
    x, y, w, h = got["rect"]
    print(f"notice: {len(px)} pixels, rows {px[:, 0].min()}-{px[:, 0].max()}, view {got['rect']}")
    assert len(px) > 100  # the text's strokes (a line of ~80 characters)
    assert abs(np.median(px[:, 1]) - (x + 0.5 * w)) < 0.1 * w  # centred in the view
    assert y + 0.45 * h < px[:, 0].min() and px[:, 0].max() < y + 0.6 * h  # on the view's middle line


def _state(model):
    from iat.io.load import load_scene
    from viewer.state import AppState

    s = AppState()
    s.model.scene = load_scene(model)
    s.view.camera = s.model.scene.default_camera()
    s.view.rect = (0, 0, 800, 600)
    return s


def test_view_notices_name_the_reason_and_are_empty_for_a_lit_model_in_view(tmp_path):
    from iat.camera import Camera
    from viewer.overlay import NO_LIGHT, NOT_IN_VIEW, OUTSIDE, nothing_in_view, view_notices

    lit = _state(CORNELL)
    assert view_notices(lit) == []
    dark = _state(unlit_cornell(tmp_path / "dark.glb"))
    assert view_notices(dark) == [NO_LIGHT]
    # turned round at home (the Cornell box's camera stands in front of its open side): only
    # empty space ahead, everything culled
    cam = lit.view.camera
    eye = np.asarray(cam.eye, dtype=np.float64)
    lit.view.camera = Camera(eye=eye, target=2 * eye - np.asarray(cam.target), up=cam.up, yfov=cam.yfov)
    assert nothing_in_view(lit) and view_notices(lit) == [NOT_IN_VIEW]
    # far outside the box: the way back comes first
    lo, hi = (np.asarray(b, dtype=np.float64) for b in lit.model.scene.bounds)
    lit.view.camera = Camera(eye=hi + 3 * (hi - lo), target=0.5 * (lo + hi), up=cam.up, yfov=cam.yfov)
    assert not nothing_in_view(lit) and view_notices(lit) == [OUTSIDE]


def test_a_black_solution_says_no_light_reaches_the_surfaces():
    """A real solve of the Cornell box (quick, cached), then the same solution with every vertex
    black: lit model, no light on its surfaces."""
    import dataclasses

    from iat.radiosity.cache import cached_solve
    from tests.test_export_clients import OUT, QUICK
    from viewer.overlay import NO_LIGHT_REACHES, view_notices

    s = _state(CORNELL)
    _, sol, _ = cached_solve(CORNELL, QUICK, OUT)
    s.model.solution = sol
    assert view_notices(s) == []
    s.model.solution = dataclasses.replace(sol, vert_radiance=np.zeros_like(sol.vert_radiance))
    assert view_notices(s) == [NO_LIGHT_REACHES]
