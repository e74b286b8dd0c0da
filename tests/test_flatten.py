"""iat.bake.flatten: quad-tree -> texture tile, exact where the maths is exact.

Solutions are built synthetically (quadtree + Solution.from_forest) with radiance a
known function of world position. Fields linear in world position are linear in
(u, v) on parallelograms and triangles, and every method must reproduce them
exactly (to float32 rounding) at every texel, and under bilinear lookup anywhere.
"""

from __future__ import annotations

import numpy as np
import pytest

from iat.bake.flatten import (
    METHODS,
    SolutionIndex,
    TileCache,
    extend_triangle,
    flatten,
    sample_tile,
    scale_tile,
    scale_tiles,
    scaled_side,
    tile_side,
    tile_uv,
)
from iat.errors import OptionError
from iat.geometry import quadtree as qt
from iat.radiosity.solution import Solution

# -- synthetic solutions (also used by test_bake / test_export) ----------------------------------


def linear_field(p: np.ndarray) -> np.ndarray:
    """(k, 3) radiance linear in world position, positive on the test geometry."""
    p = np.asarray(p, dtype=np.float64)
    return np.stack(
        [
            1.0 + 0.5 * p[:, 0] + 0.25 * p[:, 1] - 0.1 * p[:, 2],
            2.0 - 0.3 * p[:, 0] + 0.2 * p[:, 2],
            1.5 + 0.1 * p[:, 1],
        ],
        axis=1,
    )


def wavy_field(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, dtype=np.float64)
    return np.stack(
        [
            1.2 + np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]),
            1.0 + 0.5 * p[:, 0] ** 2,
            0.5 + np.exp(-(p[:, 1] ** 2)),
        ],
        axis=1,
    )


def make_solution(
    corners, is_quad, field=linear_field, max_depth=5, rounds=4, frac=0.45, seed=0, material=None, albedo=0.5
) -> Solution:
    """Random adaptive (2:1 balanced) refinement of the given root patches, radiance = field(world)."""
    rng = np.random.default_rng(seed)
    corners = np.asarray(corners, dtype=np.float64)
    forest = qt.roots(np.asarray(is_quad, dtype=bool), max_depth)
    for _ in range(rounds):
        forest = qt.split(forest, rng.random(forest.n_leaves) < frac)
    forest = qt.balance(forest)
    keys = qt.vertex_keys(forest)
    pos = qt.keys_to_world(corners, forest.patch_is_quad, keys, forest.n)
    p = len(corners)
    mat = np.zeros(p, dtype=np.int64) if material is None else np.asarray(material)
    alb = (
        np.broadcast_to(np.asarray(albedo, dtype=np.float64), (p, 3)).copy()
        if np.ndim(albedo) < 2
        else albedo
    )
    return Solution.from_forest(forest, corners, mat, alb, keys, field(pos).astype(np.float32))


def tri_corners(a, b, c) -> np.ndarray:
    return np.array([a, b, c, c], dtype=np.float64)


#: a tilted parallelogram, an axis-aligned square, and two triangles sharing the diagonal of a square
SHAPES = np.array(
    [
        [[0, 0, 0], [1, 0, 0.2], [1.3, 0.8, 0.4], [0.3, 0.8, 0.2]],
        [[2, 0, 0], [3, 0, 0], [3, 1, 0], [2, 1, 0]],
        tri_corners([4, 0, 0], [5, 0, 0], [4, 1, 0]),
        tri_corners([5, 1, 0], [4, 1, 0], [5, 0, 0]),
    ]
)
SHAPES_QUAD = [True, True, False, False]


def texel_world(sol: Solution, p: int, n: int) -> np.ndarray:
    """(n*n, 3) world positions of patch ``p``'s texel centres (row-major b, a), affine extension."""
    b, a = np.mgrid[0:n, 0:n]
    u, v = (a / (n - 1)).ravel(), (b / (n - 1)).ravel()
    return patch_world(sol, p, u, v)


