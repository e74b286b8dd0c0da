"""Regions of cut pieces that are not convex, or hold holes, come back as few convex cells
(iat.geometry.decompose): a wall with a door, three rectangles; a facade with windows, a handful.

The walls are built in memory as meshes with their openings, cut by thin slabs (:func:`cut_pierced`)
and paired into quads by :func:`merge_quads`, as the loader does; the cells' own functions are
tested on a grid's squares.
"""

from __future__ import annotations

import numpy as np
import pytest

from iat.geometry.decompose import boundary_loops, decompose_regions
from iat.geometry.mesh import merge_quads
from iat.geometry.pierce import cut_pierced

TOL = 1e-8


def _uv(p: np.ndarray) -> np.ndarray:
    """A wall's detail uv at points (..., 3): an affine map of x and y."""
    return np.stack([0.5 * p[..., 0] + 0.1 * p[..., 1] + 0.25, 0.4 * p[..., 1] - 0.2], axis=-1)


def _area(P: np.ndarray) -> np.ndarray:
    """(p,) signed areas about +z of triangles (p, 3, 3)."""
    return 0.5 * np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])[:, 2]


def grid_wall(xs, ys, holes=()):
    """(V, F): the wall z = 0 over the grid of lines ``xs`` x ``ys``, two triangles a square, less
    the squares inside the boxes ``holes`` ((x0, x1, y0, y1) each)."""
    xs, ys = np.asarray(xs, float), np.asarray(ys, float)
    gx, gy = np.meshgrid(xs, ys)
    V = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    F = []
    for j in range(len(ys) - 1):
        for i in range(len(xs) - 1):
            cx, cy = 0.5 * (xs[i] + xs[i + 1]), 0.5 * (ys[j] + ys[j + 1])
            if any(x0 < cx < x1 and y0 < cy < y1 for x0, x1, y0, y1 in holes):
                continue
            a = j * len(xs) + i
            F += [[a, a + 1, a + len(xs) + 1], [a, a + len(xs) + 1, a + len(xs)]]
    return V, np.array(F, np.int64)


def with_slabs(V, F, levels, width):
    """(V, F, objects, uv): the wall (object 0) and a thin slab y = level through it, one object each."""
    V, F, obj = [list(v) for v in V], [list(f) for f in F], [0] * len(F)
    for k, y in enumerate(levels):
        b = len(V)
        V += [[-1, y, -1], [-1, y, 1], [width + 1, y, 1], [width + 1, y, -1]]
        F += [[b, b + 1, b + 2], [b, b + 2, b + 3]]
        obj += [k + 1] * 2
    V, F = np.array(V, float), np.array(F, np.int64)
    return V, F, np.array(obj, np.int64), _uv(V[F])


def _wall_patches(V, F, obj, uv):
    """The cut and the wall's patches: (:class:`Pierced`, corners (w, 4, 3), uv (w, 4, 2), is a quad
    (w,) bool); the wall's triangles after the cut (t, 3, 3)."""
    p = cut_pierced(V, F, obj, uv, obj)
    corners, code, puv = merge_quads(p.vertices, p.faces, p.code, p.face_uv)
    wall = p.codes[code] == 0
    c = corners[wall]
    q = p.vertices[np.where(c >= 0, c, c[:, :1])]
    return p, q, puv[wall], c[:, 3] >= 0, p.vertices[p.faces[obj[p.parent] == 0]]


def _rect(q: np.ndarray) -> np.ndarray:
    """(w, 4) boxes x0, x1, y0, y1 of quads (w, 4, 3), sorted."""
    box = np.stack([q[..., 0].min(1), q[..., 0].max(1), q[..., 1].min(1), q[..., 1].max(1)], axis=1)
    return box[np.lexsort(box.T[::-1])]


def _box_area(box: np.ndarray) -> np.ndarray:
    """(w,) areas of boxes (w, 4) x0, x1, y0, y1."""
    return (box[:, 1] - box[:, 0]) * (box[:, 3] - box[:, 2])


def _door_wall():
    """A two-storey wall x in [0, 4], y in [0, 6] with a door on each floor (x in [1.5, 2.5], y in
    [0, 2] and [3, 5]), as twelve triangles, some straddling the slab at y = 3."""
    V = [(0, 0), (1.5, 0), (1.5, 2), (2.5, 2), (2.5, 0), (4, 0), (4, 6), (0, 6)]  # the outline
    V += [(1.5, 3), (2.5, 3), (2.5, 5), (1.5, 5)]  # the upper door's hole
    F = [[0, 1, 2], [0, 2, 8], [0, 8, 11], [0, 11, 7], [2, 3, 9], [2, 9, 8]]
    F += [[11, 10, 6], [11, 6, 7], [3, 4, 5], [3, 5, 9], [9, 5, 6], [9, 6, 10]]
    return np.array([(x, y, 0.0) for x, y in V]), np.array(F, np.int64)


