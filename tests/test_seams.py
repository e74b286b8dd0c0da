"""iat.bake.seams: shared-edge pairing, harmonised tile edges, the seam measure.

Synthetic solutions: root patches refined uniformly to a chosen depth each, radiance a
smooth non-linear function of world position, so neighbours of different depths describe
their shared edge by different polylines (the solved models' situation) and the baker has a
seam to remove. ``seams.applies`` patched to False gives the same bake without harmonisation.
"""

from __future__ import annotations

import numpy as np
import pytest

from iat.bake import seams
from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.geometry import quadtree as qt
from iat.measure.seams import seam_error, seam_measure
from iat.radiosity.solution import Solution
from tests.test_flatten import wavy_field


def uniform_solution(corners, is_quad, depths, field=wavy_field, max_depth=5, material=None) -> Solution:
    """Root patches refined uniformly, patch p to ``depths[p]``; radiance = field(world)."""
    corners = np.asarray(corners, dtype=np.float64)
    depths = np.asarray(depths)
    forest = qt.roots(np.asarray(is_quad, dtype=bool), max_depth)
    for _ in range(int(depths.max())):
        forest = qt.split(forest, forest.leaf_level < depths[forest.leaf_patch])
    keys = qt.vertex_keys(forest)
    pos = qt.keys_to_world(corners, forest.patch_is_quad, keys, forest.n)
    p = len(corners)
    mat = np.zeros(p, dtype=np.int64) if material is None else np.asarray(material)
    return Solution.from_forest(
        forest, corners, mat, np.full((p, 3), 0.5), keys, field(pos).astype(np.float32)
    )


def quad(x0, y0, x1, y1):
    return [[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]]


#: two unit quads side by side, sharing x = 1
TWO = [quad(0, 0, 1, 1), quad(1, 0, 2, 1)]
#: T-junction: a 2 x 1 quad below two unit quads (its top edge meets two edges, half each)
TEE = [quad(0, -1, 2, 0), quad(0, 0, 1, 1), quad(1, 0, 2, 1)]
#: a triangle whose hypotenuse (1,0)-(0,1) is edge 0 of a square turned 45 degrees
TRI_QUAD = [
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]],
    [[0, 1, 0], [1, 0, 0], [2, 1, 0], [1, 2, 0]],
]


def without_seams(monkeypatch):
    monkeypatch.setattr(seams, "applies", lambda policy: False)


def bake_both(sol, policy, monkeypatch):
    """(harmonised bake, the same bake without harmonisation)."""
    on = Baker(sol).bake(policy)
    with monkeypatch.context() as m:
        m.setattr(seams, "applies", lambda policy: False)
        off = Baker(sol).bake(policy)
    return on, off


# -- pairing -------------------------------------------------------------------------------------


def test_pairs_whole_edges_partial_overlaps_and_what_is_left_out():
    pr = seams.edge_pairs(np.array(TWO, float), [True, True])
    assert len(pr) == 1
    np.testing.assert_array_equal(pr.patch[0], [0, 1])
    np.testing.assert_array_equal(pr.edge[0], [1, 3])  # x = 1: quad 0's edge 1-2, quad 1's 3-0
    np.testing.assert_allclose(pr.lo[0], [0, 1], atol=1e-12)
    np.testing.assert_allclose(pr.hi[0], [1, 0], atol=1e-12)

    pr = seams.edge_pairs(np.array(TEE, float), [True] * 3)
    got = {
        tuple(p): (lo, hi)
        for p, lo, hi in zip(pr.patch.tolist(), pr.lo.tolist(), pr.hi.tolist(), strict=True)
    }
    assert set(got) == {(0, 1), (0, 2), (1, 2)}
    # the big quad's top edge runs 2 -> 0 (slot 2 -> 3): patch 2 covers its first half
    np.testing.assert_allclose(sorted(got[(0, 2)][0] + got[(0, 2)][1]), [0, 0, 0.5, 1], atol=1e-12)
    np.testing.assert_allclose(sorted(got[(0, 1)][0] + got[(0, 1)][1]), [0, 0.5, 1, 1], atol=1e-12)

    # another material, a fold (not coplanar), a patch overlapping on the same side: no pair
    assert len(seams.edge_pairs(np.array(TWO, float), [True, True], material=[0, 1])) == 0
    folded = np.array(TWO, float)
    folded[1, 1:3, 2] = 0.5  # quad 1 lifted along its far edge
    assert len(seams.edge_pairs(folded, [True, True])) == 0
    assert len(seams.edge_pairs(folded, [True, True], max_angle_deg=None)) == 1
    overlap = np.array([quad(0, 0, 1, 1), quad(0.5, 0, 1, 1)], float)  # shares x = 1, same side
    assert len(seams.edge_pairs(overlap, [True, True])) == 0


