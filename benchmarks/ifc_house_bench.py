"""A large IFC house, loaded and solved with and without panels: prints markdown tables.

Generates ``tests/support/large_ifc.py``'s house (about 35 000 triangles at the defaults) into a
temporary directory (or ``--out``), then measures, each in a child process of its own (so that
the process's peak RSS is that step's):

- load: ``load_scene(path)`` and ``load_scene(path, panels=False)``: time, tracemalloc peak
  (Python and numpy allocations; the geometry kernel's C++ heap is not traced), the process's max
  RSS (``resource.getrusage``) and its RSS after the imports; patches, quads, panel cells, the
  panels ``find_panels`` finds and ``sliver_count`` on the loaded scene, world triangles;
- solve: each scene with one point light per storey (``light_positions``, the intensity of
  ``tests/support/real_models.py``'s IFC lamp), ``solve(scene, SolveOptions(...))``: time,
  elements, vertices, shots, rays and max RSS. ``--depth`` sets ``max_depth`` (default: the
  solver's), ``--solve-timeout`` bounds each solve (a solve past it is reported as such),
  ``--min-element-size`` sets ``min_element_size`` (the default grows with the building's area, so
  more storeys alone do not make more elements) and ``--only`` keeps one of the two loads.

    .venv/bin/python benchmarks/ifc_house_bench.py [--out FILE.ifc] [--depth 5] [--no-solve]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support import large_ifc  # noqa: E402

MIB = 2**20


def rss_now_mib() -> float:
    """The process's resident set now (VmRSS), MiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def max_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux


def child_load(path: Path, panels: bool) -> dict:
    import ifcopenshell.geom  # noqa: F401 - imported before the baseline, as load_scene imports it

    from iat.geometry.panels import find_panels, sliver_count
    from iat.io.load import load_scene

    base = rss_now_mib()
    tracemalloc.start()
    t0 = time.perf_counter()
    scene = load_scene(path, panels=panels)
    load_s = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "load_s": load_s,
        "trace_peak_mib": peak / MIB,
        "max_rss_mib": max_rss_mib(),
        "base_rss_mib": base,
        "patches": int(scene.n_patches),
        "quads": int(scene.patch_is_quad.sum()),
        "clipped": int(scene.patch_clipped.sum()),
        "clip_triangles": int(len(scene.clip_patch)),
        "panels": int(find_panels(scene).n_panels),
        "slivers": int(sliver_count(scene)),
        "world_triangles": int(len(scene.world_triangles())),
    }


def child_solve(
    path: Path,
    panels: bool,
    depth: int | None,
    lights_per_storey: int,
    storeys: int,
    rooms: int,
    min_element_size: float | None = None,
) -> dict:
    from iat.io.load import load_scene
    from iat.io.scene import Light
    from iat.radiosity import SolveOptions, solve
    from tests.support import real_models as rm

    scene = load_scene(path, panels=panels)
    for p in large_ifc.light_positions(storeys, rooms, lights_per_storey):
        scene.lights.append(
            Light(
                kind="point", position=rm.ifc_to_yup(p), intensity=rm.IFC_LIGHT_INTENSITY, name="bench lamp"
            )
        )
    opts = {"panels": panels} | ({"max_depth": depth} if depth is not None else {})
    if min_element_size is not None:
        opts["min_element_size"] = min_element_size
    base = rss_now_mib()
    t0 = time.perf_counter()
    sol = solve(scene, SolveOptions(**opts))
    solve_s = time.perf_counter() - t0
    st = sol.stats
    return {
        "solve_s": solve_s,
        "max_rss_mib": max_rss_mib(),
        "base_rss_mib": base,
        "lights": len(scene.lights),
        "elements": int(st["elements"]),
        "vertices": int(st.get("vertices", len(sol.vert_key))),
        "shots": int(st.get("shots", -1)),
        "rays": int(st.get("rays", -1)),
        "unshot": float(st.get("unshot_fraction", float("nan"))),
        "max_depth": int(sol.max_depth),
    }


def run_child(args: list[str], timeout: float | None) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", *args]
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"did not finish in {timeout:.0f} s"}
    if r.returncode != 0:
        return {"error": f"rc {r.returncode}: {(r.stderr.strip().splitlines() or ['?'])[-1]}"}
    return json.loads(r.stdout.strip().splitlines()[-1])


