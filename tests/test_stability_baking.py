"""Stability catalogue (docs/stability.md), Meshing and baking, and Soak: refinement to max depth,
scale, budget and threshold limits, atlas pages, GL and host memory limits, mipmap bleeding; a
thousand rebakes and the viewer's bake worker under a burst."""

from __future__ import annotations

import dataclasses
import gc
import os
import subprocess
import sys
import threading
import time
import tracemalloc

import numpy as np
import pytest

from iat.bake.atlas import mip_levels
from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.camera import Camera
from iat.errors import BakeError, OptionError, RenderError
from iat.measure.seams import seam_error
from iat.radiosity import SolveOptions, solve
from tests import stability_scenes as ss
from tests.support.stability import ROOT, opts, record

pytestmark = pytest.mark.usefixtures("stability_figures")


def test_meshing_max_depth_everywhere_memory_bound():
    """A tiny tolerance splits every element to max depth: exactly 4**D leaves per patch, never more,
    and the solution's bytes grow linearly with the leaves (bytes per element measured)."""
    rows = {}
    for depth in (4, 6):
        scene = ss.floor_under_light(height=0.3)
        sol = solve(scene, opts(max_depth=depth, tolerance=1e-9, criterion="variation"))
        leaves = sol.forest.n_leaves
        nbytes = sum(
            np.asarray(getattr(sol, k)).nbytes
            for k in (
                "leaf_patch",
                "leaf_level",
                "leaf_i",
                "leaf_j",
                "leaf_flip",
                "vert_key",
                "vert_radiance",
                "tri_vertices",
            )
        )
        rows[depth] = (leaves, nbytes)
        record(
            "max_depth_everywhere",
            **{
                f"D{depth}_leaves": leaves,
                f"D{depth}_bytes": nbytes,
                f"D{depth}_bytes_per_leaf": round(nbytes / leaves, 1),
            },
        )
        assert leaves == 4**depth
        assert (sol.forest.leaf_level == depth).all()
    assert rows[6][1] / rows[6][0] < 1.1 * rows[4][1] / rows[4][0]
    with pytest.raises(OptionError, match="tolerance"):
        solve(ss.floor_under_light(), SolveOptions(tolerance=0.0))
    with pytest.raises(OptionError, match="max_depth"):
        solve(ss.floor_under_light(), SolveOptions(max_depth=13))


@pytest.fixture(scope="module")
def grid_solution():
    """4 x 3 coplanar unit quads under a point light, solved at depth 4 (a small real solution)."""
    corners = ss.grid_corners(4, 3)
    polys = list(corners)  # in z = 0, facing +z: the light is in front at z = 0.6
    scene = ss.make_scene(polys, [0] * len(polys), [ss.GREY], [ss.point_light(1.3, 1.1, 0.6, 1.0)])
    sol = solve(scene, opts(max_depth=4))
    return scene, sol


def test_baking_scale_far_below_one_gives_two_texel_tiles(grid_solution):
    """Scale 1e-6: every tile is 2 x 2 texels (the corners), seams between neighbours stay exact."""
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    full = baker.bake(BakePolicy(threshold=0))
    tiny = baker.bake(BakePolicy(threshold=0, scale=1e-6))
    seam = seam_error(tiny, sol)
    record(
        "scale_far_below_one",
        texture_bytes_scale_1=full.memory.texture_bytes,
        texture_bytes_scale_1e_6=tiny.memory.texture_bytes,
        seam_max=seam["max"],
        seam_edges=seam["edges"],
    )
    assert seam["edges"] > 0 and seam["max"] < 1e-6
    assert tiny.memory.texture_bytes < full.memory.texture_bytes
    assert all(
        t.shape[0] == 2 for t in baker.tiles.get(np.arange(len(scene.patch_corners)), "bilinear", 1e-6)
    )
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(OptionError, match="scale"):
            baker.bake(BakePolicy(scale=bad))


