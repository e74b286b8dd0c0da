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
"""

from __future__ import annotations

import sys
import tempfile
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


def main(argv: list[str] | None = None) -> int:
    parts = set(sys.argv[1:] if argv is None else argv) or {"figures", "panels"}
    unknown = parts - {"figures", "panels"}
    if unknown:
        print(f"unknown part(s): {', '.join(sorted(unknown))} (figures, panels)", file=sys.stderr)
        return 2
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
