"""Analytic form factors (iat.radiosity.formfactor) against closed-form values."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from iat.radiosity.formfactor import area_to_area, point_polygon, polygon_area, polygon_normal

# unit square in z = 0, counter-clockwise seen from +z (normal +z)
FLOOR = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)


def _parallel_squares(w: float, h: float) -> float:
    """Closed form, two coaxial parallel w x w squares at distance h (Howell C-11 with a = b = w)."""
    x = y = w / h
    a, b = np.sqrt(1 + x * x), np.sqrt(1 + y * y)
    return (2 / (np.pi * x * y)) * (
        np.log(np.sqrt((1 + x * x) * (1 + y * y) / (1 + x * x + y * y)))
        + x * b * np.arctan(x / b)
        + y * a * np.arctan(y / a)
        - x * np.arctan(x)
        - y * np.arctan(y)
    )


def test_parallel_unit_squares():
    ceiling = FLOOR[::-1] + [0, 0, 1]  # facing down
    f = area_to_area(FLOOR, ceiling, 16)
    assert f == pytest.approx(0.19982, rel=0.01)
    assert f == pytest.approx(_parallel_squares(1.0, 1.0), rel=1e-4)
    # the other way round, by symmetry
    assert area_to_area(ceiling, FLOOR, 16) == pytest.approx(f, rel=1e-6)


def test_perpendicular_unit_squares_sharing_an_edge():
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], dtype=float)  # plane x = 0
    assert polygon_normal(wall) == pytest.approx([1, 0, 0])  # the floor is in front of it
    assert area_to_area(FLOOR, wall, 16) == pytest.approx(0.20004, rel=0.01)
    assert area_to_area(wall, FLOOR, 16) == pytest.approx(0.20004, rel=0.01)
    # facing away: nothing
    assert area_to_area(wall[::-1], FLOOR, 8) == 0.0


@pytest.mark.parametrize("h", [0.1, 0.7, 3.0])
def test_point_under_a_disc(h):
    radius, sides = 1.0, 720
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    disc = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.full(sides, h)], axis=1)
    f = point_polygon([[0, 0, 0]], [[0, 0, 1]], disc)[0]
    # inscribed polygon: area ratio sin(2pi/n) n / (2 pi) -> compare with the disc of equal area
    r_eq2 = radius**2 * sides * np.sin(2 * np.pi / sides) / (2 * np.pi)
    assert f == pytest.approx(r_eq2 / (r_eq2 + h * h), rel=1e-4)


def test_point_to_rectangle_corner_closed_form():
    # receiver below the corner of an a x b rectangle at height c, parallel
    a, b, c = 0.8, 1.7, 0.6
    rect = np.array([[0, 0, c], [a, 0, c], [a, b, c], [0, b, c]])
    x, y = a / c, b / c
    exact = (
        x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
        + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))
    ) / (2 * np.pi)
    assert point_polygon([[0, 0, 0]], [[0, 0, 1]], rect)[0] == pytest.approx(exact, rel=1e-9)


def test_reciprocity():
    tri = np.array([[0.2, 0.1, 0.0], [1.3, 0.3, 0.1], [0.4, 1.2, -0.1]])  # faces roughly +z
    quad = np.array([[0.0, 0.0, 1.5], [0.3, 1.4, 1.2], [1.6, 1.5, 0.9], [1.4, 0.1, 1.1]])
    assert polygon_normal(tri)[2] > 0 and polygon_normal(quad)[2] < 0
    f_tq = area_to_area(tri, quad, 24)
    f_qt = area_to_area(quad, tri, 24)
    assert f_tq > 0.05
    assert polygon_area(tri) * f_tq == pytest.approx(polygon_area(quad) * f_qt, rel=0.01)


def test_clipping_keeps_only_the_front_half():
    # receiver at the origin facing +z; a vertical square spanning z in [-1, 1] at y = 1
    full = np.array([[-0.5, 1, -1], [0.5, 1, -1], [0.5, 1, 1], [-0.5, 1, 1]], dtype=float)
    front = np.array([[-0.5, 1, 0], [0.5, 1, 0], [0.5, 1, 1], [-0.5, 1, 1]], dtype=float)
    f_full = point_polygon([[0, 0, 0]], [[0, 0, 1]], full)[0]
    f_front = point_polygon([[0, 0, 0]], [[0, 0, 1]], front)[0]
    assert f_front > 0.01
    assert f_full == pytest.approx(f_front, rel=1e-12)
    behind = front * [1, 1, -1]
    assert point_polygon([[0, 0, 0]], [[0, 0, 1]], behind)[0] == 0.0


def test_closure_inside_a_cube():
    """From any point inside a closed cube, any normal: the six faces' form factors sum to 1."""
    rng = np.random.default_rng(3)
    faces = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        for side in (0.0, 1.0):
            q = np.zeros((4, 3))
            q[:, axis] = side
            q[:, a] = [0, 1, 1, 0]
            q[:, b] = [0, 0, 1, 1]
            faces.append(q)
    pts = rng.uniform(0.05, 0.95, (200, 3))
    nrm = rng.normal(size=(200, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    total = sum(point_polygon(pts, nrm, q) for q in faces)
    assert np.allclose(total, 1.0, atol=1e-9)


def test_receivers_on_the_polygon_edge_and_plane():
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], dtype=float)  # x = 0, spans y, z
    pts = np.array(
        [
            [0, 0.5, 0],  # on the wall's bottom edge
            [0, 0, 0],  # on its corner
            [1e-7, 0.5, 0],  # a hair in front of the edge: the wall fills half the hemisphere
            [0, 0.5, 0.5],  # in the wall's plane, inside it
        ]
    )
    nrm = np.array([[0, 0, 1], [0, 0, 1], [0, 0, 1], [1, 0, 0]], dtype=float)
    f = point_polygon(pts, nrm, wall)
    assert np.isfinite(f).all() and (f >= 0).all() and (f <= 1).all()
    assert f[2] == pytest.approx(0.5, abs=1e-5)
    assert f[3] == 0.0  # the polygon lies in the receiver's tangent plane


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-2, 2, allow_nan=False), min_size=3, max_size=3),
    st.lists(st.floats(-1, 1, allow_nan=False), min_size=3, max_size=3),
    st.floats(-1.5, 1.5, allow_nan=False),
)
def test_finite_and_bounded_for_any_receiver(point, normal, tilt):
    n = np.asarray(normal, dtype=float)
    if np.linalg.norm(n) < 1e-3:
        n = np.array([0.0, 0.0, 1.0])
    n /= np.linalg.norm(n)
    poly = np.array([[0, 0, 0], [1, 0, tilt], [1, 1, tilt], [0, 1, 0]], dtype=float)
    f = point_polygon([point], [n], poly)
    assert np.isfinite(f).all() and 0.0 <= f[0] <= 1.0


