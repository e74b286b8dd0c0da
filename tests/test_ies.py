"""IES LM-63 luminaires (issue 39): parsing, the distribution in the direct pass (illuminance at
given angles, against the analytic distribution) and when shooting (a closed room's average)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from iat.errors import LoadError
from iat.io.ies import parse_ies, read_ies
from iat.io.scene import Material
from iat.measure import photometry as ph
from iat.radiosity import SolveOptions, solve
from tests.test_photometry import box_quads, grid_quads, scene_of

PEAK = 1000.0


def distribution(gamma_deg, c_deg):
    """cd: ``1000 cos^2(gamma) (1 + 0.5 cos 2C) / 1.5`` below the horizon, 0 above: a downlight
    twice as strong along C = 0/180 as along C = 90/270."""
    g, c = np.radians(gamma_deg), np.radians(c_deg)
    return np.where(g <= np.pi / 2, PEAK * np.cos(g) ** 2 * (1 + 0.5 * np.cos(2 * c)) / 1.5, 0.0)


def ies_text(step_v=2.5, step_h=5.0, multiplier=1.0) -> str:
    """The LM-63 file of :func:`distribution` (its candela times ``multiplier``)."""
    v = np.arange(0.0, 180.0 + 1e-9, step_v)
    h = np.arange(0.0, 360.0 + 1e-9, step_h)
    cd = distribution(v[None, :], h[:, None])
    head = ["IESNA:LM-63-2002", "[TEST] issue 39", "[MANUFAC] none", "TILT=NONE"]
    nums = [1, -1, multiplier, len(v), len(h), 1, 2, 0.1, 0.1, 0.0, 1.0, 1.0, 30.0, *v, *h, *cd.ravel()]
    rows = [" ".join(f"{x:.6g}" for x in nums[k : k + 10]) for k in range(0, len(nums), 10)]
    return "\n".join(head + rows) + "\n"


def test_parse_an_lm63_file_and_its_symmetries(tmp_path):
    p = parse_ies(ies_text(), "test.ies")
    assert p.peak == pytest.approx(PEAK)
    assert p.candela.shape == (73, 73)
    g, c = [0, 30, 60, 95], [0, 90, 45, 0]
    np.testing.assert_allclose(p.candela_at(g, c), distribution(g, c), rtol=1e-5)  # (6 digits in the file)
    # the flux: integral of I dw = 1000 / 1.5 x 2 pi / 3 (the cos 2C term integrates to zero)
    assert p.solid_angle() * p.peak == pytest.approx(PEAK * 2 * math.pi / 4.5, rel=0.01)
    # one horizontal angle: axially symmetric
    axial = parse_ies("TILT=NONE\n1 -1 2 3 1 1 2 0 0 0 1 1 10\n0 45 90\n0\n100 50 0\n")
    assert axial.peak == 200.0  # the multiplier
    np.testing.assert_allclose(axial.candela_at([22.5, 22.5], [0, 200]), [150.0, 150.0])
    quad = parse_ies("TILT=NONE\n1 -1 1 2 2 1 2 0 0 0 1 1 10\n0 90\n0 90\n100 0 60 0\n")  # 0-90: quadrants
    np.testing.assert_allclose(quad.candela_at([0, 0, 0, 0], [0, 180, 90, 270]), [100, 100, 60, 60])
    with pytest.raises(ValueError, match="TILT"):
        parse_ies("IESNA91\n1 2 3\n")
    with pytest.raises(ValueError, match="type 2"):
        parse_ies("TILT=NONE\n1 -1 1 2 1 2 2 0 0 0 1 1 10\n0 90\n0\n100 0\n")
    bad = tmp_path / "bad.ies"
    bad.write_text("TILT=NONE\n1 -1 1 5 5 1 2 0 0 0 1 1 10\n0 90\n")
    with pytest.raises(LoadError, match="bad.ies.*announced"):
        read_ies(bad)


def test_non_isotropic_distribution_gives_the_illuminance_at_given_angles(tmp_path):
    """The downlight 2.5 m over a 6 x 6 m floor, its C = 0 plane along +X: at every floor vertex
    E = I(gamma, C) cos gamma / d^2 with I the analytic distribution (tolerance 2 %; the table's
    2.5 x 5 degree steps interpolate it to 0.3 %)."""
    f = tmp_path / "downlight.ies"
    f.write_text(ies_text())
    light = ph.ies_light(read_ies(f), position=[0.3, 2.5, -0.2])
    assert ph.light_candela(light) == pytest.approx(PEAK)
    floor = grid_quads(-3, 3, -3, 3, 0.0, 2, 2)
    scene = scene_of(floor, [0] * 4, [Material("floor", albedo=np.full(3, 0.5))], [light])
    sol = solve(scene, SolveOptions(max_depth=4, max_shots=0))
    d = sol.vert_position - light.position
    r = np.linalg.norm(d, axis=1)
    gamma = np.degrees(np.arccos(-d[:, 1] / r))
    c = np.degrees(np.arctan2(d[:, 2], d[:, 0]))
    expected = distribution(gamma, c) * (-d[:, 1] / r) / r**2
    got = ph.vertex_illuminance(sol)
    lit = expected > 1.0
    assert lit.sum() > 100 and (got[~lit] < 1.5).all()
    np.testing.assert_allclose(got[lit], expected[lit], rtol=0.02)
    # not isotropic: the same law with the distribution's C-mean (C = 45) misses by 30 % and more
    iso = distribution(gamma, 45.0) * (-d[:, 1] / r) / r**2
    assert np.abs(got[lit] / iso[lit] - 1).max() > 0.3


def test_a_closed_rooms_average_counts_the_ies_flux_when_shooting():
    """The downlight in a closed 4 x 3 x 5 m room (albedo 0.5): the area mean illuminance is
    Phi / (A (1 - rho)) with Phi = peak x the distribution's solid angle (2 %)."""
    light = ph.ies_light(parse_ies(ies_text()), position=[1.7, 2.6, 2.2])
    quads = [q for *_, q in box_quads([0, 0, 0], [4, 3, 5], 3)]
    scene = scene_of(quads, [0] * len(quads), [Material("grey", albedo=np.full(3, 0.5))], [light])
    sol = solve(scene, SolveOptions(max_depth=4, convergence=0.01))
    phi = ph.light_lumens(light)
    assert phi == pytest.approx(PEAK * 2 * math.pi / 4.5, rel=0.01)
    area = 2 * (4 * 3 + 4 * 5 + 3 * 5)
    mean = ph.surface_mean(sol, ph.vertex_illuminance(sol))["mean"]
    assert mean == pytest.approx(phi / (area * 0.5), rel=0.02)


