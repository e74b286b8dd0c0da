"""iat.lighting.solution_set and the set parts of iat.bake / iat.render / the CLI: lighting states solved on
one mesh, baked into texture layers that share one atlas layout, and blended per texel (IAT) or
per vertex (mesh) on the GPU: exact at the key times, linear in between."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from iat.bake.baked import BakedSet
from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.color import srgb_encode
from iat.errors import BakeError, OptionError
from iat.io.load import load_scene
from iat.lighting.edits import add_light
from iat.lighting.save import save_gltf
from iat.lighting.solution_set import SolutionSet, blend_weights, even_times, load_set, same_mesh, solve_set
from iat.lighting.states import apply_lighting_state
from iat.radiosity import SolveOptions, solve

ROOT = Path(__file__).resolve().parents[1]
CORNELL = ROOT / "sample_models" / "cornell_box.glb"
SIZE = (96, 72)

#: the Cornell box's day: the ceiling panel alone; dusk: half the panel, a dim bulb; night: the bulb
STATES = {
    "day": {"time": 0.0, "lights": {"bulb": 0.0}},
    "dusk": {"time": 0.4, "lights": {"bulb": 0.1}, "emission": {"light": 0.5}},
    "night": {"time": 1.0, "lights": {"bulb": 0.2}, "emission": {"light": 0.0}},
}


@pytest.fixture(scope="module")
def scene():
    return add_light(load_scene(CORNELL), "point", [0.12, 0.40, 0.30], intensity=0.2, name="bulb")


@pytest.fixture(scope="module")
def sset(scene):
    return solve_set(scene, STATES, SolveOptions(max_depth=3))


@pytest.fixture(scope="module")
def bset(scene, sset):
    return Baker(sset.first, scene).bake_set(sset, BakePolicy(threshold=2))


# -- weights ---------------------------------------------------------------------------------------
def test_blend_weights_exact_at_keys_linear_between_clamped_outside():
    t = [0.0, 0.4, 1.0]
    assert blend_weights(t, 0.0) == (0, 1, 0.0)
    assert blend_weights(t, 0.4) == (1, 2, 0.0)
    assert blend_weights(t, 1.0) == (2, 2, 0.0)
    a, b, w = blend_weights(t, 0.2)
    assert (a, b) == (0, 1) and w == pytest.approx(0.5)
    a, b, w = blend_weights(t, 0.85)
    assert (a, b) == (1, 2) and w == pytest.approx(0.75)
    assert blend_weights(t, -1.0) == (0, 1, 0.0) and blend_weights(t, 7.0) == (2, 2, 0.0)
    assert blend_weights([0.5], 0.9) == (0, 0, 0.0)
    np.testing.assert_array_equal(even_times(3), [0.0, 0.5, 1.0])
    with pytest.raises(OptionError, match="increase strictly"):
        blend_weights([0.0, 0.0, 1.0], 0.5)
    with pytest.raises(OptionError, match="finite"):
        blend_weights(t, float("nan"))


# -- solving a set ---------------------------------------------------------------------------------
def test_solve_set_puts_every_state_on_one_mesh(scene, sset):
    assert sset.names == list(STATES)
    np.testing.assert_array_equal(sset.times, [0.0, 0.4, 1.0])
    for s in sset.solutions[1:]:
        assert same_mesh(sset.first, s)
        assert s.stats["mode"] == "mesh"
    assert [s.stats["lighting_state"] for s in sset] == list(STATES)
    # the states really differ: by day the ceiling panel, by night the bulb alone
    day, night = (np.asarray(s.vert_radiance, np.float64).mean() for s in (sset[0], sset[2]))
    assert day > 3 * night > 0
    # at a key time the set is that solution itself; halfway the mean of its neighbours
    assert sset.at(0.4) is sset[1]
    mid = sset.at(0.2)
    np.testing.assert_allclose(
        mid.vert_radiance, 0.5 * (sset[0].vert_radiance.astype(np.float64) + sset[1].vert_radiance), rtol=1e-6
    )


def test_the_merged_mesh_resolves_every_state(scene, sset):
    """The set's mesh (default "merge") refines wherever any state's own adaptive solve refined:
    every vertex of each state's own mesh is a vertex of the set's mesh."""
    opts = SolveOptions(max_depth=3)
    for name, st in STATES.items():
        own = solve(apply_lighting_state(scene, st), opts)
        assert np.isin(own.vert_key, sset.first.vert_key).all(), name
        assert len(sset.first.leaf_patch) > len(own.leaf_patch)
    for how in ("union", "first"):
        other = solve_set(scene, STATES, opts, mesh=how)
        assert same_mesh(other[0], other[2]) and not same_mesh(other[0], sset[0])


def test_a_set_refuses_solutions_of_other_meshes(scene):
    a = solve(apply_lighting_state(scene, STATES["day"]), SolveOptions(max_depth=3))
    b = solve(apply_lighting_state(scene, STATES["night"]), SolveOptions(max_depth=3))  # its own mesh
    assert not same_mesh(a, b)
    with pytest.raises(OptionError, match="not on the mesh of solution 0"):
        SolutionSet([a, b])
    with pytest.raises(BakeError, match="not on this model's mesh"):
        Baker(a, scene).bake_set([a, b])
    with pytest.raises(OptionError, match="2 key times for 1"):
        SolutionSet([a], [0.0, 1.0])


# -- baking a set ----------------------------------------------------------------------------------
def test_bake_set_shares_one_atlas_layout(scene, sset, bset):
    n = len(sset)
    assert isinstance(bset, BakedSet) and bset.n_states == n
    assert bset.pages.shape[0] == n and bset.pages.shape[1:] == bset.bakes[0].pages.shape
    assert bset.mesh_radiance.shape == (n, *bset.bakes[0].mesh_radiance.shape)
    first = bset.bakes[0]
    assert first.memory.patches_textured > 0 and first.memory.patches_meshed > 0  # both parts
    for b in bset.bakes[1:]:
        for name in (
            "tex_uv",
            "tex_layer",
            "tex_positions",
            "tex_indices",
            "tex_patch",
            "mesh_positions",
            "mesh_indices",
        ):
            np.testing.assert_array_equal(getattr(b, name), getattr(first, name), err_msg=name)
        np.testing.assert_array_equal(b.patch_textured, first.patch_textured)
    # each state's layer is exactly what a bake of that solution alone gives
    policy = BakePolicy(threshold=2)
    for k, sol in enumerate(sset):
        alone = Baker(sol, scene).bake(policy)
        np.testing.assert_array_equal(bset.pages[k], alone.pages)
        np.testing.assert_array_equal(bset.mesh_radiance[k], alone.mesh_radiance)
        np.testing.assert_array_equal(alone.tex_uv, first.tex_uv)
    # memory: N states cost N texture layers
    m = bset.memory
    assert m.solutions == n and m.texture_bytes == n * first.memory.texture_bytes
    assert m.vertex_bytes_mesh == first.memory.vertex_bytes_mesh + 12 * len(first.mesh_positions)


def test_a_budget_chooses_a_coarser_scale_for_a_set(scene, sset):
    baker = Baker(sset.first, scene)
    full = baker.bake(BakePolicy(threshold=0)).memory.texture_bytes
    budget = 1.5 * full / (1 << 20)  # one state fits at full scale, three do not
    one = baker.bake(BakePolicy(threshold=0, budget_mb=budget))
    three = baker.bake_set(sset, BakePolicy(threshold=0, budget_mb=budget))
    assert one.policy.scale == 1.0 and one.memory.budget_fits
    assert three.policy.scale < 1.0 and three.memory.budget_fits
    assert three.memory.texture_bytes <= budget * (1 << 20) and three.memory.budget_mb == pytest.approx(
        budget
    )


def test_rgba8_set_shares_one_page_scale(scene, sset):
    b = Baker(sset.first, scene).bake_set(sset, BakePolicy(threshold=0, pixel_format="rgba8"))
    scales = {x.page_scale for x in b.bakes}
    assert len(scales) == 1
    assert b.page_scale == pytest.approx(
        max(Baker(s, scene).bake(BakePolicy(threshold=0, pixel_format="rgba8")).page_scale for s in sset)
    )


def test_cpu_blend_for_export(bset, sset):
    assert bset.blend(1, 2, 0.0) is bset.bakes[1]
    half = bset.at(0.2, sset.times)
    np.testing.assert_allclose(
        half.pages, 0.5 * (bset.pages[0].astype(np.float64) + bset.pages[1]), rtol=1e-6
    )
    np.testing.assert_allclose(
        half.mesh_radiance,
        0.5 * (bset.mesh_radiance[0] + bset.mesh_radiance[1].astype(np.float64)),
        rtol=1e-6,
    )
    np.testing.assert_array_equal(half.tex_uv, bset.tex_uv)


# -- blending on the GPU ---------------------------------------------------------------------------
@pytest.fixture
def renderer(egl_ctx):
    from iat.render.renderer import Renderer

    r = Renderer(egl_ctx)
    yield r
    r.release()
    assert egl_ctx.error == "GL_NO_ERROR"


def to8(img):
    return np.round(srgb_encode(np.clip(img, 0.0, 1.0)) * 255.0)


@pytest.mark.parametrize("mode", ["iat", "mesh"])
def test_gpu_blend_exact_at_keys_and_the_mean_halfway(renderer, scene, sset, bset, mode):
    cam = scene.default_camera()
    # each state alone, as a single solution / bake
    alone = []
    for k, sol in enumerate(sset):
        renderer.set_solution(sol)
        renderer.set_baked(bset.bakes[k])
        alone.append(renderer.render(cam, SIZE, mode))
    renderer.set_solution_set(sset.solutions)
    renderer.set_baked_set(bset)
    assert renderer.n_states("iat") == 3 and renderer.n_states("mesh") == 3
    for k, t in enumerate(sset.times):
        renderer.set_blend(*sset.weights(t))
        img = renderer.render(cam, SIZE, mode)
        np.testing.assert_array_equal(img, alone[k])  # exact at a key time
    assert np.abs(alone[0] - alone[2]).mean() > 0.05  # day and night differ
    for a, b in ((0, 1), (1, 2)):
        t = 0.5 * (sset.times[a] + sset.times[b])
        renderer.set_blend(*sset.weights(t))
        assert renderer.blend[:2] == (a, b) and renderer.blend[2] == pytest.approx(0.5)
        img = renderer.render(cam, SIZE, mode)
        mean = 0.5 * (alone[a].astype(np.float64) + alone[b])
        # linear radiance: the mean of the two renders, to float rounding
        np.testing.assert_allclose(img, mean, rtol=1e-5, atol=1e-6)
        # and within 8-bit precision once displayed
        assert np.abs(to8(img) - to8(mean)).max() <= 1.0
    # one pass: the blended frame costs the draw calls of one state
    renderer.set_blend(0, 1, 0.5)
    renderer.render(cam, SIZE, "iat")
    calls = renderer.stats()["draw_calls"]
    renderer.set_baked(bset.bakes[0])
    renderer.render(cam, SIZE, "iat")
    assert renderer.stats()["draw_calls"] == calls


def test_single_solution_after_a_set_resets_the_blend(renderer, scene, sset, bset):
    cam = scene.default_camera()
    renderer.set_solution(sset[2])
    ref = renderer.render(cam, SIZE, "mesh")
    renderer.set_solution_set(sset.solutions)
    renderer.set_blend(0, 1, 0.7)
    renderer.set_solution(sset[2])  # a set of one: any blend shows it
    np.testing.assert_array_equal(renderer.render(cam, SIZE, "mesh"), ref)
    with pytest.raises(Exception, match="blend weight"):
        renderer.set_blend(0, 1, 1.5)


# -- files and the command line -------------------------------------------------------------------
def test_save_and_load_set(tmp_path, sset):
    paths = sset.save(tmp_path, "cb")
    again = load_set(list(reversed(paths)))  # any order: the recorded key times sort them
    assert again.names == sset.names
    np.testing.assert_array_equal(again.times, sset.times)
    np.testing.assert_array_equal(again[2].vert_radiance, sset[2].vert_radiance)
    even = load_set(paths, times=None, names=["a", "b", "c"])
    np.testing.assert_array_equal(even.times, sset.times)


def iat(*args):
    return subprocess.run(
        [sys.executable, "-m", "iat.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )


def test_cli_solve_states_bake_and_render_a_moment(tmp_path, scene):
    model = save_gltf(scene, CORNELL, tmp_path / "cb.glb", lighting_states=STATES)
    r = iat("solve", model, "--states", "-o", tmp_path / "cb.npz", "--max-depth", "3", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    files = [Path(x["output"]) for x in out["states"]]
    assert [f.name for f in files] == ["cb-day.npz", "cb-dusk.npz", "cb-night.npz"]

    r = iat(
        "bake", "--set", *files, "--at", "0.2", "-o", tmp_path / "moment.glb", "--threshold", "0", "--json"
    )
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["solutions"] == 3 and rep["set"]["blend"] == {"a": "day", "b": "dusk", "w": pytest.approx(0.5)}
    assert rep["texture_bytes"] == 3 * rep["set"]["texture_bytes_exported"]
    back = load_scene(tmp_path / "moment.glb")
    assert back.n_patches > 0

    def render(*args):
        out = tmp_path / f"r{len(list(tmp_path.glob('r*.npy')))}.npy"
        r = iat("render", *args, "-o", out, "--size", "64x48", "--threshold", "0")
        assert r.returncode == 0, r.stderr
        return np.load(out)

    day = render(files[0])
    dusk = render(files[1])
    np.testing.assert_array_equal(render("--set", *files, "--at", "0"), day)
    half = render("--set", *files, "--at", "0.2")
    np.testing.assert_allclose(half, 0.5 * (day.astype(np.float64) + dusk), rtol=1e-5, atol=1e-6)
    r = iat("render", files[0], "--set", *files, "-o", tmp_path / "x.png")
    assert r.returncode == 2 and "either an input or --set" in r.stderr
    r = iat("bake", "--set", files[0], files[1], "--times", "0.5,0.2", "-o", tmp_path / "x.glb")
    assert r.returncode == 2 and "increase strictly" in r.stderr
