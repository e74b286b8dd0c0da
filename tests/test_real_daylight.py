"""Issue 36: small generated buildings, one fault each, by daylight, IAT mode against Mitsuba 3
references whose BSDFs reflect on both sides (the building as built).

Each case is an OBJ written here (:func:`write_case`) and loaded as a real-tool model is:
``load_scene(path, sides="both")`` (every format treated as IFC: inside-out solids turned outward,
open sheets given a back face, faces repeating another dropped), lit by the default daylight at
its default place (:func:`iat.lighting.daylight_default.apply_daylight`: Paris, 10:00 on the
equinox after :data:`TODAY`, the sun and a clear Preetham sky). The reference is the file as it
is (``sides="front"``: no face turned, none added) rendered by Mitsuba with two-sided diffuse
BSDFs, as two half references of other seeds (their difference measures the reference's noise),
cached under ``tests/refs/`` (``pytest --regen-refs`` renders them again).

The building is a 4 x 5 x 2.7 m room of one-sided sheets facing inward (each gets a back face, so
its outside is lit and reflects), with a 2 x 1.4 m window in the south wall (+Z), standing in a
ground of albedo 0.2. The faults:

- ``tidy``: nothing wrong (the control);
- ``inside_out_ceiling``: the roof is a 25 cm slab, a closed box whose every face points inward;
- ``open_sheet_sofa``: a sofa in the sun patch made of two sheets, written facing away from the
  room (the seat's front faces down, the backrest's towards the north wall): their lit sides are
  the back faces the loader adds;
- ``wall_through_slab``: the walls rise 1.2 m above the roof, which overhangs them by 30 cm (it
  crosses them): each wall patch stands in the sun above the roof and in the room below it;
- ``coincident_faces``: the floor written twice (a finish on the slab, same faces) and a cladding
  panel on the north wall, coplanar with it and overlapping it;
- ``near_white``: walls, floor and ceiling of albedo 0.97;
- ``no_ground``: the tidy room with no ground around it (black below the horizon);
- ``slab_ends_on_wall``: as ``wall_through_slab`` but the roof ends on the walls' inner faces (a
  contact: the loader's default cut takes contacts too for a model taken as built, ``sides="both"``).

Loaded as ``iat solve`` does at the defaults, the sun the default daylight adds is cut along too
(:func:`load_case`).

The measure (:func:`view_figures`): the IAT image box-filtered as Mitsuba's pixels are, compared on
the pixels wholly on the model that Mitsuba lights (luminance above 2 % of the view's 99th
percentile): mean relative error of the luminance, the share of them IAT leaves black (under 1 % of
the view's mean), bias and 8 x 8 block error. ``benchmarks/real_daylight.py`` runs the same
measure on more views, at every preset, and on the Madrid house.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np
import pytest

from iat.camera import Camera
from iat.color import LUMINANCE_WEIGHTS

REFS = Path(__file__).parent / "refs"
#: the day the default daylight is chosen from (its coming equinox: 2027-03-20, 10:00)
TODAY = datetime.date(2026, 12, 6)
W, D, H = 4.0, 5.0, 2.7
WINDOW = (1.0, 3.0, 0.8, 2.2)  # x0, x1, y0, y1 in the south wall z = D
GROUND = 20.0  # the ground reaches this far from the building (metres)
FLOOR, CEILING, WALL, GROUND_MAT, SOFA = "floor", "ceiling", "wall", "ground", "sofa"
ALBEDO = {
    FLOOR: (0.5, 0.45, 0.4),
    CEILING: (0.8, 0.8, 0.8),
    WALL: (0.7, 0.7, 0.7),
    GROUND_MAT: (0.2, 0.2, 0.2),
    SOFA: (0.35, 0.3, 0.5),
}
CASES = (
    "tidy",
    "inside_out_ceiling",
    "open_sheet_sofa",
    "coincident_faces",
    "near_white",
    "no_ground",
    "slab_ends_on_wall",
    "wall_through_slab",
)
#: the views: towards the sunlit floor and the west and north walls; up at the ceiling and north wall
VIEWS = {
    "floor": Camera(eye=[3.5, 1.6, 4.6], target=[0.8, 0.9, 0.8], yfov=75.0, znear=0.05, zfar=100.0),
    "ceiling": Camera(eye=[2.0, 1.4, 4.6], target=[1.6, 2.5, 0.5], yfov=75.0, znear=0.05, zfar=100.0),
}
#: the tests' image and reference: 64 x 48 pixels, 2 x 1024 samples
TEST_SIZE = (64, 48)
TEST_SPP = 1024
#: side of the blocks the relative error is taken on (pixels): a 1024-spp reference of these rooms
#: carries ~6 % of noise per pixel (the light bounced off the sun patch reaches a path only by chance),
#: ~1.5 % on 4 x 4 blocks
COARSE = 4
#: the issue's bounds (IAT mode)
BOUND_DEFAULT, BOUND_FINE, BOUND_BLACK = 0.10, 0.05, 0.01


# -- the buildings -----------------------------------------------------------------------------------
def rect(axis: int, value: float, a: tuple, b: tuple, facing: int) -> np.ndarray:
    """(4, 3) corners of the axis-aligned rectangle ``coordinate[axis] = value`` over ``a`` x ``b``
    (ranges of the two other axes, in x, y, z order), counter-clockwise seen from the ``facing``
    (+1 / -1) side of the axis."""
    u, v = [k for k in range(3) if k != axis]
    q = np.zeros((4, 3))
    q[:, axis] = value
    q[:, u] = [a[0], a[1], a[1], a[0]]
    q[:, v] = [b[0], b[0], b[1], b[1]]
    n = np.cross(q[1] - q[0], q[2] - q[0])
    return q if n[axis] * facing > 0 else q[::-1].copy()


def box(lo, hi, inward: bool = False) -> list[np.ndarray]:
    """The six faces of an axis-aligned box, facing out (or in: a solid written inside out)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    s = -1 if inward else 1
    out = []
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        a, b = (lo[u], hi[u]), (lo[v], hi[v])
        out += [rect(axis, lo[axis], a, b, -s), rect(axis, hi[axis], a, b, s)]
    return out


