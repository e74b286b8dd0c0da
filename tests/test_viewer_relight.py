"""The viewer's re-solve after a light edit: progress the panel can show (step, fraction, an ETA
from the measured rate) and a Cancel that drops the edit's re-solve (issue 20). No display needed."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "sample_models" / "cornell_box.glb"


@pytest.fixture(scope="module")
def solved():
    from iat.io.load import load_scene
    from iat.radiosity import SolveOptions, solve

    scene = load_scene(CORNELL)
    return scene, solve(scene, SolveOptions(max_depth=3))


def brighter(scene):
    from iat.lighting.editor import LightEditor

    ed = LightEditor(scene)
    for m in ed.emissive():
        ed.set_strength(m, 2.0)
    return ed.scene


def test_a_re_solve_reports_its_steps_and_progress(solved):
    from viewer.relight import ProgressRelighter

    scene, sol = solved
    rl = ProgressRelighter(sol, scene)
    try:
        assert rl.eta is None and rl.step == 0
        rl.submit(brighter(scene), 1)
        results = []
        end = time.monotonic() + 300
        while (rl.busy or not results) and time.monotonic() < end:
            r = rl.poll()
            if r is not None:
                results.append(r)
            time.sleep(0.01)
        r = rl.poll()
        results += [r] if r is not None else []
        assert results and results[-1].final and results[-1].error is None
        assert rl.step >= results[-1].steps  # one progress step per solve step
        assert rl.fraction == pytest.approx(1.0, abs=0.05)
        assert not rl.cancelled
    finally:
        rl.close()


def test_cancel_drops_the_edit_and_says_so(solved):
    from viewer.relight import ProgressRelighter

    scene, sol = solved
    rl = ProgressRelighter(sol, scene)
    try:
        rl.cancel()  # before the first progress report: nothing of this edit is published
        rl.submit(brighter(scene), 1)
        assert not rl.cancelled  # a new edit clears a cancel before it
        rl.cancel()
        assert rl.cancelled
        assert rl.wait(120)
        assert rl.poll() is None
        assert rl.cancelled
    finally:
        rl.close()


def test_the_eta_is_the_measured_rate():
    from viewer.relight import ProgressRelighter

    rl = ProgressRelighter.__new__(ProgressRelighter)  # the arithmetic alone, no thread
    rl.fraction, rl.step_started = 0.01, time.perf_counter() - 1.0
    assert rl.eta is None  # too little measured
    rl.fraction, rl.step_started = 0.25, time.perf_counter() - 10.0
    assert rl.eta == pytest.approx(30.0, rel=0.01)  # 10 s for a quarter: 30 s for the rest
