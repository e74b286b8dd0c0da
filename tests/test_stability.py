"""The stability catalogue (docs/stability.md): one test per failure mode.

Each test builds the input that provokes the failure mode (tests/stability_scenes.py),
runs what IAT does with it, measures a figure and holds the guarantee the catalogue
states. Figures are recorded with :func:`record` into a JSON file
(``$IAT_STABILITY_JSON``, default ``<pytest basetemp>/stability.json``) and printed,
so the table in docs/stability.md can be refreshed from a run:

    xvfb-run -a -s "-screen 0 1280x800x24" .venv/bin/python -m pytest -q tests/test_stability.py
    IAT_STABILITY_JSON=out/stability.json ...   # to keep the figures

Tests marked ``xfail(strict=True)`` show a defect found while writing the catalogue: they
run (nothing is skipped) and fail as expected today; when the defect is fixed they pass,
strict mode turns that into a failure, and the marker (and the doc's row) must be updated.
None is marked today: the defects found (D1-D10) are fixed and their tests hold the fixes.
Timings are bounds with a wide margin, never comparisons between runs.
"""

from __future__ import annotations

import dataclasses
import errno
import gc
import json
import os
import signal
import subprocess
import sys
import threading
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from iat.bake.atlas import mip_levels
from iat.bake.baker import Baker
from iat.bake.flatten import flatten, sample_tile
from iat.bake.formats import quantise_rgb9e5, quantise_rgba8
from iat.bake.policy import BakePolicy
from iat.camera import Camera
from iat.errors import BakeError, IATError, LoadError, OptionError, RenderError, SolutionFileError
from iat.geometry import quadtree as qt
from iat.io.load import load_scene
from iat.measure.seams import seam_error
from iat.radiosity import Solution, SolveOptions, solve
from iat.radiosity.options import RAY_EPS
from tests import stability_scenes as ss

ROOT = Path(__file__).resolve().parents[1]
CORNELL = ROOT / "sample_models" / "cornell_box.glb"

_SOLVE_FIELDS = {f.name for f in dataclasses.fields(SolveOptions)}


def opts(**kw) -> SolveOptions:
    """SolveOptions pinned for the catalogue, so that its figures measure the geometry, not a default:
    no minimum element size (max_depth is the only limit on refinement) and no ambient term (a
    uniform estimate of the light left unshot, which would light the far side of every wall).
    Fields the solver does not have are left out, so the catalogue follows the solver's API."""
    base = {"min_element_size": 0.0, "ambient": False}
    base.update(kw)
    return SolveOptions(**{k: v for k, v in base.items() if k in _SOLVE_FIELDS})


# -- recording the figures -------------------------------------------------------------------------
_FIGURES: dict[str, dict] = {}


def record(name: str, **values) -> None:
    """Keep the measured figures of one catalogue row (written to JSON at the end of the session)."""
    clean = {}
    for k, v in values.items():
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, float) and not np.isfinite(v):
            v = str(v)
        clean[k] = v
    _FIGURES.setdefault(name, {}).update(clean)
    print(f"[stability] {name}: " + ", ".join(f"{k}={v}" for k, v in clean.items()))


@pytest.fixture(scope="module", autouse=True)
def _write_figures(tmp_path_factory):
    yield
    out = os.environ.get("IAT_STABILITY_JSON") or str(tmp_path_factory.getbasetemp() / "stability.json")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(json.dumps(_FIGURES, indent=1, sort_keys=True))
    print(f"\n[stability] figures written to {out}")


@pytest.fixture(scope="module")
def renderer(egl_ctx):
    from iat.render.renderer import Renderer

    r = Renderer(egl_ctx)
    yield r
    r.release()


def luminance_of(x):
    return np.asarray(x, dtype=np.float64) @ np.array([0.2126, 0.7152, 0.0722])


def _area_weighted_mean(sol: Solution, patches) -> np.ndarray:
    """(3,) area-weighted mean radiance over ``patches`` (leaf-corner means x leaf areas)."""
    f = sol.forest
    corner = qt.lookup(sol.vert_key, qt.leaf_corner_keys(f))
    vals = sol.vert_radiance.astype(np.float64)[corner]
    q = f.leaf_is_quad
    mean = np.where(q[:, None], vals.mean(axis=1), vals[:, :3].mean(axis=1))
    area = qt.leaf_area(f, sol.patch_corners)
    sel = np.isin(f.leaf_patch, np.asarray(patches))
    return (mean[sel] * area[sel, None]).sum(axis=0) / max(area[sel].sum(), 1e-300)


def _direct_point(light, pos, normal, albedo):
    """Unshadowed reflected radiance of a point light at points (n, 3) with normals (n, 3)."""
    d = light.position[None, :] - pos
    r = np.linalg.norm(d, axis=1)
    cos = np.maximum((d * normal).sum(axis=1) / r, 0.0)
    return albedo * float(light.intensity) * cos / (np.pi * r * r)


def _vertex_patch(sol: Solution) -> np.ndarray:
    return qt.decode_key(sol.vert_key, sol.n)[0]


# =================================================================================================
# Geometry
# =================================================================================================
def test_geometry_zero_area_and_sliver_triangles(tmp_path):
    """Zero-area triangles are dropped at load; a 1e-7-wide sliver is kept and lit exactly."""
    V = [
        [0, 0, 0],
        [0, 0, 1],
        [1, 0, 1],
        [1, 0, 0],  # floor quad (y = 0, facing +y)
        [2, 0, 0],
        [2, 0, 1],
        [2, 0, 2],  # collinear
        [3, 0, 0],
        [3, 0, 1],
        [3 + 1e-7, 0, 0.5],
    ]  # sliver: 1 m long, 1e-7 m wide
    F = [[0, 1, 2], [2, 3, 0], [4, 5, 6], [0, 0, 1], [7, 8, 9]]
    path = ss.write_obj(tmp_path / "slivers.obj", V, F)
    scene = load_scene(path)
    assert scene.n_patches == 2  # the quad and the sliver; the collinear and repeated-corner faces dropped
    sliver = int(np.argmin(scene.patch_area))
    assert scene.patch_area[sliver] == pytest.approx(0.5e-7, rel=1e-6)
    scene.lights = [ss.point_light(1.5, 1.0, 0.5, 1.0)]
    sol = solve(scene, opts(max_depth=3))
    rad = sol.vert_radiance.astype(np.float64)
    assert np.isfinite(rad).all() and (rad >= 0).all()
    on = _vertex_patch(sol) == sliver
    expect = _direct_point(scene.lights[0], sol.vert_position[on], np.tile([0, 1.0, 0], (on.sum(), 1)), 0.5)
    rel = float(np.abs(rad[on, 0] - expect).max() / expect.max())
    record(
        "zero_area_sliver",
        dropped_faces=len(F) - 3,  # 5 faces: 2 floor triangles (one quad) and the sliver kept
        sliver_area=float(scene.patch_area[sliver]),
        sliver_max_rel_error=rel,
        sliver_vertices=int(on.sum()),
    )
    assert rel < 1e-3
    # a file of nothing but zero-area faces is an error naming the cause
    bad = ss.write_obj(tmp_path / "only_degenerate.obj", V[4:7], [[0, 1, 2]])
    with pytest.raises(LoadError, match="only degenerate faces"):
        load_scene(bad)


def test_geometry_coplanar_overlapping_faces():
    """Z-fighting: two overlapping coplanar faces neither shadow each other; each gets its exact light."""
    scene = ss.coplanar_overlap()
    sol = solve(scene, opts(max_depth=3))
    p = _vertex_patch(sol)
    albedo = np.where(p == 0, 0.8, 0.2)
    expect = _direct_point(scene.lights[0], sol.vert_position, np.tile([0, 1.0, 0], (len(p), 1)), albedo)
    rel = np.abs(sol.vert_radiance[:, 0] - expect) / expect
    overlap = (sol.vert_position[:, 0] > -0.5) & (sol.vert_position[:, 0] < 0.5)
    record("coplanar_overlap", max_rel_error_overlap=float(rel[overlap].max()))
    assert rel[overlap].max() < 1e-4


def test_geometry_coplanar_overlap_renders_one_face_per_pixel(renderer):
    """In the image, each pixel of the overlap shows one of the two faces (deterministic), never a mix
    or a hole: z-fighting is the model's error, shown, not hidden."""
    scene = ss.coplanar_overlap()
    sol = solve(scene, opts(max_depth=3))
    renderer.set_solution(sol)
    cam = Camera(
        eye=[0.0, 3.0, 0.0], target=[0.0, 0.0, 0.0], up=[0.0, 0.0, -1.0], yfov=40.0, znear=0.1, zfar=10
    )
    img = renderer.render(cam, (96, 96), "mesh")
    again = renderer.render(cam, (96, 96), "mesh")
    # pixel centres of the overlap strip x in (-0.4, 0.4), z in (-0.8, 0.8) (camera looks down -y)
    h = 3.0 * np.tan(np.radians(20.0))
    xs = (np.arange(96) + 0.5) / 96 * 2 * h - h
    zs = (np.arange(96) + 0.5) / 96 * 2 * h - h
    X, Z = np.meshgrid(xs, zs)
    strip = (np.abs(X) < 0.4) & (np.abs(Z) < 0.8)
    light = scene.lights[0]
    pos = np.stack([X[strip], np.zeros(strip.sum()), Z[strip]], axis=1)
    a = _direct_point(light, pos, np.tile([0, 1.0, 0], (len(pos), 1)), 0.8)
    ratio = img[strip, 0].astype(np.float64) / a  # 1 on face a (albedo 0.8), 0.25 on face b (0.2)
    face_a = np.abs(ratio - 1.0) < 0.1
    face_b = np.abs(ratio - 0.25) < 0.1 * 0.25
    record(
        "coplanar_overlap",
        overlap_pixels=int(strip.sum()),
        pixels_face_a=int(face_a.sum()),
        pixels_face_b=int(face_b.sum()),
        worst_pixel_off_both=float(np.minimum(np.abs(ratio - 1.0), np.abs(ratio - 0.25) / 0.25).max()),
    )
    assert np.array_equal(img, again)
    assert (face_a | face_b).all()


