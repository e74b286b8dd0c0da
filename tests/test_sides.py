"""Light received on the side it arrives from (issue 36, the loader's part): inside-out closed
solids turned outward, open sheets given a back face of their own (:mod:`iat.geometry.sides`),
back-to-back twins drawn each from its own side (:mod:`iat.render.renderer`)."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from iat.camera import Camera
from iat.geometry import quadtree as qt
from iat.geometry.sides import (
    add_back_faces,
    classify_sides,
    object_ids,
    twin_patches,
    winding_numbers,
)
from iat.io.glb import GlbBuilder
from iat.io.load import load_scene
from iat.io.scene import Light
from iat.radiosity import SolveOptions, solve

ROOT = Path(__file__).resolve().parents[1]
MADRID = ROOT.parent / "shared" / "real-models" / "revit2021-madrid-house.ifc"
#: the solves here: direct light only at the vertices (black surroundings, no ambient estimate)
OPTS = {"max_depth": 3, "ambient": False, "min_element_size": 0}


def _box(lo, hi, inward: bool) -> list[list[tuple]]:
    """The six quads of an axis-aligned box, corners ordered so that the normals point inward or outward."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    quads = [
        [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
        [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)],
        [(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)],
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],
    ]
    centre = (np.asarray(lo) + np.asarray(hi)) / 2
    out = []
    for q in quads:
        a, b, c = (np.asarray(p, dtype=float) for p in q[:3])
        outward = np.dot(np.cross(b - a, c - a), np.mean(q, axis=0) - centre) > 0
        out.append(q if outward != inward else q[::-1])
    return out


def _write_obj(path: Path, groups: list[tuple[str, str, list]], mtl: dict[str, str]) -> Path:
    """An OBJ of named groups ``(name, material, quads)``, each quad with its own vertices, and its MTL."""
    lines, verts = [f"mtllib {path.stem}.mtl"], []
    for name, mat, quads in groups:
        lines += [f"o {name}", f"usemtl {mat}"]
        for q in quads:
            base = len(verts) + 1
            verts += q
            lines.append("f " + " ".join(str(base + i) for i in range(len(q))))
    text = "\n".join([f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in verts] + lines) + "\n"
    path.write_text(text)
    path.with_suffix(".mtl").write_text("".join(f"newmtl {k}\n{v}\n" for k, v in mtl.items()))
    return path


def _vertex_table(sol, scene):
    """Vertex positions (V, 3), radiance (V, 3) and the normal of each vertex's patch (V, 3)."""
    m = 2 ** int(sol.max_depth) + 1
    patch = np.asarray(sol.vert_key) // (m * m)
    return np.asarray(sol.vert_position), np.asarray(sol.vert_radiance), scene.patch_normal[patch]


def _point(scene, position, intensity=1.0):
    scene.lights = [
        Light(kind="point", position=np.asarray(position, float), color=np.ones(3), intensity=intensity)
    ]
    return scene


# -- an inside-out ceiling -----------------------------------------------------------------
CEIL_ALBEDO = 0.7
LIGHT = (0.0, 1.8, 0.0)


@pytest.fixture(scope="module")
def ceiling_obj(tmp_path_factory) -> Path:
    """A closed 4 x 3 x 4 m room modelled from inside (faces inward: an enclosure, kept), black,
    and a 2 x 2 m ceiling covering 5 cm thick at 2.8-2.85 m, a closed box whose every face
    points inward (inside out), albedo 0.7."""
    d = tmp_path_factory.mktemp("ceiling")
    return _write_obj(
        d / "ceiling.obj",
        [
            ("room", "black", _box((-2, 0, -2), (2, 3, 2), inward=True)),
            ("covering", "plaster", _box((-1, 2.8, -1), (1, 2.85, 1), inward=True)),
        ],
        {"black": "Kd 0 0 0", "plaster": f"Kd {CEIL_ALBEDO} {CEIL_ALBEDO} {CEIL_ALBEDO}"},
    )


