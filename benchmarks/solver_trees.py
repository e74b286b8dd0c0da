"""Solve time of the sample models with several ``iat`` trees, alternating in one run.

    git archive 599fc3a^ iat | tar -x -C /tmp/issue18     # before the kernels (issue 18 filed)
    git archive aa82fc6 iat | tar -x -C /tmp/start        # any other tree
    .venv/bin/python benchmarks/solver_trees.py --models cornell_box,house --repeats 2 \\
        /tmp/issue18 /tmp/start .

Each solve (the defaults) runs in a process of its own with that tree first on ``sys.path``, the
trees taking turns so that they see the same load; prints each solve's wall and CPU seconds (all
threads), its rays and the load, then the best of ``--repeats`` per tree and model.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHILD = (
    "import sys, time; sys.path.insert(0, sys.argv[1]); from iat.io.load import load_scene; "
    "from iat.radiosity import solve; s = load_scene(sys.argv[2]); t = time.perf_counter(); "
    "c = time.process_time(); sol = solve(s); "
    "print(time.perf_counter() - t, time.process_time() - c, sol.stats['rays'])"
)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs="+", type=Path, help="folders holding an iat package")
    ap.add_argument("--models", default="cornell_box,house")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args(argv)
    for model in args.models.split(","):
        best: dict[Path, tuple[float, float]] = {}
        for _ in range(args.repeats):
            for tree in args.trees:
                path = ROOT / "sample_models" / f"{model}.glb"
                cmd = [sys.executable, "-c", CHILD, str(tree.resolve()), str(path)]
                run = subprocess.run(cmd, capture_output=True, text=True)
                if run.returncode:
                    sys.exit(f"{model} with {tree}: {run.stderr.strip().splitlines()[-1]}")
                wall, cpu, rays = map(float, run.stdout.split()[-3:])
                w, c = best.get(tree, (1e9, 1e9))
                best[tree] = (min(w, wall), min(c, cpu))
                load = os.getloadavg()[0]
                line = f"{wall:.2f} s, CPU {cpu:.2f} s, {rays / 1e6:.1f} M rays, load {load:.1f}"
                print(f"{model} {tree}: {line}")
        rows = ", ".join(f"{t} {w:.2f} s (CPU {c:.2f} s)" for t, (w, c) in best.items())
        print(f"best of {args.repeats}, {model}: {rows}")


if __name__ == "__main__":
    main()
