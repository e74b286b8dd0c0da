"""Embree's C API from numba kernels (:mod:`iat.radiosity.embree`, issue 41) against embreex: the same
answers ray for ray on real scenes (the sample house, a glazed room), the same solves to the bit, the
kernels cacheable across processes, and the fallback to embreex."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from iat.geometry import quadtree as qt
from iat.io.load import load_scene
from iat.io.scene import Material, Scene, Sky
from iat.radiosity import SolveOptions, embree, solve
from iat.radiosity.context import Context
from iat.radiosity.solver import evaluate_direct
from iat.radiosity.visibility import Visibility
from tests.support.daylight import daylit_room
from tests.support.rays import surface_rays

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.skipif(not embree.available(), reason="libembree4 not found")


def scene_rays(scene, n: int, seed: int = 0):
    """n rays as the solver casts them: from random points on the patches, off the surface, (a) in
    cosine directions as far as the scene's diagonal, a random fraction of it for a third of them,
    and (b) towards the corners of random patches (the edges and vertices where the triangle tests
    must agree), stopping just short of them."""
    rng = np.random.default_rng(seed)
    o, d, diag = surface_rays(scene, n, rng)
    t = np.full(n, diag)
    t[: n // 3] *= rng.random(n // 3)
    half = n // 2  # the second half aims at patch corners
    q = rng.integers(0, scene.n_patches, n - half)
    target = scene.corner_positions[q, rng.integers(0, 3, n - half)]
    to = target - o[half:]
    dist = np.linalg.norm(to, axis=1)
    d[half:] = to / np.maximum(dist, 1e-30)[:, None]
    t[half:] = dist * (1 - 1e-6)
    return o, d, t


def glazed_room():
    return daylit_room(glass=0.7)


def sample(name: str):
    return load_scene(ROOT / "sample_models" / f"{name}.glb")


def same_answers(scene, n: int) -> dict:
    """Each query of both backends on the same rays: {query: whether they agree exactly}."""
    o, d, t = scene_rays(scene, n)
    out = {}
    with Visibility.of_scene(scene, backend="embreex") as a, Visibility.of_scene(scene, backend="c") as b:
        assert (a.backend, b.backend) == ("embreex", "c")
        out["occluded"] = np.array_equal(a.occluded(o, d, t), b.occluded(o, d, t))
        va, vb = a.visible(o, d, t), b.visible(o, d, t)
        out["visible"] = np.array_equal(va, vb)
        out["first_hit"] = np.array_equal(a.first_hit(o, d, t), b.first_hit(o, d, t))
        (pa, ba), (pb, bb) = a.first_hits(o, d, t), b.first_hits(o, d, t)
        hit = pa >= 0
        out["first_hits"] = np.array_equal(pa, pb) and np.array_equal(ba[hit], bb[hit])
        out["rays counted"] = a.rays == b.rays
        out["some hit, some free"] = 0 < hit.mean() < 1 and 0 < va.mean() < 1
        if scene.patch_transmission.any():
            out["some through glass"] = bool(((va > 0) & (va < 1)).any())
    return out


@pytest.mark.parametrize("make", [lambda: sample("house"), lambda: sample("house_day"), glazed_room])
def test_same_answers_as_embreex(make):
    """Ray for ray, the C API's answers are embreex's: occlusion, the glass's transmittance, the first
    hit and its barycentric coordinates to the bit (both build robust scenes)."""
    res = same_answers(make(), 200_000)
    assert all(res.values()), res


def test_threads_do_not_change_answers():
    scene = sample("house")
    o, d, t = scene_rays(scene, 50_000, seed=3)
    with Visibility.of_scene(scene, threads=1) as one, Visibility.of_scene(scene, threads=2) as two:
        assert np.array_equal(one.visible(o, d, t), two.visible(o, d, t))
        with two.on_this_thread():
            assert two.ray_threads() == 1
            assert np.array_equal(one.first_hits(o, d, t)[0], two.first_hits(o, d, t)[0])


def test_empty_scene_and_no_rays():
    with Visibility(np.zeros((0, 3, 3))) as vis:
        o = np.zeros((3, 3))
        d = np.tile([0.0, 0.0, 1.0], (3, 1))
        assert not vis.occluded(o, d, np.ones(3)).any()
        assert (vis.visible(o, d, np.ones(3)) == 1).all()
        assert (vis.first_hit(o, d, np.ones(3)) == -1).all()
        assert len(vis.occluded(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))) == 0


def test_fallback_to_embreex(monkeypatch):
    """``IAT_EMBREE_C=0``, or no library, gives embreex's path."""
    monkeypatch.setenv(embree.EMBREE_C_ENV, "0")
    assert not embree.available()
    with Visibility(np.eye(3)[None]) as vis:
        assert vis.backend == "embreex" and vis.embree_args() is None
    monkeypatch.delenv(embree.EMBREE_C_ENV)
    monkeypatch.setenv(embree.EMBREE_LIB_ENV, "/nonexistent/libembree4.so.4")
    monkeypatch.setattr(embree, "_LIB", [])
    assert not embree.available()
    with Visibility(np.eye(3)[None]) as vis:
        assert vis.backend == "embreex"