def test_inside_out_ceiling_is_turned_outward_and_lit_from_the_room(ceiling_obj):
    """An OBJ is one-sided by convention: ``auto`` counts the inside-out covering and leaves it;
    ``both`` (what ``auto`` does to IFC) turns it outward."""
    underside = {}
    for mode in ("front", "auto", "both"):
        scene = _point(load_scene(ceiling_obj, sides=mode), LIGHT)
        rep = scene.sides
        assert (rep.closed_solids, rep.enclosures, rep.open_sheets) == (2, 1, 0)
        assert rep.inside_out == 1  # the covering (the room holds it: an enclosure, kept)
        assert rep.back_faces == 0 and scene.n_patches == 12  # closed solids get no back face
        sol = solve(scene, SolveOptions(**OPTS))
        pos, rad, nrm = _vertex_table(sol, scene)
        under = np.abs(pos[:, 1] - 2.8) < 1e-9
        room_side = under & (nrm[:, 1] < -0.99)  # the covering's faces at 2.8 m looking down at the room
        underside[mode] = (pos[room_side], rad[room_side, 0])
    # before: the covering's underside faces up into the solid; nothing looks at the room
    assert len(underside["front"][0]) == 0 and len(underside["auto"][0]) == 0
    pos, rad = underside["both"]
    assert len(pos) >= 9
    d = pos - np.asarray(LIGHT)
    r2 = (d * d).sum(axis=1)
    analytic = CEIL_ALBEDO * (d[:, 1] / np.sqrt(r2)) / (np.pi * r2)  # rho I cos / (pi r^2)
    assert np.abs(rad / analytic - 1).max() < 1e-3
    assert rad.max() == pytest.approx(CEIL_ALBEDO / np.pi, rel=1e-3)  # straight above the light, 1 m


def test_info_counts_the_inside_out_solid(ceiling_obj):
    for mode, turned in (("both", 12), ("auto", 0), ("front", 0)):  # all count; both turns it
        out = subprocess.run(
            [sys.executable, "-m", "iat", "info", str(ceiling_obj), "--json", "--sides", mode],
            capture_output=True,
            text=True,
            cwd=ROOT,
            check=True,
        )
        info = json.loads(out.stdout)
        assert info["sides"] == mode
        assert (info["closed_solids"], info["inside_out_solids"], info["enclosures"]) == (2, 1, 1)
        assert (info["open_sheets"], info["back_faces"], info["back_patches"]) == (0, 0, 0)
        assert info["faces_turned"] == turned


# -- an open-sheet sofa ----------------------------------------------------------------
SOFA_ALBEDO = 0.6
SOFA_LIGHT = (-1.5, 0.25, 0.0)


@pytest.fixture(scope="module")
def sofa_obj(tmp_path_factory) -> Path:
    """A 'sofa' of five sheets (an open box, no bottom) whose faces all point into the box, and a
    light outside, 1 m from its -x side: the side the light reaches is the sheets' back."""
    d = tmp_path_factory.mktemp("sofa")
    quads = _box((-0.5, 0.0, -0.5), (0.5, 0.5, 0.5), inward=True)
    quads = [q for q in quads if not all(abs(p[1]) < 1e-12 for p in q)]  # no bottom
    return _write_obj(d / "sofa.obj", [("sofa", "fabric", quads)], {"fabric": f"Kd {SOFA_ALBEDO} 0.3 0.2"})


@pytest.fixture(scope="module")
def sofa_solves(sofa_obj):
    out = {}
    for mode in ("front", "both"):
        scene = _point(load_scene(sofa_obj, sides=mode), SOFA_LIGHT)
        out[mode] = scene, solve(scene, SolveOptions(**OPTS))
    return out