def test_geometry_intersecting_wall_leak_is_one_element_wide():
    """A wall through a floor patch: the light leaks past the wall only inside the floor element the
    wall cuts (at most one finest element, edge / 2**D), and the leaked energy is small."""
    out = {}
    for depth in (3, 5):
        scene = ss.wall_through_floor(wall_x=0.1)
        sol = solve(scene, opts(max_depth=depth))
        tile = flatten(sol, [0], "scan")[0]
        # floor corners (-1,0,-1), (-1,0,1), (1,0,1), (1,0,-1): u runs along z, v along x = -1 + 2 v
        n = 2001
        v = np.linspace(0.0, 1.0, n)
        x = -1.0 + 2.0 * v
        vals = np.zeros(n)
        for zu in (0.25, 0.5, 0.75):
            vals = np.maximum(vals, sample_tile(tile, np.full(n, zu), v)[:, 0])
        dark = x > 0.1
        h = 2.0 / (1 << depth)  # finest element edge
        lit_side = np.trapezoid(np.where(~dark, vals, 0.0), x)
        leak = np.trapezoid(np.where(dark, vals, 0.0), x)
        width = float(x[dark & (vals > 0)].max() - 0.1) if (dark & (vals > 0)).any() else 0.0
        out[depth] = (width, h, leak / lit_side)
        record(
            "intersecting_wall_leak",
            **{
                f"D{depth}_leak_width_m": width,
                f"D{depth}_finest_element_m": h,
                f"D{depth}_leak_energy_ratio": leak / lit_side,
            },
        )
        assert width <= h + 1e-9
        assert leak / lit_side < 0.05
        # every floor vertex beyond the wall is exactly dark (the wall shadows it; nothing is interpolated)
        beyond = (_vertex_patch(sol) == 0) & (sol.vert_position[:, 0] > 0.1)
        assert sol.vert_radiance[beyond].max() == 0.0
    assert out[5][0] < out[3][0]  # deeper trees: a narrower leak
    # with the solver's defaults (ambient term on, where the solver has one) the far side is not black:
    # it gets the uniform ambient estimate of the unshot light; measured, not a leak
    sol = solve(ss.wall_through_floor(wall_x=0.1), SolveOptions(max_depth=5))
    beyond = (_vertex_patch(sol) == 0) & (sol.vert_position[:, 0] > 0.2)
    lit = (_vertex_patch(sol) == 0) & (sol.vert_position[:, 0] < 0.0)
    far = float(sol.vert_radiance[beyond, 0].max() / sol.vert_radiance[lit, 0].mean())
    record("intersecting_wall_leak", defaults_far_side_over_lit_mean=far)
    assert np.isfinite(far) and far < 0.05


def test_geometry_t_junctions_between_patches(renderer):
    """A quad edge meeting two half-length quads (a T-junction between roots): no crack in the image,
    and the radiance mismatch along the edge stays below the solve tolerance."""
    scene = ss.t_junction_scene()
    tolerance = 0.05
    sol = solve(scene, opts(max_depth=4, tolerance=tolerance))
    tiles = flatten(sol, None, "scan")
    z = np.linspace(0.0, 1.0, 401)
    big = sample_tile(tiles[0], z, np.ones_like(z))  # big quad: u along z, v = 1 at x = 1
    lo = z <= 0.5
    small = np.where(
        lo[:, None],
        sample_tile(tiles[1], np.clip(z / 0.5, 0, 1), np.zeros_like(z)),
        sample_tile(tiles[2], np.clip((z - 0.5) / 0.5, 0, 1), np.zeros_like(z)),
    )
    mismatch = float(np.abs(big - small).max() / big.max())
    renderer.set_solution(sol)
    baked = Baker(sol, scene).bake(BakePolicy(threshold=0))
    renderer.set_baked(baked)
    cam = Camera(
        eye=[1.0, 3.0, 0.5], target=[1.0, 0.0, 0.5], up=[0.0, 0.0, -1.0], yfov=40.0, znear=0.1, zfar=10
    )
    cracks = {}
    for mode in ("mesh", "iat"):
        img = renderer.render(cam, (400, 300), mode)
        lit = img.max(axis=2) > 0
        ys, xs = np.nonzero(lit)
        inner = lit[ys.min() + 2 : ys.max() - 1, xs.min() + 2 : xs.max() - 1]
        cracks[mode] = int((~inner).sum())
    record(
        "t_junction",
        edge_mismatch_rel=mismatch,
        crack_pixels_mesh=cracks["mesh"],
        crack_pixels_iat=cracks["iat"],
    )
    assert cracks == {"mesh": 0, "iat": 0}
    assert mismatch < tolerance


def test_geometry_large_and_small_scales_keep_shadows_above_the_ray_offset():
    """A 1 cm cube on a tile alone and in a scene 14 m across: its shadow is there (and in a scene
    141 m across, below: D1 fixed, the ray offset is capped by the patch size)."""
    shadow = {}
    for big in (0.0, 10.0):
        scene = ss.small_object_in_large_scene(big=big)
        shadow[big], eps = _cube_shadow_area(scene)
        record(
            "mixed_scales",
            **{f"shadow_cm2_scene_{big:g}m": shadow[big] * 1e4, f"ray_eps_m_scene_{big:g}m": eps},
        )
    assert shadow[0.0] > 1e-4  # > 1 cm^2
    assert shadow[10.0] == pytest.approx(shadow[0.0], rel=0.25)


def test_geometry_small_object_in_a_huge_scene_keeps_its_shadow():
    """D1 (fixed): the 1 cm cube keeps its shadow in a scene 141 m across (the ray offset is capped by
    2 % of the patch radius, not 1e-4 x the 141 m diagonal = 1.4 cm)."""
    scene = ss.small_object_in_large_scene(big=100.0)
    area, eps = _cube_shadow_area(scene)
    record("mixed_scales", shadow_cm2_scene_100m=area * 1e4, ray_eps_m_scene_100m=eps)
    assert area > 1e-4


def _cube_shadow_area(scene):
    """Area (m^2) of the tile (patch 0) outside the cube's footprint that the cube shadows, from the
    exact direct light at every lattice point of depth 6; and the solver's ray offset."""
    from iat.radiosity.solver import evaluate_direct

    depth = 6
    n = 1 << depth
    ii, jj = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keys = qt.make_key(np.zeros(ii.size, dtype=np.int64), ii.ravel(), jj.ravel(), n)
    pos = qt.keys_to_world(scene.corner_positions, scene.patch_is_quad, keys, n)
    got = evaluate_direct(scene, keys, opts(max_depth=depth))[:, 0]
    free = _direct_point(scene.lights[0], pos, np.tile([0, 1.0, 0], (len(pos), 1)), 0.5)
    foot = (pos[:, 0] >= 0) & (pos[:, 0] <= 0.01) & (pos[:, 2] >= 0) & (pos[:, 2] <= 0.01)
    shadowed = ~foot & (got < 0.5 * free)
    lo, hi = scene.bounds
    return float(shadowed.sum() * (0.1 / n) ** 2), float(RAY_EPS * np.linalg.norm(hi - lo))