def _table(head: str, rows: dict, row) -> list[str]:
    """A Markdown table: the header ``head`` (``| a | b | ... |``), then ``row(name, f)`` for each step,
    or for a failed one its error."""
    cols = head.count("|") - 1
    out = [head, "|" + "---|" * cols]
    for name, f in rows.items():
        out.append(f"| {name} | {f['error']} |" + " |" * (cols - 2) if "error" in f else row(name, f))
    return out


def fmt_load(rows: dict) -> list[str]:
    return _table(
        "| load | patches | quads | clipped cells (clip triangles) | panels found | slivers "
        "| world triangles | load s | tracemalloc peak MiB | max RSS MiB (after imports) |",
        rows,
        lambda name, f: (
            f"| {name} | {f['patches']:,} | {f['quads']:,} | {f['clipped']:,} ({f['clip_triangles']:,}) "
            f"| {f['panels']:,} | {f['slivers']:,} | {f['world_triangles']:,} | {f['load_s']:.1f} "
            f"| {f['trace_peak_mib']:.0f} | {f['max_rss_mib']:.0f} ({f['base_rss_mib']:.0f}) |"
        ),
    )


def fmt_solve(rows: dict) -> list[str]:
    return _table(
        "| solve | lights | max_depth | solve s | elements | vertices | shots | rays | unshot | "
        "max RSS MiB (before solve) |",
        rows,
        lambda name, f: (
            f"| {name} | {f['lights']} | {f['max_depth']} | {f['solve_s']:.1f} | {f['elements']:,} "
            f"| {f['vertices']:,} | {f['shots']:,} | {f['rays'] / 1e6:.1f} M | {f['unshot']:.3f} "
            f"| {f['max_rss_mib']:.0f} ({f['base_rss_mib']:.0f}) |"
        ),
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, help="write the IFC file here (default: a temporary directory)")
    ap.add_argument("--storeys", type=int, default=5)
    ap.add_argument("--rooms", type=int, default=9, help="rooms per side")
    ap.add_argument("--windows", type=int, default=4, help="windows per room on each facade")
    ap.add_argument("--lights", type=int, default=1, help="point lights per storey")
    ap.add_argument("--depth", type=int, default=None, help="SolveOptions.max_depth (default: the solver's)")
    ap.add_argument(
        "--min-element-size",
        type=float,
        default=None,
        help="SolveOptions.min_element_size in metres (default: the solver's, 1/600 of the square root "
        "of the surface area, so more storeys alone do not make more elements)",
    )
    ap.add_argument("--only", choices=("panels", "no-panels"), help="load and solve one way only")
    ap.add_argument("--no-solve", action="store_true")
    ap.add_argument("--solve-timeout", type=float, default=1200.0, help="seconds per solve")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        kind, panels, path = a.child[0], a.child[1] == "1", Path(a.child[2])
        if kind == "load":
            res = child_load(path, panels)
        else:
            res = child_solve(path, panels, a.depth, a.lights, a.storeys, a.rooms, a.min_element_size)
        print(json.dumps(res))
        return 0
    with tempfile.TemporaryDirectory(prefix="iat-ifc-house-") as tmp:
        path = a.out or Path(tmp) / "large_house.ifc"
        t0 = time.perf_counter()
        large_ifc.large_ifc_house(path, a.storeys, a.rooms, a.windows)
        gen_s = time.perf_counter() - t0
        print(
            f"{path.name}: {a.storeys} storeys, {a.rooms} x {a.rooms} rooms, {a.windows} windows per room "
            f"and facade; {path.stat().st_size / MIB:.2f} MiB, generated in {gen_s:.1f} s\n"
        )
        ways = [p for p in (False, True) if a.only is None or a.only == ("panels" if p else "no-panels")]
        loads = {}
        for panels in ways:
            name = "panels" if panels else "no panels"
            loads[name] = run_child(["load", str(int(panels)), str(path)], None)
            print(f"load ({name}) done", file=sys.stderr)
        print("\n".join(fmt_load(loads)))
        if a.no_solve:
            return 0
        extra = ["--depth", str(a.depth)] if a.depth is not None else []
        extra += ["--lights", str(a.lights), "--storeys", str(a.storeys), "--rooms", str(a.rooms)]
        if a.min_element_size is not None:
            extra += ["--min-element-size", str(a.min_element_size)]
        solves = {}
        for panels in ways:
            name = "panels" if panels else "no panels"
            solves[name] = run_child(["solve", str(int(panels)), str(path), *extra], a.solve_timeout)
            print(f"solve ({name}) done: {solves[name]}", file=sys.stderr)
        print()
        print("\n".join(fmt_solve(solves)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
