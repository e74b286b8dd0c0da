"""How IAT does on small models written by real tools: prints a markdown table.

Generates the models of ``tests/support/real_models.py`` (IFC house by ifcopenshell, room by
Blender as GLB and OBJ, COLLADA room by pycollada) into a temporary directory, then per model:
load time, patches, solve time (default SolveOptions), triangles of the mesh and IAT modes (default
BakePolicy), texture memory, and on the interior view (256 x 256) the PSNR of IAT against the mesh
(peak: 99.5th percentile of the mesh luminance) and the dotted fraction (lit pixels where IAT is
below half the mesh). Then the skewed-quad highlight offsets and the keyhole ring's area.

Then "panels against no panels at equal error" (part ``panels``): each model solved with panels
(``load_scene(path)``) and without (``load_scene(path, panels=False)``) at the default options and
at tighter tolerances, against a finer reference solve (:data:`REFERENCES`), all rendered in mesh
mode on the same interior view; the error of each is the relative error of the luminance on the
reference's lit pixels (mean ``|a - ref|`` / mean ``ref``) and the 99.5-percentile PSNR; also
solve time, elements, triangles (mesh mode: ``len(sol.drawn_mesh().triangles)``; IAT: mesh part +
textured part of the default bake), texture memory, the IAT image's error against the reference
and IAT against the mesh.

    .venv/bin/python benchmarks/real_models_bench.py [figures] [panels]   (under xvfb-run or with EGL)

Part ``daylight`` (issue 36's before and after): each IFC file of ``../shared/real-models`` (and
``furnished``, a generated two-storey furnished house: :func:`model_path`) solved
by the sun on :data:`SUN` at the model's place (IfcSite, else the default place) and the sky
:data:`SKY`, at each preset, by the code of each tree given (``--tree LABEL=DIR``, repeatable; the
default: this checkout as ``now``): one child process a solve (``PYTHONPATH=DIR``, :data:`CHILD`),
at most ``--cap`` seconds, one at a time. Per run: load and solve seconds, patches, elements, shots,
unshot fraction, the largest vertex radiance, a :class:`~iat.errors.SolveError` if one stopped it,
the solve's CPU seconds (all threads) and the child's (``wait4``: also of a child stopped at the cap),
its peak resident memory (``wait4``'s ``ru_maxrss``),
the load average before and after, and for a run stopped at the cap its last progress line. Rows
go to ``--json`` as each run ends (a run already there is not redone):

    .venv/bin/python benchmarks/real_models_bench.py daylight --tree before=/tmp/before --tree now=.
        [--models madrid,tekla,...] [--presets draft,default] [--cap 900] [--json F]
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from iat.bake.baker import bake  # noqa: E402
from iat.bake.policy import BakePolicy  # noqa: E402
from iat.errors import LoadError  # noqa: E402
from iat.io.load import load_scene  # noqa: E402
from iat.measure.metrics import luminance  # noqa: E402
from iat.radiosity import SolveOptions, solve  # noqa: E402
from iat.render.renderer import Renderer  # noqa: E402
from tests.support import real_models as rm  # noqa: E402


def generate(out: Path) -> dict:
    """``name -> path or error string`` of the interior models."""
    paths: dict = {}
    for name, make in (("ifc", rm.ifc_house), ("dae", rm.collada_room)):
        t0 = time.perf_counter()
        try:
            paths[name] = make(out)
        except Exception as e:  # a missing package: report it in the table
            paths[name] = f"not generated: {e}"
        print(f"generated {name} in {time.perf_counter() - t0:.2f} s", file=sys.stderr)
    reason = rm.bpy_available()
    t0 = time.perf_counter()
    if reason is None:
        files = rm.blender_room(out)
        paths["glb"], paths["obj"] = files["glb"], files["obj"]
        print(f"generated glb + obj (Blender) in {time.perf_counter() - t0:.2f} s", file=sys.stderr)
    else:
        paths["glb"] = paths["obj"] = reason
    return {k: paths[k] for k in ("ifc", "glb", "obj", "dae")}


def measure(name: str, path: Path, renderer: Renderer) -> dict:
    t0 = time.perf_counter()
    scene = load_scene(path)
    load_s = time.perf_counter() - t0
    sol, baked, solve_s, bake_s = rm.solve_and_bake(name, scene)
    cam = rm.model_cameras()[name]
    renderer.set_solution(sol)
    renderer.set_baked(baked)
    mesh = renderer.render(cam, size=rm.IMAGE_SIZE, mode="mesh")
    iat = renderer.render(cam, size=rm.IMAGE_SIZE, mode="iat")
    times = {"load_s": load_s, "solve_s": solve_s, "bake_s": bake_s, "bytes": path.stat().st_size}
    return {**rm.figures(scene, sol, baked, mesh, iat), **times}


def skewed(out: Path, renderer: Renderer) -> list[str]:
    lines = []
    for form in ("obj file", "one quad patch"):
        r = rm.skewed_quad_renders(out, form, renderer)
        scene, mesh, iat, d = r["scene"], r["mesh"], r["iat"], r["distance"]
        lines.append(
            f"- skewed quad ({form}): {scene.n_patches} patches, highlight IAT vs mesh {d:.2f} px, "
            f"PSNR {rm.percentile_psnr(iat, mesh):.2f} dB"
        )
    return lines


def ring(out: Path) -> str:
    try:
        scene = load_scene(rm.ngon_obj(out))
    except LoadError as e:
        return f"- keyhole ring: not loaded: {e}"
    centre = scene.corner_positions.mean(axis=1)
    a = float(scene.patch_area[centre[:, 0] > 3.5].sum())
    el = float(scene.patch_area[centre[:, 0] <= 3.5].sum())
    return f"- keyhole ring: area {a:.6f} (exact {rm.RING_AREA:.6f}), L-shape {el:.6f} (exact {rm.L_AREA})"


#: the reference solves: finer than the defaults on every axis (depth 7, half the tolerance, twice
#: the samples per side) and another seed (the defaults' sample errors are not shared with it)
REFERENCES = {
    "no panels": (False, SolveOptions(max_depth=7, tolerance=0.05, samples=32, seed=1, panels=False)),
    "panels": (True, SolveOptions(max_depth=7, tolerance=0.05, samples=32, seed=1)),
}
#: the solves compared: (label, panels, options)
VARIANTS = [
    ("no panels", False, SolveOptions(panels=False)),
    ("panels", True, SolveOptions()),
    ("no panels, tol 0.05", False, SolveOptions(tolerance=0.05, panels=False)),
    ("panels, tol 0.05", True, SolveOptions(tolerance=0.05)),
    ("no panels, tol 0.025", False, SolveOptions(tolerance=0.025, panels=False)),
    ("panels, tol 0.025", True, SolveOptions(tolerance=0.025)),
]


def lit_relative_error(test, ref, rel: float = 0.02, q: float = 99.5) -> float:
    """Mean ``|L_test - L_ref|`` over mean ``L_ref`` (luminance) on the reference's lit pixels
    (above ``rel`` x its ``q``-th percentile, as ``real_models.dotted_fraction`` counts them)."""
    a, b = luminance(test), luminance(ref)
    lit = b > rel * float(np.percentile(b, q))
    return float(np.abs(a[lit] - b[lit]).mean() / b[lit].mean()) if lit.any() else float("nan")


def solve_model(name: str, path: Path, panels: bool, opts: SolveOptions):
    scene = load_scene(path, panels=panels)
    if name == "ifc":
        rm.add_ifc_light(scene)
    t0 = time.perf_counter()
    sol = solve(scene, opts)
    return scene, sol, time.perf_counter() - t0


def panels_rows(name: str, path: Path, renderer: Renderer) -> list[dict]:
    """One row per reference and variant of :data:`REFERENCES` and :data:`VARIANTS`."""
    cam = rm.model_cameras()[name]
    rows, refs = [], {}
    for label, panels, opts in [(f"reference ({k})", p, o) for k, (p, o) in REFERENCES.items()] + VARIANTS:
        scene, sol, solve_s = solve_model(name, path, panels, opts)
        baked = bake(sol, scene, BakePolicy())
        renderer.set_solution(sol)
        renderer.set_baked(baked)
        mesh = renderer.render(cam, size=rm.IMAGE_SIZE, mode="mesh")
        iat = renderer.render(cam, size=rm.IMAGE_SIZE, mode="iat")
        if label.startswith("reference"):
            refs[label] = mesh
        ref = refs["reference (no panels)"]
        rows.append(
            {
                "model": name,
                "variant": label,
                "patches": int(scene.n_patches),
                "solve_s": solve_s,
                "elements": int(sol.stats["elements"]),
                "mesh_tris": int(len(sol.drawn_mesh().triangles)),
                "iat_tris": int(len(baked.mesh_indices) + len(baked.tex_indices)),
                "texture_mib": baked.memory.texture_bytes / 2**20,
                "rel": lit_relative_error(mesh, ref),
                "psnr": rm.percentile_psnr(mesh, ref),
                "rel_p": lit_relative_error(mesh, refs["reference (panels)"])
                if len(refs) > 1
                else float("nan"),
                "iat_rel": lit_relative_error(iat, ref),
                "iat_psnr": rm.percentile_psnr(iat, mesh),
            }
        )
        print(f"{name} {label}: {solve_s:.1f} s, {rows[-1]['elements']} elements", file=sys.stderr)
    return rows


def panels_table(paths: dict, renderer: Renderer) -> None:
    print(
        "| model | solve | patches | solve s | elements | mesh tris | IAT tris | texture MiB"
        " | mesh rel. error | mesh PSNR dB | vs panel ref. | IAT rel. error | IAT vs mesh PSNR dB |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, path in paths.items():
        if isinstance(path, str):
            print(f"| {name} | {path} |" + " |" * 11)
            continue
        for r in panels_rows(name, path, renderer):
            print(
                f"| {name} | {r['variant']} | {r['patches']} | {r['solve_s']:.1f} | {r['elements']:,} "
                f"| {r['mesh_tris']:,} | {r['iat_tris']:,} | {r['texture_mib']:.2f} | {r['rel']:.4f} "
                f"| {r['psnr']:.2f} | {r['rel_p']:.4f} | {r['iat_rel']:.4f} | {r['iat_psnr']:.2f} |",
                flush=True,
            )


def figures_table(paths: dict, renderer: Renderer, out: Path) -> None:
    print(
        "| model | file | load s | patches | solve s | bake s | mesh tris | IAT tris (mesh + tex) "
        "| texture MiB | PSNR dB | dotted % |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, path in paths.items():
        if isinstance(path, str):
            print(f"| {name} | {path} | | | | | | | | | |")
            continue
        try:
            f = measure(name, path, renderer)
        except LoadError as e:
            print(f"| {name} | {path.name} | {e} | | | | | | | | |")
            continue
        print(
            f"| {name} | {path.name} ({f['bytes'] / 1024:.1f} KiB) | {f['load_s']:.2f} | {f['patches']} "
            f"| {f['solve_s']:.1f} | {f['bake_s']:.2f} | {f['mesh_tris']} "
            f"| {f['iat_tris']} ({f['iat_mesh_tris']} + {f['iat_tex_tris']}) "
            f"| {f['texture_bytes'] / 2**20:.3f} | {f['psnr_db']:.2f} | {100 * f['dotted']:.3f} |"
        )
    print()
    for line in skewed(out, renderer) + [ring(out)]:
        print(line)
    lights = rm.glb_point_lights(paths["glb"]) if not isinstance(paths["glb"], str) else []
    for lt in lights:
        print(
            f"- Blender's GLB point light: {lt['intensity']:.3f} cd for {5.0} W "
            f"(= W x 683 / 4 pi = {5.0 * 683 / (4 * np.pi):.3f})"
        )


#: the real models of part ``daylight``: short name -> file in :data:`REAL_MODELS`
REAL_MODELS = Path(__file__).resolve().parents[2] / "shared" / "real-models"
DAYLIGHT_MODELS = {
    "madrid": "revit2021-madrid-house.ifc",
    "tekla": "tekla2019-carwash-structure.ifc",
    "openhouse": "ifcopenshell-open-house-ifc4.ifc",
    "swept": "blenderbim-swept-solid.ifc",
    "furnished": None,  # generated: :func:`model_path`
}
#: issue 36's light: the sun at 10:00 on the solstice at the model's place, a uniform sky
SUN = "2026-06-21T10:00"
SKY = "uniform:30,35,45"
#: seconds between the child's progress lines
PROGRESS_EVERY = 30.0

#: one solve in a child process of another tree (only API both sides of issue 36 have); argv: model,
#: preset, sun, sky; prints PROGRESS lines and one RESULT line of JSON
CHILD = r"""
import json, sys, time
import numpy as np
import iat
from iat.io.load import load_scene
from iat.lighting.daylight_default import DaylightRequest, apply_daylight
from iat.radiosity import SolveOptions, solve
path, quality, sun, sky = sys.argv[1:5]
print("TREE", iat.__file__, flush=True)
t0 = time.perf_counter()
scene = load_scene(path)
load_s = time.perf_counter() - t0
print("LOADED", scene.n_patches, flush=True)
print("LIGHT", apply_daylight(scene, DaylightRequest(sun=sun, sky=sky)), flush=True)
try:  # the sun's shadows cut as iat solve cuts them (trees from before that: not)
    from iat.geometry.discontinuity import cut_new_lights
