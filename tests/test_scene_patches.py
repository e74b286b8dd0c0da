"""Tests of iat.io.load and iat.geometry.mesh: model geometry into root patches (welding, quad
merging, zero-area faces, pre-splitting) and the scene digest.

Every model is written to ``tmp_path`` by the test itself (glTF with pygltflib,
the rest as text or with trimesh's exporters).
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from iat.errors import OptionError
from iat.geometry.mesh import merge_quads, split_patches, weld_vertices
from iat.io.load import load_scene
from iat.io.scene import Light, Scene, scene_digest
from tests.support.scene_files import (
    QUAD,
    QUAD_TRIS,
    Gltf,
    quad_gltf,
    write,
)

# ----------------------------------------------------------------------------
# geometry
# ----------------------------------------------------------------------------


def test_obj_unit_quad_is_one_quad_patch(tmp_path):
    p = write(tmp_path / "quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    s = load_scene(p)
    assert isinstance(s, Scene)
    assert s.n_patches == 1 and s.patch_is_quad.all()
    np.testing.assert_allclose(s.patch_normal[0], [0, 0, 1], atol=1e-12)
    assert s.patch_area[0] == pytest.approx(1.0)
    # corners go around the polygon (consecutive corners share a side of length 1)
    c = s.corner_positions[0]
    np.testing.assert_allclose(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1), 1.0)
    assert s.path == str(p)
    assert len(s.materials) == 1 and np.allclose(s.materials[0].albedo, 0.5)


def test_only_near_parallelograms_become_quad_roots():
    """A quad root's lattice is bilinear, its texture affine per triangle: the two agree only on
    parallelograms, so a skewed pair (the issue's ceiling: twist 0.77 of the mean diagonal) stays
    two triangle roots, while a sheared parallelogram and a quad inside the tolerance merge."""
    V = np.array([[0.1, -0.1, 0], [0.1, -9.9, 0], [7.44, -4.01, 0], [7.44, -0.3, 0]], dtype=float)
    F = np.array([[0, 1, 2], [2, 3, 0]])
    corners, _, _ = merge_quads(V, F, np.zeros(2, dtype=np.int64))
    assert len(corners) == 2 and (corners[:, 3] < 0).all()
    sheared = np.array([[0, 0, 0], [4, 0, 0], [5, 2, 0], [1, 2, 0]], dtype=float)
    assert len(merge_quads(sheared, F, np.zeros(2, dtype=np.int64))[0]) == 1
    near = sheared.copy()
    near[2, 0] += 0.01 * 0.5 * (np.linalg.norm(near[2] - near[0]) + np.linalg.norm(near[3] - near[1]))
    assert len(merge_quads(near, F, np.zeros(2, dtype=np.int64))[0]) == 1
    near[2, 0] += 0.02 * 0.5 * (np.linalg.norm(near[2] - near[0]) + np.linalg.norm(near[3] - near[1]))
    assert len(merge_quads(near, F, np.zeros(2, dtype=np.int64))[0]) == 2


def test_panels_group_coplanar_patches_and_fit_their_rectangle(tmp_path):
    """A 4 x 2 wall with a 1 x 1 window hole (8 triangles, fan-like) and a floor of another
    material: two panels; the wall's rectangle is 4 x 2 and its fill is 7/8."""
    from iat.geometry.panels import find_panels, sliver_count

    v = "v 0 0 0\nv 4 0 0\nv 4 2 0\nv 0 2 0\nv 1.5 0.5 0\nv 2.5 0.5 0\nv 2.5 1.5 0\nv 1.5 1.5 0\n"
    v += "v 0 0 0\nv 0 0 3\nv 4 0 3\nv 4 0 0\n"
    f = "usemtl wall\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n"
    f += "usemtl floor\nf 9 10 11 12\n"
    mtl = write(tmp_path / "m.mtl", "newmtl wall\nKd 0.5 0.5 0.5\nnewmtl floor\nKd 0.3 0.3 0.3\n")
    s = load_scene(write(tmp_path / "wall.obj", f"mtllib {mtl.name}\n{v}{f}"), panels=False)
    p = find_panels(s)
    assert p.n_panels == 2
    wall = int(np.argmax(np.abs(p.normal[:, 2])))
    np.testing.assert_allclose(sorted(p.extent[wall]), [2.0, 4.0], atol=1e-9)
    assert p.fill[wall] == pytest.approx(7 / 8)
    assert p.area.sum() == pytest.approx(7 + 12)
    assert sliver_count(s) == 0


def test_gltf_quad_keeps_corner_order(tmp_path):
    s = load_scene(quad_gltf(tmp_path / "q.glb"))
    assert s.n_patches == 1 and s.patch_is_quad[0]
    np.testing.assert_allclose(s.corner_positions[0], QUAD)


def test_gltf_two_nodes_with_transforms_in_world_space(tmp_path):
    g = Gltf()
    m = g.mesh(QUAD, QUAD_TRIS)
    g.node(mesh=m, translation=[10.0, 0.0, 0.0])
    # child of a scaled parent, rotated 90 degrees about X: the +Z quad faces -Y... then +Y
    c, s_ = math.cos(math.pi / 4), math.sin(math.pi / 4)
    child = g.node(root=False, mesh=m, rotation=[-s_, 0.0, 0.0, c])  # -90 deg about X: +Z -> +Y
    g.node(children=[child], scale=[2.0, 2.0, 2.0], translation=[0.0, 5.0, 0.0])
    s = load_scene(g.save(tmp_path / "nodes.glb"))
    assert s.n_patches == 2 and s.patch_is_quad.all()
    areas = sorted(s.patch_area)
    assert areas == pytest.approx([1.0, 4.0])
    a = int(np.argmin(s.patch_area))
    b = 1 - a
    np.testing.assert_allclose(s.corner_positions[a], QUAD + [10, 0, 0], atol=1e-12)
    np.testing.assert_allclose(s.patch_normal[a], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(s.patch_normal[b], [0, 1, 0], atol=1e-12)
    lo, hi = s.corner_positions[b].min(axis=0), s.corner_positions[b].max(axis=0)
    np.testing.assert_allclose(lo, [0, 5, -2], atol=1e-12)
    np.testing.assert_allclose(hi, [2, 5, 0], atol=1e-12)


def test_mirroring_transform_flips_winding(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS), scale=[-1.0, 1.0, 1.0])
    s = load_scene(g.save(tmp_path / "mirror.glb"))
    # the surface still faces +Z: mirrored positions with the winding flipped back
    np.testing.assert_allclose(s.patch_normal[0], [0, 0, 1], atol=1e-12)
    assert s.bounds[0][0] == pytest.approx(-1.0)


@pytest.mark.parametrize("ext", ["ply", "stl", "off", "glb", "obj"])
def test_cube_12_triangles_become_6_quads(tmp_path, ext):
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    assert len(box.faces) == 12
    p = tmp_path / f"box.{ext}"
    box.export(p)
    s = load_scene(p)
    assert s.n_patches == 6 and s.patch_is_quad.all()
    assert s.patch_area == pytest.approx(np.full(6, 4.0))
    centres = s.corner_positions.mean(axis=1)
    # outward normals: each normal points from the origin to its face centre
    np.testing.assert_allclose(s.patch_normal, centres, atol=1e-12)
    assert len(s.vertices) == 8


def test_non_planar_pair_stays_two_triangles(tmp_path):
    p = write(tmp_path / "bent.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0.01\nv 0 1 0\nf 1 2 3\nf 1 3 4\n")
    s = load_scene(p)
    assert s.n_patches == 2 and not s.patch_is_quad.any()
    assert (s.patch_corners[:, 3] == -1).all()


def test_non_convex_pair_stays_two_triangles(tmp_path):
    # a dart: coplanar but concave at vertex 3
    p = write(tmp_path / "dart.obj", "v 0 0 0\nv 2 0 0\nv 1 2 0\nv 1 0.5 0\nf 1 2 4\nf 2 3 4\n")
    s = load_scene(p, panels=False)
    assert s.n_patches == 2 and not s.patch_is_quad.any()
    panel = load_scene(p)  # a panel of rectangle cells cut to the dart
    assert panel.patch_is_quad.all() and panel.patch_area.sum() == pytest.approx(
        s.patch_area.sum(), rel=1e-12
    )


def test_pair_with_different_materials_stays_two_triangles(tmp_path):
    write(tmp_path / "m.mtl", "newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n")
    obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 3 4 1\n"
    s = load_scene(write(tmp_path / "two.obj", obj))
    assert s.n_patches == 2 and not s.patch_is_quad.any()
    assert sorted(tuple(m.albedo) for m in s.materials) == [(0, 1, 0), (1, 0, 0)]


def test_duplicated_vertices_are_welded_before_pairing(tmp_path):
    g = Gltf()
    pos = QUAD[np.array(QUAD_TRIS).ravel()]  # six vertices, one per corner of each triangle
    g.node(mesh=g.mesh(pos, np.arange(6)))
    s = load_scene(g.save(tmp_path / "soup.glb"))
    assert s.n_patches == 1 and s.patch_is_quad[0]
    assert len(s.vertices) == 4


def test_grid_of_quads_pairs_along_diagonals(tmp_path):
    # 3 x 3 grid of unit squares, each split along its diagonal, shuffled
    n = 3
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = (i * (n + 1) + j).ravel(), ((i + 1) * (n + 1) + j).ravel()
    faces = np.concatenate([np.stack([a, b, b + 1], 1), np.stack([b + 1, a + 1, a], 1)])
    faces = faces[np.random.default_rng(3).permutation(len(faces))]
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0), indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    c, m, uv = merge_quads(verts, faces, np.zeros(len(faces), dtype=np.int64))
    assert len(c) == n * n and (c[:, 3] >= 0).all()
    s = Scene(verts, c, m, [])
    assert s.patch_area == pytest.approx(np.ones(n * n))  # unit squares, not parallelograms
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 0, 1.0], (n * n, 1)))


