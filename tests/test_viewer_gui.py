"""The viewer end to end: the real app driven by imgui-bundle's test engine (needs a display).

``make test`` runs the suite under ``xvfb-run``; without a DISPLAY these tests skip.
One app run does everything (starting a window costs seconds): open the Cornell
box (solved at max_depth 4 into a temporary cache), drag the threshold slider
and see triangles and texture memory change, switch the modes and compare the
3D view's pixels, drag the split divider, turn the budget on, then open a broken
file and see the error while the app keeps rendering the last good model.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until

ROOT = Path(__file__).resolve().parent.parent

# Tolerances, in 8-bit sRGB levels over the 3D view (about 700 x 780 pixels at 1280 x 800):
# mesh (Gouraud on the leaf triangles) and IAT (bilinear texels at the lattice points) agree at
# every mesh vertex but interpolate differently inside the elements, so they differ by a few levels
# in places; a wrong texture placement or a missing patch gives tens of levels over large areas.
MESH_IAT_MEAN = 2.0  # mean |mesh - IAT|; measured about 0.5
MESH_IAT_P99 = 16.0  # 99th percentile; measured about 7
# The difference view shows |mesh - IAT| x gain, then the sRGB curve, which lifts tiny linear
# differences (0.002 -> 6 levels); at gain 1 "nearly black" means a low mean and few bright pixels.
DIFF_MEAN = 12.0  # mean level of the difference view at gain 1; measured about 6
DIFF_BRIGHT = 0.02  # fraction of pixels above 64 levels (a quarter of full scale); measured about 0.003
SPLIT_EXACT = 1.0  # each side of the split equals the single-mode image there


@pytest.mark.gui
@pytest.mark.filterwarnings("ignore:Ignoring chunk:UserWarning")  # pygltflib on the broken file
def test_viewer_end_to_end(tmp_path, monkeypatch, gui_child):
    if gui_child():  # ran alone in a child process (see tests/conftest.py)
        return
    from imgui_bundle import ImVec2, imgui
    from imgui_bundle.immapp import testing

    from iat.radiosity import SolveOptions
    from viewer.app import ViewerApp
    from viewer.state import default_model

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("IAT_SCREENSHOT_DIR", str(tmp_path / "shots"))
    broken = tmp_path / "broken.glb"
    broken.write_bytes(b"glTF\x02\x00\x00\x00 this is not a model")

    app = ViewerApp(default_model(), size=(1280, 800), solve_options=SolveOptions(max_depth=4), idle=False)
    s = app.state
    s.tuning.threshold = 0  # texture every patch: the IAT image is then all texture
    s.view.diff_gain = 1.0
    got: dict = {}
    images: dict[str, np.ndarray] = {}

    def settle(ctx, frames=3):
        wait_until(ctx, lambda: not s.jobs.rebaking and not s.jobs.opening, 30, "the re-bake")
        ctx.yield_(frames)

    def shot(ctx, mode: str) -> None:
        """F12 in ``mode``: the app writes the 3D view; keep its pixels."""
        s.messages.last_screenshot = ""
        ctx.key_press(imgui.Key.f12)
        wait_until(ctx, lambda: s.messages.last_screenshot, 10, f"the {mode} screenshot")
        from PIL import Image

        got.setdefault("shots", []).append(s.messages.last_screenshot)
        images[mode] = np.asarray(Image.open(s.messages.last_screenshot).convert("RGB")).astype(np.int16)
        testing.capture(ctx, str(tmp_path / f"window-{mode}.png"))

    def drive(ctx) -> None:
        wait_until(
            ctx, lambda: s.model.baked is not None and s.model.solution is not None, 120, "the Cornell box"
        )
        settle(ctx)
        got["deepest"] = s.model.deepest
        got["t0"] = (
            s.model.baked.policy.threshold,
            s.model.iat_triangles,
            s.model.memory["texture_bytes"],
            s.model.memory["patches_textured"],
        )

        # the threshold slider, through the real widget: all mesh, then back to all texture
        ctx.item_input_value("//**/Threshold", s.model.deepest + 1)
        settle(ctx)
        got["t_top"] = (
            s.model.baked.policy.threshold,
            s.model.iat_triangles,
            s.model.memory["texture_bytes"],
            s.model.memory["patches_textured"],
        )
        ctx.item_input_value("//**/Threshold", 0)
        settle(ctx)
        got["t_back"] = (
            s.model.baked.policy.threshold,
            s.model.iat_triangles,
            s.model.memory["texture_bytes"],
        )

        # modes, by their radio buttons, each with an F12 screenshot
        for label, mode in (("Mesh", "mesh"), ("IAT", "iat"), ("Split", "split"), ("Difference", "diff")):
            ctx.item_click(f"//**/{label}")
            ctx.yield_(2)
            got.setdefault("modes", []).append((s.view.mode, app.shown_mode()))
            shot(ctx, mode)
        got["split_at"] = s.view.split

        # drag the split divider in the view from the middle to 25 %
        ctx.item_click("//**/Split")
        ctx.yield_(2)
        x, y, w, h = s.view.rect
        ctx.mouse_move_to_pos(ImVec2(x + 0.5 * w, y + 0.5 * h))
        ctx.mouse_down(0)
        ctx.mouse_move_to_pos(ImVec2(x + 0.25 * w, y + 0.5 * h))
        ctx.yield_(2)
        ctx.mouse_up(0)
        got["split_dragged"] = s.view.split
        # a drag elsewhere in the view looks around
        before = s.view.camera.forward.copy()
        ctx.mouse_move_to_pos(ImVec2(x + 0.7 * w, y + 0.5 * h))
        ctx.mouse_down(0)
        ctx.mouse_move_to_pos(ImVec2(x + 0.8 * w, y + 0.55 * h))
        ctx.yield_(2)
        ctx.mouse_up(0)
        got["look_turned"] = float(np.degrees(np.arccos(np.clip(before @ s.view.camera.forward, -1, 1))))
        # W held walks forward (the click in the view took the keyboard focus from the panels)
        eye = s.view.camera.eye.copy()
        ctx.key_down(imgui.Key.w)
        ctx.yield_(4)
        ctx.key_up(imgui.Key.w)
        got["walked"] = float((s.view.camera.eye - eye) @ s.view.camera.forward)
        ctx.item_click("//**/Reset view")
        ctx.item_click("//**/IAT")

        # a texture budget smaller than any texture: everything becomes mesh
        ctx.item_click("//**/Budget")
        ctx.item_input_value("//**/Budget (MB)", 0.001)
        settle(ctx)
        m = s.model.memory
        got["budget"] = (
            s.tuning.budget_on,
            m["budget_mb"],
            m["texture_bytes"],
            m["budget_too_small"],
            s.model.iat_triangles,
        )
        ctx.item_click("//**/Budget")
        settle(ctx)
        got["budget_off"] = s.model.memory["texture_bytes"]

        # export the bake on screen as GLB (written on a background thread)
        ctx.window_focus("//Model")
        ctx.item_input_value("//**/GLB file", str(tmp_path / "export.glb"))
        ctx.item_click("//**/Export GLB")
        wait_until(ctx, lambda: "exported" in s.messages.status or s.messages.error, 60, "the export")
        got["export_status"] = s.messages.status
        # a broken file: typed into the Model panel and opened
        ctx.item_input_value("//**/File to open", str(broken))
        ctx.item_click("//**/Open")
        wait_until(ctx, lambda: bool(s.messages.error), 30, "the error")
        got["error"] = s.messages.error
        drawn = app.frames_drawn
        ctx.yield_(5)
        got["drawn_after_error"] = app.frames_drawn - drawn
        got["model_after_error"] = s.model.path
        got["error_window"] = ctx.item_exists("//Error/Dismiss")
        testing.capture(ctx, str(tmp_path / "window-error.png"))
        shot(ctx, "after-error")
        ctx.item_click("//Error/Dismiss")
        ctx.yield_(2)
        got["error_cleared"] = s.messages.error

    got["seconds"] = run_gui(app, drive)

    deepest = got["deepest"]
    mesh_tris = s.model.mesh_triangles
    # threshold 0: every patch is one textured polygon, few triangles, texture memory used
    thr, tris, tex, textured = got["t0"]
    assert thr == 0 and textured == s.model.solution.patch_is_quad.size
    assert tris < 100 < mesh_tris and tex > 0
    # above the deepest tree: all mesh, no texture memory, the mesh's triangles
    thr, tris, tex, textured = got["t_top"]
    assert thr == deepest + 1 and textured == 0
    assert tris == mesh_tris and tex == 0
    assert got["t_back"] == got["t0"][:3]

    assert got["modes"] == [("mesh", "mesh"), ("iat", "iat"), ("split", "split"), ("diff", "diff")]
    mesh, iat, split, diff = (images[k] for k in ("mesh", "iat", "split", "diff"))
    assert mesh.shape == iat.shape and mesh.shape[0] > 300 and mesh.shape[1] > 300
    assert mesh.mean() > 40  # a lit room, not a black frame
    d = np.abs(mesh - iat)
    assert d.mean() < MESH_IAT_MEAN, f"mesh vs IAT mean difference {d.mean():.2f}"
    assert np.percentile(d, 99) < MESH_IAT_P99, f"mesh vs IAT p99 difference {np.percentile(d, 99):.1f}"
    assert diff.mean() < DIFF_MEAN, f"difference view mean {diff.mean():.2f}"
    assert diff.mean() < 0.1 * iat.mean()
    assert (diff.max(axis=2) > 64).mean() < DIFF_BRIGHT
    # split: mesh left of the divider, IAT right of it, pixel for pixel
    sx = int(round(got["split_at"] * split.shape[1]))
    assert np.abs(split[:, : sx - 1] - mesh[:, : sx - 1]).max() <= SPLIT_EXACT
    assert np.abs(split[:, sx + 1 :] - iat[:, sx + 1 :]).max() <= SPLIT_EXACT
    assert got["split_dragged"] == pytest.approx(0.25, abs=0.02)
    assert got["look_turned"] > 1.0
    assert got["walked"] > 0.0
    assert all(Path(p).is_file() and Path(p).parent == tmp_path / "shots" for p in got["shots"])

    on, budget_mb, tex, too_small, tris = got["budget"]
    assert on and budget_mb == pytest.approx(0.001) and tex == 0 and too_small and tris == mesh_tris
    assert got["budget_off"] > 0

    assert "exported" in got["export_status"]
    glb = (tmp_path / "export.glb").read_bytes()
    assert glb[:4] == b"glTF" and len(glb) > 1000

    # the broken file: named in the error, shown in a window; the last good model stays and renders
    assert "broken.glb" in got["error"]
    assert got["error_window"]
    assert got["drawn_after_error"] >= 5
    assert Path(got["model_after_error"]).name == "cornell_box.glb"
    after = images["after-error"]
    assert np.abs(after - iat).mean() < MESH_IAT_MEAN  # still the IAT Cornell box
    assert got["error_cleared"] == ""
    assert got["seconds"] < 120


def test_no_display_returns_2():
    """Without a display ``main`` prints one line and returns 2 (the CLI then falls back)."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    code = "import sys; from viewer.app import main; sys.exit(main(None, size=(320, 240)))"
    r = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("iat view")]
    assert len(lines) == 1 and "cannot open a window" in lines[0]