except ImportError:
    pass
else:
    scene = cut_new_lights(scene)
    print("CUT", scene.n_patches, flush=True)
last = [0.0]
def progress(fraction, message=""):
    now = time.perf_counter() - t0
    if now - last[0] >= EVERY_S:
        last[0] = now
        print(f"PROGRESS {now:.0f} s {fraction:.3f} {message}", flush=True)
    return True
out = {"load_s": load_s, "patches": int(scene.n_patches)}
t1, c1 = time.perf_counter(), time.process_time()
try:
    sol = solve(scene, SolveOptions.preset(quality), progress=progress)
except Exception as e:  # SolveError (issue 36) or another failure: its one line
    out.update(solve_s=time.perf_counter() - t1, error=f"{type(e).__name__}: {e}")
    out["solve_cpu_s"] = time.process_time() - c1
else:
    st, rad = sol.stats, np.asarray(sol.vert_radiance, dtype=np.float64)
    out.update(
        solve_s=time.perf_counter() - t1,
        solve_cpu_s=time.process_time() - c1,
        elements=int(st["elements"]),
        shots=int(st["shots"]),
        unshot=float(st.get("unshot_fraction", float("nan"))),
        ambient_fraction=float(st.get("ambient_luminance_fraction", float("nan"))),
        max_radiance=float(rad.max()) if rad.size else 0.0,
        finite=bool(np.isfinite(rad).all()),
    )
