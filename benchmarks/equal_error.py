# ruff: noqa: E501
"""Speed at equal error (issue 18): an old ``iat`` tree against this one on the sample models.

    git archive 599fc3a^ iat | tar -x -C /tmp/issue18      # the tree when issue 18 was filed
    .venv/bin/python benchmarks/equal_error.py --before /tmp/issue18 [--models a,b] [--repeats 2]
    .venv/bin/python benchmarks/equal_error.py --rejudge     # the speed-ups again, from the saved JSON

writes ``benchmarks/equal_error.json`` and ``benchmarks/equal_error.md``. Per model the default
solve with the old tree and this tree's ``EQUAL_LADDER`` (the draft preset, convergence 0.4, 0.3, 0.2 and 0.1, 0.1 with tolerance 0.15, and the defaults), each in
its own process, alternating (best wall and CPU seconds of ``--repeats``); each solution's surface
error (area-weighted L1 of the luminance, 64 x 64 cells a patch, emitters left out) against a
reference solve (``EQUAL_REFERENCE``: the final preset with seed 1, cached in ``out/solver_refs``),
on the Cornell box also the image error (smooth lit pixels) against the 4096-spp Mitsuba reference of
``tests/test_reference_compare.py``; and this tree's time at the old tree's surface error,
interpolated (log-log) between its ladder's solves.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import tempfile
from pathlib import Path

from solver_bench import ROOT, Cornell, interp_at_error, speed_child, surface_error

from iat.radiosity import Solution
from iat.radiosity.options import QUALITY_PRESETS

OUT_JSON = ROOT / "benchmarks" / "equal_error.json"
OUT_MD = ROOT / "benchmarks" / "equal_error.md"
MODELS = ("cornell_box", "house", "cave", "lavapit", "pool")


#: the reference of ``equal``: the "final" quality preset with another seed
EQUAL_REFERENCE = {"convergence": 0.005, "tolerance": 0.05, "samples": 32, "seed": 1}
#: the settings ``equal`` solves with this tree (its time at the old tree's error is interpolated
#: between them): the "draft" quality preset, looser convergences, a looser mesh tolerance too
#: (the Cornell box's walls are one patch each: it meshes them finely at 0.1) and the defaults
EQUAL_LADDER = {
    "draft": QUALITY_PRESETS["draft"],
    "convergence 0.4": {"convergence": 0.4},
    "convergence 0.3": {"convergence": 0.3},
    "convergence 0.2": {"convergence": 0.2},
    "convergence 0.1": {"convergence": 0.1},
    "convergence 0.1, tolerance 0.15": {"convergence": 0.1, "tolerance": 0.15},
    "default": {},
}
#: cells per patch side of ``equal``'s surface error (the models have hundreds of patches)
EQUAL_CELLS = 64


def run_equal(before: Path, models=MODELS, repeats: int = 2) -> dict:
    """Speed at equal error (issue 18): per model, the default solve with the ``iat`` tree at
    ``before`` and this tree's :data:`EQUAL_LADDER`, in alternating processes (best wall and CPU
    seconds of ``repeats``), each solution's surface error against a reference solve of this
    tree (:data:`EQUAL_REFERENCE`, cached in ``out/solver_refs``; any version of the solver
    serves: it is several times more accurate than the solves it judges), on the Cornell box also
    the image error against the 4096-spp Mitsuba reference of ``tests/test_reference_compare.py``;
    and this tree's time at the old tree's surface error (log-log between its ladder's solves)."""
    tmp = Path(tempfile.mkdtemp(prefix="iat-equal-"))
    refs = ROOT / "out" / "solver_refs"
    refs.mkdir(parents=True, exist_ok=True)
    speed_child(ROOT, "cornell_box", tmp / "warm.npz")  # compile (or load) the kernels first
    cb = Cornell(spp=4096, seed=3) if "cornell_box" in models else None
    runs = [("before", before, {}), *((f"now {k}", ROOT, o) for k, o in EQUAL_LADDER.items())]
    out = {}
    for name in models:
        ref_path = refs / f"{name}.npz"
        if not ref_path.exists():
            speed_child(ROOT, name, ref_path, options=EQUAL_REFERENCE)
        ref = Solution.load(ref_path)
        times: dict[str, list[dict]] = {label: [] for label, _, _ in runs}
        for _ in range(repeats):
            for label, tree, opts in runs:
                times[label].append(speed_child(tree, name, tmp / f"{name}-{label}.npz", options=opts))
        r: dict = {"reference": EQUAL_REFERENCE, "reference_elements": int(ref.stats["elements"])}
        for label, _, opts in runs:
            sol = Solution.load(tmp / f"{name}-{label}.npz")
            r[label] = {
                "options": opts,
                "time_s": min(x["time_s"] for x in times[label]),
                "cpu_s": min(x["cpu_s"] for x in times[label]),
                "elements": times[label][0]["elements"],
                "surface_error": surface_error(sol, ref, EQUAL_CELLS),
            }
            if cb is not None and name == "cornell_box":
                r[label]["image_error"] = cb.errors(sol)["rel_smooth"]
        out[name] = judge(r)
        print(name, json.dumps(r), flush=True)
    if cb is not None:
        cb.renderer.release()
    out["meta"] = {
        "date": datetime.datetime.now().isoformat(timespec="minutes"),
        "load": round(os.getloadavg()[0], 2),
        "before": str(before),
    }
    return out


def judge(r: dict) -> dict:
    """Adds to a model's result ``r`` the speed-ups: at the defaults, and at the old tree's error
    (this tree's time there, log-log between the two solves of its ladder that bracket that error on
    the ladder's Pareto front, the solves no other is both faster and more accurate than; when even
    the fastest is more accurate, its time, and the speed-up is a lower bound: ``at_least``)."""
    b = r["before"]
    pts = [(r[f"now {k}"]["surface_error"], r[f"now {k}"]["time_s"]) for k in EQUAL_LADDER]
    front = [p for p in pts if not any(q[0] < p[0] and q[1] < p[1] for q in pts)]
    fastest = min(front, key=lambda p: p[1])
    r["at_least"] = b["surface_error"] >= fastest[0]
    t_eq = fastest[1] if r["at_least"] else interp_at_error(b["surface_error"], front)
    r["time_at_before_error_s"] = t_eq
    r["speedup_default"] = b["time_s"] / r["now default"]["time_s"]
    r["speedup_at_equal_error"] = None if t_eq is None else b["time_s"] / t_eq
    return r


def format_md(eq: dict) -> str:
    rungs = [f"now {k}" for k in EQUAL_LADDER]
    lines = [
        "## Speed at equal error (issue 18): before / now, alternating processes",
        "",
        "Surface error: area-weighted L1 of the luminance against a reference solve (the final preset, "
        "seed 1); image error (Cornell box): smooth lit pixels against the 4096-spp Mitsuba reference. "
        "'now at that error': this tree's time interpolated (log-log) at the old tree's surface error "
        "between the two of its solves that bracket it, of those no other is both faster and more "
        "accurate than ('>=': even the fastest is more accurate; '-': none is as accurate). "
        "Cells: seconds / surface error.",
        "",
        "| model | before | " + " | ".join(rungs) + " | speed-up at the defaults | now at that error: s | "
        "speed-up at equal error |",
        "|---|" + "---|" * (len(rungs) + 4),
    ]
    for name, r in eq.items():
        if name == "meta":
            continue
        cells = [name]
        for label in ("before", *rungs):
            x = r[label]
            err = f"{x['time_s']:.2f} / {x['surface_error']:.4f}"
            if "image_error" in x:
                err += f" (image {x['image_error']:.4f})"
            cells.append(err)
        t_eq, s_eq = r["time_at_before_error_s"], r["speedup_at_equal_error"]
        ge = ">= " if r["at_least"] else ""
        cells += [
            f"{r['speedup_default']:.2f}x",
            "-" if t_eq is None else ("<= " if r["at_least"] else "") + f"{t_eq:.2f}",
            "-" if s_eq is None else f"**{ge}{s_eq:.2f}x**",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    meta = eq["meta"]
    lines += ["", f"Run {meta['date']}, old tree {meta['before']}, load at the end {meta['load']}.", ""]
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="a folder holding the old iat package")
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--rejudge", action="store_true", help="recompute the speed-ups of the saved JSON")
    a = ap.parse_args(argv)
    if a.rejudge:
        res = json.loads(OUT_JSON.read_text())
        res = {k: v if k == "meta" else judge(v) for k, v in res.items()}
    elif a.before is None:
        ap.error("--before DIR is required (or --rejudge)")
    else:
        res = run_equal(a.before, tuple(a.models.split(",")), a.repeats)
    OUT_JSON.write_text(json.dumps(res, indent=1))
    OUT_MD.write_text(format_md(res) + "\n")
    print(format_md(res))


if __name__ == "__main__":
    main()
