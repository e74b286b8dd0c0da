"""``iat view MODEL --play NAME --frames N --json`` and the viewer's frame economy (issue 20).

- the playback command: exactly N frames per mode, statistics that agree with each other, the
  viewport inside the window; a path file instead of a name; an unknown name is a user error
  naming the paths there are;
- the 3D view is drawn again only when what it shows changed (camera, exposure, mode, bake), and
  copied otherwise, with the same pixels (a change is drawn into the window, and once more into
  the offscreen image when the view stops changing);
- the frame statistics leave idle frames out of the frame rate.

The window tests need a display (xvfb-run); they open the Cornell box solved at max_depth 3 into a
temporary cache. No wall-clock limits here: timings are the benchmark's
(``benchmarks/viewer_bench.py``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "sample_models" / "cornell_box.glb"
IAT = str(Path(sys.executable).with_name("iat"))


def solved_cornell(tmp_path: Path) -> Path:
    """The Cornell box's solution at max_depth 3 as a file (``iat view`` opens it without a solve)."""
    from iat.io.load import load_scene
    from iat.radiosity import SolveOptions, solve

    sol = solve(load_scene(CORNELL), SolveOptions(max_depth=3))
    sol.model_path = str(CORNELL)
    out = tmp_path / "cornell.npz"
    sol.save(out)
    return out


def play(tmp_path, *args) -> subprocess.CompletedProcess:
    env = {**os.environ, "IAT_CACHE_DIR": str(tmp_path / "cache")}
    return subprocess.run(
        [IAT, "view", *map(str, args)], capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path
    )


@pytest.mark.gui
def test_play_prints_statistics_per_mode(tmp_path):
    sol = solved_cornell(tmp_path)
    r = play(tmp_path, sol, "--play", "default", "--frames", 7, "--modes", "mesh,iat,split", "--json")
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout)
    assert res["path"] == "default" and res["frames"] == 7 and res["error"] is None
    assert set(res["modes"]) == {"mesh", "iat", "split"}
    for m, st in res["modes"].items():
        assert st["frames"] == 7, (m, st)
        assert st["shown_mode"] == m
        assert st["fps"] == pytest.approx(1000.0 / st["mean_ms"])
        assert 0 < st["p50_ms"] <= st["p95_ms"] <= st["max_ms"]
        assert st["cpu_ms"] > 0
    w, h = res["viewport"]
    assert res["window"] == [1280, 800] and 300 < w < 1280 and 300 < h <= 800
    assert res["msaa"] == 0
    # every played frame moved the camera: each drew the view anew
    assert res["redraws"] >= 3 * 7


@pytest.mark.gui
def test_play_takes_a_paths_file_and_names_the_paths_when_one_is_missing(tmp_path):
    from iat.io.load import load_scene
    from viewer.navigation import CameraPath, save_paths

    sol = solved_cornell(tmp_path)
    cams = load_scene(CORNELL).camera_paths["default"]
    f = save_paths(tmp_path / "walk.paths.json", [CameraPath("walk", list(cams[:3]))])
    r = play(tmp_path, sol, "--play", f, "--frames", 4, "--modes", "iat", "--json")
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout)
    assert res["path"] == "walk" and res["modes"]["iat"]["frames"] == 4

    r = play(tmp_path, sol, "--play", "nowhere", "--frames", 4)
    assert r.returncode == 2
    assert "no camera path named 'nowhere'" in r.stderr and "default" in r.stderr

    r = play(tmp_path, sol, "--play", "default", "--frames", 0)
    assert r.returncode != 0 and "--frames must be >= 1" in r.stderr