def test_open_sheet_sofa_is_lit_on_the_side_the_light_reaches(sofa_obj, sofa_solves):
    front_scene, front = sofa_solves["front"]
    scene, sol = sofa_solves["both"]
    assert front_scene.n_patches == 5 and scene.n_patches == 10
    assert load_scene(sofa_obj).n_patches == 5  # auto: an OBJ sheet stays one-sided (IFC's would not)
    assert (
        front_scene.sides.open_sheets == 1 and scene.sides.back_faces == 10 and scene.sides.twin_patches == 5
    )
    assert float(np.asarray(front.vert_radiance).max()) == 0.0  # before: black from where the light is
    pos, rad, nrm = _vertex_table(sol, scene)
    lit = (np.abs(pos[:, 0] + 0.5) < 1e-9) & (nrm[:, 0] < -0.99)  # the back of the -x sheet
    assert lit.sum() >= 9
    d = pos[lit] - np.asarray(SOFA_LIGHT)
    r2 = (d * d).sum(axis=1)
    analytic = SOFA_ALBEDO * (d[:, 0] / np.sqrt(r2)) / (np.pi * r2)
    assert np.abs(rad[lit, 0] / analytic - 1).max() < 1e-3
    # the sheets' own fronts, inside the box, see no light
    inside = (np.abs(pos[:, 0] + 0.5) < 1e-9) & (nrm[:, 0] > 0.99)
    assert rad[inside].max() == 0.0