# -- the viewer's background work, without a window ------------------------------------------------------
class _GatedBaker:
    """Stands in for iat.bake.baker.Baker: records the thresholds baked, waits on a gate, fails on 99."""

    def __init__(self):
        import threading

        self.calls: list[int] = []
        self.gate = threading.Event()

    def bake(self, policy):
        from types import SimpleNamespace

        from iat.errors import BakeError

        self.calls.append(policy.threshold)
        if policy.threshold == 99:
            raise BakeError("no atlas page fits a 99999 texel tile")
        self.gate.wait(10)
        return SimpleNamespace(policy=policy)


def test_bake_worker_bakes_the_newest_request_and_survives_errors():
    from iat.bake.policy import BakePolicy
    from viewer.bake_worker import BakeWorker

    baker = _GatedBaker()
    w = BakeWorker(baker)
    try:
        w.submit(BakePolicy(threshold=1))
        deadline = time.monotonic() + 5
        while not baker.calls and time.monotonic() < deadline:
            time.sleep(0.005)
        assert w.busy and w.poll() is None  # baking 1, nothing finished yet
        for t in (2, 3, 4):  # a slider dragged while the bake runs: only the newest is kept
            w.submit(BakePolicy(threshold=t))
        baker.gate.set()
        assert w.wait(10)
        r = w.poll()
        assert baker.calls == [1, 4]
        assert r.baked.policy.threshold == 4 and r.error is None and r.seconds >= 0
        assert w.poll() is None  # each result is returned once

        w.submit(BakePolicy(threshold=99))
        assert w.wait(10)
        r = w.poll()
        assert r.baked is None and "no atlas page fits" in r.error
        w.submit(BakePolicy(threshold=5))  # the worker keeps going after a failure
        assert w.wait(10)
        assert w.poll().baked.policy.threshold == 5
    finally:
        baker.gate.set()
        w.close()
    assert not w.alive


