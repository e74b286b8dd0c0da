"""Shared test fixtures.

- ``egl_ctx``: one headless moderngl context (EGL, Mesa llvmpipe here) for the
  whole session; tests skip cleanly when EGL is unavailable.
- ``--regen-refs``: rewrite reference images under ``tests/refs/`` instead of
  comparing against them (never edit a reference by hand); ``reference_image``
  is the fixture that does either.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REFS = Path(__file__).parent / "refs"


def pytest_addoption(parser):
    parser.addoption(
        "--regen-refs",
        action="store_true",
        default=False,
        help="rewrite the reference images in tests/refs/ from the current code instead of comparing",
    )


def pytest_configure(config):
    # iat.reference.render_reference_cached reads this to re-render Mitsuba references
    if config.getoption("--regen-refs"):
        import os

        os.environ["IAT_REGEN_REFS"] = "1"


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
            from iat.imageio import save_npy

            save_npy(path, image)
            return
        if not path.is_file():
            pytest.skip(f"reference {path.name} missing: run pytest --regen-refs to create it")
        ref = np.load(path, allow_pickle=False)
        assert ref.shape == image.shape, f"{path.name}: shape {image.shape} != reference {ref.shape}"
        err = float(np.abs(ref - image).max()) if ref.size else 0.0
        assert err <= atol, f"{path.name}: max abs difference {err:.3g} > {atol}"

    return check