def patch_world(sol: Solution, p: int, u, v) -> np.ndarray:
    c = sol.patch_corners[p]
    u, v = np.asarray(u, dtype=np.float64)[:, None], np.asarray(v, dtype=np.float64)[:, None]
    if sol.patch_is_quad[p]:
        return (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3]
    return c[0] + u * (c[1] - c[0]) + v * (c[2] - c[0])


@pytest.fixture(scope="module")
def lin_sol() -> Solution:
    return make_solution(SHAPES, SHAPES_QUAD, linear_field, max_depth=5, rounds=5, seed=1)


@pytest.fixture(scope="module")
def wavy_sol() -> Solution:
    return make_solution(SHAPES, SHAPES_QUAD, wavy_field, max_depth=5, rounds=5, seed=2)


# -- shapes and conventions ---------------------------------------------------------------------


def test_tile_shape_and_axis_convention(lin_sol):
    depth = lin_sol.patch_depth()
    tiles = flatten(lin_sol, None, "bilinear")
    assert sorted(tiles) == [0, 1, 2, 3]
    D = lin_sol.max_depth
    for p, t in tiles.items():
        n = (1 << int(depth[p])) + 1
        assert t.shape == (n, n, 3) and t.dtype == np.float32
        # texel (a, b) = lattice (a << (D-d), b << (D-d)), stored at tile[b, a]
        s = D - int(depth[p])
        key = qt.make_key(p, 1 << s, 0, lin_sol.n)  # a = 1, b = 0 is on the j = 0 edge: always a vertex?
        vid = qt.lookup(lin_sol.vert_key, np.array([key]))[0]
        if vid >= 0:
            np.testing.assert_array_equal(t[0, 1], lin_sol.vert_radiance[vid])


def test_tile_side_and_scaled_side():
    assert tile_side(0) == 2 and tile_side(3) == 9
    np.testing.assert_array_equal(tile_side(np.array([1, 2])), [3, 5])
    assert scaled_side(9, 1.0) == 9
    assert scaled_side(9, 0.5) == 5
    assert scaled_side(9, 0.01) == 2  # never below 2
    assert scaled_side(5, 0.375) == 3  # 4 * 0.375 = 1.5 rounds half up
    assert scaled_side(9, 2.0) == 17


def test_tile_uv_half_texel_border():
    uv = tile_uv([0.0, 1.0, 0.5], [0.0, 1.0, 0.25], 9)
    np.testing.assert_allclose(uv[0], [0.5 / 9, 0.5 / 9])
    np.testing.assert_allclose(uv[1], [8.5 / 9, 8.5 / 9])
    np.testing.assert_allclose(uv[2], [4.5 / 9, 2.5 / 9])


# -- exactness ------------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_linear_field_exact_at_every_texel(lin_sol, method):
    tiles = flatten(lin_sol, None, method)
    for p, t in tiles.items():
        want = linear_field(texel_world(lin_sol, p, t.shape[0]))
        # triangles: the outer half too (the fill extends the field linearly)
        np.testing.assert_allclose(t.reshape(-1, 3), want, rtol=0, atol=2e-6, err_msg=f"{method} patch {p}")


@pytest.mark.parametrize("method", METHODS)
def test_linear_field_exact_under_bilinear_lookup(lin_sol, method):
    rng = np.random.default_rng(5)
    tiles = flatten(lin_sol, None, method)
    for p, t in tiles.items():
        u, v = rng.random(400), rng.random(400)
        if not lin_sol.patch_is_quad[p]:
            keep = u + v <= 1
            u, v = u[keep], v[keep]
            # points exactly on the hypotenuse, where the cells are cut by the diagonal
            s = rng.random(50)
            u, v = np.concatenate([u, s]), np.concatenate([v, 1 - s])
        got = sample_tile(t, u, v)
        np.testing.assert_allclose(got, linear_field(patch_world(lin_sol, p, u, v)), atol=3e-6)