def test_the_scale_slider_snaps_to_the_prewarmed_ladder():
    """Every value the Scale slider can set is on the 2**(k/4) ladder the worker pre-warms, inside
    the slider's range, and the seam-free dyadic scales are on it."""
    from viewer.bake_worker import SCALE_MAX, SCALE_MIN, scale_neighbours, snap_scale

    for v in np.geomspace(0.05, 4.0, 97):
        s = snap_scale(v)
        assert SCALE_MIN <= s <= SCALE_MAX
        assert abs(4 * np.log2(s) - round(4 * np.log2(s))) < 1e-12
        if SCALE_MIN < v < SCALE_MAX:
            assert abs(np.log2(s) - np.log2(v)) <= 0.125 + 1e-12  # the nearest quarter octave
        for n in scale_neighbours(s):
            assert snap_scale(n) == n
    assert [snap_scale(x) for x in (1.0, 0.5, 0.25, 0.125)] == [1.0, 0.5, 0.25, 0.125]


def test_neighbour_policies_are_the_sliders_next_steps():
    from iat.bake.policy import BakePolicy
    from viewer.bake_worker import neighbour_policies, scale_neighbours

    q, r = 2.0**0.25, 2.0 ** (-1 / 4)
    assert scale_neighbours(1.0) == [2.0 ** (-1 / 4), 2.0 ** (1 / 4)]
    assert scale_neighbours(2.0) == [2.0 ** (3 / 4)]  # the slider's top
    assert scale_neighbours(0.125) == [2.0 ** (-11 / 4)]  # and its bottom
    assert scale_neighbours(0.6) == [2.0 ** (-3 / 4), 2.0 ** (-2 / 4)]  # off the ladder: either side
    assert abs(scale_neighbours(1.0)[1] - q) < 1e-15
    p = BakePolicy(threshold=2, scale=1.0, method="scan")
    got = [(n.threshold, n.scale, n.method) for n in neighbour_policies(p, deepest=3)]
    assert got == [(3, 1.0, "scan"), (1, 1.0, "scan"), (2, r, "scan"), (2, q, "scan")]
    # the slider moved last first, in its direction
    down = neighbour_policies(p, 3, previous=BakePolicy(threshold=3))
    assert [(n.threshold, n.scale) for n in down][:2] == [(1, 1.0), (3, 1.0)]
    up = neighbour_policies(p, 3, previous=BakePolicy(threshold=2, scale=r))
    assert [(n.threshold, n.scale) for n in up] == [(2, q), (2, r), (3, 1.0), (1, 1.0)]
    top = BakePolicy(threshold=4, scale=2.0)
    assert [(n.threshold, n.scale) for n in neighbour_policies(top, 3)] == [(3, 2.0), (4, 2.0**0.75)]
    assert neighbour_policies(BakePolicy(budget_mb=4.0), 3) == []  # the baker picks threshold and scale