def test_ring_order_and_apply_ring_round_trip():
    rng = np.random.default_rng(1)
    for is_tri in (False, True):
        t = rng.random((5, 5, 3)).astype(np.float32)
        ring = seams.tile_ring(t, is_tri)
        assert ring.shape == ((3 if is_tri else 4) * 4, 3)
        np.testing.assert_array_equal(ring[0], t[0, 0])  # slot 0 = (u, v) = (0, 0)
        np.testing.assert_array_equal(ring[4], t[0, 4])  # slot 1 = (1, 0)
        np.testing.assert_array_equal(ring[8], t[4, 0] if is_tri else t[4, 4])  # slot 2
        new = seams.apply_ring(t, ring + 1.0, is_tri)
        np.testing.assert_allclose(seams.tile_ring(new, is_tri), ring + 1.0, rtol=1e-6)
        if is_tri:  # parallelogram rule outside the triangle
            c = new.shape[0]
            for b in range(c):
                for a in range(c - b, c):
                    want = new[b, a - 1] + new[b - 1, a] - new[b - 1, a - 1]
                    np.testing.assert_allclose(new[b, a], want, rtol=1e-5, atol=1e-5)


# -- harmonisation -------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["bilinear", "scan", "bicubic"])
def test_two_quads_of_different_depth_share_one_function(method, monkeypatch):
    sol = uniform_solution(TWO, [True, True], [4, 2])
    assert seam_error(sol)["max"] > 1e-3  # the two trees disagree along x = 1
    for scale in (1.0, 0.5, 0.25):
        pol = BakePolicy(threshold=0, method=method, scale=scale, detail=False)
        on, off = bake_both(sol, pol, monkeypatch)
        before, after = seam_error(off, sol), seam_error(on, sol)
        assert before["edges"] == after["edges"] == 1
        assert before["max"] > 1e-3, scale
        assert after["max"] <= 1e-6, (scale, after)
        m = seam_measure(on, sol, samples=65)
        assert m["max"] <= 1e-6 and m["segments"] == 1
        assert on.timings["seams"] >= 0.0


def test_naive_scaling_is_left_alone():
    sol = uniform_solution(TWO, [True, True], [4, 2])
    baker = Baker(sol)
    naive = seam_error(baker.bake(BakePolicy(threshold=0, scale=0.25, scale_mode="naive", detail=False)), sol)
    clamped = seam_error(baker.bake(BakePolicy(threshold=0, scale=0.25, detail=False)), sol)
    assert naive["max"] > 100 * max(clamped["max"], 1e-7)
    # scale 1 is one bake for both modes (the tile cache and the page cache share it)
    n1 = seam_error(baker.bake(BakePolicy(threshold=0, scale=1.0, scale_mode="naive", detail=False)), sol)
    assert n1["max"] <= 1e-6


@pytest.mark.parametrize("depths", [(4, 1), (1, 4), (3, 3)])
def test_triangle_hypotenuse_next_to_a_quad(depths, monkeypatch):
    sol = uniform_solution(TRI_QUAD, [False, True], depths)
    for scale in (1.0, 0.5, 0.25):
        on, off = bake_both(sol, BakePolicy(threshold=0, scale=scale, detail=False), monkeypatch)
        assert seam_error(on, sol)["edges"] == 1
        assert seam_error(on, sol)["max"] <= 1e-6, (depths, scale)
        if depths[0] != depths[1]:
            assert seam_error(off, sol)["max"] > 1e-3