def test_degenerate_faces_dropped_when_others_remain(tmp_path, caplog):
    obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nf 1 2 3 4\nf 1 2 5\nf 1 1 3\n"
    with caplog.at_level(logging.INFO, logger="iat.io.load"):
        s = load_scene(write(tmp_path / "degen.obj", obj))
    assert s.n_patches == 1 and s.patch_area[0] == pytest.approx(1.0)
    assert "dropped 2 zero-area faces" in caplog.text


def test_weld_vertices_merges_close_positions():
    v = np.array([[0, 0, 0], [1, 0, 0], [1 + 1e-13, 0, 0], [0, 1, 0], [5, 5, 5]], dtype=float)
    f = np.array([[0, 1, 3], [0, 2, 3]])
    wv, wf = weld_vertices(v, f)
    assert len(wv) == 3  # the unused vertex goes too
    assert (wf[0] == wf[1]).all()


# ----------------------------------------------------------------------------
# pre-split
# ----------------------------------------------------------------------------


def test_max_edge_splits_quads_into_grids(tmp_path):
    p = write(tmp_path / "floor.obj", "v 0 0 0\nv 4 0 0\nv 4 1.5 0\nv 0 1.5 0\nf 1 2 3 4\n")
    s = load_scene(p, max_edge=1.0)
    assert s.n_patches == 4 * 2 and s.patch_is_quad.all()
    assert s.patch_area.sum() == pytest.approx(6.0)
    np.testing.assert_allclose(s.patch_area, 0.75)
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 0, 1.0], (8, 1)))
    assert len(s.vertices) == 5 * 3  # shared lattice points are welded