def test_bake_worker_prewarms_the_neighbours_so_the_next_step_is_a_cache_hit():
    """Idle, the worker bakes the last policy's neighbours (threshold +-1, the ladder scales on
    either side) into the Baker's caches, publishing nothing; a step to any of them then finds its
    pages cached: no resampling, no seam pass, no blit."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from tests.test_bake import grid_scene_solution
    from viewer.bake_worker import BakeSource, BakeWorker, neighbour_policies

    sol = grid_scene_solution()
    deepest = int(sol.patch_depth().max())
    baker = Baker(sol)
    start = BakePolicy(threshold=1)
    w = BakeWorker(baker)
    try:
        w.submit(start)
        assert w.wait(60) and w.wait_warm(60)
        assert w.poll().policy == start and w.poll() is None  # only the real request is published
        hoods = neighbour_policies(start, deepest)
        assert len(hoods) == 4 and w.prewarmed == 4 and w.bakes == 1
        assert [p for p, _, done in w.prewarm_log] == hoods and all(done for _, _, done in w.prewarm_log)
        resampled = baker.tiles.tiles_scaled
        for n in hoods:  # each step the slider can take next: the pages are cached
            hits = baker.stats["pages_hits"]
            w.prewarm = False  # measure the step alone (no pre-warm of its own neighbours)
            w.submit(n)
            assert w.wait(60)
            r = w.poll()
            assert r.error is None and r.policy == n
            assert baker.stats["pages_hits"] == hits + 1, n
            assert r.baked.timings["tiles"] == 0.0 and "scale" not in r.baked.timings
            assert "seams" not in r.baked.timings and "blit" not in r.baked.timings
        assert baker.tiles.tiles_scaled == resampled  # nothing resampled since the pre-warm
    finally:
        w.close()

    # the viewer's first bake (made by OpenJob) seeds the pre-warm as soon as the worker starts
    baker2 = Baker(sol)
    baker2.bake(start)
    w = BakeWorker(baker2, warm_from=start)
    try:
        assert w.wait_warm(60) and w.prewarmed == 4 and w.bakes == 0
        w.prewarm = False
        w.submit(BakePolicy(threshold=2))
        assert w.wait(60) and w.poll().baked.timings["tiles"] == 0.0
        # a new source (a re-solve's result) is not pre-warmed: it would compete with the re-solve
        w.prewarm = True
        w.submit(BakePolicy(threshold=2), BakeSource(sol))
        assert w.wait(60) and w.wait_warm(60) and w.poll().error is None
        assert w.prewarmed == 4 and w.baker is not baker2
    finally:
        w.close()


class _SlowNeighbourBaker:
    """Stands in for a Baker with a solution: real requests return at once; a pre-warm bake (one
    that passes ``progress``) waits on ``gate`` and then reports progress, as Baker.bake does
    between its stages (False: cancelled)."""

    def __init__(self, deepest: int = 4):
        import threading
        from types import SimpleNamespace

        self.solution = SimpleNamespace(patch_depth=lambda: np.array([0, deepest]))
        self.calls: list[tuple[str, int, float]] = []
        self.gate = threading.Event()
        self.started = threading.Event()

    def bake(self, policy, progress=None):
        from types import SimpleNamespace

        from iat.errors import Cancelled

        kind = "real" if progress is None else "warm"
        self.calls.append((kind, policy.threshold, policy.scale))
        if progress is not None:
            self.started.set()
            self.gate.wait(10)
            if progress(0.5, "tiles") is False:
                raise Cancelled("bake cancelled")
        return SimpleNamespace(policy=policy, timings={})


def test_a_request_made_during_prewarm_is_served_first():
    """A request submitted while a neighbour is being pre-warmed: the neighbour's bake stops at its
    next stage, the request is baked next, the old policy's other neighbours are dropped, and the
    new policy's neighbours are pre-warmed after it."""
    from iat.bake.policy import BakePolicy
    from viewer.bake_worker import BakeWorker

    baker = _SlowNeighbourBaker()
    w = BakeWorker(baker)
    try:
        w.submit(BakePolicy(threshold=2))
        assert baker.started.wait(10)  # baked 2, now pre-warming its first neighbour (3)
        assert w.poll().policy.threshold == 2
        assert not w.busy and w.warming  # pre-warming is not "busy": the UI shows no re-bake
        w.submit(BakePolicy(threshold=0))
        assert w.busy
        baker.gate.set()
        assert w.wait(10)
        r = w.poll()
        assert r.policy.threshold == 0 and r.error is None
        assert baker.calls[:3] == [("real", 2, 1.0), ("warm", 3, 1.0), ("real", 0, 1.0)]
        assert w.prewarm_cancelled == 1
        assert w.wait_warm(10)
        # then the new policy's neighbours (threshold 1 first: 0 is the bottom), none of the old's
        rest = baker.calls[3:]
        assert rest[0] == ("warm", 1, 1.0) and all(k == "warm" for k, _, _ in rest)
        assert {t for _, t, s in rest if s == 1.0} == {1} and len(rest) == 3
        assert w.prewarmed == 3 and w.bakes == 2
    finally:
        baker.gate.set()
        w.close()
    assert not w.alive