def test_twins_draw_their_own_light_in_mesh_and_iat_mode(sofa_solves):
    """Back-to-back twins z-fight unless back faces are culled for them: seen from the light, the
    sofa's side shows the lit twin's radiance (no black pixels of the unlit front)."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.render.renderer import Renderer

    scene, sol = sofa_solves["both"]
    cam = Camera(
        eye=np.array([-2.0, 0.25, 0.0]), target=np.array([0.0, 0.25, 0.0]), yfov=20.0, znear=0.01, zfar=10
    )
    centre = SOFA_ALBEDO / np.pi
    with Renderer() as r:
        r.set_solution(sol)
        images = {"mesh": r.render(cam, (64, 64), mode="mesh")}
        for th in (0, 9):  # all textured, all mesh part
            baked = Baker(sol, scene).bake(BakePolicy(threshold=th))
            assert baked.patch_twin.sum() == 10
            r.set_baked(baked)
            images[f"iat{th}"] = r.render(cam, (64, 64), mode="iat")
        assert r.ctx.error == "GL_NO_ERROR"
    for name, img in images.items():
        c = img[24:40, 24:40, 0]  # the middle of the -x side (0.25 m of it)
        assert c.min() > 0.93 * centre, name  # cos^3 falloff at the window's corners: 0.94
        assert c.max() <= centre * 1.001, name


# -- the rules, on small arrays ------------------------------------------------------------
def _quad_faces(quads, offset=0):
    F = []
    for k in range(len(quads)):
        b = offset + 4 * k
        F += [[b, b + 1, b + 2], [b, b + 2, b + 3]]
    return np.asarray(F, dtype=np.int64)


def _weld(quads):
    from iat.geometry.mesh import weld_vertices

    V = np.asarray([p for q in quads for p in q], dtype=float)
    return weld_vertices(V, _quad_faces(quads))


def test_classify_rules_on_small_cases():
    # an outward box: closed, nothing to do
    V, F = _weld(_box((0, 0, 0), (1, 1, 1), inward=False))
    s = classify_sides(V, F, np.zeros(len(F), np.int64), np.zeros(len(F), np.int64))
    assert (s.report.closed_solids, s.report.inside_out, s.report.open_sheets, s.back.sum()) == (1, 0, 0, 0)
    # inside out, alone: flipped (the same faces reversed)
    V, F = _weld(_box((0, 0, 0), (1, 1, 1), inward=True))
    s = classify_sides(V, F, np.zeros(len(F), np.int64), np.zeros(len(F), np.int64))
    assert s.report.inside_out == 1 and s.report.flipped_faces == 12
    np.testing.assert_array_equal(s.faces, F[:, ::-1])
    # ... unless it holds a probe (a lamp): a room modelled from inside; IFC solids never are
    lamp = [[0.5, 0.5, 0.5]]
    s = classify_sides(V, F, np.zeros(len(F), np.int64), np.zeros(len(F), np.int64), probes=lamp)
    assert (s.report.enclosures, s.report.inside_out, s.report.flipped_faces) == (1, 0, 0)
    s = classify_sides(
        V, F, np.zeros(len(F), np.int64), np.zeros(len(F), np.int64), probes=lamp, enclosures=False
    )
    assert s.report.inside_out == 1
    # a sheet written with its own back (double-sided wall): closed, flat, paired; no back added
    q = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    V, F = _weld([q, [q[0], q[3], q[2], q[1]]])  # the back split along the same diagonal
    s = classify_sides(V, F, np.zeros(len(F), np.int64), np.zeros(len(F), np.int64))
    assert (s.report.closed_solids, s.report.paired_faces, s.back.sum()) == (0, 4, 0)
    # the two faces as two objects: open sheets, paired, still no back added
    s = classify_sides(V, F, np.repeat([0, 1], 2), np.zeros(len(F), np.int64))
    assert (s.report.open_sheets, s.report.paired_faces, s.back.sum()) == (2, 4, 0)
    # a duplicated face (same orientation) is counted; an emitter or glass gets no back
    V, F = _weld([q, q])
    M = np.asarray([0, 0, 1, 1])
    s = classify_sides(V, F, np.repeat([0, 1], 2), M, one_sided=np.array([False, True]))
    assert s.report.coincident_faces == 4 and s.back.tolist() == [True, True, False, False]
    # glTF: a one-sided sheet stays one-sided unless its material is double-sided (or mode "both")
    kw = {"sheets_two_sided": False, "double_sided": np.array([False, True])}
    s = classify_sides(V, F[:2], np.zeros(2, np.int64), np.array([0, 1]), **kw)
    assert s.back.tolist() == [False, True]
    s = classify_sides(V, F[:2], np.zeros(2, np.int64), np.array([0, 1]), mode="both", **kw)
    assert s.back.tolist() == [True, True]
    assert (
        classify_sides(V, F[:2], np.zeros(2, np.int64), np.zeros(2, np.int64), mode="front").back.sum() == 0
    )


def test_object_ids_and_winding_numbers():
    F = np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6], [7, 8, 9], [9, 8, 4]])
    assert object_ids(F).tolist() == [0, 0, 1, 1, 1]
    V, F = _weld(_box((0, 0, 0), (1, 1, 1), inward=False))
    w = winding_numbers([[0.5, 0.5, 0.5], [2.0, 0.5, 0.5]], V[F])
    np.testing.assert_allclose(w, [1.0, 0.0], atol=1e-9)


def test_back_faces_of_panel_cells_keep_their_clip_triangles(tmp_path):
    """A sheet written as a fan of thin triangles becomes a panel (rectangle cells cut by clip
    triangles); its back is the same cells mirrored: same area, opposite normals, same surface."""
    n = 12
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = [(float(np.cos(a)), 0.0, float(np.sin(a))) for a in ang]
    # a 12-gon disc facing up, as an n-gon (earcut fan), an open sheet
    lines = ["mtllib disc.mtl", "usemtl m"] + [f"v {x} {y} {z}" for x, y, z in ring[::-1]]
    lines.append("f " + " ".join(str(i + 1) for i in range(n)))
    (tmp_path / "disc.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "disc.mtl").write_text("newmtl m\nKd 0.5 0.5 0.5\n")
    front = load_scene(tmp_path / "disc.obj", sides="front")
    scene = load_scene(tmp_path / "disc.obj", sides="both")
    assert front.patch_clipped.any()
    p = front.n_patches
    assert scene.n_patches == 2 * p and scene.sides.twin_patches == p
    np.testing.assert_allclose(scene.patch_area[p:], scene.patch_area[:p], rtol=1e-12)
    np.testing.assert_allclose(scene.patch_normal[p:], -scene.patch_normal[:p], atol=1e-12)
    assert scene.patch_area[p:].sum() == pytest.approx(3.0, rel=1e-9)  # (n / 2) sin(2 pi / n)
    tris = scene.world_triangles()
    tp = scene.world_triangle_patch()
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    assert area[tp >= p].sum() == pytest.approx(area[tp < p].sum(), rel=1e-9)
    assert twin_patches(scene.corner_positions, scene.patch_is_quad).all()
    assert not twin_patches(front.corner_positions, front.patch_is_quad).any()


def test_add_back_faces_reverses_corners_and_swaps_the_lattice():
    C = np.array([[0, 1, 2, 3], [4, 5, 6, -1]])
    uv = np.arange(16, dtype=float).reshape(2, 4, 2)
    clip_uv = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 0.5]]])
    c, m, u, cu, cp = add_back_faces(C, np.array([7, 8]), uv, clip_uv, np.array([0]), np.array([True, True]))
    assert c[2:].tolist() == [[0, 3, 2, 1], [4, 6, 5, -1]] and m.tolist() == [7, 8, 7, 8]
    np.testing.assert_array_equal(u[2], uv[0][[0, 3, 2, 1]])
    assert cp.tolist() == [0, 2]
    np.testing.assert_array_equal(cu[1], [[0.5, 0.0], [0.0, 1.0], [0.0, 0.0]])


# -- glTF: doubleSided, and the sample models unchanged ---------------------------------------------
def test_gltf_double_sided_material_gets_a_back_face(tmp_path):
    g = GlbBuilder()
    one = g.add_material("one", base_color=(0.5, 0.5, 0.5))
    two = g.add_material("two", base_color=(0.5, 0.5, 0.5), double_sided=True)
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    for name, mat, dx in (("a", one, 0.0), ("b", two, 2.0)):
        g.add_node(name, mesh=g.add_mesh(name, quad + [dx, 0, 0], [[0, 1, 2], [2, 3, 0]], material=mat))
    path = g.write(tmp_path / "sheets.glb")
    scene = load_scene(path)
    assert scene.n_patches == 3 and scene.sides.open_sheets == 2 and scene.sides.twin_patches == 1
    assert scene.materials[scene.patch_material[2]].name == "two"
    assert load_scene(path, sides="both").n_patches == 4
    assert load_scene(path, sides="front").n_patches == 2


@pytest.mark.parametrize("name", ["cornell_box", "house", "cave", "lavapit", "pool"])
def test_sample_models_are_left_as_they_are(name):
    """The samples are one-sided by design (glTF, single-sided materials, rooms facing in)."""
    path = ROOT / "sample_models" / f"{name}.glb"
    auto, front = load_scene(path), load_scene(path, sides="front")
    assert auto.sides.flipped_faces == 0 and auto.sides.twin_patches == 0
    np.testing.assert_array_equal(auto.patch_corners, front.patch_corners)
    np.testing.assert_array_equal(auto.vertices, front.vertices)


def test_bad_sides_option_is_an_option_error(sofa_obj):
    from iat.errors import OptionError

    with pytest.raises(OptionError, match="sides must be one of auto, both, front"):
        load_scene(sofa_obj, sides="back")


# -- a real file ----------------------------------------------------------------------------------
@pytest.mark.skipif(not MADRID.is_file(), reason=f"{MADRID} not found")
def test_madrid_house_counts():
    """Revit 2021's furnished house: 9 windows and a door are open sheets (the README's 'windows
    and a door as open sheets'); its furniture, walls and slabs are closed and outward."""
    pytest.importorskip("ifcopenshell")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(MADRID, cut="crossings")  # (the default cuts contacts too: 8 415 twins)
    rep = scene.sides
    assert rep.mode == "auto"
    assert (rep.inside_out, rep.enclosures, rep.open_sheets) == (0, 0, 10)
    assert rep.closed_solids == 286
    assert rep.back_faces == 10742 and rep.twin_patches == 8422
    assert rep.paired_faces == 148 and rep.coincident_faces == 0
    assert twin_patches(scene.corner_positions, scene.patch_is_quad).sum() >= 2 * rep.twin_patches


