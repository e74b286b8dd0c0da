"""Faces cut where other geometry pierces them (issue 36: no leaks through intersecting geometry).

The generated case: a closed room (floor, four walls, a 57 mm ceiling slab) whose walls rise 1.5 m
above the slab into a sun, as Revit exports have them. Nothing else lights the room, so its inside
is dark in the building (and in a path tracer); a wall patch that straddles the ceiling carries the
sun into it.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from iat.geometry.pierce import cut_faces, pierced_pairs, region_labels
from iat.io.load import load_scene
from iat.io.scene import Light
from iat.radiosity import SolveOptions, solve

ROOT = Path(__file__).resolve().parents[1]
MADRID = ROOT.parent / "shared" / "real-models" / "revit2021-madrid-house.ifc"

H, SLAB, UP, LX, WZ, THICK = 2.5, 0.057, 1.5, 4.0, 3.0, 0.2  # room: ceiling height, slab, wall tops
SUN = np.array([0.45, -1.0, 0.3]) / np.linalg.norm([0.45, -1.0, 0.3])  # from above, at an angle


def _box(lo, hi):
    """8 corners and 6 outward quads of an axis-aligned box."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)]
    v += [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    q = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
    return v, q


def write_room(path: Path, slab_into_walls: bool = True) -> Path:
    """The room as an OBJ, one object (material) per element: the walls pass up through the slab (as
    in a Revit export); the slab reaches into the walls, or ends on their faces (a contact)."""
    t = THICK
    s = t if slab_into_walls else 0.0
    objects = {
        "floor": _box((-t, -0.2, -t), (LX + t, 0.0, WZ + t)),
        "slab": _box((-s, H, -s), (LX + s, H + SLAB, WZ + s)),
        "wall_s": _box((-t, 0.0, -t), (LX + t, H + UP, 0.0)),
        "wall_n": _box((-t, 0.0, WZ), (LX + t, H + UP, WZ + t)),
        "wall_w": _box((-t, 0.0, 0.0), (0.0, H + UP, WZ)),
        "wall_e": _box((LX, 0.0, 0.0), (LX + t, H + UP, WZ)),
    }
    path.with_suffix(".mtl").write_text("".join(f"newmtl {k}\nKd 0.6 0.6 0.6\n" for k in objects))
    lines, n = [f"mtllib {path.with_suffix('.mtl').name}"], 0
    for name, (v, q) in objects.items():
        lines += [f"o {name}", f"usemtl {name}"]
        lines += [f"v {x} {y} {z}" for x, y, z in v]
        lines += ["f " + " ".join(str(n + i + 1) for i in f) for f in q]
        n += len(v)
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> Path:
    return write_room(tmp_path_factory.mktemp("pierce") / "room.obj")


def _surface_points(scene):
    """(patch (n,), world points (n, 3)) spread over every patch's surface (its clip triangles for
    a panel cell covered in part) and over its lattice rectangle's corners."""
    c = scene.corner_positions
    g = np.linspace(0.02, 0.98, 7)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    quad = scene.patch_is_quad[:, None]
    wq = np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v], 1)
    tri_ok = u + v <= 1
    wt = np.stack([1 - u - v, u, v, 0 * u], 1)
    pts = np.where(quad[..., None], np.einsum("sk,pkc->psc", wq, c), np.einsum("sk,pkc->psc", wt, c))
    ok = np.where(quad, True, tri_ok[None])
    cs = scene.clip_start
    for p in np.flatnonzero(scene.patch_clipped):  # cells covered in part: inside their clip triangles
        uv = scene.clip_uv[cs[p] : cs[p + 1]]
        inside = np.zeros(len(u), bool)
        for t in uv:
            d = np.stack([u, v], 1)
            (a, b, cc) = t
            m = np.stack([b - a, cc - a], 1)
            lam = np.linalg.solve(m, (d - a).T)
            inside |= (lam >= -1e-9).all(0) & (lam.sum(0) <= 1 + 1e-9)
        ok[p] = inside
    patch = np.repeat(np.arange(scene.n_patches), len(u))[ok.ravel()]
    return patch, pts.reshape(-1, 3)[ok.ravel()]


def _straddling(scene, axis: int, level: float, tol: float = 1e-6) -> np.ndarray:
    """Patches (surface) with points on both sides of the plane ``x[axis] = level``."""
    patch, x = _surface_points(scene)
    lo = np.full(scene.n_patches, np.inf)
    hi = np.full(scene.n_patches, -np.inf)
    np.minimum.at(lo, patch, x[:, axis])
    np.maximum.at(hi, patch, x[:, axis])
    return np.flatnonzero((lo < level - tol) & (hi > level + tol))


