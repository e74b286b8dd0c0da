"""Cut surfaces come back as few patches (iat.geometry.pierce.refan_regions): a wall's rectangle
between two slabs is one quad, not the fans of the pieces the cut made.

The cases are built in memory (a wall of two triangles, thin slabs through it) and cut with
:func:`cut_pierced`, then paired into quads by :func:`merge_quads`, as the loader does; one goes
through :func:`load_scene` from an OBJ.
"""

from __future__ import annotations

import numpy as np
import pytest

from iat.geometry.mesh import merge_quads
from iat.geometry.pierce import PIERCE_TOL, cut_faces, cut_pierced, pierced_pairs
from iat.io.load import load_scene

W, H = 4.0, 3.0  # the wall: x in [0, W], y in [0, H], z = 0


def _uv(p: np.ndarray) -> np.ndarray:
    """The wall's detail uv at points (..., 3): an affine map of x and y."""
    return np.stack([0.5 * p[..., 0] + 0.1 * p[..., 1] + 0.25, 0.4 * p[..., 1] - 0.2], axis=-1)


def _sheet(V: list, F: list, corners) -> None:
    """Append a quad (4 corners) as two triangles."""
    b = len(V)
    V += [list(c) for c in corners]
    F += [[b, b + 1, b + 2], [b, b + 2, b + 3]]


def wall_through(levels=(), columns=(), wall=((0, 0, 0), (W, 0, 0), (W, H, 0), (0, H, 0))):
    """(V, F, objects, uv): the wall (object 0, two triangles, or one for a 3-corner ``wall``) and a
    thin slab (y = level) or column face (x = level) through it, one object each."""
    V, F = [list(c) for c in wall], [[0, 1, 2], [0, 2, 3]][: len(wall) - 2]
    obj = [0] * len(F)
    for k, y in enumerate(levels):
        _sheet(V, F, [(-1, y, -1), (-1, y, 1), (W + 1, y, 1), (W + 1, y, -1)])
        obj += [k + 1] * 2
    for k, x in enumerate(columns):
        _sheet(V, F, [(x, -1, -1), (x, H + 1, -1), (x, H + 1, 1), (x, -1, 1)])
        obj += [len(levels) + k + 1] * 2
    V, F = np.array(V, float), np.array(F, np.int64)
    return V, F, np.array(obj, np.int64), _uv(V[F])


def _patches(V, F, obj, uv):
    """The cut (:class:`Pierced`) and its patches: corners (p, 4), object (p,), uv (p, 4, 2)."""
    p = cut_pierced(V, F, obj, uv, obj)
    corners, code, puv = merge_quads(p.vertices, p.faces, p.code, p.face_uv)
    return p, corners, p.codes[code], puv


def _area(P: np.ndarray) -> np.ndarray:
    """(p,) areas of triangles (p, 3, 3)."""
    return 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)


@pytest.mark.parametrize("levels", [(1.0,), (0.5, 1.2, 2.0, 2.7)])
def test_a_wall_through_parallel_slabs_comes_back_as_one_quad_per_strip(levels):
    V, F, obj, uv = wall_through(levels)
    p, corners, owner, puv = _patches(V, F, obj, uv)
    wall = owner == 0
    assert wall.sum() == len(levels) + 1 and (corners[wall, 3] >= 0).all()
    assert (corners[~wall, 3] >= 0).all() and (~wall).sum() == 2 * len(levels)  # each slab: two halves
    # each quad is a strip between two cuts, the wall's full width, with the pieces' area there
    q = p.vertices[corners[wall]]
    y0, y1 = q[..., 1].min(axis=1), q[..., 1].max(axis=1)
    edges = np.r_[0.0, levels, H]
    np.testing.assert_allclose(np.sort(y0), edges[:-1], atol=1e-12)
    np.testing.assert_allclose(np.sort(y1), edges[1:], atol=1e-12)
    assert np.allclose(q[..., 0].min(axis=1), 0.0) and np.allclose(q[..., 0].max(axis=1), W)
    area = _area(q[:, :3]) + _area(q[:, [0, 2, 3]])
    pp = pierced_pairs(V[F], obj, PIERCE_TOL * 10)
    V2, F2, parent, barrier, _ = cut_faces(V, F, np.r_[pp.a, pp.b], np.r_[pp.b, pp.a], 1e-9)
    pieces = V2[F2[parent < 2]]  # the wall's pieces, before the fans
    strip = np.searchsorted(edges, pieces[..., 1].mean(axis=1)) - 1
    before = np.bincount(strip, weights=_area(pieces), minlength=len(levels) + 1)
    np.testing.assert_allclose(area[np.argsort(y0)], before, rtol=1e-12)
    np.testing.assert_allclose(before, W * np.diff(edges), rtol=1e-12)
    np.testing.assert_allclose(puv[wall], _uv(q), atol=1e-12)  # the wall's map at every corner
    assert p.cut[:2].all()  # both wall triangles count as cut (iat.geometry.faults.fault_faces)
    assert p.report.faces_cut == 2 + 2 * len(levels) and p.report.triangles == len(p.faces)
    assert p.report.fanned_regions == 3 * len(levels) + 1