print("RESULT " + json.dumps(out), flush=True)
""".replace("EVERY_S", repr(PROGRESS_EVERY))


def run_child(tree: Path, model: Path, preset: str, cap: float, log: Path) -> dict:
    """One :data:`CHILD` solve of ``model`` at ``preset`` by the code in ``tree``, stopped (SIGKILL to
    its process group) after ``cap`` seconds; its output goes to ``log``. Returns the RESULT's fields
    (none when stopped) and ``wall_s``, ``peak_rss_mib`` (the child's ``ru_maxrss``), ``stopped``,
    ``returncode``, ``last_lines`` (the output's last progress and other lines)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    t0 = time.perf_counter()
    with open(log, "w") as f:
        p = subprocess.Popen(
            [sys.executable, "-c", CHILD, str(model), preset, SUN, SKY],
            cwd=tree,
            env=env,
            stdout=f,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        stopped = threading.Event()

        def stop():
            stopped.set()
            os.killpg(p.pid, signal.SIGKILL)

        timer = threading.Timer(cap, stop)
        timer.start()
        _, status, usage = os.wait4(p.pid, 0)
        timer.cancel()
        p.returncode = os.waitstatus_to_exitcode(status)
    lines = log.read_text(errors="replace").splitlines()
    row = {
        "wall_s": round(time.perf_counter() - t0, 1),
        "peak_rss_mib": round(usage.ru_maxrss / 1024, 1),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 1),
        "stopped": stopped.is_set(),
        "returncode": p.returncode,
        "last_lines": [ln[:300] for ln in lines[-4:]],
        "light": next((ln[6:] for ln in lines if ln.startswith("LIGHT ")), None),
        "tree_file": next((ln[5:] for ln in lines if ln.startswith("TREE ")), None),
    }
    for ln in lines:
        if ln.startswith("LOADED "):
            row["patches"] = int(ln.split()[1])
        if ln.startswith("RESULT "):
            row.update(json.loads(ln[7:]))
    return row


def model_path(name: str, out_dir: Path) -> Path:
    """The file of daylight model ``name``: one of :data:`REAL_MODELS`, or ``furnished``, the
    two-storey furnished house of 5 x 5 rooms that ``tests/support/large_ifc.py`` writes (27.6 k
    triangles; issue 41's generated house), written into ``out_dir``."""
    if DAYLIGHT_MODELS[name] is not None:
        return REAL_MODELS / DAYLIGHT_MODELS[name]
    from tests.support.large_ifc import large_ifc_house

    return large_ifc_house(
        out_dir / "furnished-house.ifc", storeys=2, rooms_per_side=5, windows_per_room=3, furnished=True
    )


def daylight_part(trees: dict, models: list, presets: list, cap: float, json_path: Path) -> None:
    """Part ``daylight``: every model, preset and tree, one at a time, rows into ``json_path``."""
    result = (
        json.loads(json_path.read_text()) if json_path.is_file() else {"sun": SUN, "sky": SKY, "rows": []}
    )
    done = {(r["model"], r["preset"], r["tree"]) for r in result["rows"]}
    logs = Path(__file__).resolve().parents[1] / "out" / "real_models_daylight"
    logs.mkdir(parents=True, exist_ok=True)
    for name in models:
        for preset in presets:
            for label, tree in trees.items():
                if (name, preset, label) in done:
                    continue
                commit = subprocess.run(
                    ["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True, text=True
                ).stdout.strip()
                load_before = [round(x, 2) for x in os.getloadavg()]
                date = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
                row = run_child(
                    tree,
                    model_path(name, logs),
                    preset,
                    cap,
                    logs / f"{name}-{preset}-{label}.log",
                )
                row = {
                    "model": name,
                    "preset": preset,
                    "tree": label,
                    "commit": commit,
                    "date": date,
                    "load_before": load_before,
                    "load_after": [round(x, 2) for x in os.getloadavg()],
                    **row,
                }
                result["rows"].append(row)
                json_path.write_text(json.dumps(result, indent=1) + "\n")
                what = (
                    "stopped at the cap"
                    if row["stopped"]
                    else row.get("error")
                    or (
                        f"{row.get('solve_s', float('nan')):.1f} s, {row.get('elements')} elements, "
                        f"{row.get('shots')} shots, max radiance {row.get('max_radiance', float('nan')):.3g}"
                    )
                )
                print(
                    f"{name} {preset} {label}: {what}; {row['peak_rss_mib']} MiB; load {load_before}",
                    flush=True,
                )


def daylight_markdown(result: dict) -> str:
    """The rows of part ``daylight`` as a Markdown table, before and after side by side (the first two
    trees of the rows), then the last progress line of each run stopped at the cap."""
    rows = {(r["model"], r["preset"], r["tree"]): r for r in result["rows"]}
    trees = list(dict.fromkeys(r["tree"] for r in result["rows"]))[:2]
    keys = list(dict.fromkeys((r["model"], r["preset"]) for r in result["rows"]))

    def cell(r, field, fmt="{:,}"):
        if r is None:
            return "not run"
        if r.get("stopped"):
            cpu = f", {r['cpu_s']:.0f} CPU" if "cpu_s" in r else ""
            return f"> {r['wall_s']:.0f} s (stopped{cpu})" if field == "solve_s" else "-"
        if "error" in r:
            return r["error"][:60] if field == "solve_s" else "-"
        v = r.get(field)
        return "-" if v is None else fmt.format(v)

    out = [
        f"| model | preset | {' → '.join(trees)}: patches | solve s | elements | shots | max vertex radiance "
        "| peak RSS MiB | load at start |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for model, preset in keys:
        rs = [rows.get((model, preset, t)) for t in trees]
        pair = [
            " → ".join(f(r) for r in rs)
            for f in (
                lambda r: "-" if r is None or "patches" not in r else f"{r['patches']:,}",
                lambda r: (
                    cell(r, "solve_s", "{:.0f}")
                    + (f" ({r['solve_cpu_s']:.0f} CPU)" if r is not None and "solve_cpu_s" in r else "")
                ),
                lambda r: cell(r, "elements"),
                lambda r: cell(r, "shots"),
                lambda r: cell(r, "max_radiance", "{:.3g}"),
                lambda r: "-" if r is None else f"{r['peak_rss_mib']:,.0f}",
                lambda r: "-" if r is None else f"{r['load_before'][0]:.1f}",
            )
        ]
        out.append(f"| {model} | {preset} | " + " | ".join(pair) + " |")
        for t, r in zip(trees, rs, strict=True):
            if r is not None and r.get("stopped"):
                last = [ln for ln in r["last_lines"] if ln.startswith("PROGRESS")] or ["-"]
                notes.append(f"- {model} {preset} {t}: stopped at {r['wall_s']:.0f} s; last: `{last[-1]}`")
    return "\n".join(out + [""] + notes) + "\n"


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("parts", nargs="*", help="figures, panels, daylight (default: figures panels)")
    ap.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR", help="daylight: a tree")
    ap.add_argument("--models", default=",".join(DAYLIGHT_MODELS), help="daylight: the models")
    ap.add_argument("--presets", default="draft,default", help="daylight: the presets")
    ap.add_argument("--cap", type=float, default=900.0, help="daylight: seconds a run may take")
    ap.add_argument("--table", action="store_true", help="daylight: print the JSON's table, run nothing")
    ap.add_argument(
        "--json",
        default=str(Path(__file__).with_name("real_models_daylight.json")),
        help="daylight: the rows' file",
    )
    args = ap.parse_args(argv)
    parts = set(args.parts) or {"figures", "panels"}
    unknown = parts - {"figures", "panels", "daylight"}
    if unknown:
        print(f"unknown part(s): {', '.join(sorted(unknown))} (figures, panels, daylight)", file=sys.stderr)
        return 2
    if "daylight" in parts:
        trees = dict(t.split("=", 1) for t in args.tree) or {"now": "."}
        trees = {k: Path(v).resolve() for k, v in trees.items()}
        if args.table:
            print(daylight_markdown(json.loads(Path(args.json).read_text())), end="")
            return 0
        daylight_part(trees, args.models.split(","), args.presets.split(","), args.cap, Path(args.json))
        parts.discard("daylight")
        if not parts:
            return 0
    with tempfile.TemporaryDirectory(prefix="iat-real-") as tmp:
        out = Path(tmp)
        paths = generate(out)
        renderer = Renderer()
        if "figures" in parts:
            figures_table(paths, renderer, out)
        if "panels" in parts:
            if "figures" in parts:
                print()
            panels_table(paths, renderer)
        renderer.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
