"""Stability catalogue (docs/stability.md), Geometry: zero-area, sliver, overlapping, intersecting,
T-junction, open and double-sided meshes; extreme scales; non-finite coordinates; a million triangles."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from iat.bake.baker import Baker
from iat.bake.flatten import flatten, sample_tile
from iat.bake.policy import BakePolicy
from iat.camera import Camera
from iat.errors import IATError, LoadError
from iat.geometry import quadtree as qt
from iat.io.load import load_scene
from iat.radiosity import Solution, SolveOptions, solve
from iat.radiosity.options import RAY_EPS
from tests import stability_scenes as ss
from tests.support.stability import ROOT, opts, record, vertex_patch

pytestmark = pytest.mark.usefixtures("stability_figures")


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
    on = vertex_patch(sol) == sliver
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
    p = vertex_patch(sol)
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
        beyond = (vertex_patch(sol) == 0) & (sol.vert_position[:, 0] > 0.1)
        assert sol.vert_radiance[beyond].max() == 0.0
    assert out[5][0] < out[3][0]  # deeper trees: a narrower leak
    # with the solver's defaults (ambient term on, where the solver has one) the far side is not black:
    # it gets the uniform ambient estimate of the unshot light; measured, not a leak
    sol = solve(ss.wall_through_floor(wall_x=0.1), SolveOptions(max_depth=5))
    beyond = (vertex_patch(sol) == 0) & (sol.vert_position[:, 0] > 0.2)
    lit = (vertex_patch(sol) == 0) & (sol.vert_position[:, 0] < 0.0)
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
    p = vertex_patch(sol)
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