@pytest.mark.parametrize("method", METHODS)
def test_vertex_texels_equal_vertex_values(wavy_sol, method):
    """Non-linear field: every texel that is a mesh vertex (hanging ones included) holds the vertex value."""
    tiles = flatten(wavy_sol, None, method)
    depth = wavy_sol.patch_depth()
    p, i, j = qt.decode_key(wavy_sol.vert_key, wavy_sol.n)
    sh = wavy_sol.max_depth - depth[p]
    got = np.stack([tiles[int(pp)][jj >> s, ii >> s] for pp, ii, jj, s in zip(p, i, j, sh, strict=True)])
    np.testing.assert_array_equal(got, wavy_sol.vert_radiance)
    # the hanging vertices exist in this solution (the test would be weak otherwise)
    hang = qt.hanging_midpoints(wavy_sol.forest, wavy_sol.vert_key)
    assert (hang >= 0).any()


def _brute_mesh_value(sol, p, n, tile):
    """Reference: barycentric value of the anchored triangle holding each texel (loops: test only)."""
    P, I, J = qt.decode_key(sol.vert_key, sol.n)
    sh = sol.max_depth - int(sol.patch_depth()[p])
    tris = sol.tri_vertices[P[sol.tri_vertices[:, 0]] == p]
    out = np.full((n, n, 3), np.nan)
    for t in tris:
        x, y = I[t] >> sh, J[t] >> sh
        area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
        if area == 0:
            continue
        for b in range(y.min(), y.max() + 1):
            for a in range(x.min(), x.max() + 1):
                w0 = ((x[2] - x[1]) * (b - y[1]) - (y[2] - y[1]) * (a - x[1])) / area
                w1 = ((x[0] - x[2]) * (b - y[2]) - (y[0] - y[2]) * (a - x[2])) / area
                w2 = 1 - w0 - w1
                if min(w0, w1, w2) >= -1e-12:
                    out[b, a] = (
                        w0 * sol.vert_radiance[t[0]]
                        + w1 * sol.vert_radiance[t[1]]
                        + w2 * sol.vert_radiance[t[2]]
                    )
    return out


def test_scan_reproduces_the_mesh_at_texel_centres():
    sol = make_solution(SHAPES[[1, 2]], [True, False], wavy_field, max_depth=4, rounds=4, seed=3)
    tiles = flatten(sol, None, "scan")
    for p, t in tiles.items():
        ref = _brute_mesh_value(sol, p, t.shape[0], t)
        inside = ~np.isnan(ref[..., 0])
        n = t.shape[0]
        b, a = np.mgrid[0:n, 0:n]
        expect_inside = np.ones_like(inside) if sol.patch_is_quad[p] else (a + b <= n - 1)
        np.testing.assert_array_equal(inside, expect_inside)
        np.testing.assert_allclose(t[inside], ref[inside], rtol=0, atol=1e-6)


def test_bilinear_fills_leaf_by_bilinear_interpolation_of_its_corners():
    """Root split, one child split again: the three coarse leaves' centre texels = mean of their corners."""
    forest = qt.roots(np.array([True]), 3)
    forest = qt.split(forest, np.array([True]))
    first = (forest.leaf_i == 0) & (forest.leaf_j == 0)
    forest = qt.balance(qt.split(forest, first))
    keys = qt.vertex_keys(forest)
    corners = SHAPES[[1]]
    pos = qt.keys_to_world(corners, forest.patch_is_quad, keys, forest.n)
    sol = Solution.from_forest(forest, corners, [0], [[0.5] * 3], keys, wavy_field(pos).astype(np.float32))
    t = flatten(sol, None, "bilinear")[0]
    assert t.shape == (5, 5, 3)
    # coarse leaf at lattice (4, 0) size 4 -> texels a 2..4, b 0..2; centre (3, 1)
    c = t[[0, 0, 2, 2], [2, 4, 4, 2]].astype(np.float64)
    np.testing.assert_allclose(t[1, 3], c.mean(axis=0), rtol=1e-6)
    # the edge texel (a=2, b=1) is a hanging vertex of that leaf (its neighbour is split): the vertex value
    vid = qt.lookup(sol.vert_key, qt.make_key(0, 4, 2, sol.n))
    assert vid >= 0
    np.testing.assert_array_equal(t[1, 2], sol.vert_radiance[vid])


