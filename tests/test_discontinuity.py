"""Discontinuity meshing (issue 17, :mod:`iat.geometry.discontinuity`): a thin tilted blade casts a
diagonal hard shadow from a point light across a floor and up a wall; roots cut along it against
the plain quad-trees, both against Mitsuba 3.

The reference (4096 spp, 128 x 96) and a direct-light-only render that finds the shadow (64 spp:
a pixel with no sample reaching the light is exactly 0) are cached under ``tests/refs/``
(``pytest --regen-refs`` renders them again, ~1 min on 2 cores). The *band* is the pixels within
2 of the shadow's boundary (a dark pixel next to a lit one), away from the blade and the sky; the
error is ``sum |image - reference| / sum reference`` over the band and over every surface pixel.
Two 4096-spp references of other seeds (3, 4) differ by 1.1 % in the band and 0.4 % over the image,
well below the errors judged (docs/benchmarks.md, "Discontinuity meshing").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from iat.camera import Camera
from iat.geometry.discontinuity import CUT_LIFT, occluder_edges, split_discontinuities
from iat.io.scene import Light, Material, Scene
from iat.radiosity import SolveOptions, solve

REFS = Path(__file__).parent / "refs"
SIZE = (128, 96)
LIGHT = np.array([1.6, 1.4, 1.7])
CAMERA = Camera(eye=[0.1, 1.5, 2.7], target=[0.75, 0.45, 0.45], yfov=50.0, znear=0.05, zfar=20.0)
BLADE_ALBEDO = 0.3


def blade_scene(tilt: float = 35.0) -> Scene:
    """A 2 x 2 m floor (y = 0), a 2 x 1.5 m wall behind it (z = 0), and a 1 m x 12 cm blade facing
    the point light, its long side ``tilt`` degrees from vertical."""
    V: list = []
    C: list = []

    def quad(p):
        C.append([len(V), len(V) + 1, len(V) + 2, len(V) + 3])
        V.extend(p)

    quad([(0, 0, 2), (2, 0, 2), (2, 0, 0), (0, 0, 0)])
    quad([(0, 0, 0), (2, 0, 0), (2, 1.5, 0), (0, 1.5, 0)])
    centre = np.array([1.15, 0.75, 1.05])
    n = (LIGHT - centre) * [1, 0, 1]
    n /= np.linalg.norm(n)
    t, up, a = np.cross([0, 1, 0], n), np.array([0.0, 1.0, 0.0]), np.radians(tilt)
    along, across = (np.cos(a) * up + np.sin(a) * t) * 0.5, (-np.sin(a) * up + np.cos(a) * t) * 0.06
    quad([centre - along - across, centre - along + across, centre + along + across, centre + along - across])
    mats = [Material("floor", albedo=[0.6] * 3), Material("wall", albedo=[0.5] * 3)]
    mats.append(Material("blade", albedo=[BLADE_ALBEDO] * 3))
    lights = [Light("point", position=LIGHT, intensity=2.0)]
    return Scene(np.array(V, float), np.array(C), np.arange(3), mats, lights=lights)


def shadow_lines(scene: Scene) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """The blade's edges projected from the light (along a sun) onto the floor and wall planes (exact,
    unlifted): [(a point, the direction to the other end's, the plane's axis: 1 floor, 2 wall)]."""
    light = scene.lights[0]
    out = []
    blade = scene.world_triangles()[scene.world_triangle_patch() == 2]
    for a, b in zip(*occluder_edges(blade, light), strict=True):
        for axis in (1, 2):  # the floor y = 0, the wall z = 0
            if light.kind == "directional":
                p = [q - light.direction * q[axis] / light.direction[axis] for q in (a, b)]
            else:
                p = [LIGHT + (q - LIGHT) * LIGHT[axis] / (LIGHT[axis] - q[axis]) for q in (a, b)]
            out.append((p[0], p[1] - p[0], axis))
    return out


def band_masks(ref: np.ndarray, direct: np.ndarray, preview: np.ndarray):
    """(band, surface) (h, w) bool: pixels within 2 of the shadow's boundary in the direct-only
    render, and all surface pixels, both away from the sky and the blade."""
    from scipy.ndimage import binary_dilation

    sky = preview.max(axis=2) <= 0
    blade = (preview[..., 0] > 0) & (preview[..., 0] < 0.2)  # the preview shows albedo / 2
    away = ~binary_dilation(sky | blade, iterations=2)
    dark = direct.max(axis=2) <= 0
    edge = (dark & binary_dilation(~dark)) | (~dark & binary_dilation(dark))
    return binary_dilation(edge & away, iterations=2) & away, away & (ref.max(axis=2) > 0)


def relative_error(img, ref, mask) -> float:
    return float(np.abs(img[mask] - ref[mask]).sum() / ref[mask].sum())


@pytest.fixture(scope="module")
def measured(egl_ctx):
    """{name: (band error, whole error, elements, IAT band error)} of the plain and the cut scene at a
    few depths."""
    pytest.importorskip("mitsuba")
    from iat.measure.reference import render_reference_cached
    from iat.render.renderer import Renderer

    plain = blade_scene()
    cut = split_discontinuities(plain)
    ref = render_reference_cached(plain, CAMERA, SIZE, spp=4096, cache_dir=REFS, seed=3)
    direct = render_reference_cached(plain, CAMERA, SIZE, spp=64, cache_dir=REFS, seed=3, max_depth=2)
    r = Renderer(egl_ctx)
    try:
        r.set_scene(plain)
        band, surface = band_masks(ref, direct, r.render(CAMERA, SIZE, mode="preview"))
        out = {}
        for name, scene, depth in [
            ("plain", plain, 6),
            ("plain7", plain, 7),
            ("cut", cut, 5),
            ("cut4", cut, 4),
            ("cut6", cut, 6),
        ]:
            sol = solve(scene, SolveOptions(max_depth=depth))
            img, iat = mesh_and_iat(r, scene, sol, CAMERA, SIZE)
            out[name] = (
                relative_error(img, ref, band),
                relative_error(img, ref, surface),
                len(sol.leaf_patch),
                relative_error(iat, ref, band),
            )
    finally:
        r.release()
    assert band.sum() > 300 and surface.sum() > 5 * band.sum()
    print({k: tuple(round(x, 4) for x in v) for k, v in out.items()})
    return out


def mesh_and_iat(r, scene, sol, camera, size):
    """(mesh, IAT) images (h, w, 3) of a solution, box-filtered as the reference's pixels are; IAT
    baked at the default :class:`~iat.bake.policy.BakePolicy`."""
    from iat.bake.baker import Baker
    from iat.measure.reference import box_filtered_render

    r.set_scene(scene)
    r.set_solution(sol)
    mesh = box_filtered_render(r, camera, size, "mesh")
    r.set_baked(Baker(sol, scene).bake())
    return mesh, box_filtered_render(r, camera, size, "iat")


def test_lower_band_error_at_no_more_elements(measured):
    """Cut at depth 5 against the plain defaults (depth 6): measured 0.0176 against 0.0795 in the
    band (4.5x) with 770 elements against 1038; over the image 0.0067 against 0.0092."""
    band_p, whole_p, n_p, _ = measured["plain"]
    band_c, whole_c, n_c, _ = measured["cut"]
    assert n_c <= n_p
    assert band_c * 3.0 <= band_p  # the must-show is 2x
    assert whole_c <= whole_p


def test_same_error_with_a_quarter_of_the_elements(measured):
    """Cut at depth 4 against plain depth 7: measured band 0.0276 against 0.0417 with 353 elements
    against 1998 (5.7x fewer)."""
    band_p, _, n_p, _ = measured["plain7"]
    band_c, _, n_c, _ = measured["cut4"]
    assert n_c * 4 <= n_p
    assert band_c <= band_p


def test_iat_follows_the_cut_as_closely_as_the_mesh(measured):
    """Issue 37, at the solver's and the baker's defaults (depth 6, BakePolicy()): the cut halves
    the band error in both modes, and IAT's is within 10 % of the mesh's. Measured (2026-12-06):
    plain mesh 0.0733, IAT 0.0782; cut mesh 0.0105, IAT 0.0107 (docs/baking.md, section 9)."""
    mesh_p, _, _, iat_p = measured["plain"]
    mesh_c, _, _, iat_c = measured["cut6"]
    assert mesh_c * 2.0 <= mesh_p and iat_c * 2.0 <= iat_p
    assert iat_c <= 1.10 * mesh_c


ROOM_SIZE = (96, 72)


def sun_patch(r):
    """(scene, reference (h, w, 3), band (h, w) bool) of the sun patch on the floor of
    ``tests/support/daylight.py``'s daylit room (sun and sky through an open window): the 4096-spp
    reference ``tests/test_daylight.py`` caches, and the pixels within 2 of the patch's edge in a
    direct-sun-only render (64 spp, no sky); ``r`` a Renderer (left holding the scene)."""
    from iat.measure.reference import render_reference_cached
    from tests.support.daylight import CAMERA as ROOM_CAMERA
    from tests.support.daylight import daylit_room

    plain = daylit_room()
    ref = render_reference_cached(plain, ROOM_CAMERA, ROOM_SIZE, spp=4096, cache_dir=REFS, seed=3)
    sun_only = daylit_room(sky=None)
    sun = render_reference_cached(
        sun_only, ROOM_CAMERA, ROOM_SIZE, spp=64, cache_dir=REFS, seed=3, max_depth=2
    )
    r.set_scene(plain)
    band, _ = band_masks(ref, sun, r.render(ROOM_CAMERA, ROOM_SIZE, mode="preview"))
    return plain, ref, band


def test_sun_patch_through_a_window(egl_ctx):
    """Issue 37, :func:`sun_patch`: at the defaults the cut must halve the band error in both modes,
    and IAT's must be within 10 % of the mesh's. Measured (2026-12-06): plain mesh 0.0744, IAT 0.0775;
    cut mesh 0.0242, IAT 0.0247 (0.0262 with the shadow line on the hypotenuse of the triangle
    roots); ~10 k elements cut against ~6 k plain. The reference's sun is a delta light, ours a
    0.53-degree disc: part of what is left is the penumbra (~2.5 cm here) it does not have."""
    pytest.importorskip("mitsuba")
    from iat.render.renderer import Renderer
    from tests.support.daylight import CAMERA as ROOM_CAMERA

    r = Renderer(egl_ctx)
    got = {}
    try:
        plain, ref, band = sun_patch(r)
        for name, scene in [("plain", plain), ("cut", split_discontinuities(plain))]:
            images = mesh_and_iat(r, scene, solve(scene, SolveOptions()), ROOM_CAMERA, ROOM_SIZE)
            got[name] = tuple(relative_error(img, ref, band) for img in images)
    finally:
        r.release()
    print(got, int(band.sum()))
    assert band.sum() > 250
    (mesh_p, iat_p), (mesh_c, iat_c) = got["plain"], got["cut"]
    assert mesh_c * 2.0 <= mesh_p and iat_c * 2.0 <= iat_p
    assert iat_c <= 1.10 * mesh_c


def test_shadow_lines_fall_on_the_legs_of_triangle_roots():
    """A triangle root's texture lattice runs along its legs (corners 0-1 and 0-2); a cut piece's
    corners are turned so that no shadow line is its hypotenuse (1-2) where another edge is free."""
    plain = blade_scene()
    cut = split_discontinuities(plain)
    tol = 10 * CUT_LIFT * np.linalg.norm(np.ptp(plain.vertices, axis=0))
    lines = shadow_lines(plain)

    def on_a_line(p, q):
        for a, d, _ in lines:
            u = d / np.linalg.norm(d)
            if all(np.linalg.norm(np.cross(x - a, u)) < tol for x in (p, q)):
                return True
        return False

    c, tris = cut.corner_positions, 0
    for p in np.flatnonzero(~cut.patch_is_quad):
        on = [on_a_line(c[p, i], c[p, (i + 1) % 3]) for i in range(3)]
        tris += any(on)
        assert not on[1] or all(on), f"root {p}: a shadow line on its hypotenuse"
    assert tris >= 4


@pytest.mark.parametrize("kind", ["point", "sun"])
def test_element_edges_follow_the_shadow(kind):
    """Every projected blade edge is covered, where it lands on the floor or the wall, by edges of
    the cut roots lying on it (within the cut's lift), and the cut keeps area, normals and materials;
    for the point light and for a sun (parallel projection)."""
    plain = blade_scene()
    if kind == "sun":
        sun = Light("directional", direction=(-0.45, -0.35, -0.75) / np.linalg.norm([0.45, 0.35, 0.75]))
        plain.lights = [sun]
    cut = split_discontinuities(plain)
    assert cut.n_patches > 10
    assert np.isclose(cut.patch_area.sum(), plain.patch_area.sum(), rtol=1e-9)
    for m in range(3):  # each material's area is its own
        assert np.isclose(cut.patch_area[cut.patch_material == m].sum(), plain.patch_area[m], rtol=1e-9)
    parent = np.array([0 if n[1] > 0.99 else 1 if n[2] > 0.99 else 2 for n in cut.patch_normal])
    assert (parent == cut.patch_material).all()
    c = cut.corner_positions
    k = np.where(cut.patch_is_quad, 4, 3)
    edges = np.concatenate(
        [np.stack([c[p, i], c[p, (i + 1) % k[p]]]) for p in range(cut.n_patches) for i in range(k[p])]
    )
    edges = edges.reshape(-1, 2, 3)
    tol = 10 * CUT_LIFT * np.linalg.norm(np.ptp(plain.vertices, axis=0))
    covered = 0
    for p0, d, axis in shadow_lines(plain):
        for q in (p0 + 0.25 * d, p0 + 0.5 * d, p0 + 0.75 * d):
            if not (0 < q[0] < 2 and (0 < q[2] < 2 if axis == 1 else 0 < q[1] < 1.5)):
                continue
            u = d / np.linalg.norm(d)
            a, b = edges[:, 0] - q, edges[:, 1] - q
            off = np.maximum(np.linalg.norm(np.cross(a, u), axis=1), np.linalg.norm(np.cross(b, u), axis=1))
            spans = (a @ u) * (b @ u) <= 0
            assert (spans & (off < tol)).any(), f"no element edge on the shadow line at {q}"
            covered += 1
    assert covered >= 6


def test_cut_lift_is_the_solvers_ray_offset():
    from iat.radiosity.options import RAY_EPS

    assert CUT_LIFT == RAY_EPS


def test_load_scene_records_and_cuts(tmp_path):
    """``load_scene(discontinuity=True)`` cuts a GLB's roots along its light's shadow; the option
    travels with SolveOptions' loader keywords, and ``iat solve``'s solution (cut by default since
    issue 37; ``--no-discontinuity``: not) opens on the same patches."""
    from iat.cli import main
    from iat.io.glb import GlbBuilder
    from iat.io.load import load_scene
    from iat.radiosity.inputs import open_solution

    scene = blade_scene()
    b = GlbBuilder()
    c = scene.corner_positions
    tris = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
    mats = [b.add_material(m.name, base_color=(*m.albedo, 1.0)) for m in scene.materials]
    for m in range(3):
        sel = np.r_[np.arange(3) == m, np.arange(3) == m]
        mesh = b.add_mesh(f"part{m}", tris[sel].reshape(-1, 3), np.arange(6).reshape(-1, 3), material=mats[m])
        b.add_node(f"part{m}", mesh=mesh)
    b.add_point_light("lamp", (1.0, 1.0, 1.0), 2.0, LIGHT)
    path = tmp_path / "blade.glb"
    b.write(path)
    opts = SolveOptions(discontinuity=True)
    assert opts.load_kwargs()["discontinuity"] is True
    assert SolveOptions.recorded_load_kwargs({})["discontinuity"] is False
    plain, cut = load_scene(path), load_scene(path, **opts.load_kwargs())
    assert plain.n_patches == 3 and cut.n_patches > 10
    assert len(cut.lights) == 1
    out = tmp_path / "blade.npz"
    assert SolveOptions().discontinuity is True
    for flag, want in (([], cut.n_patches), (["--no-discontinuity"], plain.n_patches)):
        assert main(["solve", str(path), "-o", str(out), *flag, "--max-depth", "3", "--json"]) == 0
        scene, sol = open_solution(out)
        assert sol.options["discontinuity"] is (not flag)
        assert scene.n_patches == len(sol.patch_is_quad) == want


@pytest.mark.parametrize("triangles", [False, True])
def test_cut_interpolates_detail_uvs(triangles):
    """Cut pieces of a quad floor (or of the floor as two triangle roots) carry the parent's detail
    UVs at their corners: here UV = (x, z) / 2, a function of the position."""
    plain = blade_scene()
    if triangles:  # floor (0, 1, 2) and (0, 2, 3) as two triangle roots
        corners = np.concatenate([[[0, 1, 2, -1], [0, 2, 3, -1]], plain.patch_corners[1:]])
        plain = Scene(plain.vertices, corners, np.array([0, 0, 1, 2]), plain.materials, lights=plain.lights)
    floor = plain.patch_material == 0
    uv = plain.corner_positions[..., [0, 2]] / 2
    plain.patch_uv = np.where(floor[:, None, None], uv, 0.0)
    cut = split_discontinuities(plain)
    pieces = cut.patch_material == 0
    assert pieces.sum() > floor.sum() + 4
    k = np.where(cut.patch_is_quad, 4, 3)
    for p in np.flatnonzero(pieces):
        got, want = cut.patch_uv[p, : k[p]], cut.corner_positions[p, : k[p]][:, [0, 2]] / 2
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_the_bicubic_fit_no_longer_crosses_the_shadow(egl_ctx):
    """Report §5.2's bicubic fit on the blade scene (IAT mode, threshold 0, the defaults): on the plain
    mesh it rings across the shadow's edge (band error 0.094, worse than the mesh's 0.080, and dips
    to 0.0002 where the light is 0.003); on the cut mesh every piece's fit ends at the edge: 0.0167
    against the mesh's 0.0150, and no dip (measured)."""
    pytest.importorskip("mitsuba")
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.measure.reference import box_filtered_render, render_reference_cached
    from iat.render.renderer import Renderer

    plain = blade_scene()
    ref = render_reference_cached(plain, CAMERA, SIZE, spp=4096, cache_dir=REFS, seed=3)
    direct = render_reference_cached(plain, CAMERA, SIZE, spp=64, cache_dir=REFS, seed=3, max_depth=2)
    r = Renderer(egl_ctx)
    got = {}
    try:
        r.set_scene(plain)
        band, _ = band_masks(ref, direct, r.render(CAMERA, SIZE, mode="preview"))
        for name, scene in [("plain", plain), ("cut", split_discontinuities(plain))]:
            sol = solve(scene, SolveOptions())
            r.set_scene(scene)
            r.set_solution(sol)
            mesh = box_filtered_render(r, CAMERA, SIZE, "mesh")
            r.set_baked(Baker(sol, scene).bake(BakePolicy(threshold=0, method="bicubic")))
            img = box_filtered_render(r, CAMERA, SIZE, "iat")
            errors = relative_error(img, ref, band), relative_error(mesh, ref, band)
            got[name] = (*errors, float(img[band].min()))
    finally:
        r.release()
    print(got)
    (bic_p, mesh_p, _), (bic_c, mesh_c, low_c) = got["plain"], got["cut"]
    assert bic_p > mesh_p  # the fit across the edge is worse than the mesh
    assert bic_c <= 1.25 * mesh_c and bic_c * 3.0 <= bic_p
    assert low_c >= 0.5 * float(ref[band].min())  # no dip below the light in the shadow


def test_new_roots_are_capped_on_a_real_model(monkeypatch):
    """The sample house (965 roots, 3 point lights and a spot): uncapped the cut adds ~730 roots
    (+76 %), each shooting on its own; the default cap keeps the new ones to a tenth of the roots,
    or 256 (here: +27 %), the receivers with the longest shadow boundary first, give or take the last
    receiver's pieces."""
    from pathlib import Path

    from iat.geometry import discontinuity
    from iat.io.load import load_scene

    plain = load_scene(Path(__file__).parent.parent / "sample_models" / "house.glb")
    n = plain.n_patches
    capped = split_discontinuities(plain).n_patches - n
    most = max(discontinuity.MIN_NEW_PATCHES, discontinuity.MAX_NEW_FRACTION * n)
    assert most <= capped <= most + 32
    monkeypatch.setattr(discontinuity, "MAX_NEW_FRACTION", 1.0)
    assert split_discontinuities(plain).n_patches - n > 0.6 * n
