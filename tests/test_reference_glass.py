"""Glass in the Mitsuba references (:mod:`iat.measure.reference`) as the solver has it: a pane does not
occlude, passes its transmittance of every light (a delta sun or lamp as well as the sky), keeps the
rest and reflects nothing, and a pane counts once however many faces it is modelled with. Before
(Mitsuba's ``path`` integrator: shadow rays stop at a ``mask``) the floor under a pane of 0.7 got
0.000 of the lamp's and the sun's light."""

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="mitsuba (Mitsuba 3) not installed: no path-traced references")

from iat.camera import Camera  # noqa: E402
from iat.io.scene import Light, Material, Scene, Sky  # noqa: E402
from iat.measure import reference  # noqa: E402

TAU, RHO, I, H = 0.7, 0.8, 10.0, 2.0
#: straight down at the floor's middle from 0.5 m, a narrow view (the light there is uniform)
CAM = Camera(eye=[0, 0.5, 0], target=[0, 0, 0], up=[0, 0, -1], yfov=10)


def _quad_y(y, h, flip=False):
    """Corners of the square |x|, |z| <= h at height y, front up (down with ``flip``)."""
    q = [[-h, y, h], [h, y, h], [h, y, -h], [-h, y, -h]]
    return q[::-1] if flip else q


def _floor_under(panes, light: str, glass: bool = True) -> Scene:
    """A 10 x 10 m floor of albedo RHO at y = 0 under 6 x 6 m glass quads (transmittance TAU) at the
    heights ``panes``, lit by a point light of I W/sr at height H or a sun of I W/m² straight down."""
    V, C, M = _quad_y(0, 5), [[0, 1, 2, 3]], [0]
    for y in panes:
        C.append(list(range(len(V), len(V) + 4)))
        V += _quad_y(y, 3)
        M.append(1)
    mats = [Material("floor", albedo=[RHO] * 3)]
    if glass:
        mats.append(Material("glass", albedo=[0, 0, 0], transmission=TAU))
    if light == "point":
        lt = Light(kind="point", position=[0, H, 0], color=[1, 1, 1], intensity=I)
    else:
        lt = Light(kind="directional", direction=[0, -1, 0], color=[1, 1, 1], intensity=I)
    return Scene(vertices=V, patch_corners=C, patch_material=M, materials=mats, lights=[lt])


def _floor_radiance(scene, spp=64):
    img = reference.render_reference(scene, CAM, size=(16, 16), spp=spp)
    return float(img[4:12, 4:12].mean())


@pytest.mark.parametrize("light", ["point", "directional"])
@pytest.mark.parametrize("panes", [(1.0,), (1.0, 1.01)], ids=["sheet", "thin solid"])
def test_a_pane_passes_its_transmittance_of_a_delta_light(light, panes):
    """Under a pane the floor has TAU x its unglazed radiance, rho / pi x I / h² (lamp) or
    rho / pi x E (sun); a pane modelled as a solid (two faces 1 cm apart) also passes TAU, not TAU²
    (the solver counts the first glass a ray crosses only)."""
    unglazed = RHO / np.pi * (I / H**2 if light == "point" else I)
    assert _floor_radiance(_floor_under((), light)) == pytest.approx(unglazed, rel=1e-3)
    assert _floor_radiance(_floor_under(panes, light)) == pytest.approx(TAU * unglazed, rel=1e-3)