def test_geometry_non_manifold_and_open_meshes(tmp_path):
    """An open box (no lid) with a fin on its floor (an edge shared by three triangles): loads, solves
    finite, and reflects less light than the closed box (light escapes; none is created)."""
    box = ss.box_faces([0, 0, 0], [1, 1, 1], inward=True)
    V, F = [], []
    for q in box:
        k = len(V)
        V.extend(q.tolist())
        F += [[k, k + 1, k + 2], [k + 2, k + 3, k]]
    # the fin: a vertical triangle standing on the floor diagonal edge of the floor's two triangles
    floor = int(np.argmin([q[:, 1].max() for q in box]))
    a, c = 4 * floor, 4 * floor + 2
    V.append([0.5, 0.4, 0.5])
    F.append([a, c, len(V) - 1])
    lid = int(np.argmax([q[:, 1].min() for q in box]))
    power = {}
    for name, faces in (("closed", F), ("open", [f for i, f in enumerate(F) if i // 2 != lid])):
        path = ss.write_obj(tmp_path / f"{name}.obj", V, faces)
        scene = load_scene(path)
        scene.lights = [ss.point_light(0.5, 0.7, 0.5, 1.0)]
        sol = solve(scene, opts(max_depth=3))
        rad = sol.vert_radiance
        assert np.isfinite(rad).all() and (rad >= 0).all()
        power[name] = float(
            luminance_of(_area_weighted_mean(sol, np.arange(scene.n_patches)) * scene.patch_area.sum())
        )
        record(
            "non_manifold_open",
            **{f"{name}_patches": scene.n_patches, f"{name}_unshot_fraction": sol.stats["unshot_fraction"]},
        )
    record("non_manifold_open", open_over_closed_reflected_power=power["open"] / power["closed"])
    assert power["open"] < power["closed"]


def test_geometry_double_sided_thin_wall(tmp_path):
    """A wall made of two coincident faces back to back (double-sided, zero thickness), light on one
    side: the lit face is exact, the floor behind is dark, and the back face gets only the light that
    leaks through the floor element straddling the wall (measured)."""
    V = [[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1], [0.1, 0, -1], [0.1, 1, -1], [0.1, 1, 1], [0.1, 0, 1]]
    F = [[0, 1, 2], [2, 3, 0], [4, 5, 6], [6, 7, 4], [7, 6, 5], [5, 4, 7]]
    scene = load_scene(ss.write_obj(tmp_path / "thin_wall.obj", V, F))
    assert scene.n_patches == 3
    scene.lights = [ss.point_light(-0.4, 0.5, 0.0, 0.25)]
    sol = solve(scene, opts(max_depth=4))
    nrm = scene.patch_normal
    lit = int(np.flatnonzero(nrm[:, 0] < -0.5)[0])
    back = int(np.flatnonzero(nrm[:, 0] > 0.5)[0])
    floor = int(np.flatnonzero(nrm[:, 1] > 0.5)[0])
    p = _vertex_patch(sol)
    pos, rad = sol.vert_position, sol.vert_radiance.astype(np.float64)
    on_lit = p == lit
    expect = _direct_point(scene.lights[0], pos[on_lit], np.tile([-1.0, 0, 0], (on_lit.sum(), 1)), 0.5)
    direct_err = float(((rad[on_lit, 0] - expect) / expect).min())  # indirect light only adds
    behind = (p == floor) & (pos[:, 0] > 0.1)
    lum_back = luminance_of(_area_weighted_mean(sol, [back]))
    ratio_mean = float(lum_back / luminance_of(_area_weighted_mean(sol, [lit])))
    ratio_max = float(rad[p == back].max() / rad[on_lit].max())
    record(
        "double_sided_wall",
        back_over_lit_mean=ratio_mean,
        back_over_lit_max=ratio_max,
        lit_face_direct_rel_error=direct_err,
    )
    assert direct_err > -1e-3
    assert rad[behind].max() == 0.0
    assert ratio_mean < 0.05 and ratio_max < 0.1


def test_geometry_nan_and_inf_coordinates_in_files(tmp_path):
    """NaN or Inf on a used vertex is a LoadError naming the file; on an unused vertex it is ignored."""
    tri = "f 1 2 3\n"
    for name, text in {
        "nan.obj": "v nan 0 0\nv 1 0 0\nv 0 1 0\n" + tri,
        "inf.obj": "v 0 0 0\nv inf 0 0\nv 0 1 0\n" + tri,
        "neg_inf.obj": "v 0 0 0\nv 1 0 0\nv 0 -inf 0\n" + tri,
    }.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(LoadError, match="non-finite vertex coordinates") as e:
            load_scene(tmp_path / name)
        assert name in str(e.value)
    (tmp_path / "unused_nan.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan nan nan\n" + tri)
    scene = load_scene(tmp_path / "unused_nan.obj")
    assert scene.n_patches == 1 and np.isfinite(scene.vertices).all()
    record("nan_inf", files_rejected=3, unused_nan_loaded=True)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_geometry_nan_in_memory_scene_is_an_iat_error():
    """D2 (fixed): an in-memory scene with a NaN vertex is an IATError from solve, not a bare ValueError."""
    scene = ss.floor_under_light()
    scene.vertices[0, 0] = np.nan
    with pytest.raises(IATError, match="non-finite"):
        solve(scene, opts(max_depth=2))


_MILLION = r"""
import json, resource, sys, time, tracemalloc
import numpy as np
from tests.stability_scenes import grid_mesh, write_binary_stl, point_light
from iat.io.load import load_scene
from iat.radiosity import solve, SolveOptions
V, F = grid_mesh(708)  # 1 002 528 triangles
path = write_binary_stl(sys.argv[1], V, F)
del V, F
tracemalloc.start()
t0 = time.perf_counter()
load_calls = []
scene = load_scene(path, progress=lambda f, m: load_calls.append((time.perf_counter(), f, m)))
t_load = time.perf_counter() - t0
load_stamps = [t0] + [c[0] for c in load_calls] + [t0 + t_load]
_, peak_load = tracemalloc.get_traced_memory()
tracemalloc.stop()  # the solve's memory: ru_maxrss below
scene.lights = [point_light(0.5, 0.5, 1.0, 1.0)]
calls = []
def progress(f, m):
    calls.append((time.perf_counter(), f, m))
    return True
t1 = time.perf_counter()
sol = solve(scene, SolveOptions(max_depth=0, max_shots=0), progress=progress)
t_solve = time.perf_counter() - t1
stamps = [t1] + [c[0] for c in calls] + [time.perf_counter()]
print(json.dumps(dict(
    triangles=1002528, patches=int(scene.n_patches), quads=int(scene.patch_is_quad.sum()),
    load_s=t_load, solve_s=t_solve, peak_load_mb=peak_load / 2**20,
    max_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    progress_calls=len(calls), progress_fractions=[c[1] for c in calls],
    progress_stages=len({c[2] for c in calls}),
    progress_max_gap_s=float(np.diff(stamps).max()),
    load_progress_calls=len(load_calls), load_progress_fractions=[c[1] for c in load_calls],
    load_progress_max_gap_s=float(np.diff(load_stamps).max()),
    finite=bool(np.isfinite(sol.vert_radiance).all()), vertices=int(len(sol.vert_key)),
)))
"""


def test_geometry_a_million_triangles(tmp_path):
    """1 002 528 triangles (binary STL): load + weld + merge into 501 264 quads, then a direct-light
    solve at depth 0, in a child process (its own peak memory); time and memory stay bounded."""
    script = tmp_path / "million.py"
    script.write_text(_MILLION)
    r = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "million.stl")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=400,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert r.returncode == 0, r.stderr[-2000:]
    m = json.loads(r.stdout.strip().splitlines()[-1])
    record(
        "million_triangles",
        **{
            k: (round(v, 2) if isinstance(v, float) else v)
            for k, v in m.items()
            if k not in ("progress_fractions", "load_progress_fractions")
        },
    )
    assert m["patches"] == 501264 and m["quads"] == 501264 and m["finite"]
    assert m["max_rss_mb"] < 3000  # ~3 kB per input triangle at most
    assert m["load_s"] + m["solve_s"] < 240
    f = m["progress_fractions"]
    assert f and f[-1] == 1.0 and all(b >= a for a, b in zip(f, f[1:], strict=False))
    assert m["progress_stages"] >= 6  # G2: preparing, meshing pass, vertex table, light, power, done
    f = m["load_progress_fractions"]  # G2: the load reports progress at each stage, 0 to 1
    assert len(f) >= 5 and f[0] == 0.0 and f[-1] == 1.0
    assert all(b >= a for a, b in zip(f, f[1:], strict=False))


def test_geometry_vertex_keys_of_a_million_corners_sort_and_mask():
    """G1 (fixed): the vertex table of a mesh pass is the sorted unique leaf-corner keys; numpy 2.4's
    np.unique was most of the million-triangle solve. qt.sorted_unique (np.sort + a first-of-run mask)
    gives the same keys; both timed on 1 M random int64 keys and on the 1 024 000 corner keys of a
    256 000-leaf forest (best of 3)."""

    def best(fn, x):
        t = []
        for _ in range(3):
            t0 = time.perf_counter()
            y = fn(x)
            t.append(time.perf_counter() - t0)
        return min(t), y

    random_keys = np.random.default_rng(0).integers(0, 1 << 40, 1_000_000)
    forest = qt.roots(np.ones(4000, dtype=bool), 6)
    for _ in range(3):
        forest = qt.split(forest, np.ones(forest.n_leaves, dtype=bool))
    corner_keys = qt.leaf_corner_keys(forest)
    figures = {}
    for name, keys in (("random_1M", random_keys), ("forest_corners_1M", corner_keys)):
        t_unique, want = best(np.unique, keys)
        t_sort, got = best(qt.sorted_unique, keys)
        assert np.array_equal(got, want), name
        figures[f"{name}_np_unique_s"] = round(t_unique, 3)
        figures[f"{name}_sort_mask_s"] = round(t_sort, 3)
    assert np.array_equal(qt.vertex_keys(forest), np.unique(corner_keys))
    assert len(qt.sorted_unique(np.zeros(0, dtype=np.int64))) == 0
    record("vertex_keys_unique", keys=len(random_keys), **figures)
    assert figures["random_1M_sort_mask_s"] < 2.0  # 0.05 s measured; a bound, not a comparison


# =================================================================================================
# Lighting
# =================================================================================================
def test_lighting_point_light_almost_touching_a_wall():
    """A point light 0.1 mm from a floor: finite radiance, bounded by I rho / (pi d^2) (reached at the
    foot today, a softened peak would also hold), and the tree refined to max depth around the foot."""
    depth = 4
    scene = ss.make_scene([ss.quad_y(-1, 1, -1, 1)], [0], [ss.GREY], [ss.point_light(0.0, 1e-4, 0.0, 1.0)])
    sol = solve(scene, opts(max_depth=depth))
    rad = sol.vert_radiance.astype(np.float64)
    assert np.isfinite(rad).all()
    peak = 0.5 * scene.lights[0].intensity / (np.pi * 1e-8)
    f = sol.forest
    # the four leaves around the foot (lattice centre) are at max depth
    n = sol.n
    centre = (f.leaf_i <= n // 2) & (f.leaf_i + f.leaf_size >= n // 2)
    centre &= (f.leaf_j <= n // 2) & (f.leaf_j + f.leaf_size >= n // 2)
    record(
        "light_touching_wall",
        peak_radiance=float(rad.max()),
        analytic_peak=peak,
        leaves_at_foot_depth=sorted(set(f.leaf_level[centre].tolist())),
        elements=sol.stats["elements"],
    )
    assert 0 < rad.max() <= peak * (1 + 1e-5)
    assert (f.leaf_level[centre] == depth).all()


def test_lighting_point_light_near_a_wall_conserves_energy():
    """Physically the indirect light in a closed room barely depends on how close the light is to a
    wall (the wall catches about half the light either way). Fixed D3: an element shoots the power it
    received (intensity x its solid angle from the light x visible fraction, finite as d -> 0), not
    its interpolated vertex irradiance (gain 0.95 at depth 3; it was ~1.5e4)."""
    far_wall = {}
    for d in (0.1, 1e-4):
        sol = solve(ss.room_with_light([0.5, 0.5, d]), opts(max_depth=3))
        on = np.isclose(sol.vert_position[:, 2], 1.0) & (_vertex_patch(sol) >= 0)
        far_wall[d] = float(sol.vert_radiance[on, 0].mean())
    record(
        "light_touching_wall",
        far_wall_radiance_d_0_1=far_wall[0.1],
        far_wall_radiance_d_1e_4=far_wall[1e-4],
        energy_gain=far_wall[1e-4] / far_wall[0.1],
    )
    assert far_wall[0.1] / 3 < far_wall[1e-4] < 3 * far_wall[0.1]


def test_lighting_emitter_facing_away_and_no_light():
    """An emitter that faces away from everything lights nothing and the solve ends at once; a scene
    with no light at all solves to exact zeros (no NaN) and renders black."""
    scene = ss.emitter_facing_away()
    t0 = time.perf_counter()
    sol = solve(scene, opts(max_depth=4))
    dt = time.perf_counter() - t0
    p = _vertex_patch(sol)
    assert sol.vert_radiance[p == 0].max() == 0.0
    assert np.all(sol.vert_radiance[p == 1] == 10.0)
    dark = ss.make_scene(ss.box_faces([0, 0, 0], [1, 1, 1]), [0] * 6, [ss.GREY])
    sol2 = solve(dark, opts(max_depth=4))
    assert np.isfinite(sol2.vert_radiance).all() and sol2.vert_radiance.max() == 0.0
    assert sol2.stats["unshot_fraction"] == 0.0 and sol2.stats["shots"] == 0
    baked = Baker(sol2, dark).bake(BakePolicy(threshold=0))
    assert np.isfinite(baked.pages).all() and baked.pages.max() == 0.0
    record(
        "emitter_away_no_light",
        away_shots=sol.stats["shots"],
        away_time_s=round(dt, 3),
        away_floor_max=0.0,
        dark_max=0.0,
        dark_elements=sol2.stats["elements"],
    )
    assert sol.stats["shots"] == 0


def test_lighting_no_light_renders_black(renderer):
    dark = ss.make_scene(ss.box_faces([0, 0, 0], [1, 1, 1]), [0] * 6, [ss.GREY])
    sol = solve(dark, opts(max_depth=2))
    renderer.set_solution(sol)
    renderer.set_baked(Baker(sol, dark).bake(BakePolicy(threshold=0)))
    cam = Camera(eye=[0.5, 0.5, 0.9], target=[0.5, 0.5, 0.0], yfov=60.0, znear=0.01, zfar=10)
    for mode in ("mesh", "iat"):
        img = renderer.render(cam, (32, 24), mode)
        assert np.isfinite(img).all() and img.max() == 0.0
    from iat.color import auto_exposure, tonemap

    assert auto_exposure(img) == 1.0 and tonemap(img, None).max() == 0


def test_lighting_albedo_zero_and_albedo_above_one_is_clamped_at_load(tmp_path):
    """Albedo 0: non-emitters are exactly black. Albedo > 1 in a file is clamped to 1 at load
    (Kd 1.5 -> 1.0) with an IATWarning naming the file and the material; albedo 1 in a closed box
    never converges: the solve stops at max_shots and reports the unshot light instead of looping."""
    sol = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=0.0), opts(max_depth=2))
    assert sol.vert_radiance.max() == 0.0 and sol.stats["shots"] == 0
    mtl = tmp_path / "bright.mtl"
    mtl.write_text("newmtl bright\nKd 1.5 0.5 0.25\n")
    obj = ss.write_obj(
        tmp_path / "bright.obj",
        [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[0, 1, 2]],
        extra="mtllib bright.mtl\nusemtl bright",
    )
    from iat.errors import IATWarning

    clamped = r"bright.obj: albedo outside \[0, 1\] clamped in 1 material: 'bright' \(1.5, 0.5, 0.25\)$"
    with pytest.warns(IATWarning, match=clamped):
        scene = load_scene(obj)
    assert np.allclose(scene.materials[0].albedo, [1.0, 0.5, 0.25])
    t0 = time.perf_counter()
    sol1 = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=1.0), opts(max_depth=2, max_shots=200))
    dt = time.perf_counter() - t0
    record(
        "albedo",
        albedo0_max=0.0,
        kd_1_5_loaded_as=scene.materials[0].albedo.tolist(),
        albedo1_shots=sol1.stats["shots"],
        albedo1_unshot_fraction=sol1.stats["unshot_fraction"],
        albedo1_time_s=round(dt, 2),
    )
    assert sol1.stats["shots"] == 200 and sol1.stats["unshot_fraction"] > 0.5
    assert np.isfinite(sol1.vert_radiance).all()


