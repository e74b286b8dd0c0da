# ruff: noqa: E501
"""Solver benchmarks (issue 4): accuracy per element, ray throughput, the Cornell box goal.

    .venv/bin/python benchmarks/solver_bench.py [adaptive] [shadow] [rays] [cornell] [quality] [speed]
        [--models a,b] [--before DIR]

writes ``benchmarks/solver.json`` (merged with what is there) and ``benchmarks/solver.md``.

* **adaptive** -- on the Cornell box: uniform subdivision (``criterion="uniform"``) at depths
  1..``UNIFORM_DEPTHS`` and the adaptive mesh (the default criterion, max depth 6) at several
  tolerances, every solve with the default convergence, samples, seed and ambient term and no
  minimum element size. Errors: (1) the relative error on smooth lit pixels against the Mitsuba
  reference of ``tests/test_reference_compare.py`` (512 spp, 96 x 96, cached in ``tests/refs``;
  its own noise floor, measured against a 4096 spp render, is ~0.035); against the radiosity
  reference ``REFERENCE`` (uniform depth 6 with 2x the samples per side and another seed, so
  that no solve shares its Monte Carlo errors): (2) the same image measure, and (3) the
  area-weighted L1 error of the surface radiance (every patch sampled at 256 x 256 cell
  centres, emitters left out), which unlike the 96 x 96 image sees shadow edges; and (4) the
  surface error of direct light alone (the same solves with ``max_shots=0``: the stage-A mesh
  and its exactly evaluated direct light, against the reference's), the mesh's error with no
  indirect-light noise. For each adaptive solve the uniform element count at the same error
  is interpolated (log elements against log error, between the two uniform solves that bracket
  it) and the ratio adaptive / uniform reported (goal <= 0.25). The uniform depth-6 row (the
  reference's mesh) shows the noise floor of a solve at the default samples.
* **quality** -- each ``--quality`` level (``QUALITY_PRESETS``) on the Cornell box and on the
  daylit room of ``tests/test_daylight.py`` against their 4096-spp references: solve time (best
  of 2, kernels loaded), vertices, the per-pixel and block errors and the bias.
* **shadow** -- the same comparison on a floor under a point light with an occluder (one hard
  shadow), by the surface error against uniform depth 7, every solve converged to 0.1 % without
  the ambient term (so the error is the mesh's).
* **rays** -- per sample model: the solve at the defaults (time, rays, the solver's rays/s:
  rays over the seconds spent inside ``Visibility.occluded``, and over the whole solve), and
  in the same run the ceiling: bare embreex replaying the solver's own rays (the first 4 M,
  recorded during the solve, already float32, cut in ``Visibility.CHUNK`` pieces as
  ``occluded`` cuts them, on the same 2 threads, no Python work around the calls), and for
  comparison bare embreex on random rays (origins on the patches, cosine directions, tfar the
  scene diagonal: longer than the solver's shadow rays, so slower).
* **cornell** -- the Cornell box at the defaults: time and the error of ``test_reference_compare``.
* **speed** -- solve time before / after a change (issue 18: the compiled kernels): default solves
  of the Cornell box and the house (or ``--models``) with an old ``iat`` tree at ``--before``
  (default ``/tmp/before``, made by ``git archive HEAD iat | tar -x -C /tmp/before``) and with
  this one, in alternating processes (best wall and CPU seconds of 2), the radiance difference,
  and the kernels' cold compile time.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# IAT_BENCH_TREE: another tree's ``iat`` (e.g. the ``rays`` figures before a change)
sys.path.insert(0, os.environ.get("IAT_BENCH_TREE", str(ROOT)))

from iat.io.load import load_scene  # noqa: E402
from iat.measure.metrics import reference_errors, smooth_lit_mask  # noqa: E402
from iat.radiosity import Solution, SolveOptions, solve  # noqa: E402
from iat.radiosity.visibility import CHUNK, Visibility  # noqa: E402

OUT_JSON = ROOT / "benchmarks" / "solver.json"
OUT_MD = ROOT / "benchmarks" / "solver.md"
MODELS = ("cornell_box", "house", "cave", "lavapit", "pool")
REFS = ROOT / "tests" / "refs"
SIZE = (96, 96)
UNIFORM_DEPTHS = (1, 2, 3, 4, 5, 6)
ADAPTIVE_TOLERANCES = (0.4, 0.2, 0.1, 0.05, 0.025)
#: the radiosity reference of ``adaptive``: uniform depth 6, 2x the samples per side, another seed
REFERENCE = {"max_depth": 6, "criterion": "uniform", "min_element_size": 0.0, "samples": 64, "seed": 1}


class Cornell:
    """The Cornell box, its camera, its Mitsuba reference (``spp``, ``seed``: 512 / 1 is the issue-4
    figures' reference, 4096 / 3 that of ``tests/test_reference_compare.py``) and a renderer (EGL)."""

    def __init__(self, spp: int = 512, seed: int = 1):
        from iat.measure.reference import render_reference_cached
        from iat.render.renderer import Renderer

        self.scene = load_scene(ROOT / "sample_models" / "cornell_box.glb")
        self.camera = self.scene.default_camera()
        self.ref = render_reference_cached(self.scene, self.camera, SIZE, spp=spp, cache_dir=REFS, seed=seed)
        self.mask = smooth_lit_mask(self.ref)
        self.renderer = Renderer(None)

    def image(self, sol) -> np.ndarray:
        """The mesh image at ``SIZE``, box-filtered as the reference's pixels are."""
        from iat.measure.reference import box_filtered_render

        self.renderer.set_solution(sol)
        return box_filtered_render(self.renderer, self.camera, SIZE, "mesh")

    def errors(self, sol, ref: np.ndarray | None = None) -> dict:
        return reference_errors(self.image(sol), self.ref if ref is None else ref, self.mask)


def surface_points(sol, n_out: int = 256) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The centres of an n_out x n_out grid of cells in each patch's (u, v) (no lattice point of any
    depth, so no solution is sampled only at its own vertices; on triangles those with u + v <= 1):
    (k,) patch, u, v and the area (m^2) each point stands for, concatenated over the patches."""
    from iat.geometry.mesh import patch_areas

    g = (np.arange(n_out) + 0.5) / n_out
    uu, vv = (x.ravel() for x in np.meshgrid(g, g, indexing="ij"))
    tri = uu + vv <= 1.0 + 1e-12
    corners, quad = np.asarray(sol.patch_corners), np.asarray(sol.patch_is_quad)
    area = patch_areas(corners, quad)
    count = np.where(quad, len(uu), int(tri.sum()))
    patch = np.repeat(np.arange(len(corners)), count)
    u = np.concatenate([uu if q else uu[tri] for q in quad])
    v = np.concatenate([vv if q else vv[tri] for q in quad])
    return patch, u, v, (area / count)[patch]


def values_at(sol, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(k,) luminance of the solution's mesh (piecewise linear in its leaves) at (u, v) (k,) of its
    patches ``patch`` (k,)."""
    from iat.color import LUMINANCE_WEIGHTS
    from iat.radiosity.sampling import Lattice, sample_lattice

    lat = Lattice(sol.forest, np.asarray(sol.vert_key))
    vals = np.asarray(sol.vert_radiance, dtype=np.float64)
    out = np.empty(len(patch))
    order = np.argsort(patch, kind="stable")
    bounds = np.searchsorted(patch[order], np.arange(len(sol.patch_corners) + 1))
    for p in np.unique(patch):
        idx = order[bounds[p] : bounds[p + 1]]
        flat = lat.grid(p, vals).reshape(-1, 3)
        out[idx] = sample_lattice(flat, sol.n, u[idx], v[idx]) @ LUMINANCE_WEIGHTS
    return out


