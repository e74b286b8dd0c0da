"""The Cornell box from its own camera in preview mode (unlit: emission + ambient x albedo)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from iat.io.load import load_scene
from iat.render.renderer import PREVIEW_AMBIENT, Renderer

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cornell_preview(egl_ctx):
    import sys

    sys.path.insert(0, str(ROOT))
    from sample_models.cornell_box import GREEN, RED

    scene = load_scene(ROOT / "sample_models" / "cornell_box.glb")
    r = Renderer(egl_ctx)
    try:
        r.set_scene(scene)
        img = r.render(scene.cameras[0], size=(128, 128), mode="preview")
    finally:
        r.release()
    assert egl_ctx.error == "GL_NO_ERROR"
    return img, np.array(RED), np.array(GREEN)


def test_red_left_wall_and_green_right_wall(cornell_preview):
    img, red, green = cornell_preview
    # pixels at mid height, 5 % in from each side: the side walls from the original camera
    left, right = img[64, 6], img[64, 121]
    np.testing.assert_allclose(left, PREVIEW_AMBIENT * red, rtol=1e-3)
    np.testing.assert_allclose(right, PREVIEW_AMBIENT * green, rtol=1e-3)


def test_light_is_brightest_and_at_the_top(cornell_preview):
    img, _, _ = cornell_preview
    lum = img.sum(axis=2)
    y, x = np.unravel_index(np.argmax(lum), lum.shape)
    assert y < 20 and 40 < x < 88  # the ceiling light, centred near the top
