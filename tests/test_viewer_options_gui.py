"""The viewer's solve options for the next model opened (Model panel) through the real UI (imgui test
engine under Xvfb; runs alone in a child process, see tests/conftest.py): the ambient term's rays set
there reach the solve of the model opened next."""

from __future__ import annotations

import pytest

from tests.conftest import run_gui, wait_until
from tests.test_real_daylight import write_case


@pytest.mark.gui
def test_ambient_rays_reach_the_next_solve(tmp_path, monkeypatch, gui_child):
    if gui_child():
        return
    from iat.radiosity import SolveOptions
    from viewer.app import ViewerApp

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    first, second = write_case("tidy", tmp_path / "a"), write_case("no_ground", tmp_path / "b")
    app = ViewerApp(first, size=(1280, 800), solve_options=SolveOptions(max_depth=2), idle=False)
    s = app.state
    got: dict = {}

    def drive(ctx) -> None:
        wait_until(ctx, lambda: s.model.baked is not None and not s.jobs.opening, 300, "the model")
        got["before"] = s.model.solution.options["ambient_rays"]
        ctx.window_focus("//Model")
        ctx.item_input_value("//Model/Ambient rays", 100)
        s.requests.open = str(second)
        wait_until(
            ctx, lambda: s.model.path == str(second) and s.model.baked is not None, 300, "the next model"
        )
        wait_until(ctx, lambda: not s.jobs.opening, 300, "the next model's solve")
        got["after"] = s.model.solution.options["ambient_rays"]

    run_gui(app, drive)
    assert (got["before"], got["after"]) == (256, 100)