# -- the 3D view is drawn only when it changes ----------------------------------------------------------
@pytest.mark.gui
def test_the_view_is_drawn_again_only_when_it_changes(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from imgui_bundle import ImVec2, imgui

    from iat.radiosity import SolveOptions
    from viewer.app import ViewerApp

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    app = ViewerApp(CORNELL, size=(1280, 800), solve_options=SolveOptions(max_depth=3), idle=False)
    s = app.state
    got: dict = {}

    def counts():
        return app.view3d.redraws, app.view3d.blits

    def shot(ctx, path: Path) -> np.ndarray:
        """The view's pixels as shown (read on the UI thread: the screenshot request)."""
        from PIL import Image

        s.messages.last_screenshot = ""
        s.requests.screenshot = str(path)
        wait_until(ctx, lambda: s.messages.last_screenshot, 10, "the screenshot")
        return np.asarray(Image.open(path).convert("RGB"))

    def drive(ctx) -> None:
        def idle() -> bool:
            w = s.jobs.bake_worker
            busy = s.jobs.rebaking or s.jobs.opening or (w is not None and w.warming)
            return s.model.baked is not None and not busy and app.pending_relit is None

        wait_until(ctx, idle, 300, "the model and the bake worker's pre-warming")
        ctx.yield_(5)
        got["still_image"] = shot(ctx, tmp_path / "still.png")
        r0, b0 = counts()
        ctx.yield_(10)
        r1, b1 = counts()
        got["quiet"] = (r1 - r0, b1 - b0)
        ctx.window_focus("//Tuning")  # panel work that changes nothing in the view
        ctx.item_click("//**/Budget (MB)")
        ctx.yield_(3)
        got["after_panel"] = counts()[0] - r1
        got["blit_image"] = shot(ctx, tmp_path / "copied.png")
        r2 = counts()[0]
        s.tuning.exposure *= 0.5
        ctx.yield_(3)
        got["exposure"] = counts()[0] - r2
        r3 = counts()[0]
        s.view.mode = "mesh"
        ctx.yield_(3)
        got["mode"] = counts()[0] - r3
        r4 = counts()[0]
        x, y, w, h = s.view.rect
        ctx.mouse_move_to_pos(ImVec2(x + 0.5 * w, y + 0.5 * h))
        ctx.mouse_down(0)  # a click in the view takes the keyboard
        ctx.mouse_up(0)
        ctx.key_down(imgui.Key.w)
        ctx.yield_(6)
        ctx.key_up(imgui.Key.w)
        got["walk"] = counts()[0] - r4
        r5 = counts()[0]
        ctx.yield_(5)
        got["still_again"] = counts()[0] - r5
        s.tuning.threshold = 0  # a new bake: drawn when it arrives
        s.view.mode = "iat"
        ctx.yield_(2)
        r6 = counts()[0]
        uploads = s.jobs.uploads
        wait_until(ctx, lambda: s.jobs.uploads > uploads and not s.jobs.rebaking, 60, "the re-bake")
        ctx.yield_(3)
        got["rebake"] = counts()[0] - r6

    run_gui(app, drive)
    assert got["quiet"] == (0, 10)  # ten frames with nothing changing: ten copies, no 3D draw
    assert got["after_panel"] == 0
    np.testing.assert_array_equal(got["blit_image"], got["still_image"])
    # a change: drawn into the window, then once more into the image the next frames copy
    assert got["exposure"] == 2 and got["mode"] == 2
    assert got["walk"] >= 5  # every frame the camera moved
    assert got["still_again"] <= 2  # (the frame after the key is released may still move)
    assert got["rebake"] >= 1


# -- frame statistics ---------------------------------------------------------------------------------
def test_idle_frames_are_not_the_frame_rate():
    from viewer.state import FrameStats

    st = FrameStats()
    for _ in range(30):
        st.add_frame_time(20.0, work_ms=18.0)  # drawing at 50 fps
    assert st.fps == pytest.approx(50.0) and not st.idling
    for _ in range(20):
        st.add_frame_time(111.0, work_ms=10.0, idle=True)  # then idling at 9 fps
    assert st.idling
    assert st.fps == pytest.approx(50.0)  # the idle waits are not frames' cost
    assert st.idle_fps == pytest.approx(1000.0 / 111.0)
    assert st.work_fps == pytest.approx(1000.0 / ((30 * 18.0 + 20 * 10.0) / 50))
    for _ in range(60):
        st.add_frame_time(111.0, work_ms=10.0, idle=True)
    assert st.fps == 0.0 and st.work_fps == pytest.approx(100.0)
    st.add_frame_time(25.0, work_ms=25.0)
    assert not st.idling and st.fps == pytest.approx(40.0)
