"""Re-bake benchmark: time from a slider change to textures ready on the GPU.

One "change" is what the viewer does when the threshold or scale slider moves:

    baked = baker.bake(policy)      # cached tiles / packing / mesh part reused
    renderer.set_baked(baked)       # vertex buffers + page texture array (+ mip levels)
    ctx.finish()                    # the upload has really happened

Runs on a solution of at least 100 000 elements (leaves), by default the house
solved at max depth 6 with cheap lighting (the element count is what matters
here, not the light; cached under ``out/bench-rebake``), or a given ``.npz``, or
``--synthetic N`` (the house's patches refined at random to >= N leaves, radiance
a smooth function of position: no solve at all).

The changes are slider walks, as a user drags: the threshold slider steps through
0 .. deepest+1 and back, the scale slider through the budget ladder
``2**(-q/4)``, q = 0..8, and back; the first visit of a scale value flattens and
resamples every textured tile ("scale_cold"), revisits hit the tile cache
("scale_warm"); the first visit of a threshold builds its pages (seam harmonisation,
blit) and mesh part ("threshold_cold"), revisits find them in the Baker's caches
("threshold_warm": only the upload is left).
Reported per kind: p50, p95 and max in milliseconds, with the bake and the
upload separately. Not a test: timings depend on the machine (llvmpipe here).

    python benchmarks/rebake.py                       # house, max depth 6
    python benchmarks/rebake.py out/x.npz --changes 100 --json out/rebake.json
    python benchmarks/rebake.py --synthetic 150000
    python benchmarks/rebake.py --trace               # every change: Baked.timings stages, upload
    python benchmarks/rebake.py --prewarm             # + the slider's neighbours baked between steps
    python benchmarks/rebake.py --worker              # the viewer's path: BakeWorker, idle gaps
    python benchmarks/rebake.py --no-reuse --no-freeze   # as before issue 5's last changes

``--prewarm`` bakes, after each change, the slider's not yet visited neighbours (timed
apart as "prewarm (idle)"): what a viewer's bake worker could do while the slider rests.
``--worker`` drives the viewer's own :class:`viewer.bake_worker.BakeWorker` instead: each change is
``submit`` on the UI side, the bake on the worker thread, then ``set_baked`` + ``finish`` once
the result is there (timed from ``submit``, without waiting for a frame), and ``--gap`` seconds
of idle time (the slider resting) before the next change, in which the worker pre-warms the
neighbours of the policy shown (``--no-prewarm`` turns that off). The script calls
``gc.freeze()`` once the solution, the Baker and the first bake are made, as the viewer does
after opening a model (``--no-freeze``: not). ``--no-reuse`` makes the renderer re-create its
page texture whenever the atlas size changes (as it did before). The load average at the end
of the run is printed and kept in the JSON (the machine may be shared).

Goal: p95 <= 16 ms (one 60 Hz frame); 100 ms p95 is the most that still counts as live.
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from iat.bake.baker import Baker  # noqa: E402
from iat.bake.policy import BakePolicy  # noqa: E402

GOAL_MS, LIVE_MS = 16.0, 100.0
LADDER = [float(2.0 ** (-q / 4)) for q in range(9)]


def bench_options(max_depth: int, tolerance: float):
    """Cheap light, deep trees: many elements in a couple of minutes on 2 cores."""
    from iat.radiosity import SolveOptions

    return SolveOptions(
        max_depth=max_depth,
        tolerance=tolerance,
        samples=1,
        max_shots=60,
        convergence=0.2,
        refine_indirect=False,
        min_element_size=0.0,
        criterion="variation",
    )


def synthetic(scene, leaves: int, max_depth: int = 7, seed: int = 0):
    """The scene's patches, refined at random (2:1 balanced) until >= ``leaves`` leaves."""
    from iat.geometry import quadtree as qt
    from iat.radiosity.solution import Solution

    rng = np.random.default_rng(seed)
    corners = np.asarray(scene.corner_positions, dtype=np.float64).reshape(-1, 4, 3)
    forest = qt.roots(np.asarray(scene.patch_is_quad, dtype=bool), max_depth)
    # a few patches go deep (the ones a threshold textures), the rest stay shallow
    deep = rng.random(len(corners)) < 0.3
    while forest.n_leaves < leaves:
        p = forest.leaf_patch
        want = np.where(deep[p], 0.6, 0.08)
        forest = qt.balance(
            qt.split(forest, (rng.random(forest.n_leaves) < want) & (forest.leaf_level < max_depth))
        )
    keys = qt.vertex_keys(forest)
    pos = qt.keys_to_world(corners, forest.patch_is_quad, keys, forest.n)
    rad = np.stack([1 + np.sin(pos[:, 0]), 1 + np.cos(pos[:, 2]), 1 + 0.3 * pos[:, 1]], axis=1)
    albedo = np.full((len(corners), 3), 0.5)
    return Solution.from_forest(forest, corners, scene.patch_material, albedo, keys, rad.astype(np.float32))


