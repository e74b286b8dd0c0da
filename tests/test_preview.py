"""A first look at new daylight (issue 41): :func:`iat.lighting.relight.preview` solves a moved sun on
the mesh on screen with :meth:`SolveOptions.preview` (the direct sun and sky with fewer rays, the
bounces from the ambient term alone), and the background re-solve publishes it before the new solve."""

from __future__ import annotations

import numpy as np
import pytest

from iat.color import LUMINANCE_WEIGHTS
from iat.errors import OptionError
from iat.lighting.edits import edit_light
from iat.lighting.relight import Relighter, preview
from iat.radiosity import SolveOptions, solve
from iat.radiosity.options import PREVIEW
from tests.support.daylight import daylit_room, room_scene

#: the sun moved from the room's SUN_DIRECTION to come in more steeply and from the other side
MOVED = -np.array([1.0, 2.0, -0.4]) / np.linalg.norm([1.0, 2.0, -0.4])


def luminance(sol) -> np.ndarray:
    return np.asarray(sol.vert_radiance) @ LUMINANCE_WEIGHTS


@pytest.fixture(scope="module")
def solved_room():
    room = daylit_room()
    opts = SolveOptions(max_depth=4)
    return room, opts, solve(room, opts)


def test_the_preview_options():
    opts = SolveOptions(max_depth=5, seed=3).preview()
    assert (opts.max_depth, opts.seed) == (5, 3)  # the rest kept
    assert {k: getattr(opts, k) for k in PREVIEW} == {
        "convergence": 0.2,
        "samples": 8,
        "ambient_rays": 64,
        "sky_samples": 64,
    }
    with pytest.raises(OptionError, match=r"^solve option sky_samples=2: must be between 4 and 4096$"):
        SolveOptions(sky_samples=2).validate()


def test_a_preview_is_the_new_sun_on_the_mesh_on_screen(solved_room):
    room, opts, base = solved_room
    moved = edit_light(room, "sun", direction=MOVED)
    pre = preview(moved, base, opts)
    assert pre.stats["mode"] == "preview" and 0 < pre.stats["shots"] < 10  # the sun patch's bounce
    np.testing.assert_array_equal(pre.vert_key, base.vert_key)  # the mesh on screen
    ref = solve(moved, opts, mesh=base)  # the same light at the options' own effort
    a, b = luminance(pre), luminance(ref)
    # measured 2.1 % apart in all, 3.3 % per vertex (the sky's 64 rays, the ambient term's 64)
    assert a.mean() == pytest.approx(b.mean(), rel=0.04)
    assert np.abs(a - b).mean() / b.mean() < 0.05
    moved_patch = np.argmax(np.abs(luminance(base) - b))  # where the sun patch moved: as the new sun
    assert abs(a[moved_patch] - b[moved_patch]) < 0.1 * abs(luminance(base)[moved_patch] - b[moved_patch])


def test_no_preview_on_other_patches(solved_room):
    room, opts, base = solved_room
    other = room_scene((4.0, 3.0, 6.0), (1.7, 3.3, 0.9, 2.1), room.materials)
    other.lights, other.sky = room.lights, room.sky
    assert preview(other, base, opts) is None


def test_the_re_solve_shows_the_preview_first(solved_room):
    room, opts, base = solved_room
    rl = Relighter(base, room, opts)
    try:
        rl.submit(edit_light(room, "sun", direction=MOVED), version=1, remesh=True)
        assert rl.wait(120)
        r = rl.poll()
        assert r.final and (r.step, r.steps, r.mode) == (2, 2, "solve")
        assert rl.steps_done == 2  # the preview was published before it
        assert rl.base is r.solution  # the next edit starts from the new solve, not the preview
    finally:
        rl.close()
