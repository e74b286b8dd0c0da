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


def test_coarse_grids_are_the_lattice_grid_subsampled():
    f = qt.roots(np.array([True, False, True]), 4)
    rng = np.random.default_rng(2)
    for _ in range(3):  # uneven leaves: some larger than the coarse step, some smaller
        f = qt.balance(qt.split(f, rng.random(f.n_leaves) < 0.4))
    keys = qt.vertex_keys(f)
    values = rng.random((len(keys), 3))
    lat = Lattice(f, keys)
    for g in (2, 4, 16):
        coarse = lat.coarse_grids(values, g)
        step = f.n // g
        for p in range(f.n_patches):
            np.testing.assert_array_equal(coarse[p], lat.grid(p, values)[::step, ::step])


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
