"""``iat view OUT.glb``: the viewer opens a GLB that ``iat bake`` wrote as baked, not as a model to
solve (issue 21). Driven through the real UI by imgui-bundle's test engine (needs a display; without
one the test skips; it runs alone in a child process, see tests/conftest.py).

The view must show what :func:`iat.render.glb_view.render_glb` draws of the file from the same
camera, at the exposure the viewer picked (the CLI's rule), and then go back to solving when a model
is opened after it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "sample_models" / "cornell_box.glb"


def exported_cornell(path: Path) -> Path:
    """The Cornell box solved at max_depth 3, baked and exported as ``iat bake`` writes it."""
    from iat.bake.baker import Baker
    from iat.export.gltf import export_glb
    from iat.io.load import load_scene
    from iat.radiosity import SolveOptions, solve

    scene = load_scene(CORNELL)
    sol = solve(scene, SolveOptions(max_depth=3))
    return export_glb(Baker(sol, scene).bake(), path, scene)


@pytest.mark.gui
def test_an_exported_bake_opens_as_baked(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from imgui_bundle import imgui
    from PIL import Image

    from iat.color import srgb_encode
    from iat.radiosity import SolveOptions
    from iat.render.glb_view import render_glb
    from viewer.app import ViewerApp

    glb = exported_cornell(tmp_path / "cornell-iat.glb")
    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("IAT_SCREENSHOT_DIR", str(tmp_path / "shots"))
    app = ViewerApp(glb, size=(1280, 800), solve_options=SolveOptions(max_depth=3), idle=False)
    s = app.state
    got: dict = {}

    def shot(ctx) -> np.ndarray:
        s.messages.last_screenshot = ""
        ctx.key_press(imgui.Key.f12)
        wait_until(ctx, lambda: s.messages.last_screenshot, 10, "the screenshot")
        return np.asarray(Image.open(s.messages.last_screenshot).convert("RGB"))

    def drive(ctx) -> None:
        wait_until(ctx, lambda: s.model.path == str(glb) and not s.jobs.opening, 120, "the export")
        ctx.yield_(4)
        got["status"] = s.messages.status
        got["errors"] = list(s.messages.errors)
        got["solution"], got["baked"] = s.model.solution, s.model.baked
        got["exposure"], got["camera"] = s.tuning.exposure, s.view.camera
        got["cameras"] = len(s.model.scene.cameras)
        got["image"] = shot(ctx)
        s.tuning.exposure *= 0.5  # the exposure slider acts on the file's image too
        ctx.yield_(3)
        got["half"] = shot(ctx)
        ctx.window_focus("//Model")
        ctx.item_input_value("//**/File to open", str(CORNELL))
        ctx.item_click("//**/Open")
        wait_until(ctx, lambda: s.model.baked is not None and s.model.path == str(CORNELL), 300, "the model")
        ctx.yield_(3)
        got["export_after"] = app.view3d.export

    run_gui(app, drive)
    assert "exported bake" in got["status"], got["status"]
    assert not got["errors"], got["errors"]
    assert got["solution"] is None and got["baked"] is None  # nothing solved
    assert got["cameras"] >= 1  # the export carries the model's cameras
    img = got["image"]
    h, w = img.shape[:2]
    linear = render_glb(glb, got["camera"], (w, h))
    want = np.round(srgb_encode(np.clip(linear * got["exposure"], 0.0, 1.0)) * 255.0)
    model = linear.max(axis=2) > 0  # not the background (the viewer's is dark grey, the file's black)
    assert model.mean() > 0.5
    err = img.astype(np.float64)[model] - want[model]
    psnr = 10 * np.log10(255.0**2 / max(float(np.mean(err**2)), 1e-12))
    assert psnr >= 45.0, psnr  # the same draw; only the 8-bit rounding and the blit differ
    lum = img.astype(np.float64).mean(axis=2)
    assert np.percentile(lum, 99) < 255  # exposed as iat render exposes: not white
    assert got["half"].astype(np.float64).mean() < 0.85 * img.astype(np.float64).mean()
    assert got["export_after"] is None  # a model opened afterwards is drawn by the renderer again


@pytest.mark.gui
def test_an_exported_bake_plays_its_camera_path(tmp_path):
    """``iat view OUT.glb --play default``: the export keeps the model's camera paths, and the player
    does not wait for a bake an export never has."""
    import json
    import os
    import subprocess
    import sys

    glb = exported_cornell(tmp_path / "cornell-iat.glb")
    iat = str(Path(sys.executable).with_name("iat"))
    env = {**os.environ, "IAT_CACHE_DIR": str(tmp_path / "cache")}
    r = subprocess.run(
        [iat, "view", str(glb), "--play", "default", "--frames", "4", "--modes", "iat", "--json"],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout)
    assert res["path"] == "default" and res["error"] is None
    assert res["modes"]["iat"]["frames"] == 4