def test_walls_with_their_own_backs_keep_the_ambient_term(tmp_path):
    """A closed room whose six walls carry a back face each (coincident, facing out): the ambient
    term's rays that meet a back read its twin facing them, so the room's light is the same as
    without the backs (it fell to 0.015 of the ambient share when those rays counted as misses)."""
    room = _box((-1, 0, -1), (1, 2, 1), inward=True)
    out = {}
    for name, groups in (
        ("plain", [("room", "white", room)]),
        ("backs", [("room", "white", room), ("back", "white", [q[::-1] for q in room])]),
    ):
        scene = load_scene(
            _write_obj(tmp_path / f"{name}.obj", groups, {"white": "Kd 0.8 0.8 0.8"}), sides="front"
        )
        scene.lights = [Light(kind="point", position=np.array([0.0, 1.0, 0.0]), intensity=1.0)]
        sol = solve(scene, SolveOptions(max_depth=2, convergence=0.2))
        patch = qt.decode_key(sol.vert_key, sol.n)[0]
        inner = (scene.patch_normal[patch] * (np.array([0.0, 1.0, 0.0]) - sol.vert_position)).sum(1) > 0
        out[name] = (float(sol.vert_radiance[inner, 0].mean()), sol.stats["ambient_luminance_fraction"])
    assert out["backs"][0] == pytest.approx(out["plain"][0], rel=0.01)
    assert out["backs"][1] == pytest.approx(out["plain"][1], rel=0.05) and out["plain"][1] > 0.3