def test_triangle_leg_next_to_a_quad(monkeypatch):
    # triangle (0,0) (1,0) (0,1) and the unit square below its leg y = 0
    sol = uniform_solution(
        [[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]], quad(0, -1, 1, 0)], [False, True], [2, 4]
    )
    on, off = bake_both(sol, BakePolicy(threshold=0, scale=0.5, detail=False), monkeypatch)
    assert seam_error(off, sol)["max"] > 1e-3
    assert seam_error(on, sol)["max"] <= 1e-6


@pytest.mark.parametrize("depths", [(3, 4, 1), (2, 4, 4), (4, 1, 2)])
def test_t_junction_partial_overlaps(depths, monkeypatch):
    sol = uniform_solution(TEE, [True] * 3, depths)
    for scale in (1.0, 0.5, 0.25):
        on, off = bake_both(sol, BakePolicy(threshold=0, scale=scale, detail=False), monkeypatch)
        m_on, m_off = seam_measure(on, sol, samples=129), seam_measure(off, sol, samples=129)
        assert m_on["segments"] == 3
        assert m_off["max"] > 1e-3, (depths, scale)
        assert m_on["max"] <= 1e-6, (depths, scale, m_on)


def test_four_patches_at_a_vertex_agree_at_the_corner(monkeypatch):
    """Diagonal neighbours never share an edge; the corner groups still give them one value."""
    sol = uniform_solution(
        [quad(0, 0, 1, 1), quad(1, 0, 2, 1), quad(0, 1, 1, 2), quad(1, 1, 2, 2)], [True] * 4, [3, 4, 4, 1]
    )
    for scale in (1.0, 0.25):
        on, off = bake_both(sol, BakePolicy(threshold=0, scale=scale, detail=False), monkeypatch)
        assert seam_error(off, sol)["max"] > 1e-3
        r = seam_error(on, sol)
        assert r["edges"] == 4 and r["max"] <= 1e-6, r


def test_textured_patch_takes_the_coarser_mesh_neighbours_edge(monkeypatch):
    sol = uniform_solution(TWO, [True, True], [4, 2])
    pol = BakePolicy(threshold=3, scale=1.0, detail=False)  # patch 0 textured, patch 1 mesh
    on, off = bake_both(sol, pol, monkeypatch)
    assert list(on.patch_textured) == [True, False]
    assert seam_measure(off, sol)["max"] > 1e-3
    assert seam_measure(on, sol)["max"] <= 1e-6
    # the mesh part itself is untouched
    np.testing.assert_array_equal(on.mesh_radiance, off.mesh_radiance)


def test_linear_fields_stay_exact_and_caches_stay_clean():
    """Where neighbours already agree (a linear field), harmonisation changes nothing visible,
    and the Baker's cached tiles and boxes are never written."""
    from tests.test_flatten import linear_field

    sol = uniform_solution(TEE, [True] * 3, [3, 4, 1], field=linear_field)
    baker = Baker(sol)
    ref = {
        p: np.array(t) for p, t in zip(range(3), baker.tiles.get(np.arange(3), "bilinear", 0.5), strict=True)
    }
    b = baker.bake(BakePolicy(threshold=0, scale=0.5, detail=False))
    assert seam_measure(b, sol)["max"] <= 1e-5
    for p, t in zip(range(3), baker.tiles.get(np.arange(3), "bilinear", 0.5), strict=True):
        np.testing.assert_array_equal(t, ref[p])


def test_threshold_steps_reuse_harmonised_boxes():
    sol = uniform_solution(
        [quad(0, 0, 1, 1), quad(1, 0, 2, 1), quad(2, 0, 3, 1), quad(3, 0, 4, 1)], [True] * 4, [4, 3, 2, 1]
    )
    baker = Baker(sol)
    for t in (0, 1, 0, 2, 1):
        b = baker.bake(BakePolicy(threshold=t, scale=0.5, detail=False))
        assert seam_measure(b, sol)["textured"]["max"] <= 1e-6
    st = baker.seam_cache
    assert st.stats["boxes_reused"] > 0
    assert len(st.pairs) == 3  # paired once per Baker