def _room_side_patches(scene) -> np.ndarray:
    """(p,) bool: patches on the walls' room sides (inner planes, facing in)."""
    c, n = scene.corner_positions, scene.patch_normal
    on = np.zeros(scene.n_patches, bool)
    for axis, level, sign in ((2, 0.0, 1), (2, WZ, -1), (0, 0.0, 1), (0, LX, -1)):
        on |= (np.abs(c[..., axis] - level).max(axis=1) < 1e-9) & (n[:, axis] * sign > 0.9)
    return on


# -- the parts ------------------------------------------------------------------------------------
def test_pierced_pairs_find_crossings_not_contacts():
    floor = [[-1, 0, -1], [1, 0, -1], [0, 0, 1]]
    crossing = [[0, -0.5, 0], [0, 0.5, 0.2], [0, 0.5, -0.2]]  # a vertical triangle through the floor
    standing = [[0, 0.0, 0], [0, 0.5, 0.2], [0, 0.5, -0.2]]  # one corner on the floor
    on_edge = [[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0, 0.5, 0]]  # an edge lying in the floor (a box on it)
    coplanar = [[-0.5, 0, 0], [0.5, 0, 0], [0, 0, 0.5]]
    grazing = [[3, -0.5, 0], [3, 0.5, 0.2], [3, 0.5, -0.2]]  # crosses the floor's plane, not the floor
    tri = np.array([floor, crossing, standing, on_edge, coplanar, grazing], dtype=float)
    pp = pierced_pairs(tri, np.arange(6), 1e-6)
    a, b = pp.a, pp.b
    assert len(pp.c) == 0  # contacts are not looked for unless asked
    assert b[a == 0].tolist() == [1]  # of the five, only the crossing one pierces the floor
    assert (2, 3) in zip(a.tolist(), b.tolist(), strict=True)  # (they cross each other)
    assert len(pierced_pairs(tri[:2], np.zeros(2, np.int64), 1e-6).a) == 0  # one object: its own business
    pp = pierced_pairs(tri[[0, 3]], np.arange(2), 1e-6, contacts=True)  # the box's side rests on the floor
    assert (pp.c.tolist(), pp.d.tolist()) == ([0], [1]) and len(pp.a) == 0
    assert pp.contact_span[0].tolist() == pytest.approx([1.0, 1.0, 1.0])  # floor chord, edge, overlap


def test_cut_faces_split_a_quad_along_the_crossing_and_mark_the_cut():
    # a vertical 2 x 2 quad (two triangles) and a horizontal triangle through it at y = 0.7
    V = np.array(
        [[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [-1, 0.7, -1], [3, 0.7, -1], [1, 0.7, 2]], float
    )
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 6, 5]])
    pp = pierced_pairs(V[F], np.array([0, 0, 1]), 1e-9)
    a, b = pp.a, pp.b
    assert sorted(a.tolist()) == [0, 1] and b.tolist() == [2, 2]
    V2, F2, parent, barrier, n_cut = cut_faces(V, F, np.r_[a, b], np.r_[b, a], 1e-9)
    tri = V2[F2]
    quad = parent < 2
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert area[quad].sum() == pytest.approx(4.0, rel=1e-12)  # the pieces cover the quad exactly
    y = tri[quad][..., 1]
    assert ((y.max(axis=1) <= 0.7 + 1e-12) | (y.min(axis=1) >= 0.7 - 1e-12)).all()  # none spans the cut
    on_cut = V2[barrier][..., 1]
    assert len(barrier) and np.allclose(on_cut, 0.7)
    region, joined = region_labels(V2, F2, np.zeros(len(F2), np.int64), barrier)
    assert joined == 0
    below = np.flatnonzero(quad)[y.max(axis=1) <= 0.7 + 1e-12]
    above = np.flatnonzero(quad)[y.min(axis=1) >= 0.7 - 1e-12]
    assert len(set(region[below])) == len(set(region[above])) == 1  # each side one region ...
    assert set(region[below]).isdisjoint(region[above])  # ... of its own


