"""Shadow cuts of lights added after loading (issues 36 and 37): a sun that the default daylight or
``--sun`` gives a model is cut along as the file's own lights are, a sheet's two faces are cut alike,
and a solution's model reloads cut the same (``stats["shadow_cuts"]``, ``stats["load"]``).

The model is the window-lit room of ``tests/test_real_daylight.py`` (an OBJ of one-sided sheets;
under ``sides="both"`` each gets a back face, its twin)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from iat.cli.commands import main
from iat.geometry.discontinuity import cut_new_lights, shadow_key
from iat.geometry.sides import twin_index
from iat.io.load import load_scene
from iat.lighting.daylight_default import apply_daylight
from iat.radiosity import Solution, SolveOptions, solve
from iat.radiosity.inputs import open_solution
from tests.test_real_daylight import TODAY, write_case


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return write_case("tidy", tmp_path_factory.mktemp("room"))


def _load(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(path, **kw)


def _unpaired(scene) -> int:
    return int((twin_index(scene.corner_positions, scene.patch_is_quad)[0] < 0).sum())


def test_a_sun_added_after_loading_is_cut_and_twins_stay_twins(room):
    """The default daylight's sun through the window: the floor and the walls it falls on are cut
    along the patch's edges, each front piece with a back piece in the same place (the renderer and
    the ambient term pair them: a piece without its twin would fight its back face in depth), and
    a second call finds nothing new to cut."""
    scene = _load(room, sides="both")
    apply_daylight(scene, today=TODAY)
    sun = next(lt for lt in scene.lights if lt.kind == "directional")
    assert scene.shadow_cuts == []
    cut = cut_new_lights(scene)
    assert cut.n_patches > scene.n_patches + 8
    assert _unpaired(cut) == _unpaired(scene)
    assert cut.shadow_cuts == [[shadow_key(sun)]]
    assert abs(cut.patch_area.sum() - scene.patch_area.sum()) < 1e-9 * scene.patch_area.sum()
    assert cut_new_lights(cut) is cut


def test_a_solution_reopens_on_the_roots_it_was_solved_on(room, tmp_path):
    """``iat solve --sides both`` of a model without lights: the default daylight's sun is cut along
    and the loader's choices are recorded, so the solution opens on the same roots (before, the
    model reloaded had other roots: refused as changed)."""
    out = tmp_path / "room.npz"
    assert main(["solve", str(room), "--sides", "both", "--quality", "draft", "-o", str(out)]) == 0
    sol = Solution.load(out)
    assert sol.stats["load"] == {"sides": "both", "cut": "all"}  # (cut auto: contacts too under --sides both)
    assert len(sol.stats["shadow_cuts"]) == 1 and sol.stats["shadow_cuts"][0][0][0] == "directional"
    scene, again = open_solution(out)
    plain = _load(room, sides="both")
    assert scene.n_patches == len(again.patch_is_quad) > plain.n_patches
    np.testing.assert_array_equal(scene.corner_positions, again.patch_corners)


def test_a_scene_solved_uncut_reopens_uncut(room, tmp_path):
    """Loaded through the API without discontinuity meshing and solved with the options' default
    (on), the solution records no cut and reopens on the loaded roots."""
    scene = _load(room, cut="all")
    apply_daylight(scene, today=TODAY)
    sol = solve(scene, SolveOptions.preset("draft"))
    assert sol.options["discontinuity"] and sol.stats["shadow_cuts"] == []
    sol.model_path = str(room)
    sol.save(tmp_path / "s.npz")
    again, _ = open_solution(tmp_path / "s.npz")
    assert again.n_patches == scene.n_patches and again.pierce.mode == "all"