def test_lighting_albedo_above_one_in_memory_is_clamped_with_a_warning():
    """An in-memory scene with albedo 1.5 (no loader clamped it): the solve clamps it to 1 with an
    IATWarning naming the material, so the result equals the albedo-1 solve (finite, stops at
    max_shots); a negative albedo is clamped to 0 the same way; NaN stays an OptionError."""
    from iat.errors import IATWarning

    scene = ss.room_with_light([0.5, 0.5, 0.5], albedo=1.5)
    clamped = r"albedo outside \[0, 1\] clamped in 1 material: 'wall' \(1.5, 1.5, 1.5\)"
    with pytest.warns(IATWarning, match=clamped):
        sol = solve(scene, opts(max_depth=2, max_shots=300))
    one = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=1.0), opts(max_depth=2, max_shots=300))
    record("albedo", albedo1_5_max_radiance_after_300_shots=float(sol.vert_radiance.max()))
    assert np.isfinite(sol.vert_radiance).all()
    assert np.allclose(sol.patch_albedo, 1.0)
    assert np.allclose(sol.vert_radiance, one.vert_radiance)
    with pytest.warns(IATWarning, match="'wall' \\(-0.5"):
        dark = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=-0.5), opts(max_depth=2))
    assert dark.vert_radiance.max() == 0.0
    with pytest.raises(OptionError, match="albedo"):
        solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=float("nan")), opts(max_depth=2))


def _format_figures(renderer, sol, scene):
    """Bake at threshold 0 in every pixel format; relative quantisation error in the dim region, from
    the pages (what the baker stores) and from the GPU image (what is shown)."""
    figures = {}
    base = Baker(sol, scene)
    ref = base.bake(BakePolicy(threshold=0, method="scan", mipmaps=False))
    ref32 = dataclasses.replace(ref, policy=dataclasses.replace(ref.policy, pixel_format="rgba32f"))
    exact = ref.pages.astype(np.float64)
    dim = (exact > 0) & (exact < 1e-6 * exact.max())
    assert dim.sum() > 100
    renderer.set_baked(ref32)
    cam = Camera(
        eye=[10.0, 1.5, 0.0], target=[10.0, 0.0, 0.0], up=[0.0, 0.0, -1.0], yfov=60.0, znear=0.01, zfar=10
    )
    img_ref = renderer.render(cam, (64, 64), "iat").astype(np.float64)
    shown = img_ref > 0
    for fmt in ("rgba16f", "rgba8", "rgb9e5"):
        b = base.bake(BakePolicy(threshold=0, method="scan", mipmaps=False, pixel_format=fmt))
        stored = b.pages.astype(np.float64)
        if fmt == "rgba16f":
            stored = exact.astype(np.float16).astype(np.float64)  # what the rgba16f texture holds
        figures[f"{fmt}_pages_dim_max_rel_err"] = float((np.abs(stored - exact)[dim] / exact[dim]).max())
        try:
            renderer.set_baked(b)
            img = renderer.render(cam, (64, 64), "iat").astype(np.float64)
            figures[f"{fmt}_gpu_dim_max_rel_err"] = float(
                (np.abs(img - img_ref)[shown] / img_ref[shown]).max()
            )
        except RenderError as e:
            figures[f"{fmt}_gpu"] = str(e)
    figures["dynamic_range"] = float(exact.max() / exact[exact > 0].min())
    return figures


