"""Tests of iat.measure.reference (Mitsuba 3 path-traced references): units and image orientation."""

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="mitsuba (Mitsuba 3) not installed: no path-traced references")

from iat.camera import Camera  # noqa: E402
from iat.io.scene import Light, Material, Scene  # noqa: E402
from iat.measure import reference  # noqa: E402


def _quad_z0(x0, x1, y0, y1):
    """Corners of an axis-aligned quad in the plane z = 0, front (normal) towards +Z."""
    return [[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]]


def test_emissive_quad_radiance():
    L = np.array([5.0, 3.0, 0.5])
    sc = Scene(
        vertices=_quad_z0(-2, 2, -2, 2),
        patch_corners=[[0, 1, 2, 3]],
        patch_material=[0],
        materials=[Material(albedo=[0.5] * 3, emission=L)],
    )
    np.testing.assert_allclose(sc.patch_normal[0], [0, 0, 1])
    cam = Camera(eye=[0, 0, 3], target=[0, 0, 0], yfov=40)
    img = reference.render_reference(sc, cam, size=(20, 16), spp=4)
    assert img.shape == (16, 20, 3) and img.dtype == np.float32
    np.testing.assert_allclose(img[8, 10], L, rtol=0.01)
    # single-sided: seen from behind the emitter is black
    back = reference.render_reference(
        sc, Camera(eye=[0, 0, -3], target=[0, 0, 0], yfov=40), size=(8, 8), spp=4
    )
    assert back.max() == 0.0


def test_emissive_triangle_winding():
    # a triangle patch (-1 as 4th corner) emits on the side of its patch normal
    sc = Scene(
        vertices=[[-2, -2, 0], [2, -2, 0], [0, 2, 0]],
        patch_corners=[[0, 1, 2, -1]],
        patch_material=[0],
        materials=[Material(emission=[1.0, 1.0, 1.0])],
    )
    np.testing.assert_allclose(sc.patch_normal[0], [0, 0, 1])
    img = reference.render_reference(sc, Camera(eye=[0, 0, 3], target=[0, 0, 0], yfov=30), size=(8, 8), spp=4)
    np.testing.assert_allclose(img[4, 4], 1.0, rtol=1e-3)


def test_point_light_units_on_floor():
    """A white floor at distance h below a point light of I W/sr has radiance rho/pi * I/h^2."""
    rho, intensity, h = 0.8, 10.0, 2.0
    sc = Scene(
        vertices=[[-5, 0, 5], [5, 0, 5], [5, 0, -5], [-5, 0, -5]],
        patch_corners=[[0, 1, 2, 3]],
        patch_material=[0],
        materials=[Material(albedo=[rho] * 3)],
        lights=[Light(kind="point", position=[0, h, 0], color=[1.0, 1.0, 1.0], intensity=intensity)],
    )
    np.testing.assert_allclose(sc.patch_normal[0], [0, 1, 0])
    # looking straight down at the point below the light, narrow field of view
    cam = Camera(eye=[0, 1.0, 0], target=[0, 0, 0], up=[0, 0, -1], yfov=10)
    img = reference.render_reference(sc, cam, size=(32, 32), spp=64)
    centre = img[14:18, 14:18].mean(axis=(0, 1))
    np.testing.assert_allclose(centre, rho / np.pi * intensity / h**2, rtol=0.03)


def test_image_orientation_left_right_top_bottom():
    """Row 0 is the top, column 0 the left, not mirrored (camera down -Z, +Y up, +X right)."""
    V = _quad_z0(-2, 0, -1, 1) + _quad_z0(0, 2, -1, 1) + _quad_z0(-1, 1, 1, 2)
    sc = Scene(
        vertices=V,
        patch_corners=[[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]],
        patch_material=[0, 1, 2],
        materials=[Material(emission=[1, 0, 0]), Material(emission=[0, 1, 0]), Material(emission=[0, 0, 1])],
    )
    img = reference.render_reference(
        sc, Camera(eye=[0, 0, 3], target=[0, 0, 0], yfov=40), size=(32, 24), spp=4
    )
    left, right = img[:, :16].mean(axis=(0, 1)), img[:, 16:].mean(axis=(0, 1))
    assert left[0] > 0.5 and left[1] == 0.0  # red (x < 0) on the left
    assert right[1] > 0.5 and right[0] == 0.0  # green (x > 0) on the right
    assert img[:12, :, 2].sum() > 0 and img[12:, :, 2].sum() == 0  # blue (y > 1) at the top


def test_reference_cached(tmp_path, monkeypatch):
    sc = Scene(
        vertices=_quad_z0(-1, 1, -1, 1),
        patch_corners=[[0, 1, 2, 3]],
        patch_material=[0],
        materials=[Material(emission=[2.0, 2.0, 2.0])],
    )
    cam = Camera(eye=[0, 0, 3], target=[0, 0, 0], yfov=40)
    monkeypatch.delenv("IAT_REGEN_REFS", raising=False)
    calls = []
    real = reference.render_reference

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(reference, "render_reference", counting)
    a = reference.render_reference_cached(sc, cam, (12, 10), 2, tmp_path)
    b = reference.render_reference_cached(sc, cam, (12, 10), 2, tmp_path)
    assert len(calls) == 1 and a.shape == (10, 12, 3)
    np.testing.assert_array_equal(a, b)
    files = list(tmp_path.iterdir())
    assert len(files) == 1 and files[0].suffix == ".npy"  # no temporary left behind
    reference.render_reference_cached(sc, cam, (12, 10), 2, tmp_path, regen=True)
    assert len(calls) == 2
    # any change to the scene, camera, size or spp is a new key
    sc.materials[0].emission[:] = 3.0
    c = reference.render_reference_cached(sc, cam, (12, 10), 2, tmp_path)
    assert len(calls) == 3 and c.max() == pytest.approx(3.0)
    reference.render_reference_cached(sc, cam, (12, 10), 4, tmp_path)
    assert len(calls) == 4 and len(list(tmp_path.iterdir())) == 3


def _inward_cube(half=1.0):
    """A closed cube of 6 quads whose normals point inwards."""
    h = half
    V = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)])  # index = 4*ix + 2*iy + iz
    outward = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    quads = [q[::-1] for q in outward]
    return V, quads


def test_closed_emissive_box_interreflection():
    """Inside a closed box that emits E and reflects rho everywhere, L = E / (1 - rho) (all bounces);
    with max_depth=2 (emission + one bounce) L = E (1 + rho)."""
    E, rho = 1.0, 0.5
    V, quads = _inward_cube()
    sc = Scene(
        vertices=V,
        patch_corners=quads,
        patch_material=[0] * 6,
        materials=[Material(albedo=[rho] * 3, emission=[E] * 3)],
    )
    assert (np.einsum("ij,ij->i", sc.patch_normal, sc.corner_positions.mean(axis=1)) < 0).all()  # inward
    cam = Camera(eye=[0, 0, 0.5], target=[0, 0, -1], yfov=90)
    full = reference.render_reference(sc, cam, size=(16, 16), spp=32)
    assert full.mean() == pytest.approx(E / (1 - rho), rel=0.03)
    two = reference.render_reference(sc, cam, size=(16, 16), spp=32, max_depth=2)
    assert two.mean() == pytest.approx(E * (1 + rho), rel=0.01)