def test_max_edge_splits_triangles_regularly(tmp_path):
    p = write(tmp_path / "tri.obj", "v 0 0 0\nv 3 0 0\nv 0 3 0\nf 1 2 3\n")
    s = load_scene(p, max_edge=1.0, panels=False)  # longest edge 3*sqrt(2): k = ceil(log2(4.24)) = 3
    assert s.n_patches == 4**3 and not s.patch_is_quad.any()
    assert s.patch_area.sum() == pytest.approx(4.5)
    np.testing.assert_allclose(s.patch_area, 4.5 / 64)
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 0, 1.0], (64, 1)))
    assert len(s.vertices) == 9 * 10 // 2


def test_max_edge_mixed_scene_keeps_area_materials_and_uvs(tmp_path):
    box = trimesh.creation.box(extents=(3.0, 1.0, 2.0))
    box.export(tmp_path / "box.ply")
    s0 = load_scene(tmp_path / "box.ply")
    s = load_scene(tmp_path / "box.ply", max_edge=0.5)
    # faces 3x1 -> 6x2, 3x2 -> 6x4, 1x2 -> 2x4: two of each
    assert s.n_patches == 2 * (12 + 24 + 8)
    assert s.patch_area.sum() == pytest.approx(s0.patch_area.sum())
    assert s.corner_positions.max() <= 1.5 + 1e-12

    verts = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [3, 0, 0]], dtype=float)
    corners = np.array([[0, 1, 2, 3], [1, 4, 2, -1]])
    uv = np.array([[[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 0], [1, 0], [0, 1], [0, 1]]], dtype=float)
    v, c, m, u = split_patches(verts, corners, np.array([3, 7]), uv, max_edge=1.0)
    assert (m == 3).sum() == 4 and (m == 7).sum() == 16
    sc = Scene(v, c, m, [], patch_uv=u)
    # UVs follow the bilinear / barycentric parametrisation
    quads = sc.patch_is_quad
    np.testing.assert_allclose(u[quads][..., 0], sc.corner_positions[quads][..., 0] / 2)
    np.testing.assert_allclose(u[quads][..., 1], sc.corner_positions[quads][..., 1] / 2)
    np.testing.assert_allclose(u[~quads][..., 0], sc.corner_positions[~quads][..., 0] - 2)
    assert sc.patch_normal[:, 2] == pytest.approx(np.ones(len(c)))