def test_a_wall_with_a_door_on_each_storey_comes_back_as_three_rectangles_each():
    V, F = _door_wall()
    assert _area(V[F]).sum() == pytest.approx(20.0, rel=1e-15) and (_area(V[F]) > 0).all()
    p, q, puv, quad, tri = _wall_patches(*with_slabs(V, F, (3.0,), 4.0))
    assert quad.all() and len(q) == 6 and p.report.decomposed_regions == 2
    box = _rect(q)
    below, above = box[box[:, 3] <= 3.0], box[box[:, 2] >= 3.0]
    assert len(below) == len(above) == 3
    for part, (y0, y1), (d0, d1) in ((below, (0, 3), (0, 2)), (above, (3, 6), (3, 5))):
        # a full-height rectangle either side of the door and one beside it (above or below)
        full = np.isclose(part[:, 2], y0, atol=1e-12) & np.isclose(part[:, 3], y1, atol=1e-12)
        np.testing.assert_allclose(part[full, :2], [[0, 1.5], [2.5, 4]], atol=1e-12)
        rest = part[~full]
        np.testing.assert_allclose(rest, [[1.5, 2.5, d1, y1] if d0 == y0 else [1.5, 2.5, y0, d0]], atol=1e-12)
    area = _area(q[:, :3]) + _area(q[:, [0, 2, 3]])
    np.testing.assert_allclose(np.sort(area), np.sort(_box_area(box)), rtol=1e-12)
    assert area.sum() == pytest.approx(20.0, rel=1e-12) and _area(tri).sum() == pytest.approx(20.0, rel=1e-12)
    assert (_area(tri) > 1e-6).all()  # the region's winding (+z), none degenerate
    np.testing.assert_allclose(puv, _uv(q), atol=1e-12)  # the wall's map at every corner


def test_a_facade_with_a_row_of_windows_comes_back_as_a_handful_of_rectangles():
    """Two windows at one height: five rectangles (a strip below, three piers, a strip above),
    where cutting across the other axis would make seven."""
    holes = [(1, 2, 1, 2), (4, 6, 1, 2)]
    V, F = grid_wall([0, 0.5, 1, 2, 3, 4, 5, 6, 7, 8], [0, 0.5, 1, 2, 2.5, 4], holes)
    p, q, puv, quad, tri = _wall_patches(*with_slabs(V, F, (3.0,), 8.0))
    assert len(F) == 2 * (9 * 5 - 3) and p.report.decomposed_regions == 1
    assert quad.all() and len(q) == 6  # and the strip above the slab
    expect = [[0, 1, 1, 2], [0, 8, 0, 1], [0, 8, 2, 3], [0, 8, 3, 4], [2, 4, 1, 2], [6, 8, 1, 2]]
    np.testing.assert_allclose(_rect(q), expect, atol=1e-12)
    area = _area(q[:, :3]) + _area(q[:, [0, 2, 3]])
    assert area.sum() == pytest.approx(32 - 3, rel=1e-12) and (_area(tri) > 1e-6).all()
    np.testing.assert_allclose(puv, _uv(q), atol=1e-12)


SLANT = [(0, 0), (4, 0), (4, 1), (1, 2), (1, 3), (0, 3)]  # a wall whose top steps down along a slant


def _slanted_wall():
    """(V, F): the wall ``SLANT`` (area 7.5) as a fan about (0.5, 1.5)."""
    V = np.array([(x, y, 0.0) for x, y in SLANT] + [(0.5, 1.5, 0.0)])
    F = np.array([[6, i, (i + 1) % 6] for i in range(6)], np.int64)
    return V, F


def test_a_region_with_a_slanted_edge_is_cut_into_convex_cells_of_its_area():
    """A rectangle and a trapezoid, both convex; the cut from the reflex corner ends on the bottom
    edge, at a new point both cells share."""
    V, F = _slanted_wall()
    assert (_area(V[F]) > 0).all() and _area(V[F]).sum() == pytest.approx(7.5, rel=1e-15)
    tri, reg, P = decompose_regions(F, V, np.arange(len(F)), np.array([0, len(F)]), TOL)
    assert len(tri) == 4 and (reg == 0).all()
    np.testing.assert_allclose(P, [[1, 0, 0]], atol=1e-15)
    T = np.concatenate([V, P])[tri]
    assert _area(T).sum() == pytest.approx(7.5, rel=1e-12) and (_area(T) > 1e-6).all()
    assert (tri[:2] == len(V)).any() and (tri[2:] == len(V)).any()
    for cell in (T[:2], T[2:]):  # each pair is a convex quad: its corners all turn left
        c = np.array([cell[0, 0], cell[0, 1], cell[0, 2], cell[1, 2]])
        d = np.roll(c, -1, axis=0) - c
        assert (np.cross(d, np.roll(d, -1, axis=0))[:, 2] > 0).all()
    assert {tuple(np.unique(cell[..., 0])) for cell in (T[:2], T[2:])} == {(0, 1), (1, 4)}


