"""The batch engine (:mod:`iat.tools.batch`) against the serial path, in one run.

1. A 6-state day cycle of the house (its 3 lighting states and the same 3 at half strength) on
   one merged mesh: :func:`iat.lighting.solution_set.solve_set` in this process against the batch
   engine on a ``LocalCluster`` of 2 workers (processes, one thread each); the solutions are
   compared bit for bit. ``--rounds N`` alternates the two N times (the load average is noted at
   each round's start and end); the tasks' own time, summed, shows how much slower a solve runs in
   a worker beside another than alone in this process, and the workers' idle time what is left.
2. The engine's overhead per task: 20 tiny jobs (a lit square, milliseconds to solve) through the
   engine, wall time against the tasks' own time.
3. What it costs to get the Scene to a worker: pickling it against loading it again there.

    .venv/bin/python benchmarks/batch_bench.py [--workers 2] [--rounds 1] [--max-depth 3]
                                               [--samples 4] [--convergence 0.2] [--json OUT.json]

Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
HOUSE = ROOT / "sample_models" / "house.glb"

TINY_OBJ = """v 0 0 0
v 1 0 0
v 1 0 1
v 0 0 1
v 0.4 0.9 0.4
v 0.6 0.9 0.4
v 0.6 0.9 0.6
v 0.4 0.9 0.6
usemtl floor
f 1 4 3 2
usemtl lamp
f 5 6 7 8
"""
TINY_MTL = "newmtl floor\nKd 0.7 0.7 0.7\nnewmtl lamp\nKd 0 0 0\nKe 10 10 10\n"


def _scaled(spec, f: float):
    if isinstance(spec, int | float):
        return float(spec) * f
    if isinstance(spec, list):
        return [float(x) * f for x in spec]
    if isinstance(spec, dict):
        return {**spec, "intensity": float(spec.get("intensity", 1.0)) * f}
    return spec


def day_cycle_states(model: Path) -> dict[str, dict]:
    """6 states: the model's own and each at half strength (lights and emission), no key times."""
    from iat.lighting.states import lighting_states

    out = {}
    for factor, suffix in ((1.0, ""), (0.5, "-dim")):
        for name, st in lighting_states(model).items():
            new = {k: v for k, v in st.items() if k not in ("time", "label")}
            for part in ("lights", "emission"):
                if part in new:
                    new[part] = {k: _scaled(v, factor) for k, v in new[part].items()}
            out[name + suffix] = new
    return out


def _toml_value(v) -> str:
    return (
        json.dumps(v)
        if not isinstance(v, dict)
        else "{ " + ", ".join(f'"{k}" = {_toml_value(x)}' for k, x in v.items()) + " }"
    )


def _job_file(folder: Path, jobs: list[str], options: dict) -> Path:
    p = folder / "jobs.toml"
    head = 'output = "out"\n[defaults]\n' + "".join(f"{k} = {json.dumps(v)}\n" for k, v in options.items())
    p.write_text(head + "".join(jobs))
    return p


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def bench_day_cycle(client, workers: int, options: dict) -> dict:
    """One round: the serial path, then the batch."""
    from iat.io.load import load_scene
    from iat.lighting.solution_set import solve_set
    from iat.radiosity import Solution, SolveOptions
    from iat.tools.batch import parse_jobs, run_batch

    states = day_cycle_states(HOUSE)
    load_start = _load()
    t0 = time.perf_counter()
    scene = load_scene(HOUSE)
    serial = solve_set(scene, states, SolveOptions(**options))
    serial_s = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as d:
        table = "".join(f'"{k}" = {_toml_value(v)}\n' for k, v in states.items())
        job = f'[[job]]\nname = "house"\nmodel = "{HOUSE}"\n[job.states]\n{table}'
        batch = parse_jobs(_job_file(Path(d), [job], options))
        t0 = time.perf_counter()
        report = run_batch(batch, client=client)
        batch_s = time.perf_counter() - t0
        failed = [f"{r.name}: {r.error}" for r in report.failed]
        identical = not failed and all(
            np.array_equal(Solution.load(Path(d) / "out" / f"house-{n}.npz").vert_radiance, s.vert_radiance)
            and np.array_equal(Solution.load(Path(d) / "out" / f"house-{n}.npz").vert_key, s.vert_key)
            for n, s in zip(serial.names, serial.solutions, strict=True)
        )
        task_s = sum(r.seconds for r in report.results)
    return {
        "states": len(states),
        "tasks": len(report.results),
        "serial_s": serial_s,
        "batch_s": batch_s,
        "speedup": serial_s / batch_s,
        "task_s": task_s,
        "idle_s": workers * batch_s - task_s,
        "load": [load_start, _load()],
        "identical": identical,
        "failed": failed,
        "vertices": int(len(serial.first.vert_key)),
        "workers": workers,
    }


