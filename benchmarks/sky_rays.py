"""What the sky's direct light costs in a daylight solve (issue 41): one model solved by a sun and a
sky at the defaults, with each stage's seconds and the sky's passes (vertices, directions each,
wall seconds), in one process per tree given (``--tree LABEL=DIR``, ``PYTHONPATH=DIR``: a checkout
of another commit, ``git worktree add``), ``--runs`` times each, alternating.

    .venv/bin/python benchmarks/sky_rays.py MODEL [--sky clear|uniform:R,G,B|...] [--sun 2026-06-21T10:00]
        [--tree before=/tmp/before --tree now=.] [--runs 2]

The model is loaded as ``iat solve`` loads it (``load_scene``, the default daylight with ``--sun``
and ``--sky`` at the model's own place, the sun's shadows cut), then ``solve(scene, SolveOptions())``.
Per run: load and solve seconds, the stages' seconds (``stats``), elements, shots, rays, and per
sky estimate the vertices, the rays traced and the directions that took their stratum's value
(``stats["sky_counts"]``, trees from issue 41's seventh stop on), or for older trees per sky pass
the calls, vertices, directions a vertex and the pass's wall seconds (by wrapping
``DirectLight._sky_pass``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time, collections
import iat
from iat.io.load import load_scene
from iat.lighting.daylight_default import DaylightRequest, apply_daylight
from iat.geometry.discontinuity import cut_new_lights
from iat.radiosity import SolveOptions, solve
from iat.radiosity import direct as D
path, sun, sky = sys.argv[1:4]
passes = collections.OrderedDict()
inner = getattr(D.DirectLight, "_sky_pass", None)
if inner is not None:
    def timed(self, geo, rows, pat, *rest):
        t = time.perf_counter()
        out = inner(self, geo, rows, pat, *rest)
        key = len(pat) if hasattr(pat, "__len__") else f"pass {pat}"  # older trees: the pass's index
        p = passes.setdefault(key, [0, 0, 0.0])
        p[0] += 1; p[1] += len(rows); p[2] += time.perf_counter() - t
        return out
    D.DirectLight._sky_pass = timed
t0 = time.perf_counter()
scene = load_scene(path)
apply_daylight(scene, DaylightRequest(sun=sun, sky=sky))
scene = cut_new_lights(scene)
load_s = time.perf_counter() - t0
t1 = time.perf_counter()
sol = solve(scene, SolveOptions())
st = sol.stats
print("RESULT " + json.dumps({
    "tree": iat.__file__, "load_s": load_s, "solve_s": time.perf_counter() - t1,
    "stages_s": {k: st.get(k) for k in ("meshing_s", "shooting_s", "refining_s")},
    "elements": int(st["elements"]), "shots": int(st["shots"]), "rays": int(st.get("rays", 0)),
    "sky_passes": [{"directions": k, "calls": v[0], "vertices": v[1], "s": v[2]} for k, v in passes.items()],
    "sky_counts": st.get("sky_counts"),
}), flush=True)
"""


def run(tree: Path, model: str, sun: str, sky: str) -> dict:
    """One solve of ``model`` by the code in ``tree`` in a child process: its RESULT line's dict."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, "-c", CHILD, str(Path(model).resolve()), sun, sky]
    # in the tree: ``-c`` puts the working directory first on the path
    out = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True, check=True).stdout
    return json.loads(next(ln[7:] for ln in out.splitlines() if ln.startswith("RESULT ")))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model")
    ap.add_argument("--sun", default="2026-06-21T10:00")
    ap.add_argument("--sky", default="clear")
    ap.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR")
    ap.add_argument("--runs", type=int, default=1)
    args = ap.parse_args(argv)
    trees = dict(t.split("=", 1) for t in args.tree) or {"now": str(ROOT)}
    print("| tree | solve s | meshing / shooting / refining s | elements | shots | sky passes "
          "(directions: vertices, s; or vertices: rays traced / directions given) |"
          "\n|---|---:|---|---:|---:|---|")  # fmt: skip
    for _ in range(args.runs):
        for label, tree in trees.items():
            r = run(Path(tree).resolve(), args.model, args.sun, args.sky)
            stages = " / ".join(f"{v:.1f}" if v is not None else "-" for v in r["stages_s"].values())
            sky = ", ".join(f"{p['directions']}: {p['vertices']}, {p['s']:.1f}" for p in r["sky_passes"])
            if r.get("sky_counts"):
                sky = ", ".join(f"{v}: {t / 1e6:.1f} M / {g / 1e6:.1f} M" for v, t, g in r["sky_counts"])
            row = f"| {label} | {r['solve_s']:.1f} | {stages} | {r['elements']} | {r['shots']} | {sky} |"
            print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