def test_open_job_solves_caches_and_reports_errors(tmp_path, monkeypatch):
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions
    from viewer.bake_worker import BakeWorker
    from viewer.jobs import OpenJob
    from viewer.state import default_model

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    opts = SolveOptions(max_depth=2)
    job = OpenJob(default_model(), opts, BakePolicy(threshold=0))
    assert job.join(120) and job.error is None, job.error
    first = job.result
    assert first.solution.max_depth == 2 and not first.from_cache and first.solve_seconds > 0
    assert first.baked.memory.patches_textured == first.scene.n_patches
    assert job.fraction == 1.0

    again = OpenJob(default_model(), opts, BakePolicy(threshold=0))
    assert again.join(120) and again.error is None
    assert again.result.from_cache.startswith(str(tmp_path / "cache"))
    np.testing.assert_array_equal(again.result.solution.vert_radiance, first.solution.vert_radiance)

    # the opened model's Baker re-bakes on the worker: all mesh above the deepest tree
    w = BakeWorker(first.baker)
    try:
        deepest = int(first.solution.patch_depth().max())
        w.submit(BakePolicy(threshold=deepest + 1))
        assert w.wait(30)
        m = w.poll().baked.memory
        assert m.texture_bytes == 0 and m.triangles_mesh_part == len(first.solution.tri_vertices)
    finally:
        w.close()

    bad = tmp_path / "broken.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00 nonsense")
    for path in (bad, tmp_path / "missing.glb"):
        j = OpenJob(path, opts, BakePolicy())
        assert j.join(60)
        assert j.result is None and path.name in j.error


