"""An IES luminaire loaded in the viewer (issue 39): the Lighting panel's IES field through the real
UI (imgui test engine under Xvfb; runs alone in a child process, see tests/conftest.py).

The Cornell box with an extra point light ("bulb", 0.12 W/sr: 21.5 cd) 15 cm under the ceiling. A
file that is not an IES file gives one error line and leaves the light as it was; then the downlight
of ``tests/test_ies.py`` scaled to the bulb's own peak (so only the distribution changes, not the
intensity) is loaded: the light holds it, the background re-solve follows, and the ceiling, which the
downlight does not light (nothing above its horizon), loses much more of its illuminance than the
floor (solved offline: ceiling 645 -> 360 lux, floor 438 -> 376)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until
from tests.test_ies import PEAK, ies_text

ROOT = Path(__file__).resolve().parent.parent
BULB = 0.12  # W/sr per unit colour (white)


def make_model(path: Path) -> Path:
    from iat.io.load import load_scene
    from iat.lighting import edits, save

    src = ROOT / "sample_models" / "cornell_box.glb"
    scene = edits.add_light(load_scene(src), "point", [0.12, 0.40, 0.30], intensity=BULB, name="bulb")
    return save.save_gltf(scene, src, path)


def ceiling_and_floor_lux(scene, solution) -> tuple[float, float]:
    """Mean lux at the solution's ceiling and floor vertices (emitters left out: NaN there)."""
    from iat.measure import photometry as ph

    lo, hi = scene.bounds
    y = solution.vert_position[:, 1]
    e = ph.vertex_illuminance(solution, scene.patch_emission)
    return float(np.nanmean(e[y > hi[1] - 1e-3])), float(np.nanmean(e[y < lo[1] + 1e-3]))


@pytest.mark.gui
def test_the_viewer_loads_an_ies_file_for_a_light(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from PIL import Image

    from iat.measure import photometry as ph
    from iat.radiosity import SolveOptions
    from viewer.app import ViewerApp

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("IAT_SCREENSHOT_DIR", str(tmp_path / "shots"))
    model = make_model(tmp_path / "bulb.glb")
    bad = tmp_path / "notes.ies"
    bad.write_text("a luminaire, but no photometry\n")
    good = tmp_path / "downlight.ies"
    good.write_text(ies_text(multiplier=BULB * ph.LUMINOUS_EFFICACY / PEAK))

    app = ViewerApp(model, size=(1280, 800), solve_options=SolveOptions(max_depth=3), idle=False)
    s = app.state
    got: dict = {}

    def settle(ctx) -> None:
        wait_until(
            ctx,
            lambda: not (s.jobs.rebaking or s.jobs.opening or s.lighting.relighting or app.pending_relit),
            120,
            "the background work",
        )
        ctx.yield_(3)

    def shot(ctx) -> np.ndarray:
        from imgui_bundle import imgui

        s.messages.last_screenshot = ""
        ctx.key_press(imgui.Key.f12)
        wait_until(ctx, lambda: s.messages.last_screenshot, 10, "the screenshot")
        return np.asarray(Image.open(s.messages.last_screenshot).convert("RGB")).astype(np.float64)

    def drive(ctx) -> None:
        wait_until(ctx, lambda: s.model.baked is not None and s.lighting.editor is not None, 120, "the model")
        settle(ctx)
        ed = s.lighting.editor
        k = [lt.name for lt in ed.lights].index("bulb")
        got["before"] = ceiling_and_floor_lux(ed.scene, s.model.solution)
        got["img_before"] = shot(ctx)
        ctx.item_click(f"//**/bulb (point)##light{k}")
        ctx.yield_(2)
        got["selected"] = s.lighting.selected_light == k

        ctx.item_input_value("//Lighting/IES file", str(bad))
        ctx.item_click("//Lighting/Load IES")
        ctx.yield_(2)
        got["error"] = s.messages.error
        got["after_bad"] = (ed.lights[k].ies, float(ed.lights[k].intensity), ed.version)
        s.messages.clear_error()

        relights = s.lighting.relights
        version = ed.version
        ctx.item_input_value("//Lighting/IES file", str(good))
        ctx.item_click("//Lighting/Load IES")
        ctx.yield_(2)
        got["status"] = s.messages.status
        got["light"] = ed.lights[k]
        got["edited"] = ed.version > version
        wait_until(ctx, lambda: s.lighting.relights > relights, 120, "the re-solve")
        step = s.lighting
        wait_until(ctx, lambda: step.relight_step[0] == step.relight_step[1] > 0, 120, "the last step")
        settle(ctx)
        got["solved_ies"] = [lt.ies for lt in s.model.scene.lights]
        got["after"] = ceiling_and_floor_lux(ed.scene, s.model.solution)
        got["img_after"] = shot(ctx)

    run_gui(app, drive)
    assert got["selected"]
    # the bad file: one line naming it, the light unchanged
    assert "notes.ies" in got["error"] and "\n" not in got["error"], got["error"]
    assert got["after_bad"][0] is None and got["after_bad"][1] == pytest.approx(BULB)
    # the good one: the light holds the distribution at the bulb's own peak, and was solved with it
    lt = got["light"]
    assert got["edited"] and lt.ies is not None and lt.ies.name == "downlight.ies"
    assert float(lt.intensity) == pytest.approx(BULB, rel=1e-5)
    assert ph.light_candela(lt) == pytest.approx(BULB * ph.LUMINOUS_EFFICACY, rel=1e-5)
    assert "downlight.ies" in got["status"] and "cd peak" in got["status"]
    assert any(d is not None and d.name == "downlight.ies" for d in got["solved_ies"])
    (c0, f0), (c1, f1) = got["before"], got["after"]
    assert c1 / c0 < 0.75, (c0, c1)  # the ceiling lost its direct light (offline: 0.56)
    assert f1 / f0 > 0.75, (f0, f1)  # the floor, under the peak, much less (offline: 0.86)
    assert np.abs(got["img_after"] - got["img_before"]).mean() > 1.0