def test_a_gltf_light_names_its_ies_file_in_extras(tmp_path):
    """``KHR_lights_punctual`` point light with ``extras.ies``: loaded with the distribution, its
    intensity the file's peak candela through the one conversion (``ies_scale`` times it); its
    light on a floor follows the file (the same figures as a light made with ``ies_light``)."""
    from iat.io.load import load_scene
    from tests.support.scene_files import Gltf

    (tmp_path / "downlight.ies").write_text(ies_text())
    g = Gltf()
    floor = np.array([[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]], dtype=float)  # faces +Y
    g.node(mesh=g.mesh(floor, [[0, 1, 2], [2, 3, 0]], material=g.material()))
    extras = {"ies": "downlight.ies", "ies_scale": 2.0}
    li = g.light({"type": "point", "intensity": 5.0, "color": [1, 1, 1], "extras": extras})
    # a node's -Z is the light's direction: turned -90 degrees about X it points down (the nadir)
    q = [-math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]
    g.node(translation=[0.3, 2.5, -0.2], rotation=q, extensions={"KHR_lights_punctual": {"light": li}})
    scene = load_scene(g.save(tmp_path / "lit.gltf"))
    (light,) = scene.lights
    assert light.ies is not None and light.ies.name == "downlight.ies"
    np.testing.assert_allclose(light.direction, [0, -1, 0], atol=1e-9)
    assert ph.light_candela(light) == pytest.approx(2 * PEAK)
    sol = solve(scene, SolveOptions(max_depth=3, max_shots=0))
    d = sol.vert_position - light.position
    r = np.linalg.norm(d, axis=1)
    gamma = np.degrees(np.arccos(-d[:, 1] / r))
    c = np.degrees(np.arctan2(d[:, 2], d[:, 0]))
    expected = 2 * distribution(gamma, c) * (-d[:, 1] / r) / r**2
    lit = expected > 1.0
    np.testing.assert_allclose(ph.vertex_illuminance(sol)[lit], expected[lit], rtol=0.02)
    (tmp_path / "downlight.ies").write_text("TILT=NONE\n1 2\n")
    with pytest.raises(LoadError, match="downlight.ies"):
        load_scene(tmp_path / "lit.gltf")


