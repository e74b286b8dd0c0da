"""Discontinuity meshing (issue 17): errors, elements and solve times with and without; prints
markdown tables.

- **blade**: ``tests/test_discontinuity.py``'s scene (a tilted blade's hard shadow from a point light
  across a floor and up a wall) against its cached 4096-spp Mitsuba reference: error in the band
  around the shadow's boundary (mesh and IAT, baked at the default policy) and over the image,
  elements, roots, solve seconds, plain and cut, at a few depths (needs mitsuba and EGL);
- **room**: the sun patch of ``tests/support/daylight.py``'s daylit room (sun and sky through an open
  window) against its cached 4096-spp reference, the band around the patch's edge, mesh and IAT,
  plain and cut at the defaults (``tests/test_discontinuity.py::test_sun_patch_through_a_window``);
- **models**: ``sample_models/*.glb`` loaded with and without ``discontinuity=True`` and solved at
  the defaults (roots, the cut's seconds, elements, shots, solve wall and CPU seconds);
- **real**: ``../shared/real-models/ifcopenshell-open-house-ifc4.ifc`` under its default daylight
  (:func:`iat.lighting.daylight_default.apply_daylight`, the tests' date), cut along the sun after it
  is added, as the models;
- **ifc**: ``tests/support/large_ifc.py``'s generated IFC house (``--storeys``, 9 x 9 rooms), one
  point light per storey as ``benchmarks/ifc_house_bench.py`` places them, cut after the lights are
  added (:func:`iat.geometry.discontinuity.split_discontinuities`).

    .venv/bin/python benchmarks/discontinuity_bench.py [--only blade,room,models,real,ifc] [--storeys 2]
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
    """(solution, wall seconds, CPU seconds of this process: both threads, less sensitive to the other
    jobs on a shared machine) of a solve at ``SolveOptions(**kw)``."""
    from iat.radiosity import SolveOptions, solve

    t0, c0 = time.perf_counter(), time.process_time()
    sol = solve(scene, SolveOptions(**kw))
    return sol, time.perf_counter() - t0, time.process_time() - c0


def _mesh_and_iat_errors(r, scene, sol, camera, size, ref, band) -> tuple[float, float]:
    """Band errors of the mesh and of the IAT image (default bake) of a solution."""
    from tests import test_discontinuity as td

    return tuple(td.relative_error(img, ref, band) for img in td.mesh_and_iat(r, scene, sol, camera, size))


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
        "| mesh | max_depth | roots | elements | band error mesh / IAT | whole-image error | solve s |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, scene in (("plain", plain), ("discontinuity", cut)):
        for depth in (4, 5, 6, 7):
            _solve(scene, max_depth=depth)  # warm (kernels, caches): the second solve is timed
            sol, sec, _ = _solve(scene, max_depth=depth)
            e_band, e_iat = _mesh_and_iat_errors(r, scene, sol, td.CAMERA, td.SIZE, ref, band)
            img = box_filtered_render(r, td.CAMERA, td.SIZE, "mesh")
            e_all = td.relative_error(img, ref, surface)
            out.append(
                f"| {name} | {depth} | {scene.n_patches} | {len(sol.leaf_patch):,} "
                f"| {e_band:.4f} / {e_iat:.4f} | {e_all:.4f} | {sec:.2f} |"
            )
    r.release()
    return out


def room_rows() -> list[str]:
    import moderngl

    from iat.geometry.discontinuity import split_discontinuities
    from iat.render.renderer import Renderer
    from tests import test_discontinuity as td
    from tests.support.daylight import CAMERA

    r = Renderer(moderngl.create_standalone_context(backend="egl"))
    plain, ref, band = td.sun_patch(r)
    out = [
        f"Daylit room, sun patch: band {int(band.sum())} pixels.",
        "",
        "| mesh | roots | elements | band error mesh / IAT | solve s (CPU s) |",
        "|---|---|---|---|---|",
    ]
    for name, scene in (("plain", plain), ("discontinuity", split_discontinuities(plain))):
        sol, sec, cpu = _solve(scene)
        e_mesh, e_iat = _mesh_and_iat_errors(r, scene, sol, CAMERA, td.ROOM_SIZE, ref, band)
        out.append(
            f"| {name} | {scene.n_patches} | {len(sol.leaf_patch):,} | {e_mesh:.4f} / {e_iat:.4f} "
            f"| {sec:.1f} ({cpu:.1f}) |"
        )
    r.release()
    return out


def _cost_row(name: str, plain, cut, cut_s: float) -> str:
    """A markdown row: lights, roots, the cut's seconds, elements, shots, solve seconds, plain / cut."""
    n_lights = sum(lt.kind in ("point", "spot", "directional") for lt in plain.lights)
    sp, tp, cp = _solve(plain)
    sc, tc, cc = _solve(cut)
    return (
        f"| {name} | {n_lights} | {plain.n_patches:,} -> {cut.n_patches:,} | {max(cut_s, 0):.2f} "
        f"| {len(sp.leaf_patch):,} / {len(sc.leaf_patch):,} | {sp.stats['shots']:,} / {sc.stats['shots']:,} "
        f"| {tp:.1f} / {tc:.1f} | {cp:.1f} / {cc:.1f} |"
    )


COST_HEADER = [
    "| model | lights (point/spot/sun) | roots plain -> cut | cut s | elements plain / cut "
    "| shots plain / cut | solve s plain / cut | CPU s plain / cut |",
    "|---|---|---|---|---|---|---|---|",
]


def model_rows() -> list[str]:
    from iat.io.load import load_scene

    out = list(COST_HEADER)
    for name in MODELS:
        path = ROOT / "sample_models" / f"{name}.glb"
        t0 = time.perf_counter()
        plain = load_scene(path)
        t1 = time.perf_counter()
        cut = load_scene(path, discontinuity=True)
        out.append(_cost_row(name, plain, cut, (time.perf_counter() - t1) - (t1 - t0)))
    return out


def real_rows() -> list[str]:
    import datetime

    from iat.geometry.discontinuity import split_discontinuities
    from iat.io.load import load_scene
    from iat.lighting.daylight_default import apply_daylight

    path = ROOT.parent / "shared" / "real-models" / "ifcopenshell-open-house-ifc4.ifc"
    plain = load_scene(path)
    line = apply_daylight(plain, today=datetime.date(2026, 12, 6))  # tests/test_real_daylight.py's TODAY
    t0 = time.perf_counter()
    cut = split_discontinuities(plain)
    return [line or "", "", *COST_HEADER, _cost_row(path.name, plain, cut, time.perf_counter() - t0)]


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
    sp, tp, _ = _solve(plain)
    sc, tc, _ = _solve(cut)
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
    ap.add_argument("--only", default="blade,room,models,real,ifc", help="comma-separated parts to run")
    ap.add_argument("--storeys", type=int, default=2, help="storeys of the generated IFC house")
    a = ap.parse_args(argv)
    parts = {
        "blade": blade_rows,
        "room": room_rows,
        "models": model_rows,
        "real": real_rows,
        "ifc": lambda: ifc_rows(a.storeys),
    }
    for name in a.only.split(","):
        print("\n".join(parts[name]()))
        print(flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