def test_bicubic_reproduces_quadratic_fields_on_quads():
    def quad_field(p):
        x, y = p[:, 0], p[:, 1]
        return np.stack([1 + x * x + 0.5 * x * y, 2 - y * y + 0.3 * x, 1 + 0.2 * (x - y) ** 2], axis=1)

    sol = make_solution(SHAPES[[1]] - [2, 0, 0], [True], quad_field, max_depth=5, rounds=5, frac=0.7, seed=4)
    assert sol.patch_depth()[0] >= 3
    t = flatten(sol, None, "bicubic")[0]
    n = t.shape[0]
    np.testing.assert_allclose(t.reshape(-1, 3), quad_field(texel_world(sol, 0, n)), atol=3e-6)
    # and the cubic sampler evaluates the same surface anywhere
    rng = np.random.default_rng(0)
    u, v = rng.random(200), rng.random(200)
    np.testing.assert_allclose(
        sample_tile(t, u, v, "cubic"), quad_field(patch_world(sol, 0, u, v)), atol=3e-5
    )
    # bilinear and scan are only piecewise linear: they miss it somewhere between vertices
    assert np.abs(flatten(sol, None, "bilinear")[0] - t).max() > 1e-4


def test_bicubic_is_smoother_than_scan_between_sparse_vertices():
    """On a coarse leaf of a smooth field, bicubic fills closer to the truth than linear interpolation."""
    sol = make_solution(SHAPES[[1]], [True], wavy_field, max_depth=5, rounds=5, frac=0.7, seed=6)
    n = tile_side(int(sol.patch_depth()[0]))
    truth = wavy_field(texel_world(sol, 0, n)).reshape(n, n, 3)
    err = {m: np.abs(flatten(sol, None, m)[0] - truth).mean() for m in ("scan", "bicubic")}
    assert err["bicubic"] < err["scan"]


def test_triangle_fill_parallelogram_rule_and_linear_exactness():
    rng = np.random.default_rng(0)
    c = 9
    t = rng.random((2, c, c, 3))
    extend_triangle(t)
    b, a = np.mgrid[1:c, 1:c]
    out = a + b > c - 1
    lhs = t[:, b, a]
    rhs = t[:, b, a - 1] + t[:, b - 1, a] - t[:, b - 1, a - 1]
    np.testing.assert_allclose(lhs[:, out], rhs[:, out], atol=1e-12)
    bb, aa = np.mgrid[0:c, 0:c]
    lin = np.stack([1 + 2 * aa - 3 * bb, aa + bb, 0.5 * bb], axis=-1)[None].astype(np.float64)
    junk = lin.copy()
    junk[:, aa + bb > c - 1] = 123.0
    np.testing.assert_allclose(extend_triangle(junk), lin, atol=1e-12)


def test_degenerate_triangles_are_skipped():
    sol = make_solution(SHAPES[[1, 2]], [True, False], wavy_field, max_depth=4, rounds=3, seed=7)
    ref = flatten(sol, None, "scan")
    t = sol.tri_vertices
    degenerate = np.array([[t[0, 0], t[0, 0], t[0, 1]], [t[1, 0], t[1, 1], t[1, 1]]], dtype=np.int32)
    sol2 = Solution(**{**sol.__dict__, "tri_vertices": np.concatenate([t, degenerate])})
    got = flatten(sol2, None, "scan")
    for p in ref:
        np.testing.assert_array_equal(got[p], ref[p])


