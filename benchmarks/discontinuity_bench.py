"""Discontinuity meshing (issue 17): errors, elements and solve times with and without; prints
markdown tables.

- **blade**: ``tests/test_discontinuity.py``'s scene (a tilted blade's hard shadow from a point light
  across a floor and up a wall) against its cached 4096-spp Mitsuba reference: error in the band
  around the shadow's boundary and over the image, elements, roots, solve seconds, plain and cut,
  at a few depths (needs mitsuba and EGL);
- **models**: ``sample_models/*.glb`` loaded with and without ``discontinuity=True`` and solved at
  the defaults (roots, the cut's seconds, elements, solve seconds);
- **ifc**: ``tests/support/large_ifc.py``'s generated IFC house (``--storeys``, 9 x 9 rooms), one
  point light per storey as ``benchmarks/ifc_house_bench.py`` places them, cut after the lights are
  added (:func:`iat.geometry.discontinuity.split_discontinuities`).

    .venv/bin/python benchmarks/discontinuity_bench.py [--only blade,models,ifc] [--storeys 2]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MODELS = ("cornell_box", "house", "house_day", "cave")


def _solve(scene, **kw):
    from iat.radiosity import SolveOptions, solve

    t0 = time.perf_counter()
    sol = solve(scene, SolveOptions(**kw))
    return sol, time.perf_counter() - t0


def blade_rows() -> list[str]:
    import moderngl

    from iat.geometry.discontinuity import split_discontinuities
    from iat.measure.reference import box_filtered_render, render_reference_cached
    from iat.render.renderer import Renderer
    from tests import test_discontinuity as td

    plain = td.blade_scene()
    t0 = time.perf_counter()
    cut = split_discontinuities(plain)
    cut_s = time.perf_counter() - t0
    ref = render_reference_cached(plain, td.CAMERA, td.SIZE, spp=4096, cache_dir=td.REFS, seed=3)
    direct = render_reference_cached(
        plain, td.CAMERA, td.SIZE, spp=64, cache_dir=td.REFS, seed=3, max_depth=2
    )
    r = Renderer(moderngl.create_standalone_context(backend="egl"))
    r.set_scene(plain)
    band, surface = td.band_masks(ref, direct, r.render(td.CAMERA, td.SIZE, mode="preview"))
    out = [
        f"Blade scene: band {int(band.sum())} pixels, surface {int(surface.sum())}; "
        f"the cut took {cut_s * 1e3:.0f} ms.",
        "",
        "| mesh | max_depth | roots | elements | band error | whole-image error | solve s |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, scene in (("plain", plain), ("discontinuity", cut)):
        for depth in (4, 5, 6, 7):
            _solve(scene, max_depth=depth)  # warm (kernels, caches): the second solve is timed
            sol, sec = _solve(scene, max_depth=depth)
            r.set_scene(scene)
            r.set_solution(sol)
            img = box_filtered_render(r, td.CAMERA, td.SIZE, "mesh")
            e_band, e_all = td.relative_error(img, ref, band), td.relative_error(img, ref, surface)
            out.append(
                f"| {name} | {depth} | {scene.n_patches} | {len(sol.leaf_patch):,} "
                f"| {e_band:.4f} | {e_all:.4f} | {sec:.2f} |"
            )
    r.release()
    return out


def model_rows() -> list[str]:
    from iat.io.load import load_scene

    out = [
        "| model | lights (point/spot/sun) | roots plain -> cut | cut s | elements plain / cut "
        "| solve s plain / cut |",
        "|---|---|---|---|---|---|",
    ]
    for name in MODELS:
        path = ROOT / "sample_models" / f"{name}.glb"
        t0 = time.perf_counter()
        plain = load_scene(path)
        t1 = time.perf_counter()
        cut = load_scene(path, discontinuity=True)
        cut_s = (time.perf_counter() - t1) - (t1 - t0)
        n_lights = sum(lt.kind in ("point", "spot", "directional") for lt in plain.lights)
        sp, tp = _solve(plain)
        sc, tc = _solve(cut)
        out.append(
            f"| {name} | {n_lights} | {plain.n_patches:,} -> {cut.n_patches:,} | {max(cut_s, 0):.2f} "
            f"| {len(sp.leaf_patch):,} / {len(sc.leaf_patch):,} | {tp:.1f} / {tc:.1f} |"
        )
    return out


def ifc_rows(storeys: int) -> list[str]:
    from iat.geometry.discontinuity import split_discontinuities
    from iat.io.load import load_scene
    from iat.io.scene import Light
    from tests.support import large_ifc
    from tests.support import real_models as rm

    with tempfile.TemporaryDirectory(prefix="iat-dm-ifc-") as tmp:
        path = large_ifc.large_ifc_house(Path(tmp) / "house.ifc", storeys, 9, 4)
        plain = load_scene(path)
    for p in large_ifc.light_positions(storeys, 9, 1):
        plain.lights.append(Light(kind="point", position=rm.ifc_to_yup(p), intensity=rm.IFC_LIGHT_INTENSITY))
    t0 = time.perf_counter()
    cut = split_discontinuities(plain)
    cut_s = time.perf_counter() - t0
    sp, tp = _solve(plain)
    sc, tc = _solve(cut)
    return [
        "| IFC house | triangles | lights | roots plain -> cut | cut s | elements plain / cut "
        "| solve s plain / cut |",
        "|---|---|---|---|---|---|---|",
        f"| {storeys} storeys, 9 x 9 rooms | {len(plain.world_triangles()):,} | {len(plain.lights)} "
        f"| {plain.n_patches:,} -> {cut.n_patches:,} | {cut_s:.1f} | {len(sp.leaf_patch):,} / "
        f"{len(sc.leaf_patch):,} | {tp:.1f} / {tc:.1f} |",
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", default="blade,models,ifc", help="comma-separated parts to run")
    ap.add_argument("--storeys", type=int, default=2, help="storeys of the generated IFC house")
    a = ap.parse_args(argv)
    parts = {"blade": blade_rows, "models": model_rows, "ifc": lambda: ifc_rows(a.storeys)}
    for name in a.only.split(","):
        print("\n".join(parts[name]()))
        print(flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
