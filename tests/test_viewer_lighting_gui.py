"""The viewer's lighting end to end: the real app driven by imgui-bundle's test engine (needs a display).

One app run: a Cornell box with an extra point light ("bulb") and three lighting
states in its extras (written by :func:`iat.lighting.save_gltf`), solved at max_depth 3.

1. drag the bulb's marker in the 3D view with the mouse: the light moves at its
   height, the background re-solve (resolve from the last solution) shows a new
   solution, the re-bake follows, and the picture changes; add and delete a light
   with the panel's buttons;
2. solve the day cycle (the three states on one mesh), drag the time-of-day slider:
   the picture changes with the time, the HUD counts three texture layers per page,
   and a time halfway between two keys shows the mean of the two keys' pictures;
3. save the lights back to glTF and load them again.

Without a DISPLAY the test skips; the GUI part runs in a child process (Mesa aborts
when a GLX window context is made in a process holding the EGL context of conftest.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until
from tests.support import gui

ROOT = Path(__file__).resolve().parent.parent

#: mean |before - after| in 8-bit levels over the 3D view that counts as "the picture changed";
#: moving the bulb across the box or going from day to night changes it by tens of levels
CHANGED = 3.0
#: the picture halfway between two key times against the mean of the two keys' pictures, in
#: 8-bit levels (sRGB encoding is not linear, so the mean of two encoded pictures is not the
#: encoding of the mean: only a loose bound here; the exact linear check is in test_solution_set)
HALFWAY_MEAN = 6.0

STATES = {
    "day": {"time": 0.0, "lights": {"bulb": 0.0}},
    "dusk": {"time": 0.5, "lights": {"bulb": 0.1}, "emission": {"light": 0.35}},
    "night": {"time": 1.0, "lights": {"bulb": 0.2}, "emission": {"light": 0.0}},
}


def make_model(path: Path) -> Path:
    from iat.io.load import load_scene
    from iat.lighting import edits, save

    src = ROOT / "sample_models" / "cornell_box.glb"
    scene = edits.add_light(load_scene(src), "point", [0.12, 0.40, 0.30], intensity=0.12, name="bulb")
    return save.save_gltf(scene, src, path, lighting_states=STATES)


@pytest.mark.gui
def test_viewer_lighting_end_to_end(tmp_path, monkeypatch, gui_child):
    if gui_child():  # ran alone in a child process (see tests/conftest.py)
        return
    from imgui_bundle import ImVec2
    from imgui_bundle.immapp import testing

    from iat.bake.baked import BakedSet
    from iat.io.load import load_scene
    from iat.radiosity import SolveOptions
    from viewer import panels
    from viewer.app import ViewerApp
    from viewer.picking import project_points

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("IAT_SCREENSHOT_DIR", str(tmp_path / "shots"))
    model = make_model(tmp_path / "cornell_day.glb")

    app = ViewerApp(model, size=(1280, 800), solve_options=SolveOptions(max_depth=3), idle=False)
    s = app.state
    s.tuning.threshold = 0
    got: dict = {}
    images: dict[str, np.ndarray] = {}

    def settle(ctx):
        gui.settle(ctx, app, 120)

    def shot(ctx, name: str) -> np.ndarray:
        images[name] = gui.screenshot(ctx, app, name)
        testing.capture(ctx, str(tmp_path / f"window-{name}.png"))
        return images[name]

    def drive(ctx) -> None:
        wait_until(ctx, lambda: s.model.baked is not None and s.lighting.editor is not None, 120, "the model")
        settle(ctx)
        ctx.item_click("//**/IAT")
        ctx.yield_(2)
        shot(ctx, "before")
        ed = s.lighting.editor
        k = [lt.name for lt in ed.lights].index("bulb")
        got["start"] = ed.lights[k].position.copy()
        got["solution0"] = s.model.solution

        # drag the bulb's marker to the right third of the view, at its height
        px, ok = project_points(s.view.camera, [ed.lights[k].position], s.view.rect)
        assert ok[0], "the bulb is not in view"
        x, y, w, h = s.view.rect
        ctx.mouse_move_to_pos(ImVec2(float(px[0, 0]), float(px[0, 1])))
        ctx.mouse_down(0)
        ctx.mouse_move_to_pos(ImVec2(float(px[0, 0]) + 0.25 * w, float(px[0, 1])))
        ctx.yield_(3)
        ctx.mouse_up(0)
        got["selected"] = s.lighting.selected_light == k
        got["dragging_after"] = s.lighting.dragging_light
        got["looked"] = s.view.looking
        got["moved_to"] = ed.lights[k].position.copy()
        # the view improves step by step: wait for the final (converged) step and its bake
        wait_until(ctx, lambda: s.lighting.relights > 0, 120, "the first re-solved solution")
        got["first_step"] = s.lighting.relight_step
        wait_until(
            ctx,
            lambda: (
                s.lighting.relight_step[0] == s.lighting.relight_step[1] and s.lighting.relight_step[1] > 0
            ),
            120,
            "the last step",
        )
        settle(ctx)
        got["relights"] = s.lighting.relights
        got["steps_published"] = s.lighting.relighter.steps_done
        got["mode"] = s.model.solution.stats.get("mode")
        got["bake_source"] = s.model.bake_source
        shot(ctx, "moved")

        # add and delete a light with the panel's buttons
        n = len(ed.lights)
        ctx.item_click("//Lighting/Add point light")
        ctx.yield_(2)
        got["added"] = (len(ed.lights), s.lighting.selected_light)
        ctx.item_click("//Lighting/Delete light")
        ctx.yield_(2)
        got["deleted"] = len(ed.lights) == n
        settle(ctx)

        # save the lights back to glTF
        ctx.item_input_value("//Lighting/glTF file##lights", str(tmp_path / "saved.glb"))
        ctx.item_click("//Lighting/Save lights")
        wait_until(ctx, lambda: "saved the lights" in s.messages.status or s.messages.error, 60, "the save")
        got["save_status"] = s.messages.status
        got["saved_lights"] = [(lt.name, lt.position.copy()) for lt in ed.lights]

        # the day cycle: solve the states, then drag the time of day
        ctx.item_click("//Lighting/Solve day cycle")
        wait_until(ctx, lambda: s.lighting.solution_set is not None, 300, "the day-cycle solve")
        wait_until(ctx, lambda: isinstance(s.model.baked, BakedSet), 120, "the day-cycle bake")
        settle(ctx)
        got["set"] = (list(s.lighting.solution_set.names), [float(t) for t in s.lighting.solution_set.times])
        got["memory"] = dict(s.model.memory)
        got["hud"] = panels.hud_lines(s)
        for t, name in ((0.0, "t0"), (1.0, "t1"), (0.5, "t05"), (0.25, "t025")):
            ctx.item_input_value("//Lighting/Time of day", t)
            ctx.yield_(3)
            got.setdefault("blend", {})[name] = (s.lighting.day_time, app.renderer.blend)
            shot(ctx, name)
        ctx.item_click("//Lighting/Day cycle on")
        settle(ctx)
        got["day_off_baked"] = type(s.model.baked).__name__

    got["seconds"] = run_gui(app, drive)
    assert not s.messages.error, s.messages.error

    # 1. the drag: the bulb was picked (not a look-around), moved at its height, and re-solved
    assert got["selected"] and not got["dragging_after"] and not got["looked"]
    start, moved = got["start"], got["moved_to"]
    assert abs(moved[1] - start[1]) < 1e-9  # dragged in its horizontal plane
    assert np.linalg.norm(moved - start) > 0.05  # a few centimetres at least in a 0.55 m box
    assert got["first_step"][1] >= 2  # coarse step first, then the final one
    assert got["steps_published"] >= 2  # each step was published (the view takes the newest per frame)
    assert got["relights"] >= 1 and got["mode"] == "resolve"
    assert got["bake_source"] > 0  # the bake on screen is of a re-solved solution
    before, after = images["before"], images["moved"]
    assert before.mean() > 30  # a lit room
    assert np.abs(after - before).mean() > CHANGED, "moving the bulb did not change the picture"

    assert got["added"][0] == len(got["saved_lights"]) + 1 and got["added"][1] == got["added"][0] - 1
    assert got["deleted"]

    # 3. saved: the new file has the moved bulb, the geometry unchanged
    assert "saved the lights" in got["save_status"]
    saved = load_scene(tmp_path / "saved.glb")
    orig = load_scene(model)
    assert [lt.name for lt in saved.lights] == [n for n, _ in got["saved_lights"]]
    np.testing.assert_allclose(saved.lights[0].position, got["saved_lights"][0][1], atol=1e-9)
    np.testing.assert_array_equal(saved.vertices, orig.vertices)

    # 2. the day cycle
    names, times = got["set"]
    assert names == list(STATES) and times == [0.0, 0.5, 1.0]
    mem = got["memory"]
    assert mem["solutions"] == 3 and mem["texture_bytes"] % 3 == 0 and mem["texture_bytes"] > 0
    assert any("3 x" in line for line in got["hud"]), got["hud"]
    b = got["blend"]
    assert b["t0"][1] == (0, 1, 0.0) and b["t1"][1] == (2, 2, 0.0)
    assert b["t05"][1] == (1, 2, 0.0)  # a key time: exactly the dusk state
    assert b["t025"][1][:2] == (0, 1) and b["t025"][1][2] == pytest.approx(0.5)
    day, night, dusk, quarter = images["t0"], images["t1"], images["t05"], images["t025"]
    assert np.abs(day - night).mean() > CHANGED, "the time slider did not change the picture"
    assert np.abs(quarter - day).mean() > 1.0 and np.abs(quarter - dusk).mean() > 1.0
    assert np.abs(quarter - 0.5 * (day + dusk)).mean() < HALFWAY_MEAN
    assert got["day_off_baked"] == "Baked"
    assert got["seconds"] < 600