def test_baking_budget_zero_and_budget_below_any_texture(grid_solution):
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    zero = baker.bake(BakePolicy(budget_mb=0.0))
    tiny = baker.bake(BakePolicy(budget_mb=1e-9))
    for b in (zero, tiny):
        assert b.memory.texture_bytes == 0 and b.memory.patches_textured == 0 and b.pages.shape[0] == 0
        assert b.memory.triangles_mesh_part == len(sol.tri_vertices)
    assert not zero.memory.budget_too_small and tiny.memory.budget_too_small
    record(
        "budget_zero_tiny",
        budget0_texture_bytes=0,
        budget1e_9_too_small=True,
        mesh_triangles=int(zero.memory.triangles_mesh_part),
    )
    with pytest.raises(OptionError, match="budget"):
        baker.bake(BakePolicy(budget_mb=-1.0))


def test_baking_threshold_above_the_deepest_tree_is_the_mesh(renderer, grid_solution):
    scene, sol = grid_solution
    baked = Baker(sol, scene).bake(BakePolicy(threshold=99))
    assert baked.memory.patches_textured == 0 and baked.pages.shape == (0, 1, 1, 3)
    renderer.set_solution(sol)
    renderer.set_baked(baked)
    cam = Camera(eye=[2.0, 1.5, 3.0], target=[2.0, 1.5, 0.0], yfov=60.0, znear=0.01, zfar=10)
    mesh = renderer.render(cam, (64, 48), "mesh")
    iat = renderer.render(cam, (64, 48), "iat")
    diff = float(np.abs(mesh - iat).max())
    record("threshold_above_deepest", max_abs_diff_iat_vs_mesh=diff)
    assert diff == 0.0