def walls(top: float) -> list[np.ndarray]:
    """The four walls from the floor to ``top``, facing the room, the window cut from the south one."""
    x0, x1, y0, y1 = WINDOW
    out = [
        rect(0, 0.0, (0, top), (0, D), +1),
        rect(0, W, (0, top), (0, D), -1),
        rect(2, 0.0, (0, W), (0, top), +1),
    ]
    for xa, xb, ya, yb in [(0, W, 0, y0), (0, W, y1, top), (0, x0, y0, y1), (x1, W, y0, y1)]:
        out.append(rect(2, D, (xa, xb), (ya, yb), -1))
    return out


def ground() -> list[np.ndarray]:
    """A frame of four rectangles around the footprint, facing up (no face under the building)."""
    g = GROUND
    return [
        rect(1, 0.0, (-g, W + g), (-g, 0), +1),
        rect(1, 0.0, (-g, W + g), (D, D + g), +1),
        rect(1, 0.0, (-g, 0), (0, D), +1),
        rect(1, 0.0, (W, W + g), (0, D), +1),
    ]


def case_objects(name: str) -> list[tuple[str, str, list[np.ndarray]]]:
    """``[(object, material, polygons)]`` of a case (:data:`CASES`)."""
    floor = [rect(1, 0.0, (0, W), (0, D), +1)]
    ceiling = [rect(1, H, (0, W), (0, D), -1)]
    room = [("floor", FLOOR, floor), ("ceiling", CEILING, ceiling), ("walls", WALL, walls(H))]
    objs = room + [("ground", GROUND_MAT, ground())]
    if name == "tidy":
        return objs
    if name == "no_ground":
        return room
    if name == "inside_out_ceiling":
        slab = box([0, H, 0], [W, H + 0.25, D], inward=True)
        return [room[0], ("slab", CEILING, slab), room[2], objs[-1]]
    if name == "open_sheet_sofa":
        seat = rect(1, 0.45, (0.6, 2.4), (3.0, 3.8), -1)  # written facing down
        back = rect(2, 3.0, (0.6, 2.4), (0.45, 1.0), -1)  # written facing the north wall
        return objs + [("sofa", SOFA, [seat, back])]
    if name == "wall_through_slab":  # the roof overhangs by 30 cm: it crosses the walls
        roof = [rect(1, H, (-0.3, W + 0.3), (-0.3, D + 0.3), -1)]
        return [room[0], ("roof", CEILING, roof), ("walls", WALL, walls(H + 1.2)), objs[-1]]
    if name == "slab_ends_on_wall":  # the roof ends on the walls' faces: touching, not crossing
        return [room[0], ("roof", CEILING, ceiling), ("walls", WALL, walls(H + 1.2)), objs[-1]]
    if name == "coincident_faces":
        cladding = rect(2, 0.0, (0.5, 3.5), (0.3, 2.4), +1)
        return objs + [("finish", FLOOR, [f.copy() for f in floor]), ("cladding", WALL, [cladding])]
    if name == "near_white":
        return [(o, m if m == GROUND_MAT else "white", p) for o, m, p in objs]
    raise KeyError(f"unknown case {name!r} (choose from {', '.join(CASES)})")