def test_scene_digest_tracks_geometry_and_materials(tmp_path):
    d1 = scene_digest(load_scene(quad_gltf(tmp_path / "a.glb", base=(0.5, 0.5, 0.5, 1))))
    d2 = scene_digest(load_scene(quad_gltf(tmp_path / "b.glb", base=(0.5, 0.5, 0.5, 1))))
    d3 = scene_digest(load_scene(quad_gltf(tmp_path / "c.glb", base=(0.5, 0.5, 0.6, 1))))
    assert d1 == d2 != d3
    assert len(d1) == 40
    s = load_scene(tmp_path / "a.glb")
    s.lights.append(Light(kind="point", position=[0, 0, 1], intensity=5.0))
    d4 = scene_digest(s)
    s.lights[0].intensity = 6.0
    assert len({d1, d4, scene_digest(s)}) == 3


def test_max_edge_must_be_positive(tmp_path):
    p = quad_gltf(tmp_path / "q.glb")
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(OptionError):
            load_scene(p, max_edge=bad)


def test_double_sided_quad_gives_two_quads(tmp_path):
    # front and back of one wall share welded vertices: the diagonal is used by four triangles
    obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 3 4 1\nf 1 3 2\nf 3 1 4\n"
    s = load_scene(write(tmp_path / "wall.obj", obj))
    assert s.n_patches == 2 and s.patch_is_quad.all()
    np.testing.assert_allclose(sorted(s.patch_normal[:, 2]), [-1.0, 1.0])
    assert s.patch_area == pytest.approx([1.0, 1.0])


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1), st.integers(min_value=4, max_value=60))
def test_merge_quads_covers_each_triangle_once(seed, n_points):
    """Random planar triangulations (rotated into 3D): every triangle ends up in exactly one patch,
    the area is kept, quads are convex and face the triangles' way."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    pts2 = np.round(rng.random((n_points, 2)) * 8) / 8 + rng.random((n_points, 2)) * 1e-3 * (seed % 2)
    pts2 = np.unique(pts2, axis=0)
    try:
        tri = Delaunay(pts2)
    except Exception:  # noqa: BLE001 - collinear draws
        return
    faces = tri.simplices.astype(np.int64)
    v = np.c_[pts2, np.zeros(len(pts2))]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    v = v @ q.T
    keep = ~(
        np.abs(np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])).sum(1) < 1e-12
    )
    faces = faces[keep]
    normal = np.cross(v[faces[0, 1]] - v[faces[0, 0]], v[faces[0, 2]] - v[faces[0, 0]])
    normal /= np.linalg.norm(normal)
    mat = rng.integers(0, 2, len(faces))
    c, m, _ = merge_quads(v, faces, mat)
    s = Scene(v, c, m, [])
    assert s.patch_area.sum() == pytest.approx(
        np.linalg.norm(
            np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]]), axis=1
        ).sum()
        / 2
    )
    assert s.patch_is_quad.sum() * 2 + (~s.patch_is_quad).sum() == len(faces)
    np.testing.assert_allclose(s.patch_normal, np.tile(normal, (len(c), 1)), atol=1e-6)
    # quads: both triangles of each diagonal have the same orientation (strictly convex)
    cp = s.corner_positions[s.patch_is_quad]
    for a, b, d in ((0, 1, 2), (1, 2, 3), (2, 3, 0), (3, 0, 1)):
        turn = np.cross(cp[:, b] - cp[:, a], cp[:, d] - cp[:, b]) @ normal
        assert (turn > 0).all()
    # the patches are exactly the input triangles: quads split back along their diagonal c0-c2
    tri_mat = {tuple(sorted(f)): mm for f, mm in zip(faces.tolist(), mat.tolist(), strict=True)}
    got = {}
    for (c0, c1, c2, c3), mm in zip(c.tolist(), m.tolist(), strict=True):
        parts = [(c0, c1, c2)] if c3 < 0 else [(c0, c1, c2), (c2, c3, c0)]
        for t in parts:
            got[tuple(sorted(t))] = mm
    assert got == tri_mat