def test_baking_atlas_pages_full_spill_to_more_pages(renderer):
    """40 patches of 17 x 17 texels on 64 x 64 pages: the atlas spills over several pages and the IAT
    image still equals the per-patch colours."""
    corners = ss.grid_corners(8, 5)
    colour = lambda p, x: np.stack([(p % 3) / 2.0, ((p // 3) % 3) / 2.0, np.full(len(p), 0.25)], 1)  # noqa: E731
    sol = ss.synthetic_solution(corners, colour, max_depth=4)
    baked = Baker(sol).bake(BakePolicy(threshold=0, page_size=64, gutter=2))
    assert baked.memory.pages > 1
    renderer.set_solution(sol)
    renderer.set_baked(baked)
    cam = Camera(eye=[4.0, 2.5, 6.0], target=[4.0, 2.5, 0.0], yfov=50.0, znear=0.01, zfar=20)
    mesh = renderer.render(cam, (128, 96), "mesh")
    iat = renderer.render(cam, (128, 96), "iat")
    diff = float(np.abs(mesh - iat).max())
    record(
        "atlas_pages_full",
        pages=baked.memory.pages,
        utilisation=round(baked.memory.utilisation, 3),
        texture_bytes=baked.memory.texture_bytes,
        max_abs_diff_iat_vs_mesh=diff,
    )
    assert diff < 2e-3


def test_baking_more_pages_than_the_gl_layer_limit_is_an_error(egl_ctx):
    """D7 (fixed): more atlas pages than GL_MAX_ARRAY_TEXTURE_LAYERS is an error, not a black image."""
    from iat.render.renderer import Renderer

    limit = int(egl_ctx.info["GL_MAX_ARRAY_TEXTURE_LAYERS"])
    corners = ss.grid_corners(limit + 1, 1)
    sol = ss.synthetic_solution(corners, lambda p, x: np.ones((len(p), 3)), max_depth=1)
    baked = Baker(sol).bake(BakePolicy(threshold=0, page_size=64, gutter=15))  # one tile per page
    assert baked.memory.pages == limit + 1
    r = Renderer(egl_ctx)
    try:
        with pytest.raises((RenderError, BakeError)):
            r.set_baked(baked)
            cam = Camera(eye=[0.5, 0.5, 2.0], target=[0.5, 0.5, 0.0], yfov=20.0, znear=0.1, zfar=10)
            img = r.render(cam, (8, 8), "iat")
            record(
                "atlas_pages_full",
                over_limit_pages=limit + 1,
                over_limit_centre_pixel=img[4, 4].tolist(),
                gl_error=egl_ctx.error,
            )
    finally:
        r.release()


def test_baking_texture_larger_than_the_gl_limit_is_a_bake_error(grid_solution, egl_ctx):
    """A tile larger than a page (pages are at most GL_MAX_TEXTURE_SIZE = 16384) is a BakeError that
    names the patch, the size and the way out, raised before any texel is allocated."""
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    deepest = int(sol.patch_depth().max())
    scale = 20000.0 / (1 << deepest)  # the deepest tile: (2**d) x scale + 1 = 20001 texels a side
    tracemalloc.start()
    try:
        with pytest.raises(BakeError) as e:
            baker.bake(BakePolicy(threshold=0, scale=scale, page_size=16384))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    msg = str(e.value)
    assert "larger than the 16384x16384 atlas page" in msg and "lower the scale" in msg and "patch" in msg
    with pytest.raises(OptionError, match="page_size"):
        baker.bake(BakePolicy(page_size=32768))
    gl_max = int(egl_ctx.info["GL_MAX_TEXTURE_SIZE"])
    record(
        "texture_over_gl_limit",
        message=msg.split(": ", 1)[-1],
        peak_alloc_mb=round(peak / 2**20, 2),
        gl_max_texture_size=gl_max,
    )
    assert peak < 64 * 2**20  # the 20001^2 tile was never made


_HUGE_BAKE = r"""
import resource, sys
sys.path.insert(0, sys.argv[1])
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))  # 3 GiB: the bake below needs ~25
import numpy as np
from tests import stability_scenes as ss
from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.errors import IATError
sol = ss.synthetic_solution(ss.grid_corners(4, 3), lambda p, x: np.ones((len(p), 3)), max_depth=2)
try:
    b = Baker(sol).bake(BakePolicy(threshold=0, scale=4000.0, page_size=16384))  # 12 tiles of 16001^2
    print("BAKED", b.memory.texture_bytes)
except IATError as e:
    print("IATError", type(e).__name__, e)
except MemoryError as e:
    print("MemoryError", e)
"""


def test_baking_texture_memory_beyond_the_host_is_a_bake_error(tmp_path):
    """D8 (fixed): a bake larger than the memory available (ulimit -v 3 GiB here) is a BakeError raised
    before allocating, not a MemoryError."""
    script = tmp_path / "huge.py"
    script.write_text(_HUGE_BAKE)
    r = subprocess.run([sys.executable, str(script), str(ROOT)], capture_output=True, text=True, timeout=300)
    out = (r.stdout.strip().splitlines() or [r.stderr.strip()[-300:]])[-1]
    record("texture_over_gl_limit", huge_scale_outcome=out)
    assert out.startswith("IATError BakeError"), out


def test_baking_mipmaps_do_not_bleed_across_gutters_far_away(renderer):
    """A checkerboard of red and green patches seen from far away (a patch covers about a pixel):
    with the mip levels the gutter allows (1 + floor(log2 gutter)), no pixel mixes two tiles; with a
    full mip chain over the same atlas, the colours bleed (measured)."""
    corners = ss.grid_corners(16, 16)
    checker = lambda p, x: np.stack([(p + p // 16) % 2, 1 - (p + p // 16) % 2, np.zeros(len(p))], 1)  # noqa: E731
    sol = ss.synthetic_solution(corners, checker, max_depth=3)
    cam_far = Camera(eye=[8.0, 8.0, 160.0], target=[8.0, 8.0, 0.0], yfov=8.0, znear=1.0, zfar=400)
    out = {}
    for gutter in (2, 4):
        baked = Baker(sol).bake(BakePolicy(threshold=0, gutter=gutter, mipmaps=True))
        assert baked.mip_levels == mip_levels(gutter)
        for label, b in (("rule", baked), ("full_chain", dataclasses.replace(baked, mip_levels=None))):
            renderer.set_baked(b)
            img = renderer.render(cam_far, (24, 24), "iat").astype(np.float64)
            rg = img[..., :2]
            shown = rg.sum(axis=2) > 0
            bleed = float((rg.min(axis=2)[shown] / rg.sum(axis=2)[shown]).max())
            out[f"gutter{gutter}_{label}_max_bleed"] = bleed
    record("mipmap_bleeding", **out)
    assert out["gutter2_rule_max_bleed"] < 1e-3 and out["gutter4_rule_max_bleed"] < 1e-3
    assert out["gutter2_full_chain_max_bleed"] > 0.05  # what the rule prevents


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_soak_a_thousand_rebakes(renderer, grid_solution):
    """1 000 re-bakes (threshold, scale, method and format cycling through more values than the caches
    hold) each uploaded and drawn: GL objects constant, traced host memory and RSS flat."""
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    deepest = int(sol.patch_depth().max())
    scales = [0.25 * 1.2**k for k in range(13)]
    methods = ["bilinear", "scan", "bicubic"]
    formats = ["rgba16f", "rgba8"]
    cam = Camera(eye=[2.0, 1.5, 3.0], target=[2.0, 1.5, 0.0], yfov=60.0, znear=0.01, zfar=10)

    def policy(k):
        return BakePolicy(
            threshold=k % (deepest + 2),
            scale=scales[k % len(scales)],
            method=methods[(k // 7) % 3],
            pixel_format=formats[(k // 11) % 2],
        )

    renderer.set_solution(sol)
    warm = 200
    for k in range(warm):
        renderer.set_baked(baker.bake(policy(k)))
        renderer.render(cam, (16, 12), "iat")
    n_gl = renderer.gl_object_count()
    tracemalloc.start()
    rss0 = _rss()
    t0 = time.perf_counter()
    gl_counts, traced = set(), []
    for k in range(warm, 1000):
        renderer.set_baked(baker.bake(policy(k)))
        renderer.render(cam, (16, 12), "iat")
        gl_counts.add(renderer.gl_object_count())
        if k % 100 == 99:
            gc.collect()
            traced.append(tracemalloc.get_traced_memory()[0])
    dt = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    growth_rss = _rss() - rss0
    mb = [round(t / 2**20, 2) for t in traced]
    record(
        "soak_1000_rebakes",
        bakes=baker.stats["bakes"],
        gl_objects=sorted(gl_counts),
        gl_objects_after_warmup=n_gl,
        traced_mb_every_100=mb,
        traced_peak_mb=round(peak / 2**20, 2),
        rss_growth_mb=round(growth_rss / 2**20, 2),
        seconds_for_800=round(dt, 1),
    )
    assert baker.stats["bakes"] == 1000
    assert gl_counts == {n_gl}
    # host memory: what the bounded caches hold goes up and down with the policy; it does not grow
    assert max(traced) < 16 * 2**20
    assert max(traced[-3:]) <= max(traced[:3]) + 2**20
    assert growth_rss < 32 * 2**20


def test_soak_bake_worker_coalesces_a_burst(grid_solution):
    """The viewer's BakeWorker under a 500-request burst (a slider dragged fast): requests coalesce,
    the thread stays single, the last policy asked is the one baked."""
    from viewer.bake_worker import BakeWorker

    scene, sol = grid_solution
    w = BakeWorker(Baker(sol, scene))
    try:
        threads0 = threading.active_count()
        last = None
        for k in range(500):
            last = BakePolicy(threshold=k % 4, scale=0.5 + (k % 5) * 0.25)
            w.submit(last)
        assert w.wait(60.0)
        r = w.poll()
        assert r is not None and r.error is None and r.policy == last
        record("soak_bake_worker", requests=500, bakes_done=w.bakes)
        assert w.bakes < 500 and threading.active_count() == threads0
    finally:
        w.close()