@pytest.mark.parametrize("pixel_format", ["rgba16f", "rgba8", "rgb9e5"])
def test_every_pixel_format_stores_both_sides_alike(pixel_format, monkeypatch):
    sol = uniform_solution(TWO, [True, True], [4, 2])
    pol = BakePolicy(threshold=0, scale=0.5, pixel_format=pixel_format, detail=False)
    on, off = bake_both(sol, pol, monkeypatch)
    before, after = seam_error(off, sol)["max"], seam_error(on, sol)["max"]
    # shared knots hold one value, hence one code; the finer side's extra knots lie on the
    # coarse polyline up to the format's rounding: the seam is at most two roundings
    from iat.bake.formats import quantise_rgb9e5, quantise_rgba8

    v = sol.vert_radiance.astype(np.float64)
    q = {
        "rgba16f": lambda x: x.astype(np.float16).astype(np.float64),
        "rgba8": lambda x: quantise_rgba8(x, on.page_scale),
        "rgb9e5": quantise_rgb9e5,
    }[pixel_format]
    rounding = float(np.abs(q(v) - v).max())
    assert after <= 2 * rounding + 1e-6, (after, rounding)
    assert after < before / 2


# -- on the GPU ----------------------------------------------------------------------------------


def _seam_step(img, world, x_seam=1.0):
    """Per row: |left - right| of the two pixels astride x = x_seam, and the larger of the
    neighbouring steps inside each patch (what a smooth image changes per pixel there)."""
    x = world[..., 0]
    rows = []
    for r in range(img.shape[0]):
        c = np.flatnonzero((x[r, :-1] < x_seam) & (x[r, 1:] >= x_seam))
        if len(c) != 1 or c[0] < 2 or c[0] + 3 > img.shape[1]:
            continue
        c = int(c[0])
        seam = np.abs(img[r, c + 1] - img[r, c]).max()
        inside = max(np.abs(img[r, c] - img[r, c - 1]).max(), np.abs(img[r, c + 2] - img[r, c + 1]).max())
        rows.append((seam, inside))
    return np.array(rows)


def test_gl_render_shows_no_step_across_the_seam(egl_ctx, monkeypatch):
    from iat.camera import Camera
    from iat.render.renderer import Renderer
    from tests.support.geometry import pixel_centres_on_plane_z0

    sol = uniform_solution(TWO, [True, True], [5, 2], max_depth=5)
    pol = BakePolicy(threshold=0, scale=0.5, detail=False)
    on, off = bake_both(sol, pol, monkeypatch)
    cam = Camera(eye=[1.0, 0.5, 1.0], target=[1.0, 0.5, 0.0], yfov=60.0, znear=0.01, zfar=10.0)
    w, h = 200, 120
    world = pixel_centres_on_plane_z0(cam, w, h)
    r = Renderer(egl_ctx)
    try:
        steps = {}
        for label, b in (("on", on), ("off", off)):
            r.set_baked(b)
            img = r.render(cam, (w, h), mode="iat").astype(np.float64)
            assert (img.max(axis=-1) > 0).mean() > 0.5  # the two quads fill most of the image
            s = _seam_step(img, world)
            assert len(s) > 50
            steps[label] = s
    finally:
        r.release()
    on_s, off_s = steps["on"], steps["off"]
    # harmonised: the step across x = 1 is no larger than a step inside a patch (fp16 texels)
    assert (on_s[:, 0] <= 1.5 * on_s[:, 1] + 2e-3).all(), float((on_s[:, 0] - 1.5 * on_s[:, 1]).max())
    # without harmonisation the same render does show a step somewhere
    assert (off_s[:, 0] > 1.5 * off_s[:, 1] + 2e-3).any()


def test_a_real_discontinuity_on_a_shared_edge_is_kept(monkeypatch):
    """A wall standing on the shared edge: one side lit, the other in its shadow at 1/10. The step is
    the solution's, not a seam: harmonisation leaves it (``MAX_STEP``), and the smooth case next to
    it still gets harmonised."""
    sol = uniform_solution(TWO, [True, True], [4, 2])
    sol.vert_radiance[qt.decode_key(sol.vert_key, sol.n)[0] == 1] *= 0.1  # patch 1 in the shadow
    on, off = bake_both(sol, BakePolicy(threshold=0, scale=0.25, detail=False), monkeypatch)
    np.testing.assert_array_equal(on.gpu_pages, off.gpu_pages)
    assert seam_error(on, sol)["max"] > 1.0


