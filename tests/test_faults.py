"""Show the user what is wrong with a model (issue 36): which patches carry the faults the loader
found (:mod:`iat.geometry.faults`), tinted in the rendered view (:mod:`iat.render.fault_tint`) and by
``iat render --faults`` (:mod:`iat.cli.faults`). The cases are the generated buildings of
tests/test_real_daylight.py, one fault each, and the walls through a slab of tests/test_pierce.py."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from iat.camera import Camera
from iat.geometry.faults import (
    COINCIDENT,
    COLORS,
    CROSSING,
    INSIDE_OUT,
    OPEN_SHEET,
    fault_counts,
    patch_faults,
)
from iat.io.load import load_scene
from tests.test_pierce import write_room
from tests.test_real_daylight import CEILING, FLOOR, GROUND_MAT, SOFA, WALL, H, write_case

ROOT = Path(__file__).resolve().parents[1]
MADRID = ROOT.parent / "shared" / "real-models" / "revit2021-madrid-house.ifc"
#: inside the room, looking up at the roof and the north-west corner
INSIDE = Camera(eye=[3.2, 1.2, 4.2], target=[1.0, 2.4, 0.8], yfov=80.0, znear=0.05, zfar=100.0)


def _load(folder: Path, case: str, sides: str = "auto"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the dropped repeats' warning (counted in Scene.sides)
        return load_scene(write_case(case, folder), sides=sides)


def _material(scene) -> np.ndarray:
    """(P,) the patches' material names."""
    return np.array([scene.materials[m].name for m in scene.patch_material])


def _centre(scene) -> np.ndarray:
    c = scene.corner_positions
    return np.where(scene.patch_is_quad[:, None], c.mean(axis=1), c[:, :3].mean(axis=1))


def test_a_tidy_building_has_no_fault(tmp_path):
    scene = _load(tmp_path, "tidy")
    assert scene.faults is not None and len(scene.faults.kinds) == 0
    assert not patch_faults(scene).any()


def test_the_inside_out_roof_is_marked_and_the_sheets_given_backs(tmp_path):
    """``both``: the roof slab (a closed box facing in) turned outward, every other sheet two-sided."""
    scene = _load(tmp_path, "inside_out_ceiling", sides="both")
    bits = patch_faults(scene)
    slab = (_material(scene) == CEILING) & (_centre(scene)[:, 1] >= H - 1e-9)
    assert slab.sum() == 6 and scene.sides.flipped_faces > 0
    np.testing.assert_array_equal(bits & INSIDE_OUT > 0, slab)
    np.testing.assert_array_equal(bits & OPEN_SHEET > 0, ~slab)  # a closed solid gets no back
    assert not (bits & (CROSSING | COINCIDENT)).any()
    assert fault_counts(bits) == {
        "inside_out": 6,
        "open_sheet": scene.n_patches - 6,
        "crossing": 0,
        "coincident": 0,
    }


def test_the_open_sheet_sofa_and_its_backs_are_marked(tmp_path):
    auto, both = _load(tmp_path, "open_sheet_sofa"), _load(tmp_path, "open_sheet_sofa", sides="both")
    assert not patch_faults(auto).any()  # an OBJ is one-sided by convention: nothing given a back
    bits = patch_faults(both)
    sofa = _material(both) == SOFA
    assert sofa.sum() == 4  # two sheets and their twins
    assert (bits == OPEN_SHEET).all() and both.n_patches == 2 * auto.n_patches


def test_the_repeated_floor_is_marked_coincident(tmp_path):
    """The floor written twice: the repeat dropped, the kept floor marked; the cladding over the north
    wall (coplanar, overlapping, other corners) is not found."""
    scene = _load(tmp_path, "coincident_faces")
    bits = patch_faults(scene)
    floor = (_material(scene) == FLOOR) & (np.abs(_centre(scene)[:, 1]) < 1e-9)
    assert floor.sum() == 1 and scene.sides.coincident_faces == 0  # (counted before the drop: none left)
    np.testing.assert_array_equal(bits, np.where(floor, COINCIDENT, 0))


def test_the_walls_through_the_roof_and_the_roof_are_marked_cut(tmp_path):
    scene = _load(tmp_path, "wall_through_slab")
    bits = patch_faults(scene)
    mat, top = _material(scene), scene.corner_positions[:, :, 1].max(axis=1)
    # the roof and the walls (above it and below it) but the south wall's parts under the roof
    np.testing.assert_array_equal(bits > 0, (mat == CEILING) | ((mat == WALL) & (top > H - 1e-9)))
    assert ((mat == WALL) & (top < H)).sum() == 3
    assert (bits[bits > 0] == CROSSING).all()
    # the walls of tests/test_pierce.py: both sides of the slab are cut, the floor is not
    room = load_scene(write_room(tmp_path / "room.obj"))
    rb, rm = patch_faults(room), _material(room)
    assert (rb[rm == "floor"] == 0).all() and (rb[np.char.startswith(rm, "wall")] == CROSSING).any()
    level = np.abs(room.patch_normal[:, 1]) > 0.99
    assert (rb[(rm == "slab") & level] == CROSSING).all() and room.pierce.faces_cut > 0  # its top and bottom


def test_no_cut_and_front_mark_nothing_of_those_kinds(tmp_path):
    path = write_case("wall_through_slab", tmp_path)
    assert not patch_faults(load_scene(path, cut="none")).any()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(write_case("inside_out_ceiling", tmp_path), sides="front")
    assert scene.sides.inside_out == 1 and not patch_faults(scene).any()


