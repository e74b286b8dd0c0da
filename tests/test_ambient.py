"""The ambient term's parts (iat.radiosity.remainder) against their definitions, and its physics: a
final gather of the unshot light, its first bounce where the light lands, its later ones on patches."""

import numpy as np
import pytest

from iat.geometry import quadtree as qt
from iat.geometry.quadtree import bilinear
from iat.io.scene import Material, Scene
from iat.radiosity import SolveOptions, solve
from iat.radiosity.sampling import Lattice
from iat.radiosity.visibility import Visibility
from tests.test_radiosity import furnace_box


def _trapezoid(grid: np.ndarray) -> np.ndarray:
    """(3,) the mean of a (m+1, m+1, 3) lattice field over its square by the trapezoid rule."""
    w = np.ones(grid.shape[0])
    w[[0, -1]] = 0.5
    return np.einsum("i,j,ijc->c", w, w, grid) / (grid.shape[0] - 1) ** 2


def test_coarse_grids_keep_the_lattice_field_integral():
    f = qt.roots(np.array([True, False, True]), 4)
    rng = np.random.default_rng(2)
    for _ in range(3):  # uneven leaves: some larger than the coarse step, some smaller
        f = qt.balance(qt.split(f, rng.random(f.n_leaves) < 0.4))
    keys = qt.vertex_keys(f)
    values = rng.random((len(keys), 3))
    lat = Lattice(f, keys)
    quads = np.flatnonzero(f.patch_is_quad)
    for g in (4, 16):  # 4: each point the tent-weighted mean of 4 x 4 cells; 16: the lattice itself
        coarse = lat.coarse_grids(values, g)
        for p in quads:
            np.testing.assert_allclose(_trapezoid(coarse[p]), _trapezoid(lat.grid(p, values)), rtol=1e-12)
    for p in range(f.n_patches):
        np.testing.assert_array_equal(lat.coarse_grids(values, 16)[p], lat.grid(p, values))
    flat = np.tile([0.2, 0.5, 0.7], (len(keys), 1))  # a uniform field stays uniform, triangles too
    coarse = lat.coarse_grids(flat, 2)
    i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    for p in range(f.n_patches):
        read = np.ones((3, 3), bool) if f.patch_is_quad[p] else i + j <= 2  # what a triangle reads
        np.testing.assert_allclose(coarse[p][read], np.broadcast_to([0.2, 0.5, 0.7], (read.sum(), 3)))


def test_world_triangle_uv_maps_onto_the_world_triangles():
    quad = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], dtype=float)
    tri = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1]], dtype=float)
    verts = np.vstack([quad, tri])
    scene = Scene(verts, np.array([[0, 1, 2, 3], [4, 5, 6, -1]]), np.array([0, 0]), [Material("grey")])
    uv = scene.world_triangle_uv()
    corners = scene.corner_positions[scene.world_triangle_patch()]
    world = bilinear(np.repeat(corners, 3, axis=0), uv[..., 0].ravel(), uv[..., 1].ravel())
    np.testing.assert_allclose(world.reshape(-1, 3, 3), scene.world_triangles(), atol=1e-12)