def test_open_job_cancel_stops_the_solve(tmp_path, monkeypatch):
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions
    from viewer.jobs import OpenJob
    from viewer.state import default_model

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    job = OpenJob(default_model(), SolveOptions(max_depth=8), BakePolicy())
    deadline = time.monotonic() + 60
    while not job.solving and not job.done and time.monotonic() < deadline:
        time.sleep(0.01)
    job.cancel()
    t0 = time.monotonic()
    assert job.join(60)
    assert time.monotonic() - t0 < 30  # far less than a depth-8 solve
    assert job.result is None and "cancelled" in job.error
    assert not list((tmp_path / "cache").glob("*.npz"))  # a cancelled solve is not cached


def test_open_job_reports_the_load_and_cancels_it(tmp_path, monkeypatch):
    """G2: the open job shows the model load's progress (``loading: ...``) and a cancel stops the load."""
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions
    from viewer.jobs import OpenJob
    from viewer.state import default_model

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    seen = []
    original = OpenJob.load_progress

    def spy(self, fraction, message):
        seen.append((fraction, message))
        if message == "welding vertices":
            self.cancel()  # as the Cancel button would, mid-load
        keep_going = original(self, fraction, message)
        seen.append((self.fraction, self.message, self.eta is None or self.eta >= 0))
        return keep_going

    monkeypatch.setattr(OpenJob, "load_progress", spy)
    job = OpenJob(default_model(), SolveOptions(max_depth=2), BakePolicy())
    assert job.join(60)
    assert job.result is None and job.error == f"{default_model()}: cancelled"
    fraction = seen[-2][0]
    assert 0 < fraction < 1 and seen[-2:] == [
        (fraction, "welding vertices"),
        (fraction, "loading: welding vertices", True),
    ]
    assert [m for _, m in seen[0::2]] == ["reading cornell_box.glb", "placing geometry", "welding vertices"]
    assert not job.solving and not list((tmp_path / "cache").glob("*.npz"))