def test_slabs_through_a_wall_in_an_obj_load_as_quads(tmp_path):
    levels = (0.8, 1.9)
    V, F, obj, _ = wall_through(levels)
    lines = ["mtllib m.mtl"] + [f"v {x} {y} {z}" for x, y, z in V]
    for k in range(obj.max() + 1):
        lines += [f"o part{k}", f"usemtl m{k}"] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F[obj == k]]
    (tmp_path / "m.mtl").write_text("".join(f"newmtl m{k}\nKd 0.5 0.5 0.5\n" for k in range(obj.max() + 1)))
    path = tmp_path / "wall.obj"
    path.write_text("\n".join(lines) + "\n")
    whole, cut = load_scene(path, cut="none"), load_scene(path, cut="crossings")
    names = np.array([m.name for m in cut.materials])
    wall = names[cut.patch_material] == "m0"
    assert wall.sum() == len(levels) + 1 and cut.patch_is_quad[wall].all()
    assert cut.n_patches == 3 * len(levels) + 1 and cut.patch_is_quad.all()
    assert cut.patch_area.sum() == pytest.approx(whole.patch_area.sum(), rel=1e-12)
    assert cut.pierce.triangles == 2 * cut.n_patches


def test_a_wall_whose_triangles_have_other_uv_maps_keeps_its_pieces():
    V, F, obj, uv = wall_through((1.0,))
    uv[1] += [1.0, 0.0]  # a seam along the wall's diagonal: no single affine map
    p, corners, owner, puv = _patches(V, F, obj, uv)
    wall = np.flatnonzero(owner == 0)
    assert len(wall) > 2 and p.report.fanned_regions == 2  # the slab's halves only
    tri = p.faces[p.parent < 2]
    expect = _uv(p.vertices[tri]) + np.where(p.parent[p.parent < 2] == 1, 1.0, 0.0)[:, None, None] * [1, 0]
    np.testing.assert_allclose(p.face_uv[p.parent < 2], expect, atol=1e-12)


def test_a_triangle_cut_into_a_parallelogram_and_trapezoids():
    """A region of one triangle's pieces is one patch when it is a triangle or a parallelogram, and
    keeps its triangles (no panel) otherwise: a cut triangle of a curved surface stays as it was."""
    V, F, obj, uv = wall_through((1.0,), (1.0,), wall=((0, 0, 0), (W, 0, 0), (0, W, 0)))
    p, corners, owner, _ = _patches(V, F, obj, uv)
    wall = owner == 0
    # the unit square in the corner: one quad; two trapezoids: two triangles each; the tip: one
    assert wall.sum() == 6 and (corners[wall, 3] >= 0).sum() == 1
    q = p.vertices[corners[wall & (corners[:, 3] >= 0)][0]]
    assert np.allclose(np.sort(q[:, 0]), [0, 0, 1, 1]) and np.allclose(np.sort(q[:, 1]), [0, 0, 1, 1])
    tri = p.faces[p.parent == 0]
    assert len(tri) == 7 and len(np.unique(p.code[p.parent == 0])) == 6  # the square's two share one
    assert _area(p.vertices[tri]).sum() == pytest.approx(0.5 * W * W, rel=1e-12)


def test_a_non_convex_region_is_two_quads():
    """An L-shaped wall cut across its foot: the strip below is one quad, the L above (not convex)
    two (iat.geometry.decompose, cut across its longest edge, the foot's)."""
    L = [(0, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0), (1, 2, 0), (0, 2, 0)]
    V = np.array(L + [(-1, 0.5, -1), (-1, 0.5, 1), (3, 0.5, 1), (3, 0.5, -1)], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 5], [3, 4, 5], [6, 7, 8], [6, 8, 9]])
    obj = np.array([0, 0, 0, 0, 1, 1])
    p, corners, owner, _ = _patches(V, F, obj, np.zeros((len(F), 3, 2)))
    wall = corners[owner == 0]
    assert (wall[:, 3] >= 0).all() and len(wall) == 3 and p.report.decomposed_regions == 1
    q = p.vertices[wall]
    box = np.stack([q[..., 0].min(1), q[..., 0].max(1), q[..., 1].min(1), q[..., 1].max(1)], axis=1)
    np.testing.assert_allclose(box[np.lexsort(box.T[::-1])], [[0, 1, 0.5, 2], [0, 2, 0, 0.5], [1, 2, 0.5, 1]])
    above = p.faces[(p.parent < 4) & (p.vertices[p.faces][..., 1].min(axis=1) >= 0.5 - 1e-12)]
    assert len(above) == 4 and _area(p.vertices[above]).sum() == pytest.approx(2.0, rel=1e-12)
    P = p.vertices[above]
    assert (np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])[:, 2] > 0).all()  # the wall's winding
