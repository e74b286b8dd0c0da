"""Whether two trees solve the sample models to the same bits (a refactor's check, issue 40).

    .venv/bin/python benchmarks/same_bits.py save TAG [MODEL ...]   # solve, keep keys and radiance
    .venv/bin/python benchmarks/same_bits.py compare TAG_A TAG_B    # np.array_equal on both

Run ``save`` once in each tree (``PYTHONPATH=/path/to/other/tree`` for the other one, from its
root); the house, the Cornell box and the cave at the defaults and the pool at convergence 0.2.
Results go to ``out/bits/TAG_MODEL.npz``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

CASES = {"house": {}, "cornell_box": {}, "cave": {}, "pool": {"convergence": 0.2}}
OUT = Path("out") / "bits"


def save(tag: str, models: list[str]) -> None:
    from iat.io.load import load_scene
    from iat.radiosity import SolveOptions, solve

    OUT.mkdir(parents=True, exist_ok=True)
    for name in models or list(CASES):
        scene = load_scene(f"sample_models/{name}.glb")
        t = time.perf_counter()
        sol = solve(scene, SolveOptions(**CASES[name]))
        np.savez(OUT / f"{tag}_{name}.npz", key=sol.vert_key, rad=sol.vert_radiance)
        print(f"{name}: {time.perf_counter() - t:.2f} s, {sol.stats['elements']} elements", flush=True)


def compare(a: str, b: str) -> bool:
    same_all = True
    for name in CASES:
        pa, pb = OUT / f"{a}_{name}.npz", OUT / f"{b}_{name}.npz"
        if not (pa.is_file() and pb.is_file()):
            continue
        x, y = np.load(pa), np.load(pb)
        same = np.array_equal(x["key"], y["key"]) and np.array_equal(x["rad"], y["rad"])
        same_all &= same
        print(f"{name}: {'same bits' if same else 'DIFFERENT'}")
    return same_all


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "save":
        save(sys.argv[2], sys.argv[3:])
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(0 if compare(sys.argv[2], sys.argv[3]) else 1)
    else:
        sys.exit(__doc__)