def test_overlap_groups_find_patches_overlapping_in_their_plane():
    """A cladding panel on its wall and a plaque on the panel make one group; the wall's back face
    (the other way), a neighbouring wall sharing an edge, the two triangles of a split quad and a
    panel a hair in front of the wall's plane make none."""
    from iat.geometry.sides import overlap_groups

    def quad(x0, x1, y0, y1, z=0.0, facing=1):
        q = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], dtype=float)
        return q if facing > 0 else q[[0, 3, 2, 1]]

    tri_a = np.array([[10, 0, 0], [12, 0, 0], [12, 2, 0], [12, 2, 0]], dtype=float)
    tri_b = np.array([[10, 0, 0], [12, 2, 0], [10, 2, 0], [10, 2, 0]], dtype=float)
    corners = np.stack(
        [
            quad(0, 4, 0, 3),  # 0 the wall
            quad(0.5, 3.5, 0.3, 2.4),  # 1 the cladding on it
            quad(1, 2, 1, 2),  # 2 a plaque on the cladding
            quad(0, 4, 0, 3, facing=-1),  # 3 the wall's back
            quad(4, 8, 0, 3),  # 4 the next wall, sharing an edge
            tri_a,  # 5, 6 a quad split in two
            tri_b,
            quad(20, 22, 0, 2),  # 7 a wall, and 8 a panel 1 mm in front of it
            quad(20.5, 21.5, 0.5, 1.5, z=0.001),
        ]
    )
    is_quad = np.array([True] * 5 + [False, False, True, True])
    normal = np.tile([0.0, 0.0, 1.0], (9, 1))
    normal[3] = [0.0, 0.0, -1.0]
    got = overlap_groups(corners, is_quad, normal, 1e-5)
    assert got[0] == got[1] == got[2] >= 0
    assert (got[3:] == -1).all()
