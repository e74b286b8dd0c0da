"""iat.bake: threshold semantics, atlas UVs, memory report, budget, cache, seams, detail textures."""

from __future__ import annotations

import numpy as np
import pytest

from iat.bake.baker import Baker, bake
from iat.bake.budget import choose_policy, cost_model
from iat.bake.formats import BYTES_PER_TEXEL, quantise_rgb9e5, quantise_rgba8
from iat.bake.memory import MemoryReport
from iat.bake.policy import BakePolicy
from iat.errors import BakeError, OptionError
from iat.geometry import quadtree as qt
from iat.io.scene import Material, Scene
from iat.measure.seams import seam_error
from iat.radiosity.solution import Solution
from tests.test_flatten import SHAPES, linear_field, make_solution, patch_world, wavy_field

# -- helpers --------------------------------------------------------------------------------


def sample_pages(pages, layer, uv):
    """GL_LINEAR lookup (texel centres at (k + 0.5) / size), (k,) layers, (k, 2) uv -> (k, 3)."""
    _, H, W, _ = pages.shape
    x, y = uv[:, 0] * W - 0.5, uv[:, 1] * H - 0.5
    x0 = np.clip(np.floor(x).astype(int), 0, W - 2)
    y0 = np.clip(np.floor(y).astype(int), 0, H - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    p = pages.astype(np.float64)
    return (
        (1 - fx) * (1 - fy) * p[layer, y0, x0]
        + fx * (1 - fy) * p[layer, y0, x0 + 1]
        + (1 - fx) * fy * p[layer, y0 + 1, x0]
        + fx * fy * p[layer, y0 + 1, x0 + 1]
    )


def corner_slots(baked, p):
    """Vertex indices of textured patch ``p`` (4 for quads, 3 for triangles), in corner order."""
    return np.flatnonzero(baked.tex_patch == p)


def atlas_uv(baked, p, u, v):
    """Atlas uv of patch points (u, v), interpolated as the GPU does across the polygon."""
    k = corner_slots(baked, p)
    uv = baked.tex_uv[k].astype(np.float64)
    u, v = np.asarray(u)[:, None], np.asarray(v)[:, None]
    far_v = uv[3] if len(k) == 4 else uv[2]
    return uv[0] + u * (uv[1] - uv[0]) + v * (far_v - uv[0])


def grid_scene_solution(field=linear_field, max_depth=5, seed=0, frac=0.5):
    """3 x 3 coplanar unit quads plus a square of two triangles at x in [3, 4], all in z = 0."""
    corners = []
    for gy in range(3):
        for gx in range(3):
            corners.append([[gx, gy, 0], [gx + 1, gy, 0], [gx + 1, gy + 1, 0], [gx, gy + 1, 0]])
    corners.append([[3, 0, 0], [4, 0, 0], [3, 1, 0], [3, 1, 0]])
    corners.append([[4, 1, 0], [3, 1, 0], [4, 0, 0], [4, 0, 0]])
    is_quad = [True] * 9 + [False, False]
    return make_solution(corners, is_quad, field, max_depth=max_depth, rounds=5, frac=frac, seed=seed)


@pytest.fixture(scope="module")
def grid_sol():
    sol = grid_scene_solution()
    assert len(np.unique(sol.patch_depth())) >= 3  # neighbours of different tile sizes
    return sol


# -- threshold ------------------------------------------------------------------------------


def test_threshold_semantics(grid_sol):
    b = Baker(grid_sol)
    depth = grid_sol.patch_depth()
    all_tex = b.bake(BakePolicy(threshold=0))
    assert all_tex.patch_textured.all()
    assert len(all_tex.mesh_indices) == 0 and len(all_tex.mesh_positions) == 0
    n_quads = int(grid_sol.patch_is_quad.sum())
    assert len(all_tex.tex_indices) == 2 * n_quads + (len(depth) - n_quads)
    assert len(all_tex.tex_positions) == 4 * n_quads + 3 * (len(depth) - n_quads)

    none = b.bake(BakePolicy(threshold=int(depth.max()) + 1))
    assert not none.patch_textured.any()
    assert none.pages.shape == (0, 1, 1, 3) and none.memory.texture_bytes == 0
    assert len(none.mesh_indices) == len(grid_sol.tri_vertices)
    # every vertex once, in patch-depth order (stable: vertex-table order within a depth)
    P, _, _ = qt.decode_key(grid_sol.vert_key, grid_sol.n)
    order = np.argsort(depth[P], kind="stable")
    np.testing.assert_array_equal(none.mesh_radiance, grid_sol.vert_radiance[order])
    np.testing.assert_array_equal(none.mesh_patch, P[order])

    for t in range(int(depth.max()) + 1):
        bk = b.bake(BakePolicy(threshold=t))
        np.testing.assert_array_equal(bk.patch_textured, depth >= t)
        assert bk.memory.patches_textured == int((depth >= t).sum())


def test_mesh_part_is_the_anchored_mesh_of_meshed_patches(grid_sol):
    """The mesh part: the meshed patches' vertices and triangles, sorted by patch depth (stable),
    so that every threshold's mesh part is a prefix of one array (views, uploaded once)."""
    b = Baker(grid_sol)
    bk = b.bake(BakePolicy(threshold=3))
    P, _, _ = qt.decode_key(grid_sol.vert_key, grid_sol.n)
    depth = grid_sol.patch_depth()
    order_v = np.argsort(depth[P], kind="stable")
    keep_v = order_v[~bk.patch_textured[P[order_v]]]
    np.testing.assert_array_equal(bk.mesh_positions, grid_sol.vert_position[keep_v].astype(np.float32))
    np.testing.assert_array_equal(bk.mesh_radiance, grid_sol.vert_radiance[keep_v])
    np.testing.assert_array_equal(bk.mesh_patch, P[keep_v])
    tp = P[grid_sol.tri_vertices[:, 0]]
    order_t = np.argsort(depth[tp], kind="stable")
    keep_t = order_t[~bk.patch_textured[tp[order_t]]]
    got = bk.mesh_positions[bk.mesh_indices.astype(int)]
    want = grid_sol.vert_position[grid_sol.tri_vertices[keep_t]].astype(np.float32)
    np.testing.assert_array_equal(got, want)
    assert bk.mesh_indices.dtype == np.uint32 and bk.tex_indices.dtype == np.uint32
    # another threshold's mesh part is a longer (or shorter) prefix of the same memory
    more = b.bake(BakePolicy(threshold=int(depth.max()) + 1))
    assert len(more.mesh_indices) > len(bk.mesh_indices) > 0
    for name in ("mesh_positions", "mesh_radiance", "mesh_indices"):
        a, full = getattr(bk, name), getattr(more, name)
        assert np.shares_memory(a, full) and not a.flags.writeable
        np.testing.assert_array_equal(full[: len(a)], a)


# -- atlas uv / texture content -------------------------------------------------------------


def test_corner_uvs_are_texel_centres_half_a_texel_in(grid_sol):
    bk = Baker(grid_sol).bake(BakePolicy(threshold=0, scale=0.7))
    _, H, W, _ = bk.pages.shape
    for p in np.flatnonzero(bk.patch_textured):
        k = corner_slots(bk, p)
        px = bk.tex_uv[k].astype(np.float64) * [W, H] - 0.5
        np.testing.assert_allclose(px, np.round(px), atol=1e-3)  # on texel centres
        side = int(round(px[1, 0] - px[0, 0])) + 1
        assert side == max(2, int(np.floor((2 ** int(grid_sol.patch_depth()[p])) * 0.7 + 0.5)) + 1)
        # the polygon's corner texel centres, half a texel inside the tile box
        x0, y0 = px[0]
        assert np.allclose(px[1], [x0 + side - 1, y0])
        assert np.allclose(px[2], [x0 + side - 1, y0 + side - 1] if len(k) == 4 else [x0, y0 + side - 1])
        assert np.all(bk.tex_layer[k] == bk.tex_layer[k[0]])


@pytest.mark.parametrize("method", ["bilinear", "scan", "bicubic"])
def test_pages_reproduce_a_linear_field_anywhere_in_the_polygons(grid_sol, method):
    bk = Baker(grid_sol).bake(BakePolicy(threshold=0, method=method))
    rng = np.random.default_rng(2)
    for p in np.flatnonzero(bk.patch_textured):
        u, v = rng.random(100), rng.random(100)
        if not grid_sol.patch_is_quad[p]:
            u, v = (
                np.concatenate([u * (1 - v), [0.0, 1.0, 0.0, 0.5]]),
                np.concatenate([v, [0.0, 0.0, 1.0, 0.5]]),
            )
        layer = bk.tex_layer[corner_slots(bk, p)[0]].astype(int)
        got = sample_pages(bk.pages, np.full(len(u), layer), atlas_uv(bk, p, u, v))
        np.testing.assert_allclose(got, linear_field(patch_world(grid_sol, p, u, v)), atol=5e-6)


def test_corner_texels_hold_the_corner_vertex_values():
    sol = grid_scene_solution(wavy_field, seed=3)
    bk = Baker(sol).bake(BakePolicy(threshold=0, method="bilinear"))
    _, H, W, _ = bk.pages.shape
    N = sol.n
    for p in range(len(sol.patch_is_quad)):
        k = corner_slots(bk, p)
        lat = [(0, 0), (N, 0), (N, N), (0, N)] if len(k) == 4 else [(0, 0), (N, 0), (0, N)]
        px = np.round(bk.tex_uv[k].astype(np.float64) * [W, H] - 0.5).astype(int)
        for (i, j), (x, y), kk in zip(lat, px, k, strict=True):
            vid = qt.lookup(sol.vert_key, qt.make_key(p, i, j, N))
            np.testing.assert_array_equal(bk.pages[int(bk.tex_layer[kk]), y, x], sol.vert_radiance[vid])


# -- memory report --------------------------------------------------------------------------


def hand_solution():
    """Two quads of depth 2 and a triangle of depth 1 (roots split once, one child of each quad again)."""
    corners = np.array(
        [
            [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
            [[2, 0, 0], [3, 0, 0], [3, 1, 0], [2, 1, 0]],
            [[4, 0, 0], [5, 0, 0], [4, 1, 0], [4, 1, 0]],
        ],
        dtype=np.float64,
    )
    f = qt.roots(np.array([True, True, False]), 4)
    f = qt.split(f, np.ones(3, bool))
    f = qt.balance(qt.split(f, (f.leaf_patch < 2) & (f.leaf_i == 0) & (f.leaf_j == 0)))
    keys = qt.vertex_keys(f)
    pos = qt.keys_to_world(corners, f.patch_is_quad, keys, f.n)
    return Solution.from_forest(
        f, corners, [0, 0, 0], np.full((3, 3), 0.5), keys, linear_field(pos).astype(np.float32)
    )


def test_memory_report_exact_bytes():
    sol = hand_solution()
    np.testing.assert_array_equal(sol.patch_depth(), [2, 2, 1])
    bk = Baker(sol).bake(BakePolicy(threshold=2, gutter=2, mipmaps=True, page_size=2048))
    m = bk.memory
    # tiles 5 x 5; box 5 + 2*2 = 9 -> aligned to 2 (2 mip levels) = 10; two boxes fit a 32 x 16 page
    assert (m.pages, m.page_width, m.page_height, m.mip_levels) == (1, 32, 16, 2)
    assert m.mip_factor == pytest.approx((32 * 16 + 16 * 8) / (32 * 16))
    assert m.texture_bytes == (32 * 16 + 16 * 8) * 8 == 5120
    assert m.utilisation == pytest.approx(2 * 25 / (32 * 16))
    # textured: 2 quads x 4 vertices x 36 B; mesh: the triangle's 6 vertices x 24 B, 4 triangles
    assert m.vertex_bytes_textured == 8 * 36
    assert m.vertex_bytes_mesh == 6 * 24
    assert m.vertex_bytes == 8 * 36 + 6 * 24
    assert (m.triangles_textured_part, m.triangles_mesh_part) == (4, 4)
    assert m.index_bytes == 8 * 12
    assert m.draw_calls == 2
    assert (m.patches_textured, m.patches_meshed) == (2, 1)
    assert m.total_bytes == 5120 + 8 * 36 + 6 * 24 + 96
    d = m.to_dict()
    assert d["texture_bytes"] == 5120 and d["total_bytes"] == m.total_bytes
    assert isinstance(m, MemoryReport)

    m8 = Baker(sol).bake(BakePolicy(threshold=2, pixel_format="rgba8")).memory
    assert m8.texture_bytes == 640 * 4 and m8.bytes_per_texel == BYTES_PER_TEXEL["rgba8"]
    # no mipmaps: one level, no alignment: boxes 9 x 9, still a 32 x 16 page
    m1 = Baker(sol).bake(BakePolicy(threshold=2, mipmaps=False)).memory
    assert (m1.mip_levels, m1.page_width, m1.page_height, m1.texture_bytes) == (1, 32, 16, 32 * 16 * 8)


def test_tile_larger_than_a_page_is_an_error():
    sol = make_solution(SHAPES[[1]], [True], linear_field, max_depth=6, rounds=6, frac=0.9, seed=0)
    assert sol.patch_depth()[0] == 6  # 65 x 65 texels
    with pytest.raises(BakeError, match=r"patch 0 is 65x65 texels"):
        Baker(sol).bake(BakePolicy(threshold=0, page_size=64))
    Baker(sol).bake(BakePolicy(threshold=0, page_size=64, scale=0.5))  # 33 x 33 fits


def test_policy_validation():
    for bad in (
        dict(threshold=-1),
        dict(scale=0.0),
        dict(scale=float("nan")),
        dict(method="nearest"),
        dict(scale_mode="stretch"),
        dict(budget_mb=-1.0),
        dict(gutter=-1),
        dict(page_size=1000),
        dict(page_size=32768),
        dict(pixel_format="rgb565"),
    ):
        with pytest.raises(OptionError, match=next(iter(bad))):
            BakePolicy(**bad).validate()


def test_scene_must_match_the_solution(grid_sol):
    sc = Scene(np.zeros((3, 3)), np.array([[0, 1, 2, -1]]), [0], [Material()])
    with pytest.raises(BakeError, match="patches"):
        Baker(grid_sol, sc)


# -- pixel formats --------------------------------------------------------------------------


def test_pixel_format_quantisation(grid_sol):
    x = np.random.default_rng(0).random((1000, 3)) * 4
    q8 = quantise_rgba8(x, 4.0)
    assert np.abs(q8 - x).max() <= 4.0 * 0.02 and np.abs(q8 - x).max() > 0
    q9 = quantise_rgb9e5(x)
    assert np.all(np.abs(q9 - x) <= x.max(axis=1, keepdims=True) * 2.0**-9 + 1e-12)
    np.testing.assert_array_equal(quantise_rgb9e5(q9), q9)  # idempotent
    b = Baker(grid_sol)
    f = b.bake(BakePolicy(threshold=0))
    e = b.bake(BakePolicy(threshold=0, pixel_format="rgba8"))
    assert e.page_scale == pytest.approx(float(grid_sol.vert_radiance.max()))
    assert np.abs(e.pages - f.pages).max() <= 0.02 * e.page_scale
    assert f.page_scale == 1.0


# -- detail textures ------------------------------------------------------------------------


def detail_scene():
    sol = make_solution(SHAPES[[1, 2]], [True, False], linear_field, max_depth=4, rounds=3, seed=5)
    verts = np.array([[2, 0, 0], [3, 0, 0], [3, 1, 0], [2, 1, 0], [4, 0, 0], [5, 0, 0], [4, 1, 0]], float)
    pc = np.array([[0, 1, 2, 3], [4, 5, 6, -1]])
    brick = np.random.default_rng(0).random((8, 8, 3)).astype(np.float32)
    mats = [
        Material("plain", albedo=[0.5, 0.5, 0.5]),
        Material("brick", albedo=[0.25, 0.5, 0.8], detail=brick),
    ]
    uv = np.array([[[0, 0], [4, 0], [4, 4], [0, 4]], [[0, 0], [2, 0], [0, 2], [0, 0]]], float)
    sc = Scene(verts, pc, [1, 0], mats, patch_uv=uv)
    sol.patch_material[:] = [1, 0]
    sol.patch_albedo[:] = [[0.25, 0.5, 0.8], [0.5, 0.5, 0.5]]
    return sol, sc, brick


def test_detail_patches_store_incoming_light():
    sol, sc, brick = detail_scene()
    bk = Baker(sol, sc).bake(BakePolicy(threshold=0, detail=True))
    k0, k1 = corner_slots(bk, 0), corner_slots(bk, 1)
    np.testing.assert_array_equal(bk.tex_detail[k0], 1.0)
    np.testing.assert_array_equal(bk.tex_detail[k1], 0.0)
    assert list(bk.detail_textures) == [1] and bk.detail_textures[1] is brick
    np.testing.assert_allclose(bk.tex_detail_uv[k0], sc.patch_uv[0], atol=0)
    np.testing.assert_allclose(bk.tex_detail_uv[k1], sc.patch_uv[1, :3], atol=0)
    np.testing.assert_array_equal(bk.tex_material[k0], 1)
    # at the corners: incoming light = radiance / albedo on the brick quad, radiance elsewhere
    c = sol.patch_corners
    got0 = sample_pages(bk.pages, bk.tex_layer[k0].astype(int), bk.tex_uv[k0].astype(np.float64))
    np.testing.assert_allclose(got0, linear_field(c[0]) / [0.25, 0.5, 0.8], rtol=1e-6)
    got1 = sample_pages(bk.pages, bk.tex_layer[k1].astype(int), bk.tex_uv[k1].astype(np.float64))
    np.testing.assert_allclose(got1, linear_field(c[1, :3]), rtol=1e-6)
    assert bk.memory.draw_calls == 2  # one texture state per detail texture plus the plain one
    assert bk.memory.detail_texture_bytes == (64 + 16 + 4 + 1) * 4
    # detail off: radiance everywhere
    off = Baker(sol, sc).bake(BakePolicy(threshold=0, detail=False))
    assert not off.tex_detail.any() and off.detail_textures == {}
    got = sample_pages(off.pages, off.tex_layer[k0].astype(int), off.tex_uv[k0].astype(np.float64))
    np.testing.assert_allclose(got, linear_field(c[0]), rtol=1e-6)
    # seams compare radiance: albedo given back through the solution
    assert seam_error(bk, sol)["edges"] == 0  # the two patches share no edge


# -- budget ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def budget_sol():
    return grid_scene_solution(wavy_field, max_depth=6, seed=4, frac=0.6)


def test_budget_fits_and_is_monotone(budget_sol):
    b = Baker(budget_sol)
    base = BakePolicy(threshold=0, page_size=256)
    full = b.bake(base).memory.texture_bytes
    assert full > 0
    prev = None
    for mb in np.linspace(0, 1.2 * full / 2**20, 25):
        bk = b.bake(BakePolicy(threshold=0, page_size=256, budget_mb=float(mb)))
        m = bk.memory
        assert m.texture_bytes <= mb * 2**20
        assert m.budget_fits and m.budget_mb == pytest.approx(mb)
        assert bk.policy.budget_mb is None and bk.policy.scale <= 1.0
        if prev is not None:
            assert m.patches_textured >= prev.memory.patches_textured
            if bk.policy.threshold == prev.policy.threshold:
                assert bk.policy.scale >= prev.policy.scale
        prev = bk
    assert prev.policy.threshold == 0 and prev.policy.scale == 1.0  # a budget above the need changes nothing


def test_budget_zero_and_too_small_give_all_mesh(budget_sol):
    deepest = int(budget_sol.patch_depth().max())
    z = choose_policy(budget_sol, 0.0, BakePolicy(threshold=1))
    assert z.threshold == deepest + 1
    b = Baker(budget_sol)
    bk = b.bake(BakePolicy(budget_mb=0.0))
    assert not bk.patch_textured.any() and bk.memory.texture_bytes == 0
    tiny = b.bake(BakePolicy(budget_mb=1e-5))  # 10 bytes: smaller than any texture
    assert not tiny.patch_textured.any()
    assert tiny.memory.budget_too_small and tiny.memory.budget_fits
    assert not b.bake(BakePolicy(budget_mb=100.0)).memory.budget_too_small
    assert choose_policy(budget_sol, None, BakePolicy(threshold=3)).threshold == 3


def test_budget_prefers_scaling_before_raising_the_threshold(budget_sol):
    b = Baker(budget_sol)
    base = BakePolicy(threshold=0, page_size=256)
    full = b.bake(base).memory.texture_bytes
    bk = b.bake(BakePolicy(threshold=0, page_size=256, budget_mb=0.5 * full / 2**20))
    assert bk.policy.threshold == 0 and 0.25 <= bk.policy.scale < 1.0


def test_cost_model_gain_grows_with_depth(budget_sol):
    cm = cost_model(budget_sol)
    depths = sorted(cm)
    assert len(depths) >= 2
    gain_per_patch = [cm[d]["gain"] / cm[d]["patches"] for d in depths]
    assert gain_per_patch == sorted(gain_per_patch)
    assert cm[depths[-1]]["gain"] > 0


# -- cache ----------------------------------------------------------------------------------


def test_rebake_reuses_tiles_and_packing():
    grid_sol = grid_scene_solution()
    # one material per patch: no seam pairs, so the only tiles flattened are the textured ones
    grid_sol.patch_material[:] = np.arange(len(grid_sol.patch_material))
    b = Baker(grid_sol)
    depth = grid_sol.patch_depth()
    lo, mid, hi = 2, 4, 5
    assert {lo, mid, hi} <= set(depth.tolist()) and not (depth == 3).all()
    b.bake(BakePolicy(threshold=mid))
    assert b.tiles.flatten_calls == 1
    assert b.tiles.tiles_flattened == int((depth >= mid).sum())
    b.bake(BakePolicy(threshold=hi))  # a subset: nothing new to flatten
    assert b.tiles.flatten_calls == 1
    b.bake(BakePolicy(threshold=lo))  # only the patches of depth lo..mid-1 are new
    assert b.tiles.flatten_calls == 2
    assert b.tiles.tiles_flattened == int((depth >= lo).sum())
    hits = b.stats["pack_hits"]
    again = b.bake(BakePolicy(threshold=lo))
    assert b.stats["pack_hits"] == hits + 1 and b.tiles.flatten_calls == 2
    assert b.stats["pages_hits"] >= 1
    # pixel format change: same tiles, same packing
    b.bake(BakePolicy(threshold=lo, pixel_format="rgb9e5"))
    assert b.tiles.flatten_calls == 2 and b.stats["pack_hits"] == hits + 2
    # a cached re-bake gives the same result
    fresh = bake(grid_sol, None, BakePolicy(threshold=lo))
    np.testing.assert_array_equal(again.pages, fresh.pages)
    np.testing.assert_array_equal(again.tex_uv, fresh.tex_uv)
    assert set(again.timings) >= {"pack", "tiles", "mesh", "textured", "total"}


# -- seams ----------------------------------------------------------------------------------


@pytest.mark.parametrize("scale", [0.5, 0.37, 1.6])
def test_clamped_scaling_keeps_seams_exact_and_naive_does_not(grid_sol, scale):
    b = Baker(grid_sol)
    top = float(grid_sol.vert_radiance.max())
    exact = seam_error(b.bake(BakePolicy(threshold=0, scale=scale, scale_mode="clamped")))
    assert exact["edges"] == 12 + 1 + 1  # 3x3 grid: 12 inner edges; quad-triangle and the diagonal
    assert exact["max"] <= 2e-6 * top
    naive = seam_error(b.bake(BakePolicy(threshold=0, scale=scale, scale_mode="naive")))
    assert naive["edges"] == exact["edges"]
    assert naive["max"] > 1e-3 * top


def test_seams_of_the_mesh_and_of_unscaled_textures():
    sol = grid_scene_solution(wavy_field, seed=8)
    assert seam_error(sol)["edges"] == 14
    lin = grid_scene_solution(linear_field, seed=8)
    assert seam_error(lin)["max"] <= 2e-6 * float(lin.vert_radiance.max())
    s1 = seam_error(Baker(lin).bake(BakePolicy(threshold=0)))
    assert s1["max"] <= 2e-6 * float(lin.vert_radiance.max())
    # non-coplanar neighbours are left out unless asked for
    fold = make_solution(
        [[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[1, 0, 0], [1, 0, 1], [1, 1, 1], [1, 1, 0]]],
        [True, True],
        wavy_field,
        max_depth=4,
        rounds=3,
        seed=1,
    )
    assert seam_error(fold)["edges"] == 0
    assert seam_error(fold, coplanar_only=False)["edges"] == 1


def test_progress_reports_and_cancels(grid_sol):
    from iat.errors import Cancelled

    seen = []
    b = Baker(grid_sol)
    b.bake(BakePolicy(threshold=2), progress=lambda f, m: seen.append((f, m)) or True)
    fr = [f for f, _ in seen]
    assert fr[0] == 0.0 and fr[-1] == 1.0 and fr == sorted(fr)
    with pytest.raises(Cancelled):
        b.bake(BakePolicy(threshold=1), progress=lambda f, m: f < 0.5)
    assert b.bake(BakePolicy(threshold=1)).patch_textured.sum() == int((grid_sol.patch_depth() >= 1).sum())


def test_gpu_iat_image_matches_the_mesh_image_on_a_linear_field(egl_ctx):
    """End to end through iat.render: atlas uv, half-texel border and triangle fill on the GPU."""
    from iat.camera import Camera
    from iat.render.renderer import Renderer

    sol = grid_scene_solution(linear_field, seed=3)
    cam = Camera(
        eye=np.array([2.0, 1.5, 4.0]), target=np.array([2.0, 1.5, 0.0]), yfov=50.0, znear=0.1, zfar=20
    )
    r = Renderer(egl_ctx)
    try:
        r.set_solution(sol)
        mesh = r.render(cam, size=(160, 120), mode="mesh")
        lit = mesh.max(axis=-1) > 0
        assert lit.mean() > 0.3
        for pol in (BakePolicy(threshold=0, method="scan"), BakePolicy(threshold=3, scale=0.5)):
            r.set_baked(Baker(sol).bake(pol))
            img = r.render(cam, size=(160, 120), mode="iat")
            np.testing.assert_array_equal(img.max(axis=-1) > 0, lit)
            # rgba16f pages: half-float rounding of values in [1, 3] is below 2e-3
            assert np.abs(img - mesh)[lit].max() < 2e-3
    finally:
        r.release()
    assert egl_ctx.error == "GL_NO_ERROR"


# -- GPU form of the pages, host memory -------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["rgba16f", "rgba8", "rgb9e5"])
def test_gpu_pages_are_the_stored_pages_in_the_gpu_dtype(grid_sol, fmt):
    """The Baker blits pages straight in their GPU form (rgba16f: float16, rgba8: sRGB8 codes of
    page / page_scale, rgb9e5: the 9e5 values as float16, exact), read-only and cached; ``pages``
    (float32, exact for rgba16f) is made on first access and equals the GPU form decoded within
    the format's rounding."""
    from iat.bake.formats import GPU_DTYPES, from_gpu, to_gpu

    b = Baker(grid_sol)
    bk = b.bake(BakePolicy(threshold=0, pixel_format=fmt))
    g = bk.gpu_form()
    assert g is not None and g.dtype == GPU_DTYPES[fmt] and g.shape[3] == 4 and not g.flags.writeable
    assert "_pages" not in bk.__dict__ or bk.__dict__["_pages"] is None  # not made yet
    pages = bk.pages
    assert pages.dtype == np.float32 and pages.shape == g.shape[:3] + (3,)
    dec = from_gpu(g, fmt, bk.page_scale)
    if fmt == "rgba16f":
        np.testing.assert_array_equal(dec, pages.astype(np.float16).astype(np.float32))
        assert (g[..., 3][pages.max(axis=-1) > 0] == 1).all()
    else:  # already rounded as the format stores it: exact
        np.testing.assert_array_equal(dec, pages)
        np.testing.assert_array_equal(to_gpu(pages, fmt, bk.page_scale)[..., :3], g[..., :3])
    # a re-bake hits the cache: the very same arrays
    again = b.bake(BakePolicy(threshold=0, pixel_format=fmt))
    assert again.gpu_form() is g
    # pages given explicitly (a blend, a test): the GPU form no longer applies
    import dataclasses

    other = dataclasses.replace(bk, pages=np.zeros_like(pages))
    assert other.gpu_form() is None and bk.gpu_form() is g


def test_to_gpu_clamps_half_floats_and_rounds_srgb():
    from iat.bake.formats import from_gpu, quantise_rgba8, to_gpu

    x = np.array([[1e5, 1.0, 0.0], [2.0**-20, 0.5, 3.0]], np.float32)
    h = to_gpu(x, "rgba16f")
    assert h.dtype == np.float16 and np.isfinite(h).all() and h[0, 0] == 65504.0 and (h[:, 3] == 1).all()
    c = to_gpu(x, "rgba8", 4.0)
    assert c.dtype == np.uint8 and (c[:, 3] == 255).all()
    np.testing.assert_array_equal(c[0, :3], [255, 137, 0])  # sRGB8 of 1 (clipped), 0.25, 0
    np.testing.assert_array_equal(from_gpu(c, "rgba8", 4.0), quantise_rgba8(x, 4.0))


def test_host_bytes_counts_pages_boxes_tiles_and_temporaries():
    from iat.bake import atlas
    from iat.bake.memory import host_bytes, host_memory_bytes

    sides = np.array([5, 5, 9])
    pk = atlas.pack(np.stack([sides, sides], axis=1), 64, 2, 2)
    pol = BakePolicy(gutter=2, page_size=64)
    box = np.array([10, 10, 14])  # sides + 2 gutter, aligned to 2
    want = (
        (25 + 25 + 81) * 12 + (box**2).sum() * (12 + 8) + pk.n_pages * pk.width * pk.height * 8 + 81 * 24 * 2
    )  # largest group: the 9 x 9 tile
    assert host_bytes(sides, pk, pol, 2) == want
    assert host_memory_bytes() > 1 << 26  # this machine has some memory