def test_light_edits_keep_the_distribution_and_the_viewer_loads_one(tmp_path):
    """Moving or recolouring a light keeps its IES distribution; ``viewer.lights.load_ies`` gives a
    light one at the file's peak (the status line says so), and a bad file raises one line naming
    it, the light unchanged."""
    from iat.errors import IATError
    from iat.lighting.editor import LightEditor
    from iat.lighting.edits import edit_light
    from viewer.lights import load_ies

    light = ph.ies_light(parse_ies(ies_text(), "d.ies"), position=[1.0, 2.0, 1.0])
    scene = scene_of(grid_quads(0, 2, 0, 2, 0.0, 1, 1), [0], [Material("f", albedo=np.full(3, 0.5))], [light])
    moved = edit_light(scene, 0, position=[0.5, 2.0, 0.5], color=[1.0, 0.9, 0.8])
    assert moved.lights[0].ies is light.ies
    ed = LightEditor(edit_light(scene, 0, ies=None, intensity=1.0))
    (tmp_path / "bad.ies").write_text("TILT=NONE\n1 2\n")
    with pytest.raises(IATError, match="bad.ies") as e:
        load_ies(ed, 0, tmp_path / "bad.ies")
    assert "\n" not in str(e.value) and ed.lights[0].ies is None and ed.version == 0
    (tmp_path / "down.ies").write_text(ies_text(multiplier=2.0))
    status = load_ies(ed, 0, tmp_path / "down.ies")
    assert ed.lights[0].ies.name == "down.ies" and ph.light_candela(ed.lights[0]) == pytest.approx(2 * PEAK)
    assert "down.ies" in status and "2000 cd peak" in status


def test_resolve_carries_a_lights_ies_distribution():
    """``resolve`` after an IES downlight in a closed room (albedo 0.5) is turned up by 30 % continues
    the solve and gives the fresh solve's mean illuminance within 1 %: the light added is the
    difference, with its distribution (a record without one took the difference for a uniform light,
    8 times the power, and solved afresh)."""
    from dataclasses import replace

    from iat.radiosity import resolve

    light = ph.ies_light(parse_ies(ies_text()), position=[1.7, 2.6, 2.2])
    quads = [q for *_, q in box_quads([0, 0, 0], [4, 3, 5], 3)]
    mats = [Material("grey", albedo=np.full(3, 0.5))]
    opts = SolveOptions(max_depth=3, convergence=0.01)
    base = solve(scene_of(quads, [0] * len(quads), mats, [light]), opts)
    brighter = replace(light, intensity=1.3 * light.intensity)
    scene = scene_of(quads, [0] * len(quads), mats, [brighter])
    fresh, again = solve(scene, opts, mesh=base), resolve(base, scene, opts)
    assert again.stats["mode"] == "resolve"
    assert again.stats["changed_power_fraction"] == pytest.approx(0.3 / 1.3)
    got, want = (ph.surface_mean(s, ph.vertex_illuminance(s))["mean"] for s in (again, fresh))
    assert got == pytest.approx(want, rel=0.01)