# -- the Baker's boxes ---------------------------------------------------------------------------


def _boxes_by_recipe(baker, baked, pol):
    """GPU pages and float32 pages as the harmonised boxes were first made: each harmonised tile
    materialised (``apply_ring``), padded with ``np.pad(mode="edge")``, divided by the albedo on
    detail patches, converted with ``to_gpu`` and blitted."""
    from iat.bake import atlas
    from iat.bake.flatten import scaled_side, tile_side
    from iat.bake.formats import from_gpu, to_gpu

    idx = baker.index
    ps = np.flatnonzero(baked.patch_textured)
    align, g = 1 << (pol.mip_levels - 1), pol.gutter
    tiles = baker.tiles.get(ps, pol.method, pol.scale, pol.scale_mode)
    new = {}
    if seams.applies(pol):
        textured = baked.patch_textured
        sides = tile_side(idx.depth).astype(np.int64)
        sides[ps] = scaled_side(tile_side(idx.depth[ps]), pol.scale)
        pairs = baker.seam_cache.pairs
        inv = set(np.unique(pairs.patch[textured[pairs.patch].any(1)]).tolist())
        rings = {
            p: seams.tile_ring(t, not idx.is_quad[p])
            for p, t in zip(ps.tolist(), tiles, strict=True)
            if p in inv
        }
        mesh = np.array(sorted(p for p in inv if not textured[p]), dtype=np.int64)
        for p, t in zip(mesh.tolist(), baker.tiles.get(mesh, "bilinear", 1.0, "clamped"), strict=True):
            rings[p] = seams.tile_ring(t, not idx.is_quad[p])
        new, _ = seams.harmonise_rings(rings, sides, textured, idx.is_quad, pairs)
    scale8 = baker.rgba8_scale(pol.detail) if pol.pixel_format == "rgba8" else 1.0
    dm = baker.detail_mask(pol)
    gpus, floats = [], []
    for p, t in zip(ps.tolist(), tiles, strict=True):
        if p in new:
            t = seams.apply_ring(t, new[p], not idx.is_quad[p])
        n = t.shape[0]
        after = int(atlas.align_up(n + 2 * g, align)) - n - g
        box = np.pad(t, ((g, after), (g, after), (0, 0)), mode="edge")
        if dm[p]:
            box *= baker.inv_albedo[p].astype(np.float32)
        gpu = to_gpu(box, pol.pixel_format, scale8)
        if pol.pixel_format in ("rgba8", "rgb9e5"):
            box = from_gpu(gpu, pol.pixel_format, scale8)
        gpus.append(gpu)
        floats.append(box)
    pk = baker.pack(ps, np.array([t.shape[0] for t in tiles]), pol, align)
    G = np.zeros(baked.gpu_pages.shape, baked.gpu_pages.dtype)
    F = np.zeros(baked.gpu_pages.shape[:3] + (3,), np.float32)
    atlas.blit_boxes(G, gpus, pk.placements, g)
    atlas.blit_boxes(F, floats, pk.placements, g)
    return G, F


@pytest.mark.parametrize(
    "kw",
    [
        {"scale": 1.0},
        {"scale": 0.5},
        {"scale": 0.7, "pixel_format": "rgba8"},
        {"scale": 0.6, "pixel_format": "rgb9e5", "method": "bicubic"},
        {"scale": 0.6, "scale_mode": "naive"},
        {"scale": 0.45, "method": "scan", "detail": False},
    ],
)
def test_boxes_built_once_equal_the_harmonise_pad_convert_recipe(kw):
    """The Baker builds each box once (harmonised ring written into the padded box, no tile copy,
    only the GPU form kept): its pages equal, bit for bit, apply_ring + pad + to_gpu + blit."""
    sol = uniform_solution(TEE + [TRI_QUAD[0]], [True, True, True, False], [2, 3, 4, 4])
    baker = Baker(sol)
    for t in (0, 3, 0):
        pol = BakePolicy(threshold=t, **kw)
        b = baker.bake(pol)
        G, F = _boxes_by_recipe(baker, b, pol)
        np.testing.assert_array_equal(np.asarray(b.gpu_pages).view(np.uint8), G.view(np.uint8))
        np.testing.assert_array_equal(b.pages, F)
