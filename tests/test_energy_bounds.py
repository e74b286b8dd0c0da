"""Numerics that cannot blow up (issue 36): coincident duplicate faces, near-white materials, and a
solve that breaks the albedos' energy bound stopping with one line."""

import warnings

import numpy as np
import pytest

from iat.errors import IATWarning, SolveError
from iat.io.load import load_scene
from iat.io.scene import Material
from iat.radiosity import SolveOptions, solve
from tests.support.quads import box_quads, scene_of


def _furnace_obj(tmp_path, albedo: float, copies: int):
    """A closed unit box, 6 x 2 x 2 inward quads, each written ``copies`` times, all emitting 1."""
    quads = [q for *_, q in box_quads([0, 0, 0], [1, 1, 1], 2, True)]
    v, f = [], []
    for q in quads:
        base = len(v)
        v.extend(q)
        f.extend([[base + 1, base + 2, base + 3, base + 4]] * copies)
    (tmp_path / "f.mtl").write_text(f"newmtl white\nKd {albedo} {albedo} {albedo}\nKe 1 1 1\n")
    lines = ["mtllib f.mtl", "usemtl white"] + [f"v {x} {y} {z}" for x, y, z in v]
    lines += ["f " + " ".join(map(str, face)) for face in f]
    path = tmp_path / "furnace.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_near_white_furnace_with_duplicated_faces_is_the_analytic_value(tmp_path):
    """Albedo 0.97, every face written twice: the copies are dropped on load (with a warning), and
    the furnace's radiance is the analytic 1 / (1 - 0.97) = 33.3 (a doubled face used to double the
    light at every bounce: radiance 1e164 after 3 000 shots)."""
    path = _furnace_obj(tmp_path, 0.97, copies=2)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        scene = load_scene(path, panels=False)
    assert any("dropped 48 faces repeating another in the same place" in str(w.message) for w in rec)
    assert scene.n_patches == 24
    sol = solve(scene, SolveOptions(max_depth=2, convergence=1e-3, max_shots=4000))
    assert np.allclose(sol.vert_radiance, 1.0 / (1.0 - 0.97), rtol=0.01)


def test_a_solve_that_diverges_stops_with_one_line():
    """Coincident duplicates built in memory (past the loader) in a closed albedo-0.5 box: the light
    doubles at each bounce; the solve stops with a SolveError naming the bound instead of writing
    a solution 60 times too bright."""
    quads = [q for *_, q in box_quads([0, 0, 0], [1, 1, 1], 2, True)]
    quads = quads + [q.copy() for q in quads]
    scene = scene_of(quads, [0] * len(quads), [Material("grey", albedo=np.full(3, 0.5), emission=np.ones(3))])
    with pytest.raises(
        SolveError, match=r"the solve diverged after \d+ shots: \w+ power .* W exceeds the .* W"
    ):
        solve(scene, SolveOptions(max_depth=2, convergence=1e-3, max_shots=3000))


@pytest.mark.parametrize("albedo", [0.95, 0.99])
def test_near_white_closed_room_stays_bounded(albedo):
    """A closed box at a near-white albedo lit by its ceiling: the solve converges, no error, and
    its reflected light stays under what the albedo allows (rho / (1 - rho) of the received)."""
    from tests.test_radiosity import lit_box

    sol = solve(lit_box(albedo), SolveOptions(max_depth=3, convergence=0.01, max_shots=20000))
    r = sol.stats
    assert np.isfinite(sol.vert_radiance).all() and r["unshot_fraction"] <= 0.011
    assert not r.get("renormalised_shots")


def test_the_repeated_faces_warning_is_one_line(tmp_path):
    path = _furnace_obj(tmp_path, 0.5, copies=3)
    with pytest.warns(
        IATWarning, match=r"furnace\.obj: dropped 96 faces repeating another in the same place$"
    ):
        load_scene(path, panels=False)