# -- the tint in the rendered view ---------------------------------------------------------------
def _materials_seen(scene, preview: np.ndarray) -> np.ndarray:
    """(h, w) the material drawn at each pixel of a preview (-1: none, or a silhouette's pixel whose
    3 x 3 neighbourhood holds another): preview colours are 0.5 x albedo (to float rounding)."""
    colors = np.array([0.5 * m.albedo for m in scene.materials])
    d = np.abs(preview[:, :, None, :] - colors[None, None]).max(axis=-1)
    label = np.where(d.min(axis=-1) < 1e-5, d.argmin(axis=-1), -1)
    same = np.ones(label.shape, dtype=bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            same &= np.roll(label, (dy, dx), axis=(0, 1)) == label
    same[[0, -1]], same[:, [0, -1]] = False, False
    return np.where(same, label, -1)


@pytest.fixture(scope="module")
def cut_room(tmp_path_factory):
    """The walls through the roof, with the default daylight, solved and baked at draft quality."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions, solve
    from tests.test_real_daylight import load_case

    scene = load_case(write_case("wall_through_slab", tmp_path_factory.mktemp("tint")), sides="auto")
    sol = solve(scene, SolveOptions.preset("draft"))
    return scene, sol, Baker(sol, scene).bake(BakePolicy())


def test_faulty_patches_carry_the_tint_in_preview_mesh_and_iat_mode(egl_ctx, cut_room):
    """Tint at full strength: a pixel of a wall or the roof (the cut patches) is the crossing colour
    exactly, every other pixel is the mode's own; at 0.6 the tint is mixed in exactly."""
    from iat.render.fault_tint import FaultTint
    from iat.render.renderer import Renderer

    scene, sol, baked = cut_room
    size = (96, 72)
    red = np.float32(COLORS["crossing"])
    r = Renderer(egl_ctx)
    try:
        r.set_scene(scene)
        r.set_solution(sol)
        r.set_baked(baked)
        preview = r.render(INSIDE, size, mode="preview")
        names = np.array([m.name for m in scene.materials] + [""])
        seen = names[_materials_seen(scene, preview)]  # (-1: the last, "")
        faulty, clean = np.isin(seen, [WALL, CEILING]), np.isin(seen, [FLOOR, GROUND_MAT])
        assert faulty.mean() > 0.3 and clean.mean() > 0.04
        tint = FaultTint(egl_ctx)
        tint.set_scene(scene)
        for mode in ("preview", "mesh", "iat"):
            base = r.render(INSIDE, size, mode=mode)
            assert base[clean].max() > 0  # the floor is lit
            r.overlays.append(tint)
            try:
                tint.alpha = 1.0
                full = r.render(INSIDE, size, mode=mode)
                tint.alpha = 0.6
                mixed = r.render(INSIDE, size, mode=mode)
                tint.enabled = False
                off = r.render(INSIDE, size, mode=mode)
                tint.enabled = True
            finally:
                r.overlays.remove(tint)
            assert (full[faulty] == red).all(), mode
            np.testing.assert_array_equal(full[clean], base[clean])
            np.testing.assert_allclose(mixed[faulty], 0.4 * base[faulty] + 0.6 * red, rtol=1e-6, atol=1e-6)
            np.testing.assert_array_equal(off, base)
        tint.shown = OPEN_SHEET | INSIDE_OUT  # the crossing kind unticked: nothing is tinted
        r.overlays.append(tint)
        np.testing.assert_array_equal(r.render(INSIDE, size, mode="iat"), base)
        tint.release()
    finally:
        r.release()


def test_render_faults_cli_writes_the_tinted_view_with_a_legend(tmp_path):
    from PIL import Image

    from iat.cli.commands import main
    from iat.color import srgb_encode

    path = write_case("wall_through_slab", tmp_path)
    out = tmp_path / "faults.png"
    args = [
        "render",
        str(path),
        "--faults",
        "--mode",
        "mesh",
        "--no-daylight",
        "--quality",
        "draft",
        "-o",
        str(out),
    ]
    assert (
        main(args + ["--eye", "3.2,1.2,4.2", "--target", "1.0,2.4,0.8", "--fov", "80", "--size", "320x240"])
        == 0
    )
    got = np.asarray(Image.open(out).convert("RGB")).astype(int)
    # no light: the surfaces are black, the cut ones show 0.6 x the crossing colour
    want = np.round(srgb_encode(0.6 * np.asarray(COLORS["crossing"])) * 255)
    assert (np.abs(got - want).max(axis=-1) <= 1).mean() > 0.25
    legend = got[:20, :60]  # its first row: the inside-out swatch
    assert (np.abs(legend - np.round(srgb_encode(np.asarray(COLORS["inside_out"])) * 255)).max(-1) <= 1).any()


# -- a real file ----------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.skipif(not MADRID.is_file(), reason=f"{MADRID} not found")
def test_madrid_house_faulty_patches():
    """Revit 2021's furnished house: its 10 open sheets (9 windows and a door) with their backs, the
    wall faces the windows cross and the faces other elements rest on (the default cut, ``auto``, is
    ``all`` for an IFC; measured: docs/stability.md; a rectangle between two cuts is one quad)."""
    pytest.importorskip("ifcopenshell")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(MADRID)
    counts = fault_counts(patch_faults(scene))
    assert counts == {"inside_out": 0, "open_sheet": 16982, "crossing": 812, "coincident": 0}
    assert counts["open_sheet"] >= 2 * scene.sides.twin_patches