def test_lighting_bright_and_dim_emitters_pixel_formats(renderer):
    """A 5e4 emitter and a 1e-3 point light in one scene (8+ decades): rgba16f keeps the dim region
    within 2**-11 relative error; rgba8 (one scale for all pages) loses it entirely (banding to black);
    rgb9e5 keeps 2**-9 per texel in the baker's pages."""
    scene = ss.bright_and_dim()
    sol = solve(scene, opts(max_depth=3))
    fig = _format_figures(renderer, sol, scene)
    record("pixel_formats", **fig)
    assert fig["rgba16f_pages_dim_max_rel_err"] <= 2.0**-11
    assert fig["rgba16f_gpu_dim_max_rel_err"] <= 2.0**-10  # half-float texels, then filtering
    assert fig["rgb9e5_pages_dim_max_rel_err"] <= 2.0**-9 * 1.01
    assert fig["rgba8_pages_dim_max_rel_err"] == 1.0  # everything dim rounds to 0: documented limit
    # the quantisers themselves: rgb9e5 relative step of the largest channel <= 2**-9, rgba8 sRGB step
    x = np.geomspace(1e-4, 6e4, 4001)[:, None] * np.ones(3)
    assert (np.abs(quantise_rgb9e5(x) - x) / x).max() <= 2.0**-9 * 1.01
    q8 = quantise_rgba8(x, float(x.max()))
    assert (q8[x[:, 0] < 1e-5 * x.max()] == 0).all()