def test_closed_scene_releases_handles():
    vis = Visibility(np.eye(3)[None])
    assert vis.embree_args()[2] != 0
    vis.close()
    assert vis._c.handle == 0
    vis.close()  # twice is fine


def test_kernels_cache_across_processes(tmp_path):
    """The kernels take the entry points' addresses as arguments: a second process loads them from
    numba's cache (the library at another address there) and still answers right."""
    code = textwrap.dedent(
        """
        import numpy as np
        from iat.radiosity import embree
        from iat.radiosity.visibility import Visibility
        with Visibility(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float), backend="c") as vis:
            o = np.array([[0.2, 0.2, 1.0], [2.0, 2.0, 1.0]])
            d = np.array([[0.0, 0.0, -1.0]] * 2)
            assert vis.occluded(o, d, np.full(2, 5.0)).tolist() == [True, False]
            prim, bary = vis.first_hits(o, d, np.full(2, 5.0))
            assert prim.tolist() == [0, -1] and np.allclose(bary[0], [0.2, 0.2])
        print("hits", sum(len(k.stats.cache_hits) for k in (embree.trace_visible, embree.trace_first_hits)))
        """
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    runs = [
        subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True)
        for _ in range(2)
    ]
    for r in runs:
        assert r.returncode == 0, r.stderr[-3000:]
    assert runs[0].stdout.strip() == "hits 0"  # compiled ...
    assert runs[1].stdout.strip() == "hits 2"  # ... then loaded from the cache


def pane_scene() -> Scene:
    """A 4 x 4 m floor under a 2 x 2 m ceiling panel 2 m up, and between them an opaque tile and a
    glass pane (transmittance 0.6) that cover parts of the floor's view of the panel."""

    def quad(y, x0, x1, z0, z1, up):
        c = [(x0, y, z0), (x0, y, z1), (x1, y, z1), (x1, y, z0)]
        return c if up else c[::-1]

    quads = [
        quad(0.0, -2, 2, -2, 2, True),  # floor (0)
        quad(2.0, -1, 1, -1, 1, False),  # ceiling panel (1): the shooter
        quad(1.0, -1.5, 0.0, -0.5, 0.5, True),  # opaque tile (2)
        quad(1.2, 0.2, 1.6, -1.2, 1.2, True),  # glass (3)
    ]
    mats = [Material("white", albedo=[0.6, 0.6, 0.6]), Material("glass", albedo=[0.0] * 3, transmission=0.6)]
    return Scene(
        vertices=np.array(quads, float).reshape(-1, 3),
        patch_corners=np.arange(16).reshape(4, 4),
        patch_material=np.array([0, 0, 0, 1]),
        materials=mats,
    )