def write_case(name: str, folder: Path) -> Path:
    """Write case ``name`` as ``folder/<name>.obj`` (+ ``.mtl``); returns the OBJ's path."""
    folder.mkdir(parents=True, exist_ok=True)
    objs = case_objects(name)
    albedo = {**ALBEDO, "white": (0.97, 0.97, 0.97)}
    mats = sorted({m for _, m, _ in objs})
    mtl = "".join(f"newmtl {m}\nKd {albedo[m][0]} {albedo[m][1]} {albedo[m][2]}\n\n" for m in mats)
    (folder / f"{name}.mtl").write_text(mtl)
    lines, n = [f"mtllib {name}.mtl"], 0
    for obj, mat, polys in objs:
        lines += [f"o {obj}", f"usemtl {mat}"]
        for p in polys:
            lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in p]
            lines.append("f " + " ".join(str(n + k + 1) for k in range(len(p))))
            n += len(p)
    path = folder / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def load_case(path: Path, sides: str = "both"):
    """The case's scene as loaded (``sides``), with the default daylight of :data:`TODAY`; as the
    solve at the defaults takes it (``sides`` other than ``"front"``), its sun's shadows cut
    (:func:`iat.geometry.discontinuity.cut_new_lights`, as ``iat solve`` does)."""
    import warnings

    from iat.geometry.discontinuity import cut_new_lights
    from iat.io.load import load_scene
    from iat.lighting.daylight_default import apply_daylight

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the dropped repeated faces are counted in scene.sides
        scene = load_scene(path, sides=sides)
    apply_daylight(scene, today=TODAY)
    return scene if sides == "front" else cut_new_lights(scene)