def test_first_hits_give_the_point_the_ray_meets():
    c = np.array([[-5, -5, 2], [5, -5, 2], [5, 5, 2], [-5, 5, 2]], dtype=float)
    plane = c[[[0, 1, 2], [0, 2, 3]]]
    rng = np.random.default_rng(4)
    o = np.column_stack([rng.uniform(-1, 1, (500, 2)), np.zeros(500)])
    d = np.column_stack([rng.normal(0, 0.3, (500, 2)), np.ones(500)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:50, 2] *= -1  # away from the plane: no hit
    with Visibility(plane) as vis:
        tri, b = vis.first_hits(o, d, np.full(500, 100.0))
    assert (tri[:50] == -1).all() and (tri[50:] >= 0).all()
    t = plane[tri[50:]]
    hit = (1 - b[50:, :1] - b[50:, 1:]) * t[:, 0] + b[50:, :1] * t[:, 1] + b[50:, 1:] * t[:, 2]
    want = o[50:] + d[50:] * (2.0 / d[50:, 2:])
    np.testing.assert_allclose(hit, want, atol=1e-5)


@pytest.mark.parametrize("albedo", [0.5, 0.8])
def test_ambient_term_is_the_furnace_after_one_shot(albedo):
    """One shot of the furnace (every patch emits 1 and reflects ``albedo``), the rest of the light
    all in the ambient term: its later bounces, summed on the patches, make the mean exact to the
    hemisphere's sampling (within 1 %), every vertex within 3 %."""
    expected = 1.0 / (1.0 - albedo)
    sol = solve(furnace_box(albedo), SolveOptions(max_depth=2, max_shots=1))
    assert sol.stats["unshot_fraction"] > 0.3
    assert sol.vert_radiance.mean() == pytest.approx(expected, rel=0.01)
    assert np.allclose(sol.vert_radiance, expected, rtol=0.03)


def test_ambient_hits_read_the_lattice_where_the_rays_land():
    """The compiled kernel against numpy: front hits, each read with ``sample_lattice`` from its
    patch's grid; back hits on a patch with a twin read the twin (at (v, u) for a swapped twin, its
    mean otherwise), other back hits nothing; the vertex's mean over its rays, the fraction of its
    rays on each patch, and the fraction on a back face with no twin."""
    from iat.radiosity.ambient_kernels import ambient_hits
    from iat.radiosity.sampling import sample_lattice

    rng = np.random.default_rng(6)
    n, k, g, n_p, n_t = 40, 16, 4, 5, 9
    tri = rng.integers(-1, n_t, n * k)
    bary = rng.dirichlet(np.ones(3), n * k)[:, 1:]
    dirs = rng.normal(size=(n * k, 3))
    tri_patch = rng.integers(0, n_p, n_t)
    tri_uv = rng.random((n_t, 3, 2))
    normal = rng.normal(size=(n_p, 3))
    twin = np.array([1, 0, 3, 2, -1])  # 0 and 1 made by add_back_faces ((u, v) swapped), 2 and 3 not
    swap = np.array([True, True, False, False, False])
    grids = rng.random((n_p, (g + 1) ** 2, 3))
    means = grids.mean(axis=1)
    first, inside = np.zeros((n, 3)), np.zeros(n)
    r, c, f = np.empty(n * k, np.int64), np.empty(n * k, np.int64), np.empty(n * k)
    args = (tri, bary, dirs, tri_patch, tri_uv, normal, twin, swap, means, grids.reshape(-1, 3), g, k)
    m = ambient_hits(*args, first, inside, r, c, f)
    hit = tri_patch[np.maximum(tri, 0)]
    front = (tri >= 0) & (np.einsum("nc,nc->n", dirs, normal[hit]) < 0)
    back = (tri >= 0) & ~front & (twin[hit] >= 0)
    p = np.where(back, twin[hit], hit)
    b = np.column_stack([1 - bary.sum(axis=1), bary])
    uv = np.clip(np.einsum("nk,nkc->nc", b, tri_uv[np.maximum(tri, 0)]), 0, 1)
    want = np.zeros((n * k, 3))
    for q in np.flatnonzero(front | back):
        u, v = (uv[q, 1], uv[q, 0]) if back[q] and swap[hit[q]] else (uv[q, 0], uv[q, 1])
        if back[q] and not swap[hit[q]]:
            want[q] = means[p[q]]
        else:
            want[q] = sample_lattice(grids[p[q]], g, np.array([u]), np.array([v]))[0]
    assert back.any() and (back & swap[hit]).any() and (back & ~swap[hit]).any()
    buried = (tri >= 0) & ~front & (twin[hit] < 0)
    assert buried.any()
    np.testing.assert_allclose(inside, buried.reshape(n, k).mean(axis=1), rtol=1e-12)
    np.testing.assert_allclose(first, want.reshape(n, k, 3).mean(axis=1), rtol=1e-12, atol=1e-15)
    got = {(int(a), int(b)): float(x) for a, b, x in zip(r[:m], c[:m], f[:m], strict=True)}
    met = front | back
    pairs, counts = np.unique(np.column_stack([np.arange(n * k) // k, p])[met], axis=0, return_counts=True)
    assert got == {(int(a), int(b)): x / k for (a, b), x in zip(pairs, counts, strict=True)}


@pytest.mark.parametrize("shots", [2, 20])
def test_ambient_term_keeps_a_near_white_rooms_energy(shots):
    """A closed box of albedo 0.97 lit by its centre ceiling quad, a block standing on its floor (the
    floor under it buried), stopped after ``shots`` shots so that nearly all the light is the
    ambient term's: the reflected power is the analytic rho / (1 - rho) of the emitted (every watt
    is absorbed in the end), within 2 %. Its later bounces used to dilute each patch's light over
    its buried part and lose the first bounce's light on coarse elements: 18 % short at 2 shots
    (docs/benchmarks.md, 'The ambient term by the power each patch receives')."""
    from tests.test_radiosity import lit_box

    rho = 0.97
    sol = solve(lit_box(rho), SolveOptions(max_depth=3, max_shots=shots))
    assert sol.stats["ambient_luminance_fraction"] > 25.0  # the ambient term holds nearly all the light
    drawn = sol.drawn_mesh()
    p, t = drawn.position, drawn.triangles
    area = 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
    total = np.pi * (area[:, None] * drawn.radiance(sol.vert_radiance)[t].mean(axis=1)).sum(axis=0)
    emitted = np.pi * 10.0 / 9.0  # the light quad: radiance 10 over 1/9 m^2
    np.testing.assert_allclose(total - emitted, rho / (1 - rho) * emitted, rtol=0.02)


def test_seen_average_weighs_out_buried_vertices():
    """A patch's mean over the part of it that can be seen: a vertex whose rays all met back faces
    counts for nothing, a half-buried one for half, and a patch buried whole keeps its row; that
    part's share of the patch's area, at least ``AMBIENT_SEEN_FLOOR`` (a patch buried whole counts
    whole)."""
    from scipy import sparse

    from iat.radiosity.options import AMBIENT_SEEN_FLOOR
    from iat.radiosity.remainder import seen_average

    avg = np.zeros((3, 8))
    avg[0, :4], avg[1, 4:6], avg[2, 6:] = 0.25, 0.5, 0.5
    got, seen = seen_average(sparse.csr_matrix(avg), np.array([1.0, 0.5, 0.0, 0.0, 1.0, 1.0, 0.9, 1.0]))
    want = np.zeros((3, 8))
    want[0, 1:4] = np.array([0.125, 0.25, 0.25]) / 0.625
    want[1, 4:6], want[2, 6] = 0.5, 1.0
    np.testing.assert_allclose(got.toarray(), want)
    np.testing.assert_allclose(seen, [0.625, 1.0, AMBIENT_SEEN_FLOOR])  # (the third: 0.05 seen)
