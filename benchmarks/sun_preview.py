"""How soon a moved sun shows (issue 41): the viewer's re-solve (:class:`iat.lighting.relight.Relighter`)
handed a model's new sun, as the Sun & sky panel hands it, with the time to its first picture (the
preview on the mesh on screen, :func:`iat.lighting.relight.preview`) and to the new solve.

    .venv/bin/python benchmarks/sun_preview.py MODEL [MODEL ...] [--hours 10,15] [--sky clear]
        [--reference] [--json out/sun_preview.json]

Per model: loaded as ``iat solve`` loads it (the default daylight at the model's place at the first
hour, ``--sky``, the sun's shadows cut), solved at the defaults; then the same patches lit by each
later hour's sun and sky (what the panel's time slider does) handed to a Relighter with
``remesh=True``. Columns: the first solve's seconds and elements, the preview's seconds (since the
edit was taken up), the new solve's seconds, and with ``--reference`` the preview against
``solve(scene, SolveOptions(), mesh=first)`` (the same light on the same mesh at full effort): its
seconds, the mean relative difference of the vertices' luminance, and the ratio of the means.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from iat.color import LUMINANCE_WEIGHTS  # noqa: E402
from iat.geometry.discontinuity import cut_new_lights  # noqa: E402
from iat.io.load import load_scene  # noqa: E402
from iat.lighting.daylight_default import DaylightRequest, apply_daylight  # noqa: E402
from iat.lighting.relight import Relighter  # noqa: E402
from iat.radiosity import SolveOptions, solve  # noqa: E402


def lit(path: str, when: str, sky: str):
    scene = load_scene(path)
    apply_daylight(scene, DaylightRequest(sun=when, sky=sky))
    return scene


def relit(scene, other):
    """``scene``'s patches under ``other``'s sun and sky (what the Sun & sky panel's slider does)."""
    s = copy.copy(scene)
    s.lights, s.sky = other.lights, other.sky
    return s


def one(path: str, date: str, hours: list[str], sky: str, reference: bool) -> list[dict]:
    t = time.perf_counter()
    first = cut_new_lights(lit(path, f"{date}T{hours[0]}", sky))
    base = solve(first, SolveOptions())
    base_s = time.perf_counter() - t
    rows = []
    for h in hours[1:]:
        scene = relit(first, lit(path, f"{date}T{h}", sky))
        rl = Relighter(base, first, SolveOptions())
        try:
            rl.submit(scene, version=1, remesh=True)
            got = {}
            while "solve" not in got:
                r = rl.poll()
                if r is not None:
                    if r.error:
                        raise RuntimeError(r.error)
                    got[r.mode] = r
                time.sleep(0.02)
        finally:
            rl.close()
        row = {
            "model": Path(path).name,
            "hours": f"{hours[0]} -> {h}",
            "first_solve_s": round(base_s, 1),
            "elements": int(base.stats["elements"]),
            "preview_s": round(got["preview"].total_seconds, 2) if "preview" in got else None,
            "solve_s": round(got["solve"].seconds, 1),
            "new_elements": int(got["solve"].solution.stats["elements"]),
        }
        if reference and "preview" in got:
            t = time.perf_counter()
            ref = solve(scene, SolveOptions(), mesh=base)
            a = got["preview"].solution.vert_radiance @ LUMINANCE_WEIGHTS
            b = ref.vert_radiance @ LUMINANCE_WEIGHTS
            row.update(
                reference_s=round(time.perf_counter() - t, 1),
                preview_error=round(float(np.abs(a - b).mean() / b.mean()), 4),
                preview_ratio=round(float(a.mean() / b.mean()), 4),
            )
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="+")
    ap.add_argument("--date", default="2026-06-21")
    ap.add_argument("--hours", default="10:00,15:00", help="the first solve's hour, then the hours moved to")
    ap.add_argument("--sky", default="clear")
    ap.add_argument("--reference", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    hours = args.hours.split(",")
    rows = [r for m in args.models for r in one(m, args.date, hours, args.sky, args.reference)]
    print("\n| model | hours | first solve s | elements | preview s | new solve s | preview off | ratio |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        err = f"{100 * r['preview_error']:.1f} %" if "preview_error" in r else "-"
        ratio = f"{r['preview_ratio']:.3f}" if "preview_ratio" in r else "-"
        print(
            f"| {r['model']} | {r['hours']} | {r['first_solve_s']} | {r['elements']:,} | {r['preview_s']} | "
            f"{r['solve_s']} | {err} | {ratio} |"
        )
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