def load(args):
    from iat.io.load import load_scene
    from iat.radiosity.cache import cached_solve
    from iat.radiosity.inputs import is_solution_path, open_solution

    src = Path(args.input)
    if is_solution_path(src):
        scene, sol = open_solution(src)
        return scene, sol, f"{src} (solution file)"
    if args.synthetic:
        scene = load_scene(src)
        return scene, synthetic(scene, args.synthetic), f"{src.name}, synthetic >= {args.synthetic} leaves"
    opts = bench_options(args.max_depth, args.tolerance)
    t0 = time.perf_counter()
    scene, sol, info = cached_solve(src, opts, args.cache_dir)
    how = "cached" if info["cached"] else f"solved in {time.perf_counter() - t0:.0f} s"
    return scene, sol, f"{src.name}, max_depth {args.max_depth}, tolerance {args.tolerance} ({how})"


def walk(values: list, n: int, start: int = 0) -> list:
    """Indices of a slider dragged back and forth over ``values``: n steps of +-1."""
    out, i, step = [], start, 1
    for _ in range(n):
        if not 0 <= i + step < len(values):
            step = -step
        i += step
        out.append(i)
    return out


def percentiles(xs) -> dict:
    a = np.asarray(xs, dtype=np.float64) * 1e3
    if not len(a):
        return {"n": 0}
    return {
        "n": int(len(a)),
        "p50_ms": float(np.percentile(a, 50)),
        "p95_ms": float(np.percentile(a, 95)),
        "max_ms": float(a.max()),
    }