# -- the room: loading ----------------------------------------------------------------------------
def test_room_walls_are_cut_at_the_ceiling_and_no_patch_spans_it(room):
    whole = load_scene(room, cut=False)
    cut = load_scene(room)
    assert whole.pierce.pairs == cut.pierce.pairs == 36 and cut.pierce.objects == 5
    assert whole.pierce.faces_cut == 0 and cut.pierce.faces_cut == 20
    assert cut.pierce.joined_regions == 0
    for scene, straddle in ((whole, True), (cut, False)):
        wall = _room_side_patches(scene)
        spans = np.zeros(scene.n_patches, bool)
        for level in (H, H + SLAB):
            spans[_straddling(scene, 1, level)] = True
        assert (spans & wall).any() == straddle
    # the ceiling's underside is cut along the walls' room sides as well: no patch of it lies both
    # over the room and inside a wall
    for scene, straddle in ((whole, True), (cut, False)):
        patch, x = _surface_points(scene)
        under = (scene.patch_normal[patch, 1] < -0.9) & (np.abs(x[:, 1] - H) < 1e-9)
        over_room = (x[:, 0] > 1e-6) & (x[:, 0] < LX - 1e-6) & (x[:, 2] > 1e-6) & (x[:, 2] < WZ - 1e-6)
        in_wall = (x[:, 0] < -1e-6) | (x[:, 0] > LX + 1e-6) | (x[:, 2] < -1e-6) | (x[:, 2] > WZ + 1e-6)
        both = np.intersect1d(patch[under & over_room], patch[under & in_wall])
        assert (len(both) > 0) == straddle
    assert cut.n_patches > whole.n_patches
    assert cut.patch_area.sum() == pytest.approx(whole.patch_area.sum(), rel=1e-9)


@pytest.mark.parametrize("name", ["cornell_box", "lavapit", "pool"])
def test_sample_models_without_crossings_load_as_before(name):
    path = ROOT / "sample_models" / f"{name}.glb"
    a, b = load_scene(path), load_scene(path, cut=False)
    assert a.pierce.pairs == 0
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.patch_corners, b.patch_corners)
    np.testing.assert_array_equal(a.patch_material, b.patch_material)


# -- the room: solved in the sun ------------------------------------------------------------------
def _drawn_samples(sol, k: int = 6):
    """(points (n, 3), normals (n, 3), radiance (n,)) spread over the drawn Gouraud field."""
    dm = sol.drawn_mesh()
    rad = dm.radiance(sol.vert_radiance).mean(axis=1)
    P = dm.position[dm.triangles]
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    ok = i + j < k
    b1, b2 = (i[ok] + 1 / 3) / k, (j[ok] + 1 / 3) / k
    w = np.stack([1 - b1 - b2, b1, b2], axis=1)
    pts = np.einsum("sk,tkc->tsc", w, P).reshape(-1, 3)
    r = np.einsum("sk,tk->ts", w, rad[dm.triangles]).reshape(-1)
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return pts, np.repeat(n, len(w), axis=0), r


def _room_figures(path: Path, cut) -> dict:
    scene = load_scene(path, cut=cut)
    scene.lights = [Light(kind="directional", direction=SUN, intensity=1000.0)]
    sol = solve(scene, SolveOptions(max_depth=4))
    x, n, r = _drawn_samples(sol)
    room_side = np.zeros(len(x), bool)
    for axis, level, sign in ((2, 0.0, 1), (2, WZ, -1), (0, 0.0, 1), (0, LX, -1)):
        room_side |= (np.abs(x[:, axis] - level) < 1e-6) & (n[:, axis] * sign > 0.9)
    inside = (x[:, 0] > 0) & (x[:, 0] < LX) & (x[:, 2] > 0) & (x[:, 2] < WZ)
    room_side &= (x[:, 0] > -1e-6) & (x[:, 0] < LX + 1e-6) & (x[:, 2] > -1e-6) & (x[:, 2] < WZ + 1e-6)
    ceiling = inside & (n[:, 1] < -0.9) & (np.abs(x[:, 1] - H) < 1e-6)
    band = room_side & (x[:, 1] < H) & (x[:, 1] > H - 0.25)
    return {
        "scene": scene,
        "solution": sol,
        "band": r[band].mean(),
        "band_max": r[band].max(),
        "below": r[room_side & (x[:, 1] < H)].max(),
        "ceiling": r[ceiling].max() if ceiling.any() else 0.0,
        "above": r[room_side & (x[:, 1] > H + SLAB)].mean(),
    }