def test_subset_and_bad_arguments(lin_sol):
    tiles = flatten(lin_sol, [2, 0], "scan")
    assert sorted(tiles) == [0, 2]
    np.testing.assert_array_equal(tiles[2], flatten(lin_sol, None, "scan")[2])
    with pytest.raises(OptionError, match="method"):
        flatten(lin_sol, None, "nearest")
    with pytest.raises(OptionError, match="out of range"):
        flatten(lin_sol, [99], "scan")


# -- scaling --------------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("scale", [0.5, 0.37, 1.6])
def test_clamped_scaling_of_a_linear_field_is_exact(lin_sol, method, scale):
    tiles = flatten(lin_sol, None, method)
    for p, t in tiles.items():
        s = scale_tile(t, scale, "clamped", method, triangle=not lin_sol.patch_is_quad[p])
        m = scaled_side(t.shape[0], scale)
        assert s.shape == (m, m, 3)
        np.testing.assert_allclose(s.reshape(-1, 3), linear_field(texel_world(lin_sol, p, m)), atol=3e-6)


@pytest.mark.parametrize("method", METHODS)
def test_clamped_scaling_keeps_corners_and_edges_from_edge_texels(wavy_sol, method):
    t = flatten(wavy_sol, None, method)[1]
    s = scale_tile(t, 0.45, "clamped", method)
    for (b0, a0), (b1, a1) in [
        ((0, 0), (0, 0)),
        ((0, -1), (0, -1)),
        ((-1, 0), (-1, 0)),
        ((-1, -1), (-1, -1)),
    ]:
        np.testing.assert_array_equal(s[b1, a1], t[b0, a0])
    # edges depend on edge texels only: change the interior, the edges of the result stay
    t2 = t.copy()
    t2[1:-1, 1:-1] += 5.0
    s2 = scale_tile(t2, 0.45, "clamped", method)
    for sl in (np.s_[0, :], np.s_[-1, :], np.s_[:, 0], np.s_[:, -1]):
        np.testing.assert_array_equal(s2[sl], s[sl])


def test_naive_scaling_moves_texel_centres(lin_sol):
    t = flatten(lin_sol, None, "bilinear")[1]
    s = scale_tile(t, 0.5, "naive", "bilinear")
    assert s.shape == (scaled_side(t.shape[0], 0.5),) * 2 + (3,)
    want = linear_field(texel_world(lin_sol, 1, s.shape[0])).reshape(s.shape)
    assert np.abs(s[0, 0] - want[0, 0]).max() > 1e-3  # the corner no longer holds the corner value


def test_scale_one_is_identity_and_errors(lin_sol):
    t = flatten(lin_sol, None, "scan")[0]
    np.testing.assert_array_equal(scale_tile(t, 1.0), t)
    with pytest.raises(OptionError):
        scale_tiles(t[None], 0.0)
    with pytest.raises(OptionError, match="mode"):
        scale_tiles(t[None], 0.5, "fancy")


# the previous per-tile scaling (float64 per-tap gathers; PIL per tile and channel), kept here
# as the reference the batched matrix products must reproduce
def _reference_scale(tile, scale, mode, method, triangle):
    from PIL import Image

    from iat.bake.flatten import axis_weights

    n = tile.shape[0]
    m = scaled_side(n, scale)
    if m == n:
        return tile.astype(np.float32)
    if mode == "naive":
        res = Image.Resampling.BICUBIC if method == "bicubic" else Image.Resampling.BILINEAR
        out = np.empty((m, m, 3), dtype=np.float32)
        for ch in range(3):
            img = Image.fromarray(np.ascontiguousarray(tile[:, :, ch], dtype=np.float32))
            out[:, :, ch] = np.asarray(img.resize((m, m), res), dtype=np.float32)
        return out
    pos = np.arange(m) * ((n - 1) / (m - 1))
    pos[-1] = n - 1
    kern = "cubic" if method == "bicubic" else "bilinear"
    r = np.asarray(tile, dtype=np.float64)
    for axis in (1, 0):
        idx, w = axis_weights(r.shape[axis], pos, kern)
        x = np.moveaxis(r, axis, 0)
        acc = np.zeros((m,) + x.shape[1:])
        for t in range(idx.shape[1]):
            acc += w[:, t][:, None, None] * x[idx[:, t]]
        r = np.moveaxis(acc, 0, axis)
    if triangle:
        r = extend_triangle(r[None])[0]
    return r.astype(np.float32)


