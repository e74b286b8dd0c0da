"""Shared test fixtures.

- ``egl_ctx``: one headless moderngl context (EGL, Mesa llvmpipe here) for the
  whole session; tests skip cleanly when EGL is unavailable.
- ``--regen-refs``: rewrite reference images under ``tests/refs/`` instead of
  comparing against them (never edit a reference by hand); ``reference_image``
  is the fixture that does either.
- GUI end-to-end tests (``@pytest.mark.gui``) skip without a display; the
  ``gui_child`` fixture re-runs such a test alone in a child process (Mesa aborts
  when a GLX window context is made in a process that holds ``egl_ctx``), and
  :func:`run_gui`, :func:`wait_until` drive the app under imgui-bundle's test engine.
- ``renderer``: a module's :class:`iat.render.renderer.Renderer` on ``egl_ctx`` (modules
  that check the GL state after it define their own).
- ``stability_figures``: writes the stability catalogue's recorded figures to JSON after
  each ``tests/test_stability_*.py`` module (see ``tests/support/stability.py``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

REFS = Path(__file__).parent / "refs"
HAS_DISPLAY = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
GUI_CHILD_ENV = "IAT_GUI_CHILD"  # set to "1" in the child process of a GUI test


def pytest_addoption(parser):
    parser.addoption(
        "--regen-refs",
        action="store_true",
        default=False,
        help="rewrite the reference images in tests/refs/ from the current code instead of comparing",
    )


def pytest_configure(config):
    # iat.measure.reference.render_reference_cached reads this to re-render Mitsuba references
    if config.getoption("--regen-refs"):
        import os

        os.environ["IAT_REGEN_REFS"] = "1"


def pytest_runtest_setup(item):
    if item.get_closest_marker("gui") is not None and not HAS_DISPLAY:
        pytest.skip("no DISPLAY: run under xvfb-run (make test does)")


@pytest.fixture
def gui_child(request):
    """``run() -> bool``: in the test process, run this test alone in a child process, assert it
    passed and return True (the test then returns at once); in that child, return False (the test
    runs its body). Mesa aborts when a GLX window context is made in a process that already holds
    the session's EGL context (``egl_ctx``), so a window test must not run beside it."""

    def run() -> bool:
        if os.environ.get(GUI_CHILD_ENV) == "1":
            return False
        r = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", request.node.nodeid],
            cwd=request.config.rootpath,
            env={**os.environ, GUI_CHILD_ENV: "1"},
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert r.returncode == 0, r.stdout[-6000:] + r.stderr[-3000:]
        assert " passed" in r.stdout, r.stdout[-3000:]
        return True

    return run


def wait_until(ctx, cond, seconds: float, what: str) -> None:
    """Yield frames of the imgui test engine's ``ctx`` until ``cond()``; fail after ``seconds``."""
    end = time.monotonic() + seconds
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {seconds} s waiting for {what}")
        ctx.yield_()


def _relaxed_watchdog() -> None:
    """The engine stops a test after 60 s; a loaded machine (llvmpipe) can be slower than that."""
    from imgui_bundle import hello_imgui, imgui

    io = imgui.test_engine.get_io(hello_imgui.get_imgui_test_engine())
    io.config_watchdog_warning = 300.0
    io.config_watchdog_kill_test = 600.0


def run_gui(app, drive) -> float:
    """Run the viewer ``app`` with ``drive(ctx)`` as the test engine's test (relaxed watchdog);
    returns the seconds it took."""
    from imgui_bundle.immapp import testing

    params = app.runner_params()
    params.callbacks.register_tests = _relaxed_watchdog
    t0 = time.monotonic()
    testing.run(test_function=drive, runner_params=params, add_ons_params=app.addons())
    return time.monotonic() - t0


@pytest.fixture(scope="session")
def regen_refs(request) -> bool:
    return bool(request.config.getoption("--regen-refs"))


@pytest.fixture(scope="session")
def egl_ctx():
    """A standalone moderngl context on EGL, shared by the session; skips when there is none."""
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as e:  # no libEGL, no device
        pytest.skip(f"no EGL OpenGL context: {e}")
    yield ctx
    ctx.release()


@pytest.fixture(scope="module")
def renderer(egl_ctx):
    from iat.render.renderer import Renderer

    r = Renderer(egl_ctx)
    yield r
    r.release()


@pytest.fixture(scope="module")
def stability_figures(tmp_path_factory):
    """After the module: write the figures recorded so far to ``$IAT_STABILITY_JSON``
    (default ``<pytest basetemp>/stability.json``)."""
    from tests.support.stability import write_figures

    yield
    out = os.environ.get("IAT_STABILITY_JSON") or str(tmp_path_factory.getbasetemp() / "stability.json")
    write_figures(Path(out))


@pytest.fixture
def reference_image(regen_refs):
    """``check(name, image, atol)``: compare a float image with ``tests/refs/<name>.npy``.

    With ``--regen-refs`` the reference is (re)written and the check passes; a
    missing reference skips the test with a reason saying how to make it.
    """

    def check(name: str, image: np.ndarray, atol: float) -> None:
        path = REFS / f"{name}.npy"
        image = np.asarray(image, dtype=np.float32)
        if regen_refs:
            from iat.io.images import save_npy

            save_npy(path, image)
            return
        if not path.is_file():
            pytest.skip(f"reference {path.name} missing: run pytest --regen-refs to create it")
        ref = np.load(path, allow_pickle=False)
        assert ref.shape == image.shape, f"{path.name}: shape {image.shape} != reference {ref.shape}"
        err = float(np.abs(ref - image).max()) if ref.size else 0.0
        assert err <= atol, f"{path.name}: max abs difference {err:.3g} > {atol}"

    return check