def bench_overhead(client, workers: int, n: int = 20) -> dict:
    from iat.tools.batch import parse_jobs, run_batch

    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "tiny.obj").write_text("mtllib tiny.mtl\n" + TINY_OBJ)
        (Path(d) / "tiny.mtl").write_text(TINY_MTL)
        jobs = [f'[[job]]\nname = "t{k}"\nmodel = "tiny.obj"\noptions = {{ seed = {k} }}\n' for k in range(n)]
        batch = parse_jobs(_job_file(Path(d), jobs, {"max_depth": 2}))
        t0 = time.perf_counter()
        report = run_batch(batch, client=client)
        wall = time.perf_counter() - t0
    own = sum(r.seconds for r in report.results)
    t0 = time.perf_counter()
    client.gather([client.submit(abs, -k, pure=False) for k in range(n)])
    bare = time.perf_counter() - t0
    return {
        "tasks": n,
        "wall_s": wall,
        "task_s": own,
        "overhead_per_task_ms": 1e3 * (wall - own / workers) / n,
        "dask_noop_per_task_ms": 1e3 * bare / n,
        "failed": [f"{r.name}: {r.error}" for r in report.failed],
    }


def bench_scene_transfer() -> dict:
    from iat.io.load import load_scene

    t0 = time.perf_counter()
    scene = load_scene(HOUSE)
    load_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    blob = pickle.dumps(scene, protocol=5)
    dump_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    pickle.loads(blob)
    loads_s = time.perf_counter() - t0
    return {"load_s": load_s, "pickle_s": dump_s, "unpickle_s": loads_s, "pickle_mb": len(blob) / 2**20}


def format_table(r: dict) -> str:
    rounds, o, s = r["day_cycle"], r["overhead"], r["scene"]
    d = rounds[0]
    opts = ", ".join(f"{k}={v}" for k, v in r["options"].items())
    rows = [
        f"Day cycle: house, {d['states']} states on one merged mesh ({d['tasks']} tasks, "
        f"{d['vertices']} vertices; {opts}), {d['workers']} workers",
        "",
        "| round | load | serial `solve_set` s | `iat batch` s | speed-up | tasks' own s | workers idle s "
        "| bit-identical |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for k, d in enumerate(rounds, 1):
        rows.append(
            f"| {k} | {d['load'][0]:.1f}-{d['load'][1]:.1f} | {d['serial_s']:.1f} | {d['batch_s']:.1f} | "
            f"{d['speedup']:.2f} | {d['task_s']:.1f} | {d['idle_s']:.1f} | "
            f"{'yes' if d['identical'] else 'NO'} |"
        )
    if len(rounds) > 1:
        rows.append(f"\nMedian speed-up: {statistics.median(d['speedup'] for d in rounds):.2f}")
    rows += [
        "",
        "| engine overhead | |",
        "|---|---:|",
        f"| {o['tasks']} tiny tasks: wall s | {o['wall_s']:.2f} |",
        f"| their own time s | {o['task_s']:.2f} |",
        f"| overhead per task (wall - own/workers) / n | {o['overhead_per_task_ms']:.0f} ms |",
        f"| bare Dask no-op task, per task | {o['dask_noop_per_task_ms']:.1f} ms |",
        "",
        "| house Scene to a worker | |",
        "|---|---:|",
        f"| load_scene on the worker | {1e3 * s['load_s']:.0f} ms |",
        f"| pickle + unpickle (sent once per worker) | {1e3 * (s['pickle_s'] + s['unpickle_s']):.1f} ms, "
        f"{s['pickle_mb']:.2f} MB |",
    ]
    return "\n".join(rows) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=1, help="serial and batch, alternated this many times")
    ap.add_argument("--max-depth", type=int, default=3)
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--convergence", type=float, default=0.2)
    ap.add_argument("--json", metavar="OUT.json")
    a = ap.parse_args(argv)
    from iat.tools.batch import start_client

    options = {"max_depth": a.max_depth, "samples": a.samples, "convergence": a.convergence}
    result = {"options": options, "scene": bench_scene_transfer()}
    t0 = time.perf_counter()
    client, cluster = start_client(a.workers)
    result["cluster_start_s"] = time.perf_counter() - t0
    try:
        result["overhead"] = bench_overhead(client, a.workers)
        result["day_cycle"] = [bench_day_cycle(client, a.workers, options) for _ in range(a.rounds)]
    finally:
        client.close()
        cluster.close()
    table = (
        format_table(result)
        + f"\nCluster start: {result['cluster_start_s']:.1f} s (not in the times above).\n"
    )
    sys.stdout.write(table)
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