# -- the measure -------------------------------------------------------------------------------------
def reference(scene, camera, size, spp, cache_dir):
    """``(image, half_difference)``: the two-sided Mitsuba reference of ``scene`` (load it with
    ``sides="front"``: as the file is) at ``spp`` samples, the mean of two halves of seeds 1 and 2,
    and ``(h, w)`` half the halves' luminance difference (the mean's noise, about)."""
    from iat.measure.reference import render_reference_cached

    halves = [
        render_reference_cached(scene, camera, size, spp // 2, cache_dir, seed=s, two_sided=True)
        for s in (1, 2)
    ]
    ya, yb = (h.astype(np.float64) @ LUMINANCE_WEIGHTS for h in halves)
    return (halves[0].astype(np.float64) + halves[1]) / 2, (ya - yb) / 2


def iat_image(renderer, scene, baked, camera, size):
    """``(image, surface)``: IAT mode box-filtered as Mitsuba's pixels are, and (h, w) bool the pixels
    wholly on the model (no sky)."""
    from iat.measure.reference import SUPERSAMPLE, box_filtered_render

    w, h, k = size[0], size[1], SUPERSAMPLE
    renderer.set_scene(scene)
    renderer.set_baked(baked)
    img = box_filtered_render(renderer, camera, size, "iat")
    covered = renderer.render(camera, (w * k, h * k), mode="preview").max(axis=-1) > 0
    return img, covered.reshape(h, k, w, k).all(axis=(1, 3))


def _blocks(a: np.ndarray, k: int) -> np.ndarray:
    """(h // k, w // k) means of k x k blocks of an (h, w) array."""
    h, w = a.shape[0] // k, a.shape[1] // k
    return a[: h * k, : w * k].reshape(h, k, w, k).mean(axis=(1, 3))


def view_figures(img, ref, surface, half_diff=None) -> dict:
    """The measure of one view (all on Rec. 709 luminance).

    ``rel_error``: mean |L_iat - L_ref| / L_ref over the lit pixels of the image taken in
    :data:`COARSE` x :data:`COARSE` blocks (both images are box-filtered, so this is the image
    rendered that much smaller: edges fall alike, and the reference's noise drops by the block's
    side); a block counts when wholly on the model and above 2 % of the view's 99th percentile.
    ``rel_error_px``: the same per pixel (the reference's noise included). ``black``: the share of
    the lit pixels (per pixel, same rule) IAT leaves under 1 % of the view's mean. ``bias``: mean over
    the lit pixels against the reference's, minus 1. ``ref_noise`` / ``ref_noise_px``: the
    reference's own relative noise on the blocks / pixels (from the halves' difference)."""
    yr, yi = ref @ LUMINANCE_WEIGHTS, img @ LUMINANCE_WEIGHTS
    if not surface.any():
        raise ValueError("the view holds no surface")
    lit = surface & (yr > 0.02 * np.percentile(yr[surface], 99))
    mean = float(yr[surface].mean())
    br, bi = _blocks(yr, COARSE), _blocks(yi, COARSE)
    bs = _blocks(surface.astype(np.float64), COARSE) == 1.0
    blit = bs & (br > 0.02 * np.percentile(br[bs], 99)) if bs.any() else bs
    out = {
        "rel_error": float((np.abs(bi - br)[blit] / br[blit]).mean()) if blit.any() else float("nan"),
        "rel_error_px": float((np.abs(yi - yr)[lit] / yr[lit]).mean()),
        "black": float((yi[lit] < 0.01 * mean).mean()),
        "bias": float(yi[lit].mean() / yr[lit].mean() - 1.0),
        "lit": int(lit.sum()),
        "lit_blocks": int(blit.sum()),
        "surface": float(surface.mean()),
    }
    if half_diff is not None:
        out["ref_noise"] = float((np.abs(_blocks(half_diff, COARSE))[blit] / br[blit]).mean())
        out["ref_noise_px"] = float((np.abs(half_diff)[lit] / yr[lit]).mean())
    return out


def solve_and_bake(scene, quality: str):
    """``(solution, baked)`` at a ``--quality`` preset, baked with the default policy."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions, solve

    sol = solve(scene, SolveOptions.preset(quality))
    return sol, Baker(sol, scene).bake(BakePolicy())


# -- the tests ---------------------------------------------------------------------------------------
#: cases whose figures at the defaults were outside the issue's bounds when last measured
#: (docs/benchmarks.md, "Real and generated buildings by daylight against Mitsuba")
KNOWN_SHORT: dict[str, str] = {}

_FIGURES: dict[tuple[str, str], dict] = {}


def _figures(case: str, quality: str, egl_ctx, tmp_path_factory) -> dict:
    if (case, quality) not in _FIGURES:
        from iat.render.renderer import Renderer

        folder = tmp_path_factory.mktemp(case)
        path = write_case(case, folder)
        scene, as_built = load_case(path), load_case(path, sides="front")
        cam = VIEWS["floor"]
        ref, half_diff = reference(as_built, cam, TEST_SIZE, TEST_SPP, REFS)
        sol, baked = solve_and_bake(scene, quality)
        r = Renderer(egl_ctx)
        try:
            img, surface = iat_image(r, scene, baked, cam, TEST_SIZE)
        finally:
            r.release()
        f = view_figures(img, ref, surface, half_diff)
        f["elements"] = int(sol.stats.get("elements", 0) or 0)
        print(f"{case} {quality}: {f}")
        _FIGURES[(case, quality)] = f
    return _FIGURES[(case, quality)]


@pytest.mark.parametrize("case", CASES)
def test_within_the_issue_bounds_at_the_defaults(case, egl_ctx, tmp_path_factory):
    """At the defaults: at most 10 % mean relative error on the lit pixels, at most 1 % of them black."""
    pytest.importorskip("mitsuba")
    if case in KNOWN_SHORT:
        pytest.xfail(KNOWN_SHORT[case])
    f = _figures(case, "default", egl_ctx, tmp_path_factory)
    assert f["lit_blocks"] > 0.5 * (TEST_SIZE[0] // COARSE) * (TEST_SIZE[1] // COARSE)
    assert f["ref_noise"] < 0.025  # the reference is good enough to judge 10 %
    assert f["black"] <= BOUND_BLACK, f
    assert f["rel_error"] <= BOUND_DEFAULT, f


#: cases whose error rose from draft to default to fine when last measured (draft 6.9-7.8 %, default
#: 2.4-4.2 %, fine 2.2-3.8 %)
KNOWN_RISING: dict[str, str] = {}
#: cases above 5 % at fine when last measured
KNOWN_SHORT_FINE: dict[str, str] = {}
#: how much an error may rise from one preset to the next and still count as not rising (the
#: reference's noise on the blocks is ~1.5 %, but common to all presets: the solves differ far less)
RISE_SLACK = 0.005


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
def test_error_does_not_rise_along_the_presets(case, egl_ctx, tmp_path_factory):
    """From draft to default to fine the error does not rise."""
    pytest.importorskip("mitsuba")
    if case in KNOWN_RISING:
        pytest.xfail(KNOWN_RISING[case])
    errs = [_figures(case, q, egl_ctx, tmp_path_factory)["rel_error"] for q in ("draft", "default", "fine")]
    assert errs[1] <= errs[0] + RISE_SLACK and errs[2] <= errs[1] + RISE_SLACK, errs


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
def test_within_five_percent_at_fine(case, egl_ctx, tmp_path_factory):
    """At ``--quality fine``: at most 5 % mean relative error on the lit pixels, at most 1 % black."""
    pytest.importorskip("mitsuba")
    if case in KNOWN_SHORT_FINE:
        pytest.xfail(KNOWN_SHORT_FINE[case])
    f = _figures(case, "fine", egl_ctx, tmp_path_factory)
    assert f["black"] <= BOUND_BLACK, f
    assert f["rel_error"] <= BOUND_FINE, f
