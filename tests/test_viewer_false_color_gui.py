"""The viewer's false-colour view mode with its legend (issue 39), through the real UI (imgui test
engine under Xvfb; runs alone in a child process, see tests/conftest.py)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "sample_models" / "cornell_box.glb"
#: set to a path to keep the view's picture (the docs' screenshot)
SHOT_ENV = "IAT_FALSE_COLOR_SHOT"


def _shot(ctx, s, path: Path) -> np.ndarray:
    """The 3D view as the app's screenshot writes it (drawn in the frame, GL context current)."""
    from PIL import Image

    s.messages.last_screenshot = ""
    s.requests.screenshot = str(path)
    wait_until(ctx, lambda: s.messages.last_screenshot, 10, "the screenshot")
    return np.asarray(Image.open(path).convert("RGB"))


def _has(img: np.ndarray, rgb, tol: int = 3) -> bool:
    d = np.abs(img.reshape(-1, 3).astype(int) - np.round(np.asarray(rgb) * 255).astype(int)).max(axis=1)
    return bool((d <= tol).any())


@pytest.mark.gui
def test_false_colour_mode_shows_lux_and_luminance_with_a_legend(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from imgui_bundle import ImVec2

    from iat.measure import photometry as ph
    from iat.radiosity import SolveOptions
    from iat.render.false_color import PALETTE
    from viewer.app import ViewerApp

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    app = ViewerApp(CORNELL, size=(1280, 800), solve_options=SolveOptions(max_depth=3), idle=False)
    s = app.state
    got: dict = {}

    def drive(ctx) -> None:
        wait_until(ctx, lambda: s.model.baked is not None and not s.jobs.opening, 300, "the model")
        ctx.yield_(3)
        got["mesh"] = _shot(ctx, s, tmp_path / "mesh.png")
        ctx.item_click("//**/False colour")
        wait_until(ctx, lambda: s.view.false_color.shown is not None, 30, "the false-colour view")
        ctx.yield_(3)
        got["lux"] = _shot(ctx, s, tmp_path / "lux.png")
        got["lux_scale"] = s.view.false_color.shown
        lux = ph.vertex_illuminance(s.model.solution, s.model.scene.patch_emission)
        got["lux_max"] = float(np.nanmax(lux))
        if os.environ.get(SHOT_ENV):
            from PIL import Image

            Image.fromarray(got["lux"]).save(os.environ[SHOT_ENV])
        x, y, w, h = s.view.rect  # the probe: the mouse over the middle of the view
        ctx.mouse_move_to_pos(ImVec2(x + w * 0.45, y + h * 0.4))
        wait_until(ctx, lambda: s.view.false_color.probed is not None, 30, "the probe's readout")
        ctx.yield_(3)
        got["probe"] = dict(s.view.false_color.probed)
        got["albedo"] = s.model.solution.patch_albedo[got["probe"]["patch"]]
        got["probe_shot"] = _shot(ctx, s, tmp_path / "probe.png")
        ctx.item_click("//**/Luminance (cd\\/m2)")  # (a slash in a label is escaped)
        wait_until(ctx, lambda: s.view.false_color.shown.quantity == "luminance", 30, "luminance")
        ctx.yield_(3)
        got["lum"] = _shot(ctx, s, tmp_path / "lum.png")
        got["lum_scale"] = s.view.false_color.shown
        ctx.item_click("//**/Log scale")  # off: a linear scale
        wait_until(ctx, lambda: not s.view.false_color.shown.log, 30, "the linear scale")
        ctx.yield_(3)
        got["linear"] = _shot(ctx, s, tmp_path / "linear.png")

    run_gui(app, drive)
    lux, lum = got["lux"], got["lum"]
    assert got["lux_scale"].quantity == "illuminance" and got["lux_scale"].log
    assert got["lux_scale"].lo < got["lux_scale"].hi and got["lux_scale"].hi >= 0.3 * got["lux_max"]
    assert got["lum_scale"].unit == "cd/m2"
    h, w = lux.shape[:2]
    # the legend at the right edge: its bar holds both ends of the colour map
    right = lux[:, -w // 5 :]
    assert _has(right, PALETTE[0]) and _has(right, PALETTE[-1])
    assert _has(lum[:, -w // 5 :], PALETTE[-1])
    # the model in false colour: many colours of the map, and not the mesh view's picture
    left = lux[:, : w // 2].reshape(-1, 3).astype(int)
    assert np.abs(left - got["mesh"][:, : w // 2].reshape(-1, 3)).mean() > 10
    assert len(np.unique(left // 8, axis=0)) > 20
    assert np.abs(got["linear"].astype(int) - lum.astype(int)).mean() > 2  # the scale changed the picture
    # the probe: lux and cd/m² of the surface under the mouse, L = rho E / pi on a diffuse surface
    probe = got["probe"]
    assert 1.0 < probe["lux"] <= got["lux_max"]
    rho = float(np.asarray(got["albedo"]) @ [0.2126, 0.7152, 0.0722])
    assert probe["cd_m2"] == pytest.approx(rho * probe["lux"] / np.pi, rel=0.02)
    assert np.abs(got["probe_shot"].astype(int) - lux.astype(int)).max() > 100  # its label is drawn