def run(args) -> dict:
    import moderngl

    from iat.render.renderer import Renderer

    scene, sol, source = load(args)
    elements = int(len(sol.leaf_patch))
    depth = sol.patch_depth()
    deepest = int(depth.max())
    ctx = moderngl.create_standalone_context(backend="egl")
    Renderer.reuse_pages = not args.no_reuse
    r = Renderer(ctx)
    baker = Baker(sol, scene)
    base = BakePolicy(threshold=args.threshold, method=args.method)
    times: dict[str, list] = {}
    worker = None

    def bake_now(policy: BakePolicy):
        """The bake of one change: on this thread, or through the viewer's worker (--worker)."""
        if worker is None:
            return baker.bake(policy)
        time.sleep(args.gap)  # the slider rests: the worker pre-warms meanwhile
        worker.poll()
        t0 = time.perf_counter()
        worker.submit(policy)
        if not worker.wait(120.0):
            raise RuntimeError(f"no bake of {policy} within 120 s")
        res = worker.poll()
        if res is None or res.error is not None:
            raise RuntimeError(f"bake of {policy} failed: {res and res.error}")
        res.t_submit = t0
        return res

    def change(kind: str, policy: BakePolicy) -> None:
        t0 = time.perf_counter()
        baked = bake_now(policy)
        if worker is not None:
            t0, baked = baked.t_submit, baked.baked
        t1 = time.perf_counter()
        r.set_baked(baked)
        ctx.finish()
        t2 = time.perf_counter()
        for k, v in ((kind, t2 - t0), (kind + ":bake", t1 - t0), (kind + ":upload", t2 - t1)):
            times.setdefault(k, []).append(v)
        times.setdefault("all", []).append(t2 - t0)
        last["baked"] = baked
        trace.append(
            {
                "kind": kind,
                "threshold": policy.threshold,
                "scale": policy.scale,
                "bake_ms": (t1 - t0) * 1e3,
                "upload_ms": (t2 - t1) * 1e3,
                "timings_ms": {k: v * 1e3 for k, v in baked.timings.items()},
            }
        )
        if args.trace:
            tm = " ".join(f"{k}={v * 1e3:.1f}" for k, v in baked.timings.items() if k != "total")
            print(
                f"  {kind:<15} t={policy.threshold} s={policy.scale:.3f}: bake {(t1 - t0) * 1e3:6.1f} "
                f"upload {(t2 - t1) * 1e3:6.1f} ms ({tm})"
            )

    last: dict = {}
    trace: list = []
    t0 = time.perf_counter()
    first = baker.bake(base)
    r.set_baked(first)
    ctx.finish()
    first_s = time.perf_counter() - t0
    n = max(args.changes, 50)
    freeze_s = None
    if not args.no_freeze:  # as the viewer does once a model is open (viewer.app.freeze_heap)
        t0 = time.perf_counter()
        gc.collect()
        gc.freeze()
        freeze_s = time.perf_counter() - t0
    if args.worker:
        from viewer.bake_worker import BakeWorker

        worker = BakeWorker(baker, prewarm=not args.no_prewarm, warm_from=base)

    def prewarm(policies) -> None:
        """--prewarm: what a viewer could do while the slider rests (untimed as a change): bake
        the slider's neighbours of the value just shown, so the next step finds them cached."""
        if not args.prewarm or worker is not None:
            return
        for pol in policies:
            t0 = time.perf_counter()
            baker.bake(pol)
            times.setdefault("prewarm (idle)", []).append(time.perf_counter() - t0)

    # threshold slider at scale 1, then the scale slider at the base threshold (cold, then warm)
    thresholds = list(range(deepest + 2))
    seen_t: set = {args.threshold}
    for i in walk(thresholds, n // 2, start=min(args.threshold, deepest + 1)):
        t = thresholds[i]
        change(
            "threshold_cold" if t not in seen_t else "threshold_warm", dataclasses.replace(base, threshold=t)
        )
        seen_t.add(t)
        prewarm(
            dataclasses.replace(base, threshold=thresholds[j])
            for j in (i - 1, i + 1)
            if 0 <= j < len(thresholds) and thresholds[j] not in seen_t
        )
    seen: set = {1.0}
    for i in walk(LADDER, n - n // 2):
        s = LADDER[i]
        change("scale_cold" if s not in seen else "scale_warm", dataclasses.replace(base, scale=s))
        seen.add(s)
        prewarm(
            dataclasses.replace(base, scale=LADDER[j])
            for j in (i - 1, i + 1)
            if 0 <= j < len(LADDER) and LADDER[j] not in seen
        )
    m = last["baked"].memory
    mode = "worker" if worker is not None else ("direct + prewarm" if args.prewarm else "direct")
    if worker is not None:
        worker.close()
        for _pol, secs, done in worker.prewarm_log:
            times.setdefault("prewarm (idle)" if done else "prewarm (cancelled)", []).append(secs)
        mode += f", gap {args.gap:g} s" + ("" if worker.prewarm else ", no prewarm")
        mode += f"; prewarmed {worker.prewarmed}, cancelled {worker.prewarm_cancelled}"
    res = {
        "source": source,
        "mode": mode,
        "gc_frozen": freeze_s is not None,
        "freeze_s": freeze_s,
        "page_texture_reuse": bool(Renderer.reuse_pages),
        "page_texture": r.page_texture,
        "elements": elements,
        "patches": int(len(depth)),
        "mesh_triangles": int(len(sol.tri_vertices)),
        "depths": {int(d): int(c) for d, c in zip(*np.unique(depth, return_counts=True), strict=True)},
        "policy": dataclasses.asdict(base),
        "first_bake_s": first_s,
        "last_texture_bytes": int(m.texture_bytes),
        "last_pages": [int(m.pages), int(m.page_width), int(m.page_height)],
        "renderer": ctx.info.get("GL_RENDERER", "?"),
        "changes": {k: percentiles(v) for k, v in sorted(times.items())},
        "trace": trace,
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    r.release()
    ctx.release()
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "input", nargs="?", default=str(ROOT / "sample_models" / "house.glb"), help="MODEL or SOL.npz"
    )
    ap.add_argument("--max-depth", type=int, default=6)
    ap.add_argument("--tolerance", type=float, default=0.1)
    ap.add_argument(
        "--synthetic", type=int, default=0, metavar="N", help="random trees of >= N leaves, no solve"
    )
    ap.add_argument("--changes", type=int, default=60, help="slider changes (at least 50)")
    ap.add_argument("--threshold", type=int, default=2, help="base threshold (the scale walk uses it)")
    ap.add_argument("--method", default="bilinear")
    ap.add_argument("--cache-dir", default=str(ROOT / "out" / "bench-rebake"))
    ap.add_argument("--json", default=None, help="also write the results here")
    ap.add_argument("--trace", action="store_true", help="print every change (bake stages, upload)")
    ap.add_argument(
        "--prewarm",
        action="store_true",
        help="after each change, bake the slider's unvisited neighbours (idle work, timed apart): "
        "what the viewer's bake worker could do between slider steps",
    )
    ap.add_argument(
        "--worker",
        action="store_true",
        help="drive the viewer's BakeWorker (bake on its thread, pre-warm in the idle gaps)",
    )
    ap.add_argument("--gap", type=float, default=0.25, help="--worker: idle seconds before each change")
    ap.add_argument("--no-prewarm", action="store_true", help="--worker: no pre-warming")
    ap.add_argument("--no-freeze", action="store_true", help="no gc.freeze() after the first bake")
    ap.add_argument("--no-reuse", action="store_true", help="re-create the page texture on every size change")
    args = ap.parse_args(argv)
    res = run(args)
    print(
        f"{res['source']}: {res['elements']} elements, {res['patches']} patches, "
        f"{res['mesh_triangles']} mesh triangles, depths {res['depths']}"
    )
    print(f"first bake + upload {res['first_bake_s'] * 1e3:.0f} ms; renderer {res['renderer']}")
    fz = (
        f"gc.freeze() after the first bake ({res['freeze_s'] * 1e3:.0f} ms)"
        if res["gc_frozen"]
        else "no gc.freeze()"
    )
    reuse = "kept when the pages fit" if res["page_texture_reuse"] else "re-created on size changes"
    print(f"mode: {res['mode']}; {fz}; page texture {reuse} (last: {res['page_texture']})")
    if res["load_average"]:
        print("load average (1, 5, 15 min) at the end: " + ", ".join(f"{x:.2f}" for x in res["load_average"]))
    print(f"{'change':<22}{'n':>4}{'p50 ms':>9}{'p95 ms':>9}{'max ms':>9}")
    for k, v in res["changes"].items():
        if v["n"]:
            print(f"{k:<22}{v['n']:>4}{v['p50_ms']:>9.1f}{v['p95_ms']:>9.1f}{v['max_ms']:>9.1f}")
    p95 = res["changes"]["all"]["p95_ms"]
    verdict = "meets the 16 ms goal" if p95 <= GOAL_MS else ("live" if p95 <= LIVE_MS else "NOT live")
    print(f"all changes: p95 {p95:.1f} ms -> {verdict}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