@pytest.mark.parametrize("mode", ["clamped", "naive"])
@pytest.mark.parametrize("method", METHODS)
def test_batched_scaling_equals_per_tile_scaling(wavy_sol, mode, method):
    rng = np.random.default_rng(3)
    for n in (2, 3, 5, 9, 17, 33, 65):
        stack = (1.0 + rng.random((7, n, n, 3)) * 10.0 ** rng.uniform(-2, 2, (7, 1, 1, 1))).astype(np.float32)
        tri = np.arange(7) % 3 == 0
        for scale in [2.0 ** (-q / 4) for q in range(1, 9)] + [0.37, 1.6]:
            got = scale_tiles(stack, scale, mode, method, triangle=tri)
            for q in range(len(stack)):
                want = _reference_scale(stack[q], scale, mode, method, bool(tri[q]) and mode == "clamped")
                assert got[q].shape == want.shape and got.dtype == np.float32
                # within float32 rounding of the values (PIL's and the reference's float64 sums)
                np.testing.assert_allclose(got[q], want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
                if mode == "clamped":  # corners are copies
                    for b, a in ((0, 0), (0, -1), (-1, 0)):
                        np.testing.assert_array_equal(got[q][b, a], stack[q][b, a])
    # real tiles too (triangles and quads of a solution)
    tiles = flatten(wavy_sol, None, method)
    for p, t in tiles.items():
        is_tri = not wavy_sol.patch_is_quad[p]
        got = scale_tile(t, 0.59, mode, method, triangle=is_tri)
        want = _reference_scale(t, 0.59, mode, method, is_tri and mode == "clamped")
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())


# -- cache ----------------------------------------------------------------------------------


def test_tile_cache_reuses_tiles(lin_sol):
    cache = TileCache(lin_sol, SolutionIndex(lin_sol))
    a = cache.get([0, 1, 2], "bilinear")
    assert cache.flatten_calls == 1 and cache.tiles_flattened == 3
    b = cache.get([1, 2], "bilinear")
    assert cache.flatten_calls == 1
    assert b[0] is a[1]
    cache.get([0, 3], "bilinear")
    assert cache.flatten_calls == 2 and cache.tiles_flattened == 4  # only patch 3 was new
    s = cache.get([0, 1], "bilinear", 0.5, "clamped")
    assert cache.flatten_calls == 2 and cache.scale_calls == 1  # scaled from cached tiles
    assert s[0].shape[0] == scaled_side(a[0].shape[0], 0.5)
    cache.get([0, 1], "bilinear", 0.5, "clamped")
    assert cache.scale_calls == 1
    cache.get([0], "bilinear", 0.5, "naive")
    assert cache.scale_calls == 2
    cache.get([0], "scan")
    assert cache.flatten_calls == 3


def test_tile_cache_keeps_few_scaled_sets_and_read_only_tiles(lin_sol):
    cache = TileCache(lin_sol, max_scaled_sets=2)
    base = cache.get([0, 1], "scan")
    assert not base[0].flags.writeable
    for s in (0.3, 0.4, 0.5):
        cache.get([0, 1], "scan", s)
    assert cache.scale_calls == 3
    cache.get([0, 1], "scan", 0.5)  # kept
    cache.get([0, 1], "scan", 0.3)  # evicted: scaled again from the kept scale-1 tiles
    assert cache.scale_calls == 4 and cache.flatten_calls == 1
    assert len(cache) == 2 + 2 * 2