def test_lighting_banding_8_bit_vs_16_bit_on_a_smooth_ramp():
    """Banding measured: a smooth exponential ramp over 3 decades (1e-3 to 1, a light's falloff) baked
    at 1 025 texels across in rgba16f and rgba8. Per decade: distinct texel values, the widest band
    (run of equal texels where the exact value rises 0.7 % per texel), the largest step between
    neighbouring levels and the largest relative error. rgba16f: every texel its own level; rgba8
    (sRGB 8-bit, one scale for all pages): bands widen as the radiance falls below the maximum."""
    ramp = lambda p, x: (10.0 ** (-3.0 + 3.0 * x[:, 0]))[:, None] * np.ones(3)  # noqa: E731
    sol = ss.uniform_depth_solution(ss.grid_corners(1, 1), 6, ramp)
    base = Baker(sol)
    policy = dict(threshold=0, method="bilinear", mipmaps=False, scale=16.0)
    exact = base.bake(BakePolicy(**policy)).pages.astype(np.float64)  # rgba16f pages hold exact values
    stored = {
        "rgba16f": exact.astype(np.float16).astype(np.float64),  # what the rgba16f texture holds
        "rgba8": base.bake(BakePolicy(**policy, pixel_format="rgba8")).pages.astype(np.float64),
    }
    lit = exact[0, ..., 0] > 0
    ys, xs = np.nonzero(lit)
    row = ys[len(ys) // 2]
    cols = xs[ys == row]
    e = exact[0, row, cols, 0]
    rising = np.r_[np.diff(e) > 0, False] & np.r_[False, np.diff(e) > 0]  # inside the tile, no gutter
    e = e[rising]
    assert len(e) > 1000 and (e[1:] / e[:-1]).max() < 1.01
    fig = {}
    for fmt, pages in stored.items():
        q = pages[0, row, cols, 0][rising]
        for k, name in enumerate(("1e-3_1e-2", "1e-2_1e-1", "1e-1_1")):
            sel = (e >= 10.0 ** (k - 3)) & (e < 10.0 ** (k - 2))
            qq = q[sel]
            runs = np.diff(np.flatnonzero(np.r_[True, qq[1:] != qq[:-1], True]))
            levels = np.unique(qq)
            fig[f"{fmt}_{name}_texels"] = int(sel.sum())
            fig[f"{fmt}_{name}_levels"] = len(levels)
            fig[f"{fmt}_{name}_widest_band_texels"] = int(runs.max())
            fig[f"{fmt}_{name}_max_level_step"] = round(float((levels[1:] / levels[:-1] - 1).max()), 4)
            fig[f"{fmt}_{name}_max_rel_err"] = round(float((np.abs(qq - e[sel]) / e[sel]).max()), 5)
    record("banding_8_vs_16_bit", **fig)
    for name in ("1e-3_1e-2", "1e-2_1e-1", "1e-1_1"):
        assert fig[f"rgba16f_{name}_widest_band_texels"] == 1  # no band: the ramp's 0.7 % steps survive
        assert fig[f"rgba16f_{name}_max_rel_err"] <= 2.0**-11
    assert fig["rgba8_1e-1_1_max_rel_err"] < 0.02  # the top decade is fine in 8 bits
    assert fig["rgba8_1e-3_1e-2_widest_band_texels"] > 10  # 3 decades down: visible bands (documented)


def test_lighting_rgb9e5_bake_renders(renderer):
    """D4 (fixed): an rgb9e5 bake uploads (GL_RGB9_E5) instead of raising RenderError."""
    scene = ss.bright_and_dim()
    sol = solve(scene, opts(max_depth=2))
    renderer.set_baked(Baker(sol, scene).bake(BakePolicy(threshold=0, pixel_format="rgb9e5")))


def test_lighting_rgba8_gpu_matches_the_baked_pages(renderer):
    """D5 (fixed): rgba8 pages are drawn as the baker stored them (sRGB8 texture), not 29 % off."""
    scene = ss.floor_under_light(height=0.3)
    sol = solve(scene, opts(max_depth=4))
    base = Baker(sol, scene)
    b8 = base.bake(BakePolicy(threshold=0, method="scan", mipmaps=False, pixel_format="rgba8"))
    ref = dataclasses.replace(
        b8, policy=dataclasses.replace(b8.policy, pixel_format="rgba32f"), page_scale=1.0
    )
    cam = Camera(
        eye=[0.0, 2.0, 0.0], target=[0.0, 0.0, 0.0], up=[0.0, 0.0, -1.0], yfov=60.0, znear=0.01, zfar=10
    )
    renderer.set_baked(ref)  # the stored (already sRGB8-quantised) values, uploaded exactly
    want = renderer.render(cam, (64, 64), "iat").astype(np.float64)
    renderer.set_baked(b8)
    got = renderer.render(cam, (64, 64), "iat").astype(np.float64)
    m = want > 1e-3 * want.max()
    err = float((np.abs(got - want)[m] / want[m]).max())
    record("pixel_formats", rgba8_gpu_vs_pages_max_rel_err=err)
    assert err < 0.05


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
def test_lighting_very_bright_texel_stays_finite_in_rgba16f(renderer):
    """D6 (fixed): a 1e5 texel is clamped to 65504 before the float16 cast, never inf on screen."""
    scene = ss.bright_and_dim(bright=1.0e5)
    sol = solve(scene, opts(max_depth=2))
    renderer.set_baked(Baker(sol, scene).bake(BakePolicy(threshold=0)))
    cam = Camera(
        eye=[0.0, 4.0, 0.0], target=[0.0, 3.0, 0.0], up=[0.0, 0.0, -1.0], yfov=30.0, znear=0.01, zfar=10
    )
    img = renderer.render(cam, (32, 32), "iat")
    record("pixel_formats", rgba16f_1e5_emitter_pixels_not_finite=int((~np.isfinite(img)).any(axis=2).sum()))
    assert np.isfinite(img).all()


# =================================================================================================
# Meshing and baking
# =================================================================================================
def test_meshing_max_depth_everywhere_memory_bound():
    """A tiny tolerance splits every element to max depth: exactly 4**D leaves per patch, never more,
    and the solution's bytes grow linearly with the leaves (bytes per element measured)."""
    rows = {}
    for depth in (4, 6):
        scene = ss.floor_under_light(height=0.3)
        sol = solve(scene, opts(max_depth=depth, tolerance=1e-9, criterion="variation"))
        leaves = sol.forest.n_leaves
        nbytes = sum(
            np.asarray(getattr(sol, k)).nbytes
            for k in (
                "leaf_patch",
                "leaf_level",
                "leaf_i",
                "leaf_j",
                "leaf_flip",
                "vert_key",
                "vert_radiance",
                "tri_vertices",
            )
        )
        rows[depth] = (leaves, nbytes)
        record(
            "max_depth_everywhere",
            **{
                f"D{depth}_leaves": leaves,
                f"D{depth}_bytes": nbytes,
                f"D{depth}_bytes_per_leaf": round(nbytes / leaves, 1),
            },
        )
        assert leaves == 4**depth
        assert (sol.forest.leaf_level == depth).all()
    assert rows[6][1] / rows[6][0] < 1.1 * rows[4][1] / rows[4][0]
    with pytest.raises(OptionError, match="tolerance"):
        solve(ss.floor_under_light(), SolveOptions(tolerance=0.0))
    with pytest.raises(OptionError, match="max_depth"):
        solve(ss.floor_under_light(), SolveOptions(max_depth=13))


@pytest.fixture(scope="module")
def grid_solution():
    """4 x 3 coplanar unit quads under a point light, solved at depth 4 (a small real solution)."""
    corners = ss.grid_corners(4, 3)
    polys = list(corners)  # in z = 0, facing +z: the light is in front at z = 0.6
    scene = ss.make_scene(polys, [0] * len(polys), [ss.GREY], [ss.point_light(1.3, 1.1, 0.6, 1.0)])
    sol = solve(scene, opts(max_depth=4))
    return scene, sol


def test_baking_scale_far_below_one_gives_two_texel_tiles(grid_solution):
    """Scale 1e-6: every tile is 2 x 2 texels (the corners), seams between neighbours stay exact."""
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    full = baker.bake(BakePolicy(threshold=0))
    tiny = baker.bake(BakePolicy(threshold=0, scale=1e-6))
    seam = seam_error(tiny, sol)
    record(
        "scale_far_below_one",
        texture_bytes_scale_1=full.memory.texture_bytes,
        texture_bytes_scale_1e_6=tiny.memory.texture_bytes,
        seam_max=seam["max"],
        seam_edges=seam["edges"],
    )
    assert seam["edges"] > 0 and seam["max"] < 1e-6
    assert tiny.memory.texture_bytes < full.memory.texture_bytes
    assert all(
        t.shape[0] == 2 for t in baker.tiles.get(np.arange(len(scene.patch_corners)), "bilinear", 1e-6)
    )
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(OptionError, match="scale"):
            baker.bake(BakePolicy(scale=bad))


def test_baking_budget_zero_and_budget_below_any_texture(grid_solution):
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    zero = baker.bake(BakePolicy(budget_mb=0.0))
    tiny = baker.bake(BakePolicy(budget_mb=1e-9))
    for b in (zero, tiny):
        assert b.memory.texture_bytes == 0 and b.memory.patches_textured == 0 and b.pages.shape[0] == 0
        assert b.memory.triangles_mesh_part == len(sol.tri_vertices)
    assert not zero.memory.budget_too_small and tiny.memory.budget_too_small
    record(
        "budget_zero_tiny",
        budget0_texture_bytes=0,
        budget1e_9_too_small=True,
        mesh_triangles=int(zero.memory.triangles_mesh_part),
    )
    with pytest.raises(OptionError, match="budget"):
        baker.bake(BakePolicy(budget_mb=-1.0))


def test_baking_threshold_above_the_deepest_tree_is_the_mesh(renderer, grid_solution):
    scene, sol = grid_solution
    baked = Baker(sol, scene).bake(BakePolicy(threshold=99))
    assert baked.memory.patches_textured == 0 and baked.pages.shape == (0, 1, 1, 3)
    renderer.set_solution(sol)
    renderer.set_baked(baked)
    cam = Camera(eye=[2.0, 1.5, 3.0], target=[2.0, 1.5, 0.0], yfov=60.0, znear=0.01, zfar=10)
    mesh = renderer.render(cam, (64, 48), "mesh")
    iat = renderer.render(cam, (64, 48), "iat")
    diff = float(np.abs(mesh - iat).max())
    record("threshold_above_deepest", max_abs_diff_iat_vs_mesh=diff)
    assert diff == 0.0


def test_baking_atlas_pages_full_spill_to_more_pages(renderer):
    """40 patches of 17 x 17 texels on 64 x 64 pages: the atlas spills over several pages and the IAT
    image still equals the per-patch colours."""
    corners = ss.grid_corners(8, 5)
    colour = lambda p, x: np.stack([(p % 3) / 2.0, ((p // 3) % 3) / 2.0, np.full(len(p), 0.25)], 1)  # noqa: E731
    sol = ss.synthetic_solution(corners, colour, max_depth=4)
    baked = Baker(sol).bake(BakePolicy(threshold=0, page_size=64, gutter=2))
    assert baked.memory.pages > 1
    renderer.set_solution(sol)
    renderer.set_baked(baked)
    cam = Camera(eye=[4.0, 2.5, 6.0], target=[4.0, 2.5, 0.0], yfov=50.0, znear=0.01, zfar=20)
    mesh = renderer.render(cam, (128, 96), "mesh")
    iat = renderer.render(cam, (128, 96), "iat")
    diff = float(np.abs(mesh - iat).max())
    record(
        "atlas_pages_full",
        pages=baked.memory.pages,
        utilisation=round(baked.memory.utilisation, 3),
        texture_bytes=baked.memory.texture_bytes,
        max_abs_diff_iat_vs_mesh=diff,
    )
    assert diff < 2e-3


def test_baking_more_pages_than_the_gl_layer_limit_is_an_error(egl_ctx):
    """D7 (fixed): more atlas pages than GL_MAX_ARRAY_TEXTURE_LAYERS is an error, not a black image."""
    from iat.render.renderer import Renderer

    limit = int(egl_ctx.info["GL_MAX_ARRAY_TEXTURE_LAYERS"])
    corners = ss.grid_corners(limit + 1, 1)
    sol = ss.synthetic_solution(corners, lambda p, x: np.ones((len(p), 3)), max_depth=1)
    baked = Baker(sol).bake(BakePolicy(threshold=0, page_size=64, gutter=15))  # one tile per page
    assert baked.memory.pages == limit + 1
    r = Renderer(egl_ctx)
    try:
        with pytest.raises((RenderError, BakeError)):
            r.set_baked(baked)
            cam = Camera(eye=[0.5, 0.5, 2.0], target=[0.5, 0.5, 0.0], yfov=20.0, znear=0.1, zfar=10)
            img = r.render(cam, (8, 8), "iat")
            record(
                "atlas_pages_full",
                over_limit_pages=limit + 1,
                over_limit_centre_pixel=img[4, 4].tolist(),
                gl_error=egl_ctx.error,
            )
    finally:
        r.release()


def test_baking_texture_larger_than_the_gl_limit_is_a_bake_error(grid_solution, egl_ctx):
    """A tile larger than a page (pages are at most GL_MAX_TEXTURE_SIZE = 16384) is a BakeError that
    names the patch, the size and the way out, raised before any texel is allocated."""
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    deepest = int(sol.patch_depth().max())
    scale = 20000.0 / (1 << deepest)  # the deepest tile: (2**d) x scale + 1 = 20001 texels a side
    tracemalloc.start()
    try:
        with pytest.raises(BakeError) as e:
            baker.bake(BakePolicy(threshold=0, scale=scale, page_size=16384))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    msg = str(e.value)
    assert "larger than the 16384x16384 atlas page" in msg and "lower the scale" in msg and "patch" in msg
    with pytest.raises(OptionError, match="page_size"):
        baker.bake(BakePolicy(page_size=32768))
    gl_max = int(egl_ctx.info["GL_MAX_TEXTURE_SIZE"])
    record(
        "texture_over_gl_limit",
        message=msg.split(": ", 1)[-1],
        peak_alloc_mb=round(peak / 2**20, 2),
        gl_max_texture_size=gl_max,
    )
    assert peak < 64 * 2**20  # the 20001^2 tile was never made


_HUGE_BAKE = r"""
import resource, sys
sys.path.insert(0, sys.argv[1])
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))  # 3 GiB: the bake below needs ~25
import numpy as np
from tests import stability_scenes as ss
from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.errors import IATError
sol = ss.synthetic_solution(ss.grid_corners(4, 3), lambda p, x: np.ones((len(p), 3)), max_depth=2)
try:
    b = Baker(sol).bake(BakePolicy(threshold=0, scale=4000.0, page_size=16384))  # 12 tiles of 16001^2
    print("BAKED", b.memory.texture_bytes)
except IATError as e:
    print("IATError", type(e).__name__, e)
except MemoryError as e:
    print("MemoryError", e)
"""


def test_baking_texture_memory_beyond_the_host_is_a_bake_error(tmp_path):
    """D8 (fixed): a bake larger than the memory available (ulimit -v 3 GiB here) is a BakeError raised
    before allocating, not a MemoryError."""
    script = tmp_path / "huge.py"
    script.write_text(_HUGE_BAKE)
    r = subprocess.run([sys.executable, str(script), str(ROOT)], capture_output=True, text=True, timeout=300)
    out = (r.stdout.strip().splitlines() or [r.stderr.strip()[-300:]])[-1]
    record("texture_over_gl_limit", huge_scale_outcome=out)
    assert out.startswith("IATError BakeError"), out


def test_baking_mipmaps_do_not_bleed_across_gutters_far_away(renderer):
    """A checkerboard of red and green patches seen from far away (a patch covers about a pixel):
    with the mip levels the gutter allows (1 + floor(log2 gutter)), no pixel mixes two tiles; with a
    full mip chain over the same atlas, the colours bleed (measured)."""
    corners = ss.grid_corners(16, 16)
    checker = lambda p, x: np.stack([(p + p // 16) % 2, 1 - (p + p // 16) % 2, np.zeros(len(p))], 1)  # noqa: E731
    sol = ss.synthetic_solution(corners, checker, max_depth=3)
    cam_far = Camera(eye=[8.0, 8.0, 160.0], target=[8.0, 8.0, 0.0], yfov=8.0, znear=1.0, zfar=400)
    out = {}
    for gutter in (2, 4):
        baked = Baker(sol).bake(BakePolicy(threshold=0, gutter=gutter, mipmaps=True))
        assert baked.mip_levels == mip_levels(gutter)
        for label, b in (("rule", baked), ("full_chain", dataclasses.replace(baked, mip_levels=None))):
            renderer.set_baked(b)
            img = renderer.render(cam_far, (24, 24), "iat").astype(np.float64)
            rg = img[..., :2]
            shown = rg.sum(axis=2) > 0
            bleed = float((rg.min(axis=2)[shown] / rg.sum(axis=2)[shown]).max())
            out[f"gutter{gutter}_{label}_max_bleed"] = bleed
    record("mipmap_bleeding", **out)
    assert out["gutter2_rule_max_bleed"] < 1e-3 and out["gutter4_rule_max_bleed"] < 1e-3
    assert out["gutter2_full_chain_max_bleed"] > 0.05  # what the rule prevents


# =================================================================================================
# Files
# =================================================================================================
def _bad_inputs(root: Path, solution: Path) -> dict[str, Path]:
    """name -> path of every bad input (models and solutions)."""
    root.mkdir(parents=True, exist_ok=True)
    files = {
        "empty.obj": b"",
        "garbage.glb": b"this is not a glb file at all" * 10,
        "truncated.glb": CORNELL.read_bytes()[:3000],
        "index_out_of_range.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
        "nan.obj": b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "degenerate.obj": b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
        "binary_junk.obj": bytes(range(256)) * 8,
        "points.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n",
        "header_only.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        "truncated.stl": b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n",
        "model.xyz123": b"v 0 0 0\n",
        "empty.npz": b"",
        "junk.npz": bytes(range(256)) * 4,
    }
    out = {}
    for name, data in files.items():
        (root / name).write_bytes(data)
        out[name] = root / name
    (root / "a_directory.obj").mkdir(exist_ok=True)
    out["a_directory.obj"] = root / "a_directory.obj"
    out["missing.glb"] = root / "missing.glb"
    np.savez(root / "not_a_solution.npz", a=np.zeros(3))
    out["not_a_solution.npz"] = root / "not_a_solution.npz"
    with np.load(solution, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    other = dict(data, version=np.array(99))
    np.savez(root / "version99.npz", **other)
    out["version99.npz"] = root / "version99.npz"
    damaged = {k: v for k, v in data.items() if k != "vert_radiance"}
    np.savez(root / "missing_array.npz", **damaged)
    out["missing_array.npz"] = root / "missing_array.npz"
    one_triangle = ss.write_obj(root / "edited_model.obj", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    np.savez(root / "model_changed.npz", **dict(data, model_path=np.array(str(one_triangle))))
    out["model_changed.npz"] = root / "model_changed.npz"
    return out


@pytest.fixture(scope="module")
def small_solution_file(tmp_path_factory):
    """A Cornell box solution at depth 2 (its model_path points at the sample file)."""
    path = tmp_path_factory.mktemp("sol") / "cornell.npz"
    scene = load_scene(CORNELL)
    sol = solve(scene, opts(max_depth=2, samples=4))
    sol.model_path = str(CORNELL)
    sol.save(path)
    return path


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory, small_solution_file):
    return _bad_inputs(tmp_path_factory.mktemp("bad"), small_solution_file)


def _run_cli(argv, capsys, caplog) -> tuple[int, list[str], list]:
    from iat.cli.commands import main

    capsys.readouterr()
    caplog.clear()
    rc = main([str(a) for a in argv])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    return rc, err, [r for r in caplog.records if r.levelno >= 30]


def test_files_every_bad_input_is_one_line_and_exit_2(tmp_path, bad_inputs, capsys, caplog):
    """Every bad file x every command (info, solve, bake, render): exit status 2, exactly one line on
    stderr naming the file, no traceback, no warning logged (it would be a second line), no output file."""
    rows = {}
    out = {"solve": tmp_path / "s.npz", "bake": tmp_path / "o.glb", "render": tmp_path / "o.png"}
    for name, path in bad_inputs.items():
        for command in ("info", "solve", "bake", "render"):
            if command == "solve" and name.endswith(".npz"):
                pass  # a solution given to solve is an unsupported model type: still one line, exit 2
            extra = [] if command == "info" else ["-o", out[command], "--max-depth", "1", "--samples", "1"]
            if command == "render":
                extra += ["--size", "8x6"]
            rc, err, warnings = _run_cli([command, path, *extra], capsys, caplog)
            assert rc == 2, (command, name, err)
            assert len(err) == 1 and name in err[0] and "Traceback" not in err[0], (command, name, err)
            assert not warnings, (command, name, [w.getMessage() for w in warnings])
            assert not any(p.exists() for p in out.values()), (command, name)
            rows[f"{command} {name}"] = err[0]
    record(
        "cli_bad_inputs",
        cases=len(rows),
        messages={k: v.split(": error: ")[1].split(": ", 1)[1] for k, v in rows.items()},
    )


def test_files_bad_inputs_real_stderr_is_one_line(bad_inputs, tmp_path):
    """The same through a real process (what a shell sees): nothing but the one line on stderr, for a
    sample of the new bad inputs and commands."""
    cases = [
        ("info", "truncated.glb"),
        ("solve", "points.ply"),
        ("bake", "junk.npz"),
        ("render", "version99.npz"),
        ("render", "model_changed.npz"),
    ]
    for command, name in cases:
        extra = [] if command == "info" else ["-o", tmp_path / ("o.png" if command == "render" else "o.out")]
        r = subprocess.run(
            [sys.executable, "-m", "iat.cli", command, str(bad_inputs[name]), *map(str, extra)],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=120,
        )
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 2 and len(lines) == 1 and name in lines[0], (command, name, r.stderr)
        assert r.stdout == "", (command, name, r.stdout)


def test_files_junk_npz_message_does_not_suggest_unpickling(bad_inputs):
    """D9 (fixed): a junk .npz is refused before np.load, whose message suggested allow_pickle."""
    with pytest.raises(SolutionFileError) as e:
        Solution.load(bad_inputs["junk.npz"])
    record("cli_bad_inputs", junk_npz_message=str(e.value))
    assert "pickle" not in str(e.value)


def test_files_viewer_open_job_reports_each_bad_input_on_one_line(bad_inputs, tmp_path, monkeypatch):
    """The viewer's open path (viewer.jobs.OpenJob, what `iat view FILE` runs after the window is up):
    every bad file ends in one line naming it, the job finishes, nothing is raised into the UI."""
    from viewer.jobs import OpenJob

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    errors = {}
    for name, path in bad_inputs.items():
        job = OpenJob(path, opts(max_depth=1, samples=1), BakePolicy())
        assert job.join(60.0), name
        assert job.result is None and job.error, (name, job.error)
        assert "\n" not in job.error and name in job.error, (name, job.error)
        errors[name] = job.error
    record("viewer_bad_inputs", cases=len(errors), version99=errors["version99.npz"])


def test_files_view_without_a_display_is_one_line_naming_the_file(bad_inputs):
    """`iat view missing.glb` with no DISPLAY, in a real process: exit 2 and one line of ours naming the
    file (D10 fixed: the file is checked and the display looked for before GLFW is loaded, so GLFW
    prints nothing)."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run(
        [sys.executable, "-m", "iat.cli", "view", str(bad_inputs["missing.glb"])],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=120,
    )
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    record("view_no_display", exit_status=r.returncode, stderr_lines=len(lines), stderr=lines)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(lines) == 1 and lines[0].startswith("iat view: ") and "missing.glb" in lines[0]


def test_files_view_without_a_display_every_bad_input_is_one_line_and_exit_2(
    bad_inputs, capsys, caplog, monkeypatch
):
    """`iat view BAD` with no display, for every bad input: exit 2, one line naming the file and its
    fault, no traceback, no window: with no display `view` reads the file first (with a display the
    window's open job reads it, see the viewer row)."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    named = 0
    for name, path in bad_inputs.items():
        rc, err, warnings = _run_cli(["view", path], capsys, caplog)
        assert rc == 2 and len(err) == 1 and "Traceback" not in err[0], (name, err)
        assert not warnings, (name, [w.getMessage() for w in warnings])
        assert name in err[0] and "no display" not in err[0], (name, err)
        named += name in err[0]
    record("view_no_display", bad_inputs=len(bad_inputs), bad_inputs_named=named)


def test_files_missing_file_is_file_not_found_everywhere(tmp_path, capsys, caplog, monkeypatch):
    """G5 (fixed): a missing file is "<path>: file not found" from load_scene, open_solution and
    Solution.load, and from every command (info, solve, bake, render, view)."""
    from iat.radiosity.inputs import open_solution

    model, solution = tmp_path / "gone.glb", tmp_path / "gone.npz"
    for fn, path in (
        (load_scene, model),
        (open_solution, model),
        (open_solution, solution),
        (Solution.load, solution),
    ):
        with pytest.raises(IATError) as e:
            fn(path)
        assert str(e.value) == f"{path}: file not found", (fn, str(e.value))
    monkeypatch.delenv("DISPLAY", raising=False)  # view: never open a window here
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = {
        "solve": ["-o", tmp_path / "s.npz"],
        "bake": ["-o", tmp_path / "o.glb"],
        "render": ["-o", tmp_path / "o.png"],
    }
    for command in ("info", "solve", "bake", "render", "view"):
        for path in (model, solution):
            rc, err, _ = _run_cli([command, path, *out.get(command, [])], capsys, caplog)
            assert rc == 2 and err == [f"iat {command}: error: {path}: file not found"], (command, path, err)


def test_files_info_and_solve_on_a_solution_say_what_would_help(
    small_solution_file, tmp_path, capsys, caplog
):
    """G5 (fixed): `iat info SOL.npz` / `iat solve SOL.npz` say the file is a solution, which commands
    read models, and name the model it was solved from (was "unsupported file type '.npz'")."""
    lines = {}
    for command, extra in (("info", []), ("solve", ["-o", tmp_path / "again.npz"])):
        rc, err, _ = _run_cli([command, small_solution_file, *extra], capsys, caplog)
        assert rc == 2 and len(err) == 1, (command, err)
        head, msg = err[0].split(": error: ", 1)
        assert head == f"iat {command}", err
        assert msg.startswith(f"{small_solution_file}: a solution file, not a model"), msg
        assert f"'iat {command}' reads models (.glb" in msg and "read solutions" in msg
        assert f"run it on {CORNELL}, the model it was solved from" in msg
        lines[command] = msg
    assert not (tmp_path / "again.npz").exists()
    record("cli_bad_inputs", info_on_a_solution=lines["info"])


# -- interrupted writes --------------------------------------------------------------------------------
class _DiskFull:
    """A file object that takes ``limit`` bytes, then fails like a full disk."""

    def __init__(self, f, limit):
        self._f, self._left = f, limit

    def write(self, data):
        data = memoryview(data).cast("B") if not isinstance(data, bytes | bytearray) else data
        if len(data) > self._left:
            self._f.write(bytes(data[: self._left]))
            self._left = 0
            raise OSError(errno.ENOSPC, "No space left on device (simulated)")
        self._left -= len(data)
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


def _writers(tmp_path, small_solution_file):
    """name -> (target path, write function) for the three files IAT writes."""
    from iat.export.gltf import export_glb
    from iat.io.images import save_png

    sol = Solution.load(small_solution_file)
    baked = Baker(sol).bake(BakePolicy(threshold=0))
    img = np.random.default_rng(0).random((64, 64, 3)).astype(np.float32)
    return {
        "solution": (tmp_path / "out.npz", lambda p: sol.save(p)),
        "glb": (tmp_path / "out.glb", lambda p: export_glb(baked, p)),
        "png": (tmp_path / "out.png", lambda p: save_png(p, img)),
    }


def test_files_interrupted_writes_leave_the_previous_file_intact(tmp_path, small_solution_file, monkeypatch):
    """The disk fills up half-way through each writer: the exception reaches the caller, the previous
    file is byte-for-byte intact, and no temporary file is left behind."""
    writers = _writers(tmp_path, small_solution_file)
    real_fdopen = os.fdopen
    sizes = {}
    for name, (target, write) in writers.items():
        write(target)
        before = target.read_bytes()
        sizes[name] = len(before)
        half = len(before) // 2
        monkeypatch.setattr(
            os, "fdopen", lambda fd, *a, _n=half, **k: _DiskFull(real_fdopen(fd, *a, **k), _n)
        )
        with pytest.raises(OSError, match="No space left"):
            write(target)
        monkeypatch.setattr(os, "fdopen", real_fdopen)
        assert target.read_bytes() == before, name
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")) == [], name
    record("interrupted_writes", disk_full_previous_intact=True, file_bytes=sizes)


def test_files_atomic_writers_fsync_the_temporary_before_the_rename(
    tmp_path, small_solution_file, monkeypatch
):
    """G3 (fixed): Solution.save, export_glb and save_png all go through imageio.atomic_write: the
    temporary `.<name>.<random>.tmp` is fsynced, then renamed over the target, nothing else."""
    from iat.fsutil import temporary_pattern

    writers = _writers(tmp_path, small_solution_file)
    real_fsync, real_replace = os.fsync, os.replace
    events = []

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        return real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", os.fspath(src), os.fspath(dst)))
        return real_replace(src, dst)

    for name, (target, write) in writers.items():
        events.clear()
        monkeypatch.setattr(os, "fsync", fsync)
        monkeypatch.setattr(os, "replace", replace)
        try:
            write(target)
        finally:
            monkeypatch.setattr(os, "fsync", real_fsync)
            monkeypatch.setattr(os, "replace", real_replace)
        assert [e[0] for e in events] == ["fsync", "replace"], (name, events)
        assert events[0][1] == events[1][1] and events[1][2] == str(target), (name, events)
        assert temporary_pattern(target).fullmatch(Path(events[1][1]).name), (name, events)
    record("interrupted_writes", fsync_then_rename=sorted(writers))


_KILLED_WRITER = r"""
import os, sys, time
sys.path.insert(0, sys.argv[1])
from tests.test_stability import _writers, _DiskFull
from pathlib import Path
name, target_dir, sol = sys.argv[2], Path(sys.argv[3]), Path(sys.argv[4])
target, write = _writers(target_dir, sol)[name]
real = os.fdopen
class Stall(_DiskFull):
    def write(self, data):
        n = len(memoryview(data).cast("B")) if not isinstance(data, (bytes, bytearray)) else len(data)
        if n > self._left:
            self._f.write(bytes(memoryview(data).cast("B")[: self._left])); self._f.flush()
            print("HALF", flush=True); time.sleep(60)
        self._left -= n
        return self._f.write(data)
os.fdopen = lambda fd, *a, **k: Stall(real(fd, *a, **k), target.stat().st_size // 2)
write(target)
"""


def test_files_killed_writers_leave_the_previous_file_intact(tmp_path, small_solution_file):
    from iat.fsutil import STALE_TEMPORARY_S, temporary_pattern

    """SIGKILL half-way through each writer (no cleanup can run): the previous file is intact; the
    half-written temporary `.<name>.<random>.tmp` stays behind next to it until the next successful
    write of the same file, which removes it once it is older than STALE_TEMPORARY_S (1 h; a younger
    one may be another process's write in progress) (G4 fixed)."""
    script = tmp_path / "killed.py"
    script.write_text(_KILLED_WRITER)
    debris = {}
    for name, (target, write) in _writers(tmp_path, small_solution_file).items():
        write(target)
        before = target.read_bytes()
        p = subprocess.Popen(
            [sys.executable, str(script), str(ROOT), name, str(tmp_path), str(small_solution_file)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        try:
            line = p.stdout.readline()
            assert line.strip() == "HALF", (name, line, p.stderr.read() if p.poll() is not None else "")
        finally:
            p.send_signal(signal.SIGKILL)
            p.wait(30)
        assert target.read_bytes() == before, name
        left = [q for q in tmp_path.iterdir() if q.name.endswith(".tmp")]
        debris[name] = [[q.name, q.stat().st_size] for q in left]
        assert len(left) == 1 and temporary_pattern(target).fullmatch(left[0].name), (name, left)
        # the next write cleans it up once it is stale; a young one (a live writer's) and files of
        # other names are left alone
        stale = time.time() - 2 * STALE_TEMPORARY_S
        os.utime(left[0], (stale, stale))
        young = target.with_name(f".{target.name}.young0.tmp")
        other = target.with_name(f".{target.name}.keep.me.tmp")  # not the pattern: a dot in <random>
        for q in (young, other):
            q.write_bytes(b"x")
        os.utime(other, (stale, stale))
        write(target)
        assert not left[0].exists() and young.exists() and other.exists(), name
        assert target.read_bytes() != b"" and target.stat().st_size > 0
        young.unlink()
        other.unlink()
        assert [q.name for q in tmp_path.iterdir() if q.name.endswith(".tmp")] == [], name
    record(
        "interrupted_writes",
        sigkill_previous_intact=True,
        sigkill_debris=debris,
        debris_removed_by_next_write=True,
        stale_after_s=STALE_TEMPORARY_S,
    )


# =================================================================================================
# Soak
# =================================================================================================
def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_soak_a_thousand_rebakes(renderer, grid_solution):
    """1 000 re-bakes (threshold, scale, method and format cycling through more values than the caches
    hold) each uploaded and drawn: GL objects constant, traced host memory and RSS flat."""
    scene, sol = grid_solution
    baker = Baker(sol, scene)
    deepest = int(sol.patch_depth().max())
    scales = [0.25 * 1.2**k for k in range(13)]
    methods = ["bilinear", "scan", "bicubic"]
    formats = ["rgba16f", "rgba8"]
    cam = Camera(eye=[2.0, 1.5, 3.0], target=[2.0, 1.5, 0.0], yfov=60.0, znear=0.01, zfar=10)

    def policy(k):
        return BakePolicy(
            threshold=k % (deepest + 2),
            scale=scales[k % len(scales)],
            method=methods[(k // 7) % 3],
            pixel_format=formats[(k // 11) % 2],
        )

    renderer.set_solution(sol)
    warm = 200
    for k in range(warm):
        renderer.set_baked(baker.bake(policy(k)))
        renderer.render(cam, (16, 12), "iat")
    n_gl = renderer.gl_object_count()
    tracemalloc.start()
    rss0 = _rss()
    t0 = time.perf_counter()
    gl_counts, traced = set(), []
    for k in range(warm, 1000):
        renderer.set_baked(baker.bake(policy(k)))
        renderer.render(cam, (16, 12), "iat")
        gl_counts.add(renderer.gl_object_count())
        if k % 100 == 99:
            gc.collect()
            traced.append(tracemalloc.get_traced_memory()[0])
    dt = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    growth_rss = _rss() - rss0
    mb = [round(t / 2**20, 2) for t in traced]
    record(
        "soak_1000_rebakes",
        bakes=baker.stats["bakes"],
        gl_objects=sorted(gl_counts),
        gl_objects_after_warmup=n_gl,
        traced_mb_every_100=mb,
        traced_peak_mb=round(peak / 2**20, 2),
        rss_growth_mb=round(growth_rss / 2**20, 2),
        seconds_for_800=round(dt, 1),
    )
    assert baker.stats["bakes"] == 1000
    assert gl_counts == {n_gl}
    # host memory: what the bounded caches hold goes up and down with the policy; it does not grow
    assert max(traced) < 16 * 2**20
    assert max(traced[-3:]) <= max(traced[:3]) + 2**20
    assert growth_rss < 32 * 2**20


def test_soak_bake_worker_coalesces_a_burst(grid_solution):
    """The viewer's BakeWorker under a 500-request burst (a slider dragged fast): requests coalesce,
    the thread stays single, the last policy asked is the one baked."""
    from viewer.bake_worker import BakeWorker

    scene, sol = grid_solution
    w = BakeWorker(Baker(sol, scene))
    try:
        threads0 = threading.active_count()
        last = None
        for k in range(500):
            last = BakePolicy(threshold=k % 4, scale=0.5 + (k % 5) * 0.25)
            w.submit(last)
        assert w.wait(60.0)
        r = w.poll()
        assert r is not None and r.error is None and r.policy == last
        record("soak_bake_worker", requests=500, bakes_done=w.bakes)
        assert w.bakes < 500 and threading.active_count() == threads0
    finally:
        w.close()