def patch_uv(
    corners: np.ndarray, is_quad: np.ndarray, patch: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) (k,) of world points x (k, 3) on patches ``patch`` (k,) of corners (P, 4, 3): the
    inverse of :func:`iat.geometry.quadtree.patch_point` (Gauss-Newton; exact on triangles)."""
    from iat.geometry.quadtree import patch_point

    c = np.asarray(corners)[patch]
    quad = np.asarray(is_quad)[patch][:, None]
    u, v = np.full(len(patch), 0.5), np.full(len(patch), 0.5)
    for _ in range(8):
        uc, vc = u[:, None], v[:, None]
        du = np.where(quad, (1 - vc) * (c[:, 1] - c[:, 0]) + vc * (c[:, 2] - c[:, 3]), c[:, 1] - c[:, 0])
        dv = np.where(quad, (1 - uc) * (c[:, 3] - c[:, 0]) + uc * (c[:, 2] - c[:, 1]), c[:, 2] - c[:, 0])
        r = x - patch_point(corners, is_quad, patch, u, v)
        a, b, d = (du * du).sum(1), (du * dv).sum(1), (dv * dv).sum(1)
        ru, rv = (du * r).sum(1), (dv * r).sum(1)
        det = np.maximum(a * d - b * b, 1e-300)
        u, v = u + (d * ru - b * rv) / det, v + (a * rv - b * ru) / det
    return u, v


def read_on(sol, ref_sol, q: np.ndarray, x: np.ndarray, tol: float = 1e-6):
    """Where the reference's points x (k, 3), on its patches q (k,), fall on ``sol``'s patches,
    when the two were loaded with other cuts (an older loader that cut nothing where geometry
    crosses or along shadows, or a region made again as other cells): (k,) the patch of ``sol``
    that holds each point and faces the same way, and its (u, v) there. Raises ValueError when a
    point lies on none."""
    from iat.geometry.mesh import patch_normals

    corners, quad = np.asarray(sol.patch_corners), np.asarray(sol.patch_is_quad)
    nrm = patch_normals(corners, quad)
    ref_nrm = patch_normals(np.asarray(ref_sol.patch_corners), np.asarray(ref_sol.patch_is_quad))
    lo = np.where(quad[:, None], corners.min(axis=1), corners[:, :3].min(axis=1)) - tol
    hi = np.where(quad[:, None], corners.max(axis=1), corners[:, :3].max(axis=1)) + tol
    offset = np.einsum("pc,pc->p", nrm, corners[:, 0])
    root, ur, vr = np.full(len(q), -1), np.zeros(len(q)), np.zeros(len(q))
    order = np.argsort(q, kind="stable")
    bounds = np.searchsorted(q[order], np.arange(len(ref_sol.patch_corners) + 1))
    for p in np.unique(q):
        idx = order[bounds[p] : bounds[p + 1]]
        pts = x[idx]
        cand = np.flatnonzero(
            (nrm @ ref_nrm[p] > 0.999)
            & np.all((lo <= pts.max(axis=0)) & (pts.min(axis=0) <= hi), axis=1)
            & (np.abs(nrm @ pts[0] - offset) < 1e-5)
        )
        for c in cand:
            todo = idx[root[idx] < 0]
            if not len(todo):
                break
            u, v = patch_uv(corners, quad, np.full(len(todo), c), x[todo])
            inside = (
                (u >= -tol)
                & (v >= -tol)
                & ((u <= 1 + tol) & (v <= 1 + tol) if quad[c] else (u + v <= 1 + tol))
            )
            root[todo[inside]], ur[todo[inside]], vr[todo[inside]] = c, u[inside], v[inside]
    if (root < 0).any():
        raise ValueError(f"{int((root < 0).sum())} of the reference's points lie on no patch of the solution")
    return root, np.clip(ur, 0.0, 1.0), np.clip(vr, 0.0, 1.0)


def surface_error(sol, ref_sol, n_out: int = 256) -> float:
    """Area-weighted L1 error of the radiance over all surfaces (luminance, sampled at n_out x n_out
    cell centres per patch of the reference, emitters excluded) relative to the reference's mean:
    shadow edges count here, unlike in the smooth-pixel image measure. A solution whose patches are
    not the reference's is read where the reference's points fall on its patches (:func:`read_on`)."""
    from iat.geometry.quadtree import patch_point

    q, u, v, w = surface_points(ref_sol, n_out)
    b = values_at(ref_sol, q, u, v)
    ref_corners = np.asarray(ref_sol.patch_corners)
    if len(sol.patch_corners) == len(ref_corners) and np.allclose(sol.patch_corners, ref_corners):
        a = values_at(sol, q, u, v)
    else:
        a = values_at(
            sol, *read_on(sol, ref_sol, q, patch_point(ref_corners, ref_sol.patch_is_quad, q, u, v))
        )
    emitters = [int(row[0]) for row in ref_sol.stats.get("sources", {}).get("emitters", [])]
    w = np.where(np.isin(q, emitters), 0.0, w)
    return float((np.abs(a - b) * w).sum() / (np.abs(b) * w).sum())


def timed_solve(scene, opts: SolveOptions):
    t0 = time.perf_counter()
    sol = solve(scene, opts)
    return sol, time.perf_counter() - t0


# -- adaptive against uniform -------------------------------------------------------------------
def interp_at_error(err: float, curve: list[tuple[float, float]]) -> float | None:
    """The cost (uniform elements, seconds) at error ``err``: log-log interpolation between the
    two points of ``curve`` ((error, cost), any order) that bracket it; None outside the curve."""
    pts = sorted(curve, key=lambda p: -p[0])  # error decreasing, cost increasing
    for (e0, n0), (e1, n1) in zip(pts, pts[1:], strict=False):
        if e1 <= err <= e0 and e0 > e1:
            t = (math.log(e0) - math.log(err)) / (math.log(e0) - math.log(e1))
            return float(math.exp(math.log(n0) + t * (math.log(n1) - math.log(n0))))
    return None


def run_adaptive(depths=UNIFORM_DEPTHS, tolerances=ADAPTIVE_TOLERANCES) -> dict:
    """Adaptive against uniform on the Cornell box (see the module docstring). The radiosity
    reference is uniform depth 6 solved with ``REFERENCE`` (2x the samples per side, another
    seed): a reference of the same samples and seed as the solves shares their Monte Carlo
    errors where their vertices coincide (the depth-6 adaptive mesh's vertex keys and sample
    rotations are the depth-6 solve's), which flatters the adaptive mesh, and its own noise
    would be a floor under every error. The uniform depth-6 row, solved like the others,
    measures what is left: the noise of a solve at the default samples (its mesh is the
    reference's)."""
    cb = Cornell()
    rows = []
    sols, direct = {}, {}

    def add(key, opts):
        sol, dt = timed_solve(cb.scene, opts)
        sols[key] = sol
        direct[key], _ = timed_solve(cb.scene, replace(opts, max_shots=0))
        rows.append(
            {
                "mesh": key[0],
                "depth": opts.max_depth,
                "tolerance": key[1] if key[0] == "adaptive" else None,
                "elements": sol.stats["elements"],
                "direct_elements": direct[key].stats["elements"],
                "time_s": dt,
                **cb.errors(sol),
            }
        )
        print(rows[-1], flush=True)

    for d in depths:
        add(("uniform", d), SolveOptions(max_depth=d, criterion="uniform", min_element_size=0.0))
    for tol in tolerances:
        add(("adaptive", tol), SolveOptions(tolerance=tol, min_element_size=0.0))
    ref_opts = SolveOptions(**REFERENCE)
    ref, ref_dt = timed_solve(cb.scene, ref_opts)
    ref_direct, _ = timed_solve(cb.scene, replace(ref_opts, max_shots=0))
    ref_img = cb.image(ref)
    for r in rows:
        key = ("uniform", r["depth"]) if r["mesh"] == "uniform" else ("adaptive", r["tolerance"])
        r["rel_smooth_vs_uniform"] = reference_errors(cb.image(sols[key]), ref_img, cb.mask)["rel_smooth"]
        r["surface_vs_uniform"] = surface_error(sols[key], ref)
        r["direct_surface_vs_uniform"] = surface_error(direct[key], ref_direct)
    for measure, count in (
        ("rel_smooth", "elements"),
        ("rel_smooth_vs_uniform", "elements"),
        ("surface_vs_uniform", "elements"),
        ("direct_surface_vs_uniform", "direct_elements"),
    ):
        curve = [(r[measure], r[count]) for r in rows if r["mesh"] == "uniform"]
        for r in rows:
            if r["mesh"] != "adaptive":
                continue
            nu = interp_at_error(r[measure], curve)
            r[f"uniform_elements_at_{measure}"] = nu
            r[f"ratio_{measure}"] = (r[count] / nu) if nu else None
    cb.renderer.release()
    return {
        "model": "cornell_box",
        "reference": {"options": ref_opts.to_dict(), "elements": ref.stats["elements"], "time_s": ref_dt},
        "rows": rows,
    }


def shadow_scene():
    """A 2 x 2 m floor (4 quads) under a point light 2 m up, with a 0.5 m square occluder halfway:
    one hard-edged shadow and a smooth 1/r^2 fall-off, the case adaptive meshing is for (the
    scene of ``tests/test_radiosity.floor_scene``)."""
    from iat.io.scene import Light, Material, Scene

    polys = []
    for i in range(2):
        for j in range(2):
            x0, z0 = i - 1.0, j - 1.0
            polys.append([[x0, 0, z0], [x0, 0, z0 + 1], [x0 + 1, 0, z0 + 1], [x0 + 1, 0, z0]])
    polys.append([[-0.25, 1.0, -0.25], [-0.25, 1.0, 0.25], [0.25, 1.0, 0.25], [0.25, 1.0, -0.25]])
    verts = np.array(polys, dtype=float).reshape(-1, 3)
    corners = np.arange(len(verts)).reshape(-1, 4)
    light = Light(kind="point", position=[0.1, 2.0, 0.05], intensity=4.0)
    return Scene(
        verts,
        corners,
        np.zeros(len(polys), dtype=int),
        [Material("white", albedo=np.full(3, 0.6))],
        lights=[light],
    )


def run_adaptive_surface(depths=(1, 2, 3, 4, 5, 6), ref_depth=7, tolerances=ADAPTIVE_TOLERANCES) -> dict:
    """Adaptive against uniform on :func:`shadow_scene`, by the surface error against a uniform
    solve at ``ref_depth`` (all solves to 0.1 % unshot without the ambient term, so that the error
    is the mesh's; no minimum element size)."""
    scene = shadow_scene()
    common = {"convergence": 0.001, "ambient": False, "min_element_size": 0.0}
    ref, _ = timed_solve(scene, SolveOptions(max_depth=ref_depth, criterion="uniform", **common))
    rows = []
    for d in depths:
        sol, dt = timed_solve(scene, SolveOptions(max_depth=d, criterion="uniform", **common))
        rows.append(
            {
                "mesh": "uniform",
                "depth": d,
                "tolerance": None,
                "elements": sol.stats["elements"],
                "time_s": dt,
                "surface_vs_uniform": surface_error(sol, ref),
            }
        )
        print(rows[-1], flush=True)
    for tol in tolerances:
        sol, dt = timed_solve(scene, SolveOptions(max_depth=ref_depth - 1, tolerance=tol, **common))
        rows.append(
            {
                "mesh": "adaptive",
                "depth": ref_depth - 1,
                "tolerance": tol,
                "elements": sol.stats["elements"],
                "time_s": dt,
                "surface_vs_uniform": surface_error(sol, ref),
            }
        )
        print(rows[-1], flush=True)
    curve = [(r["surface_vs_uniform"], r["elements"]) for r in rows if r["mesh"] == "uniform"]
    for r in rows:
        if r["mesh"] == "adaptive":
            nu = interp_at_error(r["surface_vs_uniform"], curve)
            r["uniform_elements_at_surface_vs_uniform"] = nu
            r["ratio_surface_vs_uniform"] = (r["elements"] / nu) if nu else None
    return {"model": "shadow_scene", "reference": f"uniform depth {ref_depth}", "rows": rows}


# -- ray throughput -----------------------------------------------------------------------------
def random_rays(scene, n: int, seed: int = 0):
    """n rays from random points on the patches (area-weighted), off the surface, in cosine
    directions, tfar the scene diagonal: the solver's mix of shadow and hemisphere rays."""
    from tests.support.rays import surface_rays

    origin, d, diag = surface_rays(scene, n, np.random.default_rng(seed))
    return origin, d, np.full(n, diag)


def bare_rays_per_s(scene, n: int = 4 * CHUNK, rounds: int = 3) -> float:
    """Occlusion rays/s of embreex through :class:`Visibility` alone (CHUNK batches, its threads),
    best of ``rounds``: the ceiling of the solver's tracing."""
    o, d, t = random_rays(scene, n)
    best = 0.0
    with Visibility.of_scene(scene) as vis:
        vis.occluded(o[:CHUNK], d[:CHUNK], t[:CHUNK])  # warm up (BVH build, threads)
        for _ in range(rounds):
            t0 = time.perf_counter()
            vis.occluded(o, d, t)
            best = max(best, n / (time.perf_counter() - t0))
    return best


class RayRecorder:
    """Records (a sample of) the rays a solve traces, by wrapping :meth:`Visibility.occluded`:
    every batch while fewer than ``limit`` rays are kept (float32, as embreex gets them)."""

    def __init__(self, limit: int = 1 << 22):
        self.limit, self.kept, self.batches = limit, 0, []
        self.original = Visibility.occluded

    def __enter__(self):
        rec = self

        def occluded(vis, origins, dirs, tfar):
            if rec.kept < rec.limit and len(origins):
                rec.batches.append(
                    tuple(
                        np.ascontiguousarray(x, dtype=np.float32).reshape(len(origins), -1)
                        for x in (origins, dirs, tfar)
                    )
                )
                rec.kept += len(origins)
            return rec.original(vis, origins, dirs, tfar)

        Visibility.occluded = occluded
        return self

    def __exit__(self, *exc):
        Visibility.occluded = self.original


def bare_replay_rays_per_s(scene, batches, rounds: int = 3) -> float:
    """Bare embreex on the solver's own rays: the recorded batches, already float32, cut into
    ``CHUNK`` pieces as :meth:`Visibility.occluded` cuts them, on its 2 threads, with no Python
    work around the calls (best of ``rounds``)."""
    from concurrent.futures import ThreadPoolExecutor

    n = sum(len(b[0]) for b in batches)
    with (
        Visibility.of_scene(scene) as vis,
        ThreadPoolExecutor(vis.threads) as pool,
    ):
        jobs = []
        for o, d, t in batches:
            c = max(4096, min(CHUNK, -(-len(o) // vis.threads)))
            jobs += [(o[a : a + c], d[a : a + c], t[a : a + c, 0]) for a in range(0, len(o), c)]
        best = 0.0
        for _ in range(rounds + 1):  # the first round warms up
            t0 = time.perf_counter()
            for f in [pool.submit(vis.occluded_chunk, o, d, t) for o, d, t in jobs]:
                f.result()
            best = max(best, n / (time.perf_counter() - t0))
    return best


def run_rays(models=MODELS) -> dict:
    out = {}
    for name in models:
        scene = load_scene(ROOT / "sample_models" / f"{name}.glb")
        with RayRecorder() as rec:
            sol, dt = timed_solve(scene, SolveOptions())
        replay = bare_replay_rays_per_s(scene, rec.batches)
        random_ceiling = bare_rays_per_s(scene)
        st = sol.stats
        trace_s = st["rays"] / st["rays_per_s"] if st["rays_per_s"] > 0 else 0.0
        out[name] = {
            "elements": st["elements"],
            "triangles": st["triangles"],
            "shots": st["shots"],
            "time_s": dt,
            "unshot_fraction": st["unshot_fraction"],
            "ambient_luminance_fraction": st["ambient_luminance_fraction"],
            "rays": st["rays"],
            "trace_s": trace_s,
            "rays_per_s_tracing": st["rays_per_s"],
            "rays_per_s_solve": st["rays"] / dt,
            "bare_rays_per_s": replay,
            "bare_rays_replayed": rec.kept,
            "bare_random_rays_per_s": random_ceiling,
            "fraction_tracing": st["rays_per_s"] / replay,
            "fraction_solve": st["rays"] / dt / replay,
            "timings": {k: st.get(k) for k in ("meshing_s", "shooting_s", "refining_s")},
        }
        print(name, out[name], flush=True)
    return out


#: what one subprocess of ``speed`` (and ``equal_error.py``) runs: a solve of a sample model with the ``iat``
#: on its PYTHONPATH and the options given (JSON), printing its wall and CPU seconds (all threads),
#: and saving the solution
SPEED_CHILD = """
import json, sys, time
from iat.io.load import load_scene
from iat.radiosity import SolveOptions, solve
scene = load_scene(sys.argv[1])
opts = SolveOptions(**json.loads(sys.argv[4]))
w, c = time.perf_counter(), time.process_time()
sol = solve(scene, opts)
w, c = time.perf_counter() - w, time.process_time() - c
assert __import__("iat").__file__.startswith(sys.argv[3]), "iat imported from another tree"
sol.save(sys.argv[2])
print(json.dumps({"time_s": w, "cpu_s": c, "elements": sol.stats["elements"], "rays": sol.stats["rays"]}))
"""


def speed_child(
    tree: Path, model: str, out: Path, env_extra: dict | None = None, options: dict | None = None
) -> dict:
    import os
    import subprocess

    env = {**os.environ, "PYTHONPATH": str(tree), **(env_extra or {})}
    path = ROOT / "sample_models" / f"{model}.glb"
    args = [str(path), str(out), str(Path(tree).resolve()), json.dumps(options or {})]
    # run from the output's folder: `python -c` puts the working directory first on sys.path
    run = subprocess.run(
        [sys.executable, "-c", SPEED_CHILD, *args], env=env, capture_output=True, text=True, cwd=out.parent
    )
    if run.returncode:
        raise RuntimeError(f"solve of {model} with {tree} failed:\n{run.stderr[-2000:]}")
    return json.loads(run.stdout.strip().splitlines()[-1])


def run_speed(before: Path, models=("cornell_box", "house"), repeats: int = 2) -> dict:
    """Solve time before/after (issue 18): default solves of ``models`` with the ``iat`` tree at
    ``before`` (e.g. ``git archive HEAD iat | tar -x -C /tmp/before``) and with this one, each in
    its own process, alternating (before, after, before, after, ...) so that both see the same
    load; best wall and CPU seconds of ``repeats``, and how far the after radiance is from the
    before one. Also the kernels' cold compile time (an empty numba cache, a small solve, less
    the same solve with the cache warm)."""
    import os
    import tempfile

    tmp = Path(tempfile.mkdtemp(prefix="iat-speed-"))
    speed_child(ROOT, "cornell_box", tmp / "warm.npz")  # compile (or load) the kernels first
    out = {}
    for name in models:
        rows = {"before": [], "after": []}
        for _ in range(repeats):
            for label, tree in (("before", before), ("after", ROOT)):
                rows[label].append(speed_child(tree, name, tmp / f"{name}-{label}.npz"))
        a, b = (Solution.load(tmp / f"{name}-{label}.npz") for label in ("before", "after"))
        same_mesh = a.vert_key.shape == b.vert_key.shape and bool(np.all(a.vert_key == b.vert_key))
        a_rad = np.asarray(a.vert_radiance, dtype=np.float64)
        diff = np.abs(a_rad - b.vert_radiance) if same_mesh else None
        r = {
            label: {
                "time_s": min(x["time_s"] for x in v),
                "cpu_s": min(x["cpu_s"] for x in v),
                "elements": v[0]["elements"],
                "rays": v[0]["rays"],
            }
            for label, v in rows.items()
        }
        r["speedup_wall"] = r["before"]["time_s"] / r["after"]["time_s"]
        r["speedup_cpu"] = r["before"]["cpu_s"] / r["after"]["cpu_s"]
        r["same_mesh"] = same_mesh
        r["max_abs_radiance_diff"] = None if diff is None else float(diff.max())
        r["max_rel_radiance_diff"] = (
            None if diff is None else float((diff / np.maximum(np.abs(a_rad), 1e-6)).max())
        )
        out[name] = r
        print(name, r, flush=True)
    with tempfile.TemporaryDirectory() as cold:
        cold_s = speed_child(ROOT, "cornell_box", tmp / "cold.npz", {"NUMBA_CACHE_DIR": cold})["time_s"]
    warm_s = speed_child(ROOT, "cornell_box", tmp / "warm.npz")["time_s"]
    out["compile_s"] = cold_s - warm_s
    out["load"] = round(os.getloadavg()[0], 2)
    return out


def run_cornell(options: dict | None = None, repeats: int = 2) -> dict:
    cb = Cornell()
    opts = SolveOptions(**(options or {}))
    best = None
    for _ in range(repeats):
        sol, dt = timed_solve(cb.scene, opts)
        best = dt if best is None else min(best, dt)
    res = {
        "options": opts.to_dict(),
        "time_s": best,
        "elements": sol.stats["elements"],
        "shots": sol.stats["shots"],
        **cb.errors(sol),
    }
    cb.renderer.release()
    print(res, flush=True)
    return res


def preset_solves(scene, repeats: int = 2):
    """``(level, solution, best time)`` of each ``--quality`` level on ``scene``, best of ``repeats``
    (the kernels loaded before the first timing)."""
    from iat.radiosity.options import QUALITY_PRESETS

    timed_solve(scene, SolveOptions(max_depth=2))
    for level in QUALITY_PRESETS:
        opts = SolveOptions.preset(level)
        best = None
        for _ in range(repeats):
            sol, dt = timed_solve(scene, opts)
            best = dt if best is None else min(best, dt)
        yield level, sol, best


def run_quality(repeats: int = 2) -> list[dict]:
    """Each ``--quality`` level on the Cornell box against the Mitsuba reference (best of ``repeats``)."""
    cb = Cornell(spp=4096, seed=3)
    rows = []
    for level, sol, best in preset_solves(cb.scene, repeats):
        rows.append({"quality": level, "time_s": best, "vertices": len(sol.vert_key), **cb.errors(sol)})
        print(rows[-1], flush=True)
    cb.renderer.release()
    return rows


def run_quality_daylit(repeats: int = 2) -> list[dict]:
    """Each ``--quality`` level on the daylit room of ``tests/test_daylight.py`` (sun and sky through
    a window) against its 4096-spp reference, on the pixels wholly on the model (the sky left out)."""
    from iat.measure.reference import SUPERSAMPLE, box_filtered_render, render_reference_cached
    from iat.render.renderer import Renderer
    from tests.support.daylight import CAMERA, daylit_room

    scene, size, k = daylit_room(), (96, 72), SUPERSAMPLE
    ref = render_reference_cached(scene, CAMERA, size, spp=4096, cache_dir=REFS, seed=3)
    r = Renderer(None)
    r.set_scene(scene)
    covered = r.render(CAMERA, (size[0] * k, size[1] * k), mode="preview").max(axis=-1) > 0
    surface = covered.reshape(size[1], k, size[0], k).all(axis=(1, 3))
    ref = np.where(surface[..., None], ref, 0.0)
    mask = smooth_lit_mask(ref) & surface
    rows = []
    for level, sol, best in preset_solves(scene, repeats):
        r.set_solution(sol)
        e = reference_errors(box_filtered_render(r, CAMERA, size, "mesh"), ref, mask)
        rows.append({"quality": level, "time_s": best, "vertices": len(sol.vert_key), **e})
        print(rows[-1], flush=True)
    r.release()
    return rows


# -- output -------------------------------------------------------------------------------------
def _f(x, nd=3):
    return "-" if x is None else (f"{x:.{nd}f}" if isinstance(x, float) else str(x))


def _quality_table(rows: list[dict]) -> list[str]:
    head = [
        "| quality | solve (best of 2) | vertices | per pixel | 8 x 8 blocks | bias |",
        "|---|---|---|---|---|---|",
    ]
    return head + [
        f"| {r['quality']} | {r['time_s']:.2f} s | {r['vertices']:,} | {r['rel_smooth']:.4f} | "
        f"{r['rel_blocks']:.4f} | {r['bias']:+.1%} |"
        for r in rows
    ]


def format_md(res: dict) -> str:
    lines = ["# Solver benchmarks (`benchmarks/solver_bench.py`)", ""]
    meta = res.get("meta", {})
    if meta:
        lines += [
            f"Run {meta.get('date', '')}, {meta.get('cpus', '')} CPUs, load {meta.get('load', '')}.",
            "",
        ]
    ad = res.get("adaptive")
    if ad:
        ref = ad.get("reference") or {}
        ro = ref.get("options", {})
        ref_name = (
            f"uniform depth {ro.get('max_depth')}, samples {ro.get('samples')}, seed {ro.get('seed')}"
            if ro
            else "uniform depth 6"
        )
        lines += [
            "## Adaptive mesh against uniform subdivision (Cornell box)",
            "",
            f"Radiosity reference: {ref_name}"
            + (f" ({ref['elements']} elements, {ref['time_s']:.0f} s)." if ref else "."),
            "Ratio: adaptive elements / uniform elements at the same error (log-log interpolation;"
            " '-' where the error is outside the uniform curve).",
            "",
            "| mesh | depth | tolerance | elements | time s | image error vs Mitsuba | ratio | image error vs reference | ratio | surface error vs reference | uniform elements at that error | ratio | direct light only: elements | surface error | ratio |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in ad["rows"]:
            lines.append(
                f"| {r['mesh']} | {r['depth']} | {_f(r['tolerance'])} | {r['elements']} | {_f(r['time_s'], 2)} | "
                f"{_f(r['rel_smooth'], 4)} | {_f(r.get('ratio_rel_smooth'), 2)} | "
                f"{_f(r['rel_smooth_vs_uniform'], 4)} | {_f(r.get('ratio_rel_smooth_vs_uniform'), 2)} | "
                f"{_f(r['surface_vs_uniform'], 4)} | {_f(r.get('uniform_elements_at_surface_vs_uniform'), 0)} | "
                f"{_f(r.get('ratio_surface_vs_uniform'), 2)} | {r.get('direct_elements', '-')} | "
                f"{_f(r.get('direct_surface_vs_uniform'), 4)} | {_f(r.get('ratio_direct_surface_vs_uniform'), 2)} |"
            )
        lines.append("")
    sh = res.get("adaptive_shadow")
    if sh:
        lines += [
            f"## Adaptive mesh against uniform subdivision (shadow scene; reference: {sh['reference']})",
            "",
            "| mesh | depth | tolerance | elements | time s | surface error | uniform elements at that error | ratio |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in sh["rows"]:
            lines.append(
                f"| {r['mesh']} | {r['depth']} | {_f(r['tolerance'])} | {r['elements']} | {_f(r['time_s'], 2)} | "
                f"{_f(r['surface_vs_uniform'], 4)} | {_f(r.get('uniform_elements_at_surface_vs_uniform'), 0)} | "
                f"{_f(r.get('ratio_surface_vs_uniform'), 2)} |"
            )
        lines.append("")
    rays = res.get("rays")
    if rays:
        lines += [
            "## Ray throughput against bare embreex (same run, 2 threads)",
            "",
            "| model | elements | shots | solve s | rays | tracing s | solver rays/s (in `occluded`) | bare embreex rays/s (solver's rays replayed) | fraction | solver rays/s (whole solve) | fraction | bare embreex, random rays |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for name, r in rays.items():
            lines.append(
                f"| {name} | {r['elements']} | {r['shots']} | {_f(r['time_s'], 1)} | {r['rays']:,} | {_f(r['trace_s'], 1)} | "
                f"{r['rays_per_s_tracing'] / 1e6:.2f} M | {r['bare_rays_per_s'] / 1e6:.2f} M | {r['fraction_tracing']:.0%} | "
                f"{r['rays_per_s_solve'] / 1e6:.2f} M | {r['fraction_solve']:.0%} | {r['bare_random_rays_per_s'] / 1e6:.2f} M |"
            )
        lines.append("")
    sp = res.get("speed")
    if sp:
        lines += [
            "## Compiled kernels (issue 18): before / after, alternating processes",
            "",
            "| model | elements before / after | rays | solve s before | after | speed-up | CPU s before | after | speed-up | max radiance difference |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for name, r in sp.items():
            if not isinstance(r, dict):
                continue
            b, a = r["before"], r["after"]
            diff = (
                "-" if r["max_rel_radiance_diff"] is None else f"{r['max_rel_radiance_diff']:.1e} (relative)"
            )
            lines.append(
                f"| {name} | {b['elements']} / {a['elements']} | {a['rays']:,} | {b['time_s']:.1f} | {a['time_s']:.1f} | "
                f"{r['speedup_wall']:.2f}x | {b['cpu_s']:.1f} | {a['cpu_s']:.1f} | {r['speedup_cpu']:.2f}x | {diff} |"
            )
        lines += ["", f"Cold compile of the kernels: {sp['compile_s']:.0f} s (load {sp['load']}).", ""]
    cb = res.get("cornell")
    if cb:
        lines += [
            "## Cornell box at the defaults",
            "",
            f"time {cb['time_s']:.2f} s (best of 2), {cb['elements']} elements, {cb['shots']} shots; "
            f"error vs Mitsuba: smooth lit pixels {cb['rel_smooth']:.4f}, 8x8 blocks {cb['rel_blocks']:.4f}, "
            f"bias {cb['bias']:+.1%}",
            "",
        ]
    q = res.get("quality")
    if q:
        lines += [
            "## Quality presets on the Cornell box (`--quality`)",
            "",
            f"Run {q['date']}, load {q['load']}; against the 4096-spp reference of the tests.",
            "",
            *_quality_table(q["rows"]),
        ]
        if q.get("daylit"):
            lines += [
                "",
                "The daylit room of `tests/test_daylight.py` (sun and sky through a window; 96 x 72):",
                "",
                *_quality_table(q["daylit"]),
            ]
        lines.append("")
    return "\n".join(lines)


#: what ``main`` runs, by name
PARTS = ("adaptive", "shadow", "rays", "cornell", "quality", "speed")


def main(argv=None) -> None:
    import datetime
    import os

    argv = list(sys.argv[1:] if argv is None else argv)
    models = MODELS
    if "--models" in argv:
        i = argv.index("--models")
        models = tuple(argv[i + 1].split(","))
        del argv[i : i + 2]
    before = Path("/tmp/before")
    if "--before" in argv:
        i = argv.index("--before")
        before = Path(argv[i + 1])
        del argv[i : i + 2]
    parts = argv or ["adaptive", "rays", "cornell"]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        sys.exit(f"solver_bench.py: unknown part or option {', '.join(unknown)}\n{__doc__}")
    res = json.loads(OUT_JSON.read_text()) if OUT_JSON.exists() else {}
    meta = {
        "date": datetime.datetime.now().isoformat(timespec="minutes"),
        "cpus": os.cpu_count(),
        "load": round(os.getloadavg()[0], 2),
    }
    if parts != ["quality"]:  # the quality table carries its own run's date and load
        res["meta"] = meta
    if "cornell" in parts:
        res["cornell"] = run_cornell()
    if "adaptive" in parts:
        res["adaptive"] = run_adaptive()
    if "shadow" in parts:
        res["adaptive_shadow"] = run_adaptive_surface()
    if "rays" in parts:
        res.setdefault("rays", {}).update(run_rays(models))
    if "quality" in parts:
        res["quality"] = {**meta, "rows": run_quality(), "daylit": run_quality_daylit()}
    if "speed" in parts:
        res["speed"] = run_speed(before, models if models != MODELS else ("cornell_box", "house"))
    OUT_JSON.write_text(json.dumps(res, indent=1))
    OUT_MD.write_text(format_md(res) + "\n")
    print(format_md(res))


if __name__ == "__main__":
    main()