def test_a_slanted_wall_cut_by_a_slab_keeps_its_map_at_the_new_corners():
    """Above the slab the cut from the reflex corner ends on the slab's line, where the wall had no
    vertex: a new one, its uv by the wall's map."""
    V, F = _slanted_wall()
    p, q, puv, quad, tri = _wall_patches(*with_slabs(V, F, (0.5,), 4.0))
    # the strip below the slab and the rectangle: quads; the trapezoid: two triangles (no parallelogram)
    assert len(q) == 4 and quad.sum() == 2 and len(tri) == 6 and p.report.decomposed_regions == 1
    new = np.flatnonzero(np.all(np.abs(p.vertices - [1, 0.5, 0]) < 1e-12, axis=1))
    assert len(new) == 1 and np.isin(p.faces, new).any(axis=1).sum() >= 2
    assert _area(tri).sum() == pytest.approx(7.5, rel=1e-12) and (_area(tri) > 1e-6).all()
    np.testing.assert_allclose(puv[quad], _uv(q[quad]), atol=1e-12)
    np.testing.assert_allclose(puv[:, :3], _uv(q[:, :3]), atol=1e-12)
    wall = p.parent < len(F)
    np.testing.assert_allclose(p.face_uv[wall], _uv(p.vertices[p.faces[wall]]), atol=1e-12)


def test_a_plus_shaped_region_is_three_rectangles_on_its_own_corners():
    """The bar across the cuts' axis and the two arms either side: no new point."""
    V = [(1, 0), (2, 0), (2, 1), (3, 1), (3, 2), (2, 2), (2, 3), (1, 3), (1, 2), (0, 2), (0, 1), (1, 1)]
    V = np.array([(x, y, 0.0) for x, y in V])
    F = np.array([[11, 2, 5], [11, 5, 8], [0, 1, 2], [0, 2, 11], [2, 3, 4], [2, 4, 5]])
    F = np.r_[F, [[5, 6, 7], [5, 7, 8], [8, 9, 10], [8, 10, 11]]]
    tri, reg, P = decompose_regions(F, V, np.arange(len(F)), np.array([0, len(F)]), TOL)
    assert len(tri) == 6 and len(P) == 0 and set(np.unique(tri)) == set(range(12))
    T = V[tri]
    assert _area(T).sum() == pytest.approx(5.0, rel=1e-12) and (_area(T) > 1e-6).all()
    box = _rect(np.concatenate([T[0::2], T[1::2, 2:]], axis=1))
    assert len(np.unique(box, axis=0)) == 3 and sorted(_box_area(box)) == [1, 1, 3]


def test_boundary_loops_give_the_outline_and_its_holes_or_nothing_when_pinched():
    V, F = grid_wall([0, 1, 2, 3], [0, 1, 2, 3], [(1, 2, 1, 2)])
    verts, starts = boundary_loops(F, np.arange(len(F)), len(V))
    assert len(starts) == 3 and len(verts) == 12 + 4
    loops = [V[verts[a:b]] for a, b in zip(starts[:-1], starts[1:], strict=True)]
    signed = sorted(0.5 * np.cross(c, np.roll(c, -1, axis=0))[:, 2].sum() for c in loops)
    np.testing.assert_allclose(signed, [-1.0, 9.0])  # the hole clockwise, the outline counter-clockwise
    V, F = grid_wall([0, 1, 2], [0, 1, 2], [(0, 1, 0, 1), (1, 2, 1, 2)])  # two squares at a corner
    verts, starts = boundary_loops(F, np.arange(len(F)), len(V))
    assert len(verts) == 0 and len(starts) == 0
    tri, reg, P = decompose_regions(F, V, np.arange(len(F)), np.array([0, len(F)]), TOL)
    assert len(tri) == 0 and len(reg) == 0  # such a region keeps its pieces


def test_a_region_out_of_its_plane_keeps_its_pieces():
    V, F = grid_wall([0, 1, 2, 3], [0, 1, 2, 3], [(1, 2, 1, 2)])
    tri, _, _ = decompose_regions(F, V, np.arange(len(F)), np.array([0, len(F)]), TOL)
    assert len(tri) == 8  # four rectangles round the hole
    V[0, 2] = 1e-3
    tri, _, _ = decompose_regions(F, V, np.arange(len(F)), np.array([0, len(F)]), TOL)
    assert len(tri) == 0