@pytest.mark.parametrize("field", [False, True])
@pytest.mark.parametrize("correlated", [False, True])
def test_traced_gather_is_the_three_steps(field, correlated):
    """:func:`.traced.gather_traced` (one kernel: samples, Embree, sum) gives the rows, rays and culling
    counts of ``gather_rays`` + ``Visibility.visible`` + ``gather_finish`` to the bit, through an
    occluder and glass, with and without a field, on one thread and two."""
    scene = pane_scene()
    out = {}
    for name, threads in (("embreex", 2), ("c", 1), ("c", 2)):
        with Visibility.of_scene(scene, threads=threads, backend=name) as vis:
            ctx = Context(scene, SolveOptions(), vis)
            n = ctx.patches.n
            g = np.arange(0, n + 1, n // 16)
            i, j = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
            geo = ctx.patches.geometry(qt.make_key(np.zeros_like(i), i, j, n))
            fld = mean = None
            if field:
                fld = np.random.default_rng(1).random((9, 9, 3))
                mean = fld.reshape(-1, 3).mean(axis=0)
            got = ctx.gathers.gathers(1, [(geo, None)], 5, 3, fld, mean, correlated=correlated)[0]
            patch, rays, seen = ctx.gathers.culling.rows[1]
            out[name, threads] = (*got, patch, rays, seen > 0, vis.rays)
    ref = out["embreex", 2]
    assert len(ref[0]) > 200 and 0 < (ref[1] > 0).mean() < 1
    for key, res in out.items():
        for a, b in zip(ref, res, strict=True):
            assert np.array_equal(a, b), key


def test_direct_daylight_same_bits(monkeypatch):
    """The sun's and the sky's rays made and traced in one kernel (:func:`.traced.sun_escape`,
    :func:`.sky_traced.sky_estimate`) give the direct light of the numpy directions and embreex to the
    bit: house_day (Preetham sky, sun, lamps, glass) at a lattice of points of every patch."""
    scene = sample("house_day")
    n = 1 << SolveOptions().max_depth
    g = np.arange(0, n + 1, n // 4)
    p, i, j = (a.ravel() for a in np.meshgrid(np.arange(scene.n_patches), g, g, indexing="ij"))
    inside = scene.patch_is_quad[p] | (i + j <= n)
    keys = np.unique(qt.make_key(p[inside], i[inside], j[inside], n))
    monkeypatch.setenv(embree.EMBREE_C_ENV, "0")
    ref = evaluate_direct(scene, keys)
    monkeypatch.delenv(embree.EMBREE_C_ENV)
    got = evaluate_direct(scene, keys)
    assert (ref > 0).mean() > 0.5
    assert np.array_equal(ref, got)


def test_sky_kernel_same_bits_at_three_estimates(monkeypatch):
    """The sky's kernel (:func:`.sky_traced.sky_vertices`) is numpy's path to the bit (its noise to
    1e-9) with a third
    estimate (``SKY_PASSES`` = 3: the finer grids built in the kernel), a CIE overcast sky (looked
    up in the kernel) and a black ground (no direction below the horizon traced, none made under the
    ceiling): the window-lit room at a lattice of points of every patch."""
    import iat.radiosity.direct as direct
    from tests.support.daylight import window_room

    scene = window_room()
    scene.sky = Sky(kind="cie_overcast", radiance=(1.0, 1.1, 1.3), ground=(0.0, 0.0, 0.0))
    n = 1 << SolveOptions().max_depth
    g = np.arange(1, n, n // 8)
    p, i, j = (a.ravel() for a in np.meshgrid(np.arange(scene.n_patches), g, g, indexing="ij"))
    keys = np.unique(qt.make_key(p, i, j, n))
    monkeypatch.setattr(direct, "SKY_PASSES", 3)

    def sky_light():
        with Visibility.of_scene(scene) as vis:
            ctx = Context(scene, SolveOptions().validate(), vis)
            noise = np.zeros(len(keys))
            return ctx.light.direct(keys, lambda: None, noise=noise), ctx.light.sky_counts.copy(), noise

    monkeypatch.setenv(embree.EMBREE_C_ENV, "0")
    ref, ref_counts, ref_noise = sky_light()
    monkeypatch.delenv(embree.EMBREE_C_ENV)
    got, counts, noise = sky_light()
    assert counts[2, 0] > 0 and (ref > 0).mean() > 0.3 and (ref == 0).any()  # a ceiling sees no sky
    assert np.array_equal(ref, got) and np.array_equal(ref_counts, counts)
    # the noise's luminance sums differ in order (a loop, a matrix product): the last bits
    assert (ref_noise > 0).mean() > 0.3
    np.testing.assert_allclose(noise, ref_noise, rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("make", [lambda: sample("cornell_box"), glazed_room])
def test_solves_same_bits(make, monkeypatch):
    """A solve with the C API (its gathers trace their own rays) is the embreex solve to the bit."""
    scene = make()
    glazed = scene.patch_transmission.any()  # sun and sky through the glass, at draft's cost
    opts = SolveOptions.preset("draft", convergence=0.2) if glazed else SolveOptions()
    monkeypatch.setenv(embree.EMBREE_C_ENV, "0")
    ref = solve(scene, opts)
    monkeypatch.delenv(embree.EMBREE_C_ENV)
    sol = solve(scene, opts)
    assert np.array_equal(ref.vert_key, sol.vert_key)
    assert np.array_equal(ref.vert_radiance, sol.vert_radiance)
    assert ref.stats["rays"] == sol.stats["rays"]


def test_sky_rays_below_a_black_ground_are_not_traced():
    """:func:`.sky_traced.sky_estimate` with ``dark_ground``: the directions below the horizon are
    not traced (a black ground brings nothing there), and the first estimates are those of tracing
    them (the same bits), with fewer rays."""
    from iat.radiosity.sky import SkyTable
    from iat.radiosity.sky_traced import pack_levels, sky_estimate

    scene = pane_scene()  # no ground: the ceiling panel sees the sky below the horizon
    with Visibility.of_scene(scene, backend="c") as vis:
        ctx = Context(scene, SolveOptions(), vis)
        n = ctx.patches.n
        p = np.arange(scene.n_patches)
        keys = qt.make_key(p, np.full(len(p), n // 2), np.full(len(p), n // 2), n)
        geo = ctx.patches.geometry(keys)
        rot = np.random.default_rng(0).random((len(p), 2))
        pat = ctx.gathers.pattern(0, 8, 2)
        light = SkyTable(Sky(kind="uniform", radiance=(1.0, 2.0, 3.0), ground=(0.0, 0.0, 0.0))).kernel_args()
        frame = (ctx.patches.tangent[p, 0], ctx.patches.tangent[p, 1], geo.normal)
        args = (vis, light, pat, 8, pack_levels([]), 1, rot, frame, geo.origin32(), 4.0 * ctx.patches.scale)
        before = vis.rays
        every, c_every, _ = sky_estimate(*args, False, np.zeros(len(p)), 0.0, 2)
        traced_every = vis.rays - before
        dark, c_dark, _ = sky_estimate(*args, True, np.zeros(len(p)), 0.0, 2)
        assert (every > 0).any() and np.array_equal(every, dark)
        assert c_every[0, 1] == 64 * len(p) and c_dark[0, 1] < 0.9 * c_every[0, 1]
        assert vis.rays - before - traced_every < traced_every
