"""The viewer's Model faults panel (issue 36) through the real UI (imgui test engine under Xvfb; runs
alone in a child process, see tests/conftest.py): turning the tint on colours the patches the
loader cut along the roof that crosses the walls, unticking their kind takes the colour off."""

from __future__ import annotations

import numpy as np
import pytest

from iat.color import srgb_encode
from iat.geometry.faults import COLORS
from tests.conftest import run_gui, wait_until
from tests.test_faults import INSIDE
from tests.test_real_daylight import write_case

#: the crossing colour as a display pixel, with the tint at full strength
RED = np.round(srgb_encode(np.asarray(COLORS["crossing"])) * 255).astype(int)


def _view(ctx, s, path) -> np.ndarray:
    """(h, w) bool the 3D view's pixels in the crossing colour (the app's screenshot, drawn in the frame)."""
    from PIL import Image

    s.messages.last_screenshot = ""
    s.requests.screenshot = str(path)
    wait_until(ctx, lambda: s.messages.last_screenshot, 10, "the screenshot")
    img = np.asarray(Image.open(path).convert("RGB")).astype(int)
    return np.abs(img - RED).max(axis=-1) <= 1


@pytest.mark.gui
def test_model_faults_panel_tints_the_cut_walls(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from iat.radiosity import SolveOptions
    from viewer import faults_view
    from viewer.app import ViewerApp

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    path = write_case("wall_through_slab", tmp_path)
    app = ViewerApp(path, size=(1280, 800), solve_options=SolveOptions(max_depth=2), idle=False)
    s = app.state
    got: dict = {}

    def drive(ctx) -> None:
        wait_until(ctx, lambda: s.model.baked is not None and not s.jobs.opening, 300, "the model")
        s.view.nav.set_camera(INSIDE)
        ctx.yield_(3)
        got["plain"] = _view(ctx, s, tmp_path / "plain.png")
        ctx.window_focus("//Model faults")
        ctx.item_click("//Model faults/Tint faults in the view")
        ctx.item_input_value("//Model faults/Tint", 1.0)
        v = faults_view.of(s)
        wait_until(
            ctx, lambda: v.uploaded is s.model.scene and v.applied[0] and v.alpha == 1.0, 30, "the tint"
        )
        ctx.yield_(3)
        got["tinted"] = _view(ctx, s, tmp_path / "tinted.png")
        got["bits"] = v.bits.copy()
        got["cut"] = s.model.scene.pierce.faces_cut
        ctx.item_click("//Model faults/cut by a crossing element")
        wait_until(ctx, lambda: v.applied[1] & 4 == 0, 30, "the kind unticked")
        ctx.yield_(3)
        got["unticked"] = _view(ctx, s, tmp_path / "unticked.png")

    run_gui(app, drive)
    # the roof and the walls' cut faces (27 patches once the default daylight's sun is cut along: a
    # rectangle between two cuts is one quad)
    assert got["cut"] > 0 and int((got["bits"] == 4).sum()) == 27
    assert not got["plain"].any()
    assert got["tinted"].mean() > 0.3  # the roof and the walls, seen from inside
    assert not got["unticked"].any()
