"""What a solve spends per ray, and how close a whole solve comes to bare Embree (issues 18 and 41).

1. **Budget.** One solve on one thread (one ray thread, numba's kernels on one thread) per backend,
   with the thread's CPU clock (``time.thread_time``: what the load of other processes does not
   inflate) around the gather's steps and the whole solve. With embreex (``IAT_EMBREE_C=0``): the form-factor
   kernel, ``block_inputs``, ``gather_rays`` (the samples' weights and rays), ``Visibility.visible``
   and ``gather_finish`` (the sum); with Embree's C API: the form-factor kernel and
   ``traced.gather_traced`` (the rows' inputs, samples, traversal and sum in one kernel), and
   ``Visibility.visible`` for the other rays (sun, sky, lights). ``first_hits`` is the ambient term's.
   Nanoseconds per ray of the gathers and direct light each.
2. **Bare Embree.** Random rays of a model: embreex ``run(query='OCCLUDED')`` on one thread, and
   ``rtcOccluded1`` from the numba kernel of :mod:`iat.radiosity.embree` on one thread and on two
   (``prange``); whether they answer alike, ray for ray.
3. **Whole solves** (issue 41). Each model at the defaults on the ray threads (two), each solve in
   a fresh process, before and after alternating (after, before, before, after for two rounds):
   ``--before PATH`` a checkout of the tree before issue 41 (``git worktree add``), else this tree's
   embreex backend (``IAT_EMBREE_C=0``). Wall and CPU seconds, rays traced, and rays per second of
   solve against bare Embree replaying the solver's own rays (every 16th ``visible`` /
   ``first_hits`` call of an extra embreex solve, traced again by the C kernels on the same
   threads: what the rays alone cost).

Usage: ``.venv/bin/python benchmarks/ray_budget.py [--model pool] [--convergence 0.2]
[--models cornell_box,house,pool,cave,house_day] [--rounds 2] [--parts 1,2,3] [--before PATH]``; writes
``benchmarks/ray_budget.md`` and ``.json`` (parts not run keep their last figures).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from collections import Counter
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from numba import get_num_threads, set_num_threads

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from solver_bench import random_rays  # noqa: E402

import iat.radiosity.kernels as kernels_module  # noqa: E402
import iat.radiosity.traced as traced_module  # noqa: E402
from iat.io.load import load_scene  # noqa: E402
from iat.radiosity import SolveOptions, embree, solve  # noqa: E402
from iat.radiosity.visibility import RAY_THREADS_ENV, Visibility  # noqa: E402

OUT = ROOT / "benchmarks"
#: the steps timed in part 1 per backend: (where the name is looked up, name)
STEPS = {
    "embreex": (
        (kernels_module, "patch_form_factors"),
        (kernels_module, "block_inputs"),
        (kernels_module, "gather_rays"),
        (Visibility, "visible"),
        (kernels_module, "gather_finish"),
        (Visibility, "first_hits"),
    ),
    "c": (
        (kernels_module, "patch_form_factors"),
        (traced_module, "gather_traced"),
        (Visibility, "visible"),
        (Visibility, "first_hits"),
    ),
}
#: the steps whose rays part 1 divides by (the gathers' and the direct light's)
RAY_STEPS = ("visible", "gather_traced")


@contextmanager
def backend(name: str, threads: int):
    """Solves inside use ``name`` ("c" or "embreex") on ``threads`` ray threads."""
    saved = {k: os.environ.get(k) for k in (embree.EMBREE_C_ENV, RAY_THREADS_ENV)}
    os.environ[embree.EMBREE_C_ENV] = "1" if name == "c" else "0"
    os.environ[RAY_THREADS_ENV] = str(threads)
    before = get_num_threads()
    set_num_threads(min(threads, before))
    try:
        yield
    finally:
        set_num_threads(before)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextmanager
def wrapped(steps, make):
    """Each ``owner.name`` of ``steps`` replaced by ``make(name, fn)`` inside."""
    originals = [(owner, name, getattr(owner, name)) for owner, name in steps]
    for owner, name, fn in originals:
        setattr(owner, name, make(name, fn))
    try:
        yield
    finally:
        for owner, name, fn in originals:
            setattr(owner, name, fn)


def _rays_of(name: str, args, out) -> int:
    if name == "gather_traced":
        return int(out[2].sum()) + int(out[3])
    if name in ("visible", "first_hits"):
        return len(args[1])
    return 0


def budget(model: str, convergence: float, name: str) -> dict:
    """Part 1: seconds, calls and ns per ray of each step of one solve of ``model`` on one thread."""
    seconds, calls, rays = Counter(), Counter(), Counter()
    lock = threading.Lock()

    def make(step, fn):
        def call(*args, **kwargs):
            t = time.thread_time()
            out = fn(*args, **kwargs)
            dt = time.thread_time() - t
            with lock:
                seconds[step] += dt
                calls[step] += 1
                rays[step] += _rays_of(step, args, out)
            return out

        return call

    scene = load_scene(ROOT / "sample_models" / f"{model}.glb")
    with backend(name, 1):
        solve(scene, SolveOptions(max_shots=5))  # the kernels loaded
        with wrapped(STEPS[name], make):
            t, c = time.perf_counter(), time.thread_time()
            sol = solve(scene, SolveOptions(convergence=convergence))
            wall, cpu = time.perf_counter() - t, time.thread_time() - c
    n = max(sum(rays[k] for k in RAY_STEPS), 1)
    steps = {
        step: {
            "s": seconds[step],
            "calls": calls[step],
            "rays": rays[step],
            "ns_per_ray": 1e9 * seconds[step] / n,
        }
        for _, step in STEPS[name]  # noqa: E501
    }
    return {
        "model": model,
        "convergence": convergence,
        "backend": name,
        "solve_s": cpu,
        "wall_s": wall,
        "rays_total": int(sol.stats["rays"]),
        "gather_rays": n,
        "steps": steps,
    }


def bare(model: str, n: int = 1 << 21, rounds: int = 3) -> dict:
    """Part 2: embreex and Embree from numba on the same ``n`` random rays of ``model``."""
    if not embree.available():
        return {"skipped": "libembree4 not found"}
    scene = load_scene(ROOT / "sample_models" / f"{model}.glb")
    o, d, t = random_rays(scene, n)
    t = t * np.random.default_rng(1).random(n)  # some rays short enough to pass
    o, d, t = (np.ascontiguousarray(x, dtype=np.float32) for x in (o, d, t))
    best = {"embreex": 0.0, "numba": 0.0, "numba_2_threads": 0.0}
    same = True
    threads = get_num_threads()
    with Visibility.of_scene(scene, threads=1, backend="embreex") as ref_vis:
        es = embree.EmbreeScene(scene.world_triangles()[ref_vis.opaque])
        fn, handle = es.entry.occluded1, es.handle
        out1, out2 = np.zeros(n, bool), np.zeros(n, bool)
        embree.trace_occluded(fn, handle, o[:64], d[:64], t[:64], out1[:64])  # loaded
        for _ in range(rounds):
            t0 = time.perf_counter()
            ref = ref_vis.occluded_chunk(o, d, t) == 0
            t1 = time.perf_counter()
            set_num_threads(1)
            embree.trace_occluded(fn, handle, o, d, t, out1)
            t2 = time.perf_counter()
            set_num_threads(min(2, threads))
            embree.trace_occluded(fn, handle, o, d, t, out2)
            t3 = time.perf_counter()
            set_num_threads(threads)
            same &= bool(np.array_equal(ref, out1) and np.array_equal(ref, out2))
            for key, dt in (("embreex", t1 - t0), ("numba", t2 - t1), ("numba_2_threads", t3 - t2)):
                best[key] = max(best[key], n / dt)
        es.close()
    return {
        "model": model,
        "rays": n,
        "occluded_fraction": float(ref.mean()),
        "same_answers": same,
        "library": Path(embree.library_path()).name,
        "rays_per_s": best,
    }


def capture(scene, every: int = 16, cap: int = 6_000_000) -> dict:
    """The rays of every ``every``-th ``visible`` and ``first_hits`` call of an embreex solve of
    ``scene`` at the defaults (copies, ``cap`` rays at most)."""
    got = {"visible": [], "first_hits": []}
    count = Counter()
    lock = threading.Lock()

    def make(step, fn):
        def call(self, o, d, t):
            with lock:
                count[step] += 1
                keep = count[step] % every == 0 and count["rays"] < cap
                if keep:
                    count["rays"] += len(o)
            if keep:
                arrays = tuple(np.array(x, dtype=np.float32) for x in (o, d, t))
                with lock:
                    got[step].append(arrays)
            return fn(self, o, d, t)

        return call

    with backend("embreex", 2), wrapped([(Visibility, "visible"), (Visibility, "first_hits")], make):
        solve(scene, SolveOptions())
    return {
        k: tuple(np.ascontiguousarray(np.concatenate([a[j] for a in v])) for j in range(3))
        for k, v in got.items()
        if v
    }


def replay(scene, rays: dict, threads: int = 2, rounds: int = 3) -> dict:
    """Bare rays per second of the captured rays on ``threads`` threads: Embree's C kernels
    (``trace_visible``, ``trace_first_hits``: the glass's second rays counted as the solver counts
    them) and embreex (:meth:`Visibility.visible` / ``first_hits`` on its thread pool)."""
    out = {}
    for name in ("c", "embreex"):
        best = 0.0
        with Visibility.of_scene(scene, threads=threads, backend=name) as vis:
            for _ in range(rounds):
                r0, t0 = vis.rays, time.perf_counter()
                with backend(name, threads):
                    if "visible" in rays:
                        vis.visible(*rays["visible"])
                    if "first_hits" in rays:
                        vis.first_hits(*rays["first_hits"])
                best = max(best, (vis.rays - r0) / (time.perf_counter() - t0))
        out[name] = best
    out["rays"] = int(sum(len(v[0]) for v in rays.values()))
    return out


#: one timed solve at the defaults in a fresh process of a tree (``PYTHONPATH``): the kernels loaded
#: by a short solve first; prints its figures as one JSON line
CHILD = """
import json, sys, time
from iat.io.load import load_scene
from iat.radiosity import SolveOptions, solve
scene = load_scene(sys.argv[1])
solve(scene, SolveOptions(max_shots=5))
t, c = time.perf_counter(), time.process_time()
sol = solve(scene, SolveOptions())
wall, cpu = time.perf_counter() - t, time.process_time() - c
out = {"wall_s": wall, "cpu_s": cpu, "rays": int(sol.stats["rays"]), "elements": int(sol.stats["elements"])}
print("RESULT " + json.dumps(out))
"""


def timed_solve(tree: Path, model: str, env: dict) -> dict:
    """:data:`CHILD` of ``model`` in ``tree`` with ``env`` on top of this process's environment."""
    full = {k: v for k, v in os.environ.items() if k not in (embree.EMBREE_C_ENV, RAY_THREADS_ENV)}
    full.update(PYTHONPATH=str(tree), **env)
    path = ROOT / "sample_models" / f"{model}.glb"
    r = subprocess.run(
        [sys.executable, "-c", CHILD, str(path)], cwd=tree, env=full, capture_output=True, text=True
    )
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")]
    if r.returncode or not lines:
        raise RuntimeError(f"{model} in {tree}: {r.stderr[-2000:]}")
    return {**json.loads(lines[-1][7:]), "load": os.getloadavg()[0]}