def _box_under_sky(panes) -> Scene:
    """A 2 x 2 x 1 m box of black walls (faces inward), floor of albedo RHO, open at the top or
    glazed by quads (transmittance TAU) at the heights ``panes``, under a uniform sky."""
    V, C, M = _quad_y(0, 1), [[0, 1, 2, 3]], [0]
    for a, b in [((-1, -1), (1, -1)), ((1, -1), (1, 1)), ((1, 1), (-1, 1)), ((-1, 1), (-1, -1))]:
        C.append(list(range(len(V), len(V) + 4)))
        V += [[a[0], 0, a[1]], [a[0], 1, a[1]], [b[0], 1, b[1]], [b[0], 0, b[1]]]
        M.append(1)
    for y in panes:
        C.append(list(range(len(V), len(V) + 4)))
        V += _quad_y(y, 1, flip=True)
        M.append(2)
    mats = [
        Material("floor", albedo=[RHO] * 3),
        Material("wall", albedo=[0, 0, 0]),
        Material("glass", albedo=[0, 0, 0], transmission=TAU),
    ]
    scene = Scene(vertices=V, patch_corners=C, patch_material=M, materials=mats)
    scene.sky = Sky(kind="uniform", radiance=(1.0, 1.0, 1.0))
    return scene


def test_a_pane_passes_its_transmittance_of_the_sky():
    """The black box's floor sees the sky only through its top: glazed (a sheet, or a solid of two
    faces) it has TAU x the open box's radiance, to the samples' noise (measured 0.702 and 0.703; with
    ``path`` and no pane grouping 0.710 and 0.486 at 256 spp: the solid passed TAU²)."""
    cam = Camera(eye=[0, 0.5, 0], target=[0, 0, 0], up=[0, 0, -1], yfov=10)
    y = {}
    for name, panes in [("open", ()), ("sheet", (0.98,)), ("solid", (0.98, 0.99))]:
        img = reference.render_reference(_box_under_sky(panes), cam, size=(16, 16), spp=1024)
        y[name] = float(img[4:12, 4:12].mean())
    assert y["open"] > 0.1
    assert y["sheet"] / y["open"] == pytest.approx(TAU, rel=0.015)
    assert y["solid"] / y["open"] == pytest.approx(TAU, rel=0.015)


def test_pane_layers_counts_the_faces_of_one_pane():
    """A sheet is one face, a pane modelled as a solid two, double glazing of two such panes four;
    panes farther apart than PANE_DEPTH are panes of their own."""

    def tris(heights):
        sc = Scene(
            vertices=sum((_quad_y(y, 1) for y in heights), []),
            patch_corners=[list(range(4 * k, 4 * k + 4)) for k in range(len(heights))],
            patch_material=[0] * len(heights),
            materials=[Material("glass", transmission=TAU)],
        )
        return sc.world_triangles()

    assert reference.pane_layers(tris([1.0])).tolist() == [1, 1]
    assert reference.pane_layers(tris([1.0, 1.006])).tolist() == [2] * 4
    assert reference.pane_layers(tris([1.0, 1.004, 1.02, 1.024])).tolist() == [4] * 8
    assert reference.pane_layers(tris([1.0, 1.0 + 2 * reference.PANE_DEPTH])).tolist() == [1] * 4


def test_references_without_glass_keep_their_keys(monkeypatch):
    """A scene without glass keeps ``path`` and the key it had before glass was handled (the literal:
    that scene's key at commit 7516ab2), so its cached references stay valid; a scene with glass
    renders with ``volpath`` under a key that names the glass model (its old references, which lost
    the sun behind the glass, are not read again)."""
    plain = _floor_under((), "point", glass=False)
    glazed = _floor_under((1.0,), "point")
    assert reference.reference_key(plain, CAM, (16, 16), 64) == "6ae5691b24da8fb956f2f30d"
    assert "Volumetric" not in str(reference.build_mitsuba_scene(plain, CAM, (4, 4)).integrator())
    assert "Volumetric" in str(reference.build_mitsuba_scene(glazed, CAM, (4, 4)).integrator())
    keys = [reference.reference_key(s, CAM, (16, 16), 64) for s in (plain, glazed)]
    monkeypatch.setattr(reference, "GLASS_MODEL", "another glass model")
    assert reference.reference_key(plain, CAM, (16, 16), 64) == keys[0]
    assert reference.reference_key(glazed, CAM, (16, 16), 64) != keys[1]