def test_solid_angles_of_elements():
    """iat.radiosity.pointlight: the six faces of a cube seen from inside sum to 4 pi, from its centre
    each is 4 pi / 6, a face seen from a point on its own plane or from behind counts 0, and an
    element touched by the point subtends at most 2 pi."""
    from iat.radiosity.pointlight import element_solid_angle

    c = np.array([[[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]]], dtype=float)  # z = 0, inward normal +z
    faces, normals = [], []
    for axis in range(3):
        for side in (0.0, 1.0):
            f = np.zeros((4, 3))
            f[:, axis] = side
            f[:, (axis + 1) % 3] = [0, 1, 1, 0]
            f[:, (axis + 2) % 3] = [0, 0, 1, 1]
            faces.append(f)
            nrm = np.zeros(3)
            nrm[axis] = 1.0 if side == 0.0 else -1.0
            normals.append(nrm)
    faces, normals, quad = np.array(faces), np.array(normals), np.ones(6, dtype=bool)
    for p in ([0.5, 0.5, 0.5], [0.1, 0.2, 0.7], [0.5, 0.5, 1e-6]):
        om = element_solid_angle(np.array(p), faces, normals, quad)
        assert om.sum() == pytest.approx(4 * np.pi, rel=1e-9)
    assert element_solid_angle(np.array([0.5, 0.5, 0.5]), faces, normals, quad) == pytest.approx(
        np.full(6, 4 * np.pi / 6)
    )
    assert element_solid_angle(np.array([0.0, 2.0, 0.5]), faces[:1], normals[:1], quad[:1])[0] == 0.0
    up = np.array([[0, 0, 1.0]])
    assert element_solid_angle(np.array([0.5, 0.5, -1.0]), c, up, quad[:1])[0] == 0.0
    assert element_solid_angle(np.array([0.5, 0.5, 1e-9]), c, up, quad[:1])[0] == pytest.approx(
        2 * np.pi, rel=1e-6
    )