def solves(models: list[str], rounds: int, before: Path | None) -> dict:
    """Part 3: per model, timed solves at the defaults alternating before / after (``before``: a
    checkout of the tree before issue 41; else embreex / the C API in this tree), and bare Embree
    replaying the solver's rays."""
    if before is not None:
        sides = {"after": (ROOT, {}), "before": (before, {})}
    else:
        sides = {"after": (ROOT, {embree.EMBREE_C_ENV: "1"}), "before": (ROOT, {embree.EMBREE_C_ENV: "0"})}
    res = {}
    for model in models:
        scene = load_scene(ROOT / "sample_models" / f"{model}.glb")
        with backend("c", 2):
            solve(scene, SolveOptions(max_shots=5))  # the kernels loaded
        bare_rates = replay(scene, capture(scene))
        print(model, "bare", bare_rates, flush=True)
        runs = {"after": [], "before": []}
        for name in (["after", "before", "before", "after"] * rounds)[: 2 * rounds]:
            runs[name].append(timed_solve(sides[name][0], model, sides[name][1]))
            print(model, name, runs[name][-1], flush=True)
        res[model] = {"runs": runs, "bare": bare_rates}
    return res


def _fmt_budget(b: dict) -> list[str]:
    lines = [
        f"### {b['backend']}: solve {b['solve_s']:.1f} s of CPU ({b['wall_s']:.1f} s wall), "
        f"{b['rays_total']:,} rays, "
        f"{b['gather_rays']:,} of them in the gathers and the direct light",
        "",
        "| step | s | calls | ns per ray |",
        "|---|---:|---:|---:|",
    ]
    for name, s in b["steps"].items():
        lines.append(f"| `{name}` | {s['s']:.2f} | {s['calls']:,} | {s['ns_per_ray']:.0f} |")
    other = b["solve_s"] - sum(s["s"] for s in b["steps"].values())
    rest = "the rest of the solve (meshing, each call's Python, the ambient term's kernels)"
    lines += [f"| {rest} | {other:.2f} | | |"]
    return lines + [""]