def test_a_wall_through_a_sunlit_slab_leaks_whole_and_not_cut(room):
    """Whole, the walls' room sides glow in a band under the ceiling (their elements interpolate
    the sunlit vertices above the slab); cut, the room is dark, as in the building (a path tracer's
    room is black: nothing reaches it)."""
    whole, cut = _room_figures(room, False), _room_figures(room, True)
    for f in (whole, cut):  # the walls above the slab are in the sun either way
        assert f["above"] > 30.0
    # the reference: Mitsuba, both sides of every surface reflecting, looking at a wall's room side
    # just under the ceiling: black
    pytest.importorskip("mitsuba")
    from iat.camera import Camera
    from iat.measure.reference import render_reference

    scene = load_scene(room, cut=False)
    scene.lights = [Light(kind="directional", direction=SUN, intensity=1000.0)]
    eye, target = (LX / 2, 1.2, WZ / 2), (LX / 2, H - 0.1, 0.0)
    camera = Camera(eye=eye, target=target, yfov=50.0)
    ref = render_reference(scene, camera, (48, 32), spp=16, two_sided=True)
    assert ref.max() <= 1e-9 * cut["above"]
    outside = Camera(eye=(LX / 2, H + UP + 3.0, -4.0), target=(LX / 2, H, WZ / 2), yfov=50.0)
    assert render_reference(scene, outside, (48, 32), spp=4, two_sided=True).mean() > 10.0  # the sun is on
    assert whole["band"] > 1e-3 * whole["above"]  # the leak (measured 0.094 of 54.6)
    assert cut["below"] <= ref.max() + 1e-9 * cut["above"]  # no direct sun, nothing carried below
    assert cut["band_max"] <= cut["ceiling"] + 1e-12 * cut["above"]
    # as drawn: mesh mode, and IAT mode all textured (threshold 0) and all mesh part (9)
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.render.renderer import Renderer

    with Renderer() as r:
        for f, leaks in ((whole, True), (cut, False)):
            r.set_solution(f["solution"])
            images = [r.render(camera, (48, 32), mode="mesh")]
            for threshold in (0, 9):
                r.set_baked(Baker(f["solution"], f["scene"]).bake(BakePolicy(threshold=threshold)))
                images.append(r.render(camera, (48, 32), mode="iat"))
            assert r.ctx.error == "GL_NO_ERROR"
            for img in images:  # the wall under the ceiling: lit whole (0.125 measured), black cut
                assert (np.abs(img - ref).max() > 1e-3 * f["above"]) == leaks


def test_a_slab_ending_on_the_walls_faces_is_cut_with_contacts(tmp_path):
    """The slab bounded by the walls' room sides touches them and crosses nothing: ``crossings``
    leaves the walls whole (the leak stays), ``all`` cuts them along the slab resting on them."""
    path = write_room(tmp_path / "bounded.obj", slab_into_walls=False)
    plain, contacts = load_scene(path), load_scene(path, cut="all")
    assert plain.pierce.pairs == 0 and plain.pierce.faces_cut == 0
    assert contacts.pierce.contacts > 0 and contacts.pierce.faces_cut > 0
    assert contacts.pierce.joined_regions == 0
    for scene, straddle in ((plain, True), (contacts, False)):
        spans = np.zeros(scene.n_patches, bool)
        for level in (H, H + SLAB):
            spans[_straddling(scene, 1, level)] = True
        assert (spans & _room_side_patches(scene)).any() == straddle
    whole, cut = _room_figures(path, "crossings"), _room_figures(path, "all")
    assert whole["band"] > 1e-3 * whole["above"]
    assert cut["below"] <= 1e-9 * cut["above"]


def test_auto_cuts_contacts_of_a_model_taken_as_built(tmp_path, capsys):
    """``cut="auto"`` (the default) is ``all`` under ``sides="both"`` (and for IFC) and ``crossings``
    for the rest, and ``iat info`` says which it did."""
    import json

    from iat.cli.commands import main

    path = write_room(tmp_path / "bounded.obj", slab_into_walls=False)
    assert load_scene(path).pierce.mode == "crossings"
    built = load_scene(path, sides="both")
    assert built.pierce.mode == "all" and built.pierce.faces_cut > 0
    assert built.n_patches == load_scene(path, sides="both", cut="all").n_patches
    for sides, mode in (("auto", "crossings"), ("both", "all")):
        assert main(["info", str(path), "--sides", sides, "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["cut"] == mode


def test_bad_cut_option_is_an_option_error(room):
    from iat.errors import OptionError

    with pytest.raises(OptionError, match="cut must be one of auto, crossings, all, none"):
        load_scene(room, cut="some")


# -- a real file ----------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.skipif(not MADRID.is_file(), reason=f"{MADRID} not found")
def test_madrid_house_faces_cut():
    """Revit 2021's furnished house: what pierces what (measured once: docs/benchmarks.md)."""
    pytest.importorskip("ifcopenshell")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(MADRID, cut="crossings")
    rep = scene.pierce
    # the window elements (stone) pass through the plastered wall they sit in: its faces are cut
    # (cut="all" also along contacts: 45 objects, 401 faces cut into 3 539 pieces)
    assert rep.mode == "crossings"
    assert (rep.pairs, rep.objects, rep.faces_cut, rep.pieces, rep.joined_regions) == (154, 10, 132, 1316, 0)