def _median(xs):
    return float(np.median(xs)) if xs else float("nan")


def format_md(res: dict) -> str:
    lines = [
        "# Ray budget of a solve, and a whole solve against bare Embree (`benchmarks/ray_budget.py`)",
        "",
        f"{os.cpu_count()} CPUs. Each part gives its date and the machine's load (1-minute average).",
        "",
    ]
    if "budget" in res:
        b0 = next(iter(res["budget"].values()))
        lines += [
            f"## 1. Budget: {b0['model']} at convergence {b0['convergence']}, one thread "
            f"({res['budget_when']}, load {res['budget_load']:.1f})",
            "",
        ]
        for b in res["budget"].values():
            lines += _fmt_budget(b)
    e = res.get("bare")
    if e is not None:
        lines += ["## 2. Bare Embree: embreex and the C API from numba", ""]
        if "skipped" in e:
            lines.append(f"Skipped: {e['skipped']}.")
        else:
            r = e["rays_per_s"]
            lines += [
                f"{e['model']}, {e['rays']:,} random rays ({e['occluded_fraction']:.0%} occluded), "
                f"`{e['library']}` ({res['bare_when']}, load {res['bare_load']:.1f}); "
                f"the same answers as embreex: **{e['same_answers']}**.",
                "",
                "| tracer | M rays/s |",
                "|---|---:|",
                f"| embreex `run(query='OCCLUDED')`, one thread | {r['embreex'] / 1e6:.2f} |",
                f"| `embree.trace_occluded` (`rtcOccluded1`), one thread | {r['numba'] / 1e6:.2f} |",
                f"| the same, two threads (`prange`) | {r['numba_2_threads'] / 1e6:.2f} |",
            ]
        lines.append("")
    s = res.get("solves")
    if s:
        lines += [
            f"## 3. Whole solves at the defaults, two threads ({res['solves_when']}; before: "
            f"{res.get('solves_before') or 'the embreex backend of this tree'})",
            "",
            "Medians of the runs, each in a fresh process (after, before, before, after, ...); the load is "
            "the 1-minute average after each run. Bare: the C kernels (and embreex) replaying every 16th "
            "tracing call of an embreex solve on two threads.",
            "",
            "| model | elements | rays | before s (CPU s) | after s (CPU s) | speedup (CPU) | solve M rays/s "
            "| bare C M rays/s | **fraction of bare** | bare embreex M rays/s | load |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for model, m in s.items():
            b_runs, a_runs = m["runs"]["before"], m["runs"]["after"]
            bw, aw = _median([r["wall_s"] for r in b_runs]), _median([r["wall_s"] for r in a_runs])
            bc, ac = _median([r["cpu_s"] for r in b_runs]), _median([r["cpu_s"] for r in a_runs])
            rays = a_runs[0]["rays"]
            rate = rays / aw
            load = _median([r["load"] for r in a_runs + b_runs])
            lines.append(
                f"| {model} | {a_runs[0]['elements']:,} | {rays / 1e6:.1f} M | {bw:.2f} ({bc:.2f}) | "
                f"{aw:.2f} ({ac:.2f}) | {bw / aw:.2f}x ({bc / ac:.2f}x) | {rate / 1e6:.2f} | "
                f"{m['bare']['c'] / 1e6:.2f} | **{rate / m['bare']['c']:.0%}** | "
                f"{m['bare']['embreex'] / 1e6:.2f} | {load:.1f} |"
            )
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="pool", help="model of part 1")
    ap.add_argument("--convergence", type=float, default=0.2, help="part 1's convergence")
    ap.add_argument("--rays-model", default="house", help="model of part 2's random rays")
    ap.add_argument("--models", default="cornell_box,house,pool,cave,house_day", help="models of part 3")
    ap.add_argument("--rounds", type=int, default=2, help="runs of each backend in part 3")
    ap.add_argument("--parts", default="1,2,3")
    ap.add_argument("--before", type=Path, help="part 3: a checkout of the tree before issue 41")
    args = ap.parse_args(argv)
    parts = {int(p) for p in args.parts.split(",")}
    path = OUT / "ray_budget.json"
    res = json.loads(path.read_text()) if path.is_file() else {}
    res = {k: v for k, v in res.items() if k not in ("when", "embree_from_numba", "load")}  # the old layout
    if isinstance(res.get("budget"), dict) and "steps" in res["budget"]:
        res.pop("budget")
    now = lambda: time.strftime("%Y-%m-%dT%H:%M")  # noqa: E731
    if 1 in parts:
        res["budget"] = {name: budget(args.model, args.convergence, name) for name in ("embreex", "c")}
        res["budget_when"], res["budget_load"] = now(), os.getloadavg()[0]
    if 2 in parts:
        res["bare"] = bare(args.rays_model)
        res["bare_when"], res["bare_load"] = now(), os.getloadavg()[0]
    if 3 in parts:
        res["solves"] = solves(args.models.split(","), args.rounds, args.before)
        res["solves_when"] = now()
        res["solves_before"] = str(args.before) if args.before else None
    path.write_text(json.dumps(res, indent=1))
    (OUT / "ray_budget.md").write_text(format_md(res))
    print(format_md(res))


if __name__ == "__main__":
    main()
