"""The ``iat`` command line (names and flags are a contract: see docs/architecture.md).

Every IATError is printed on one line and exits 2 (``--debug`` shows the traceback).
Every :class:`~iat.errors.IATWarning` (an albedo clamped at load, ...) is printed on one
line, ``iat CMD: warning: ...``, on stderr. Loads and solves draw a progress bar on a
terminal.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from iat.cli.analysis import add_analyse_parser, add_false_color_flags, open_overcast, render_false_color
from iat.cli.args import add_sides_flags, join_negative_values, parse_size, parse_vec
from iat.cli.daylight import (
    add_daylight_flags,
    apply_to,
    check_solution_flags,
    cut_after_daylight,
    daylight_request,
)
from iat.cli.faults import add_faults_flag, render_view
from iat.cli.warning_lines import WarningLines, warning_printer
from iat.errors import IATError, IATWarning, OptionError
from iat.progress import ProgressBar
from iat.tools.common import policy_dict

EXIT_USER_ERROR = 2


@contextmanager
def _progress_bar(args, desc: str, close_when_done: bool = False):
    """A :class:`ProgressBar` (none with ``--json``), closed on the way out."""
    bar = ProgressBar(desc, enabled=not getattr(args, "json", False), close_when_done=close_when_done)
    try:
        yield bar
    finally:
        bar.close()


def _solution_not_a_model(args, path) -> None:
    """``iat info SOL.npz`` / ``iat solve SOL.npz``: say what the file is and what would help (one line),
    instead of "unsupported file type '.npz'". A missing file is left to load_scene ("file not found")."""
    from iat.errors import LoadError
    from iat.io.load import SUPPORTED_EXTENSIONS
    from iat.radiosity.inputs import is_solution_path

    path = Path(path)
    if not (is_solution_path(path) and path.is_file()):
        return
    model = ""
    try:  # the model it was solved from, if the file says (cheap: one array of the archive)
        with np.load(path, allow_pickle=False) as z:
            model = str(z["model_path"]) if "model_path" in z.files else ""
    except Exception:
        pass
    command = getattr(args, "command", "info")
    reads = f"'iat {command}' reads models ({', '.join(SUPPORTED_EXTENSIONS)})"
    if model:
        what = f"a solution file, not a model: {reads}; run it on {model}, the model it was solved from"
    else:  # unreadable, or not an IAT solution at all: say what the extension means
        what = f"'.npz' is IAT's solution format, not a model: {reads}"
    raise LoadError(f"{what}; 'iat bake/render/view' read solutions", path)


def _load(args, path, max_edge=None):
    """:func:`iat.io.load.load_scene` with a progress bar (``--no-panels``, ``--discontinuity`` honoured)."""
    from iat.io.load import load_scene

    _solution_not_a_model(args, path)
    with _progress_bar(args, f"load {Path(path).name}") as bar:
        return load_scene(
            path,
            max_edge=max_edge,
            progress=bar,
            panels=not getattr(args, "no_panels", False),
            discontinuity=_solve_options(args).discontinuity,
            sides=getattr(args, "sides", None) or "auto",
            cut=getattr(args, "cut", None) or "auto",
        )


def _solve_options(args):
    from iat.radiosity import SolveOptions

    kw = {}
    for name in (
        "max_depth",
        "tolerance",
        "max_edge",
        "samples",
        "convergence",
        "ambient_rays",
        "sky_samples",
    ):
        v = getattr(args, name, None)
        if v is not None:
            kw[name] = v
    if getattr(args, "no_panels", False):
        kw["panels"] = False
    if getattr(args, "discontinuity", None) is not None:  # --[no-]discontinuity, else the default
        kw["discontinuity"] = args.discontinuity
    return SolveOptions.preset(getattr(args, "quality", None) or "default", **kw)


def _bake_policy(args):
    from iat.bake.policy import BakePolicy

    kw = {}
    for name in ("threshold", "scale", "method", "budget_mb"):
        v = getattr(args, name, None)
        if v is not None:
            kw[name] = v
    for name in ("lod", "lod_stream"):  # levels of detail (iat.bake.lod)
        if getattr(args, name, False):
            kw[name] = True
    return BakePolicy(**kw)


def _open(args, what: str):
    """(scene, solution) of a solution file, or of a model given its daylight (``--sun``, ``--sky``,
    ``--no-daylight``: :mod:`iat.cli.daylight`) and solved."""
    from iat.radiosity import solve
    from iat.radiosity.inputs import is_solution_path, open_solution

    name = Path(args.input).name
    if is_solution_path(args.input):
        check_solution_flags(args)
        with _progress_bar(args, f"load {name}", close_when_done=True) as load_bar:
            return open_solution(args.input, load_progress=load_bar)
    opts = _solve_options(args)
    scene = _load(args, args.input, max_edge=opts.max_edge)
    apply_to(args, scene)
    scene = cut_after_daylight(scene, opts)
    with _progress_bar(args, f"solve {name}") as bar:
        return scene, solve(scene, opts, progress=bar)


# -- commands --------------------------------------------------------------------
def cmd_info(args) -> int:
    from iat.geometry.panels import find_panels, sliver_count

    scene = _load(args, args.input)
    q = scene.patch_is_quad
    info = {
        "file": str(args.input),
        "triangles": int(len(scene.world_triangles())),
        "patches": scene.n_patches,
        "quads": int(q.sum()),
        "triangle_patches": int((~q).sum()),
        "panel_cells": int(scene.patch_clipped.sum()),
        "panels": find_panels(scene, fit="none").n_panels,
        "slivers": sliver_count(scene),
        "materials": len(scene.materials),
        "emissive_materials": int(sum(m.emission.max() > 0 for m in scene.materials)),
        "lights": len(scene.lights),
        "light_sources": "yes" if scene.has_light_sources else "no light sources",
        "cameras": len(scene.cameras),
        "camera_paths": {k: len(v) for k, v in scene.camera_paths.items()},
        "bounds": scene.bounds.tolist(),
        "area": float(scene.patch_area.sum()),
    }
    if scene.sides is not None:  # inside-out solids, open sheets, back faces (iat.geometry.sides)
        sd = scene.sides
        info.update(
            {
                "sides": sd.mode,
                "closed_solids": sd.closed_solids,
                "inside_out_solids": sd.inside_out,
                "faces_turned": sd.flipped_faces,
                "enclosures": sd.enclosures,
                "open_sheets": sd.open_sheets,
                "back_faces": sd.back_faces,
                "back_patches": sd.twin_patches,
                "paired_faces": sd.paired_faces,
                "coincident_faces": sd.coincident_faces,
            }
        )
    if scene.pierce is not None:  # faces other objects pierce (iat.geometry.pierce)
        pc = scene.pierce
        info.update(cut=pc.mode, piercing_pairs=pc.pairs, contacts=pc.contacts)
        info.update(intersecting_objects=pc.objects, faces_cut=pc.faces_cut, regions_fanned=pc.fanned_regions)
        info.update(regions_in_cells=pc.decomposed_regions)
    _emit(args, info)
    return 0


def _set_output(out: Path, name: str) -> Path:
    """``OUT.npz`` -> ``OUT-<name>.npz`` (a solution per lighting state)."""
    return out.with_name(f"{out.stem}-{name}{out.suffix or '.npz'}")


def _solve_states_on_engine(args, opts) -> int:
    """``solve --states --workers N`` / ``--scheduler ADDR``: the states job of :mod:`iat.tools.batch`
    (the states' own solves and then every state on the shared mesh as parallel Dask tasks), run in
    the hidden folder ``.<OUT>.batch`` beside the output (a rerun skips what is done there); each
    state's solution is then copied to ``OUT-<state>.npz``."""
    import shutil

    from iat.tools.batch import Batch, Job, print_errors, run_batch

    if args.sun or args.sky:
        raise OptionError(
            "--workers/--scheduler cannot take --sun or --sky yet: put the sun and sky in "
            "the model's lighting states, or solve the states without --workers"
        )
    out = Path(args.output)
    folder = out.with_name(f".{out.stem}.batch")
    job = Job(out.stem, Path(args.input).resolve(), opts, states=True, states_mesh=args.states_mesh)
    with _progress_bar(args, f"solve states of {Path(args.input).name} on Dask") as bar:
        report = run_batch(Batch(folder, [job]), workers=args.workers, scheduler=args.scheduler, progress=bar)
    print_errors(report, prog="iat solve")
    if report.failed:
        return 1
    written = []
    for r in report.results:
        if not r.name.startswith(f"{out.stem}-"):
            continue  # a state's own solve or the shared mesh
        state = r.name[len(out.stem) + 1 :]
        p = _set_output(out, state)
        shutil.copyfile(folder / f"{r.name}.npz", p)
        written.append({"state": state, "output": str(p), "status": r.status, "time_s": r.seconds})
    _emit(args, {"states": written, "workers": report.workers, "wall_s": report.wall_s})
    return 0


def cmd_solve(args) -> int:
    from iat.radiosity import solve

    opts = _solve_options(args)
    if args.workers is not None or args.scheduler:
        if not args.states:
            raise OptionError("--workers and --scheduler go with --states (one solve runs in this process)")
        return _solve_states_on_engine(args, opts)
    scene = _load(args, args.input, max_edge=opts.max_edge)
    apply_to(args, scene)
    if getattr(args, "states", False) or getattr(args, "sun_study", None):  # (--sun-study: a day's hours)
        from iat.lighting.solution_set import solve_set

        with _progress_bar(args, f"solve states of {Path(args.input).name}") as bar:
            sset = solve_set(scene, getattr(args, "study", None), opts, progress=bar, mesh=args.states_mesh)
        out = Path(args.output)
        written = []
        for name, t, sol in zip(sset.names, sset.times, sset.solutions, strict=True):
            sol.model_path = str(Path(args.input).resolve())
            sol.stats = {**sol.stats, "lighting_state": name, "lighting_time": float(t)}
            p = _set_output(out, name)
            sol.save(p)
            written.append(
                {"state": name, "time": float(t), "output": str(p), "time_s": sol.stats.get("time_s")}
            )
        _emit(args, {"states": written, "vertices": int(len(sset.first.vert_key))})
        return 0
    scene = cut_after_daylight(scene, opts)
    with _progress_bar(args, f"solve {Path(args.input).name}") as bar:
        sol = solve(scene, opts, progress=bar)
    sol.model_path = str(Path(args.input).resolve())
    sol.save(args.output)
    stats = dict(sol.stats)
    stats["output"] = str(args.output)
    _emit(args, stats)
    return 0


def _open_set(args):
    """(scene, SolutionSet) of ``--set A.npz B.npz ...`` (times: ``--times``, the files, the model)."""
    from iat.lighting.solution_set import load_set
    from iat.radiosity.inputs import open_solution

    times = None
    if args.times:
        try:
            times = [float(x) for x in args.times.split(",")]
        except ValueError:
            raise OptionError(f"--times must be comma-separated numbers, got {args.times!r}") from None
    sset = load_set(args.set, times=times)
    with _progress_bar(args, f"load {Path(args.set[0]).name}") as bar:
        scene, _ = open_solution(args.set[0], load_progress=bar)
    return scene, sset


def _check_set_args(args) -> None:
    if args.set is None:
        if args.at is not None or args.times:
            raise OptionError("--at and --times go with --set A.npz B.npz ...")
        if args.input is None:
            raise OptionError("give a model or solution, or --set A.npz B.npz ...")
        return
    if args.input is not None:
        raise OptionError("give either an input or --set, not both")
    if args.at is None:
        args.at = 0.0


def _export_options(args) -> dict:
    """export_glb's keywords from ``iat bake``'s flags (watertight and match_clip unless turned off)."""
    if args.hdr and not args.layered:
        raise OptionError("--hdr goes with --layered (the lightmaps are what it stores above white)")
    keys = ("layered", "watertight", "match_clip", "hdr")
    return {k: getattr(args, k) for k in keys}


def cmd_bake(args) -> int:
    from iat.bake.baker import Baker
    from iat.export.gltf import export_glb

    _check_set_args(args)
    if args.set is not None:
        scene, sset = _open_set(args)
        bset = Baker(sset.first, scene).bake_set(sset, _bake_policy(args))
        a, b, w = sset.weights(args.at)
        baked = bset.blend(a, b, w)
        export_glb(baked, args.output, scene=scene, **_export_options(args))
        report = {"output": str(args.output), "policy": policy_dict(bset.policy), **bset.memory.to_dict()}
        report["set"] = {
            "states": sset.names,
            "times": [float(x) for x in sset.times],
            "at": float(args.at),
            "blend": {"a": sset.names[a], "b": sset.names[b], "w": w},
            "texture_bytes_exported": int(baked.memory.texture_bytes),
        }
        report["timings"] = bset.timings
        _emit(args, report)
        return 0
    scene, sol = _open(args, "bake")
    baked = Baker(sol, scene).bake(_bake_policy(args))
    export_glb(baked, args.output, scene=scene, **_export_options(args))
    report = {"output": str(args.output), "policy": policy_dict(baked.policy), **baked.memory.to_dict()}
    report["timings"] = getattr(baked, "timings", {})
    _emit(args, report)
    return 0


def cmd_render(args) -> int:
    from iat.camera import Camera
    from iat.io.images import save_npy, save_png
    from iat.radiosity.inputs import is_solution_path

    size = parse_size(args.size)
    out = Path(args.output)
    if out.suffix.lower() not in (".png", ".npy"):
        raise OptionError(f"output must end in .png or .npy, got {out.name}")
    _check_set_args(args)
    mode = args.mode
    sset = None
    if args.set is not None:
        if mode == "preview":
            raise OptionError("--set renders solutions: use --mode mesh, iat, split or diff")
        scene, sset = _open_set(args)
        sol = sset.first
    elif (mode == "preview" and not is_solution_path(args.input)) or (  # a model's preview needs no solve
        Path(args.input).suffix.lower() in (".glb", ".gltf") and _is_export(args.input)
    ):
        if mode not in ("iat", "preview"):
            raise OptionError(f"{args.input} is an exported bake: render it with --mode iat (or preview)")
        scene, sol = _load(args, args.input), None
    elif args.false_color == "daylight-factor":
        scene, sol = open_overcast(args, _load, _solve_options, _progress_bar)
    else:
        scene, sol = _open(args, "render")
    if args.eye or args.target:
        if not (args.eye and args.target):
            raise OptionError("--eye and --target go together")
        cam = Camera(
            eye=parse_vec(args.eye, "--eye"), target=parse_vec(args.target, "--target"), yfov=args.fov
        )
        lo, hi = scene.bounds
        r = float(np.linalg.norm(hi - lo))
        cam.znear, cam.zfar = r * 1e-3, r * 10
    elif args.camera is not None:
        if not (0 <= args.camera < len(scene.cameras)):
            raise OptionError(f"--camera {args.camera}: the file has {len(scene.cameras)} camera(s)")
        cam = scene.cameras[args.camera]
    else:
        cam = scene.default_camera()
    if args.false_color:  # lux, cd/m² or daylight factor with a legend (iat.cli.analysis)
        return _emit(args, render_false_color(args, scene, sol, cam, size, out)) or 0
    if sol is None and sset is None and mode == "iat" and not args.faults:  # an exported bake, as baked
        from iat.render.glb_view import render_glb

        img = render_glb(args.input, cam, size)
    else:
        img = _render_solution(args, scene, sol, sset, cam, size, mode)
    if out.suffix.lower() == ".npy":
        save_npy(out, img)
    else:
        from iat.color import auto_exposure

        save_png(out, img, exposure=1.0 if args.faults else args.exposure or auto_exposure(img))
    info = {"output": str(out), "mode": mode, "size": list(size)}
    if sset is not None:
        a, b, w = sset.weights(args.at)
        info["set"] = {"states": sset.names, "at": float(args.at), "blend": [sset.names[a], sset.names[b], w]}
    _emit(args, info)
    return 0


def _render_solution(args, scene, sol, sset, cam, size, mode) -> np.ndarray:
    """(h, w, 3) linear radiance of a solution (or a set's blended moment, or the scene's preview)."""
    from iat.render.renderer import Renderer

    r = Renderer()
    try:
        r.set_scene(scene)
        r.set_sky(scene.sky)  # the model's own sky behind it (not a state's)
        if sset is not None:  # one moment of a solution set, blended on the GPU
            r.set_solution_set(sset.solutions)
            if mode in ("iat", "split", "diff"):
                from iat.bake.baker import Baker

                r.set_baked_set(Baker(sset.first, scene).bake_set(sset, _bake_policy(args)))
            r.set_blend(*sset.weights(args.at))
        elif sol is not None:
            r.set_solution(sol)
            if mode in ("iat", "split", "diff"):
                from iat.bake.baker import Baker

                r.set_baked(Baker(sol, scene).bake(_bake_policy(args)))
        return render_view(args, r, scene, cam, size, mode)  # --faults: tinted (iat.cli.faults)
    finally:
        r.release()


def _is_export(path) -> bool:
    """True for a GLB that ``iat bake`` wrote (its root extras say so)."""
    from iat.render.glb_view import is_iat_export

    return Path(path).is_file() and is_iat_export(path)


def _size_and_frames(args, size: str, frames: int) -> tuple[tuple[int, int], int]:
    """``(--size, --frames)`` of the benchmark commands, with their defaults; frames >= 1."""
    wh = parse_size(getattr(args, "size", size) or size)
    frames = int(getattr(args, "frames", frames) or frames)
    if frames < 1:
        raise OptionError(f"--frames must be >= 1, got {frames}")
    return wh, frames


def cmd_bench(args) -> int:
    """``iat bench [MODEL…] [--json] [--frames N] [--size WxH]``: Markdown on stdout, or JSON."""
    from iat.tools.bench import format_table, run_bench

    size, frames = _size_and_frames(args, "640x480", 60)
    bar = ProgressBar("bench")
    try:
        result = run_bench(list(getattr(args, "models", []) or []), frames=frames, size=size, progress=bar)
    finally:
        bar.close()
    if getattr(args, "json", False):
        print(json.dumps(result, indent=2))
    else:
        sys.stdout.write(format_table(result))
    return 0


def cmd_chart(args) -> int:
    """``iat chart [MODEL…] -o CHART.png [--size WxH] [--frames N] [--workers N | --scheduler ADDRESS]``:
    writes CHART.png and CHART.json."""
    from iat.tools.chart import run_chart

    size, frames = _size_and_frames(args, "160x120", 10)
    bar = ProgressBar("chart")
    try:
        result = run_chart(
            list(getattr(args, "models", []) or []),
            args.output,
            size=size,
            frames=frames,
            progress=bar,
            workers=args.workers,
            scheduler=args.scheduler,
        )
    finally:
        bar.close()
    print(f"wrote {result['png']} and {result['json']}")
    for row in result["models"]:
        front = row["pareto"].get("flip_vs_finest/gpu_mb", [])
        print(f"{row['model']}: {len(row['points'])} points, {len(front)} on the memory Pareto front")
    return 0


def cmd_batch(args) -> int:
    """``iat batch JOBS.toml [--workers N] [--scheduler ADDRESS] [--json]``: every job's tasks on a Dask
    cluster; one line ``iat batch: error: <task>: <cause>`` per failed task on stderr. Exit 0 when
    all succeed, 2 when the failures are all user errors (a bad file, a bad option), else 1."""
    from iat.tools.batch import parse_jobs, print_errors, run_batch

    batch = parse_jobs(args.jobs)
    req = daylight_request(args)
    batch.daylight = req if req.enabled else None  # (None: the models' own light, as run_batch's default)
    with _progress_bar(args, f"batch {Path(args.jobs).name}") as bar:
        report = run_batch(batch, workers=args.workers, scheduler=args.scheduler, progress=bar)
    if getattr(args, "json", False):
        print(json.dumps(report.to_dict(), indent=2, default=_json_default))
    else:
        for r in report.results:
            print(f"{r.name:>24}: {r.status} {r.seconds:.1f} s")
        n, wall = len(report.results), report.wall_s
        print(f"{n} tasks in {wall:.1f} s on {report.workers} workers: {report.output}")
    print_errors(report)
    if not report.failed:
        return 0
    return EXIT_USER_ERROR if all(r.user_error for r in report.failed) else 1


def _app(name: str):
    """The application registered as entry point ``name`` in group ``iat.apps`` (the viewer is
    ``view``): the library never imports an app, the app's package says where it is."""
    from importlib.metadata import entry_points

    found = entry_points(group="iat.apps", name=name)
    if not found:
        from iat.errors import RenderError

        raise RenderError(f"no '{name}' application is installed (entry point group 'iat.apps')")
    return next(iter(found)).load()


def cmd_view(args) -> int:
    import os

    from iat.errors import LoadError, RenderError

    if args.input is not None:
        path = Path(args.input)
        if not path.is_file():
            raise LoadError("file not found" if not path.exists() else "not a regular file", path)
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        if args.input is not None:  # nothing can be shown: name a bad file before the display
            from iat.radiosity.inputs import is_solution_path, open_solution

            open_solution(path) if is_solution_path(path) else _load(args, path)
        raise RenderError(
            "no display (DISPLAY is not set): run under xvfb-run or on a desktop, or use 'iat render'"
        )
    daylight = daylight_request(args)
    if args.play is None:
        return _app("view")(args.input, size=parse_size(args.size), daylight=daylight)
    if args.frames < 1:
        raise OptionError(f"--frames must be >= 1, got {args.frames}")
    modes = tuple(m.strip() for m in args.modes.split(",") if m.strip())
    size = parse_size(args.size)
    play = {"play": args.play, "frames": args.frames, "modes": modes, "as_json": args.json}
    play["daylight"] = daylight
    return _app("view")(args.input, size=size, **play)


def _emit(args, data: dict) -> None:
    if getattr(args, "json", False):
        print(json.dumps(data, indent=2, default=_json_default))
    else:
        for k, v in data.items():
            print(f"{k:>24}: {v}")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o).__name__)


# -- parser ----------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="iat", description="Illumination as texture: solve, bake, render, view.")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = p.add_subparsers(dest="command", required=True)

    def solve_flags(sp):
        sp.add_argument(
            "--quality",
            choices=["draft", "default", "fine", "final"],  # QUALITY_PRESETS (not imported: start-up)
            help="a preset of the options below (SolveOptions.preset); flags given override it",
        )
        sp.add_argument("--max-depth", type=int, dest="max_depth", help="deepest quad-tree level (default 6)")
        sp.add_argument("--tolerance", type=float, help="relative radiance change that splits an element")
        sp.add_argument("--max-edge", type=float, dest="max_edge", help="pre-split patches longer than this")
        sp.add_argument("--samples", type=int, help="shooter samples for visibility")
        sp.add_argument("--ambient-rays", type=int, dest="ambient_rays", help="ambient term's rays a vertex")
        sp.add_argument(
            "--sky-samples", type=int, dest="sky_samples", help="sky's directions a vertex (1024)"
        )
        sp.add_argument(
            "--convergence",
            type=float,
            help="stop shooting below this fraction of the received power (default 0.05)",
        )
        sp.add_argument(
            "--no-panels",
            action="store_true",
            dest="no_panels",
            help="keep coplanar triangles as roots of their own (default: panels)",
        )
        sp.add_argument(
            "--discontinuity",
            action=argparse.BooleanOptionalAction,
            default=None,
            help="cut patches along the hard shadows of the model's point, spot and sun lights (default: on)",
        )

    def set_flags(sp):
        sp.add_argument(
            "--set",
            nargs="+",
            metavar="SOL.npz",
            help="solutions of one model on one mesh (lighting states, e.g. times of day)",
        )
        sp.add_argument("--at", type=float, help="time in [0, 1] to blend the set at (default 0)")
        sp.add_argument(
            "--times", help="key times of the set, comma-separated (default: from the files or the model)"
        )

    def bake_flags(sp):
        sp.add_argument("--threshold", type=int, help="tree depth from which a patch becomes a texture")
        sp.add_argument("--scale", type=float, help="texture scale factor (1 = a texel per mesh vertex)")
        sp.add_argument("--method", choices=["bilinear", "scan", "bicubic"])
        sp.add_argument(
            "--budget-mb", type=float, dest="budget_mb", help="texture budget; chooses threshold/scale"
        )
        sp.add_argument(
            "--lod", action="store_true", help="levels of detail: coarser levels of each quad-tree, blended"
        )
        sp.add_argument(
            "--lod-stream",
            action="store_true",
            dest="lod_stream",
            help="levels of detail, only the levels the view needs resident (the budget caps them)",
        )

    s = sub.add_parser("info", help="counts: triangles, patches, materials, lights, cameras")
    s.add_argument("input", metavar="MODEL")
    s.add_argument("--no-panels", action="store_true", dest="no_panels", help="count without panels")
    add_sides_flags(s)
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("solve", help="radiosity solution with adaptive quad-tree meshing")
    s.add_argument("input", metavar="MODEL")
    add_daylight_flags(s, study=True)
    s.add_argument("-o", "--output", required=True, metavar="SOL.npz")
    solve_flags(s)
    add_sides_flags(s)
    s.add_argument(
        "--states",
        action="store_true",
        help="solve the model's lighting states (extras iat_lighting_states) on one mesh: "
        "SOL-<state>.npz each",
    )
    s.add_argument(
        "--workers",
        type=int,
        help="with --states: solve them as Dask tasks on N local worker processes (iat batch's engine)",
    )
    s.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="with --states: on an existing Dask scheduler (tcp://host:8786)",
    )
    s.add_argument(
        "--states-mesh",
        dest="states_mesh",
        choices=["merge", "union", "first"],
        default="merge",
        help="mesh of the states: the union of their own adaptive meshes (default), "
        "the mesh of all sources at once, or the first state's",
    )
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_solve)

    s = sub.add_parser("bake", help="illumination as texture, exported as GLB")
    s.add_argument("input", nargs="?", metavar="SOL|MODEL")
    set_flags(s)
    s.add_argument("-o", "--output", required=True, metavar="OUT.glb")
    bake_flags(s)
    solve_flags(s)
    add_daylight_flags(s)
    s.add_argument("--layered", action="store_true", help="albedo on TEXCOORD_0, illumination on TEXCOORD_1")
    s.add_argument(
        "--no-watertight",
        dest="watertight",
        action="store_false",
        help="keep the T-junctions between patches (clients show see-through pixels along them)",
    )
    s.add_argument(
        "--hdr",
        action="store_true",
        help="with --layered: lightmaps as RGBM PNGs (up to 16x white), for the shipped three.js plugin "
        "and Blender script (docs/export.md)",
    )
    s.add_argument(
        "--no-match-clip",
        dest="match_clip",
        action="store_false",
        help="write colours clipped at the vertices and texels only (clients then clip before "
        "interpolating, darker than IAT mode by the lights)",
    )
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_bake)

    s = sub.add_parser("render", help="render a solution (mesh or IAT mode) or a model (preview)")
    s.add_argument("input", nargs="?", metavar="SOL|MODEL|GLB")
    set_flags(s)
    s.add_argument("-o", "--output", required=True, metavar="OUT.png|OUT.npy")
    add_daylight_flags(s)
    s.add_argument("--mode", choices=["mesh", "iat", "preview", "split", "diff"], default="iat")
    s.add_argument("--camera", type=int, help="use the file's K-th camera")
    s.add_argument("--eye")
    s.add_argument("--target")
    s.add_argument("--fov", type=float, default=50.0)
    s.add_argument("--size", default="640x480")
    s.add_argument("--exposure", type=float, help="PNG exposure (default: automatic)")
    add_false_color_flags(s)
    add_faults_flag(s)
    bake_flags(s)
    solve_flags(s)
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_render)

    s = sub.add_parser("bench", help="the report's Figure 3 table, and more")
    s.add_argument("models", nargs="*", metavar="MODEL")
    s.add_argument("--json", action="store_true")
    s.add_argument("--frames", type=int, default=60)
    s.add_argument("--size", default="640x480")
    s.set_defaults(func=cmd_bench)

    s = sub.add_parser("chart", help="speed against accuracy")
    s.add_argument("models", nargs="*", metavar="MODEL")
    s.add_argument("-o", "--output", required=True, metavar="CHART.png")
    s.add_argument("--size", default="320x240")
    s.add_argument("--frames", type=int, default=10)
    s.add_argument("--workers", type=int, help="solve the sweep first as Dask tasks on N local workers")
    s.add_argument("--scheduler", metavar="ADDRESS", help="... or on an existing Dask scheduler")
    s.set_defaults(func=cmd_chart)

    s = sub.add_parser("batch", help="solves, bakes and renders of a job file as Dask tasks")
    s.add_argument("jobs", metavar="JOBS.toml")
    s.add_argument("--workers", type=int, help="local worker processes (default: one per core)")
    add_daylight_flags(s)
    s.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (tcp://host:8786)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_batch)

    s = sub.add_parser("view", help="the walkthrough viewer")
    s.add_argument("input", nargs="?", metavar="SOL|MODEL")
    add_daylight_flags(s)
    s.add_argument("--size", default="1280x800", help="window size WxH")
    s.add_argument("--play", metavar="NAME", help="play camera path NAME (or a .paths.json file), then exit")
    s.add_argument("--frames", type=int, default=120, help="frames of the --play playback")
    s.add_argument("--modes", default="mesh,iat", help="modes --play measures, comma-separated")
    s.add_argument("--json", action="store_true", help="--play statistics as JSON")
    s.set_defaults(func=cmd_view)
    add_analyse_parser(sub, solve_flags, add_sides_flags, _load, _solve_options, _progress_bar, _emit)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(join_negative_values(sys.argv[1:] if argv is None else list(argv)))
    logger = logging.getLogger("iat")
    handler = WarningLines(args.command)
    logger.addHandler(handler)
    propagate, logger.propagate = logger.propagate, False
    try:
        return _run(args)
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


def _run(args) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("always", IATWarning)
        warnings.showwarning = warning_printer(args.command)
        try:
            return int(args.func(args) or 0)
        except IATError as e:
            if args.debug:
                raise
            print(f"iat {args.command}: error: {e}", file=sys.stderr)
            return EXIT_USER_ERROR
        except KeyboardInterrupt:
            print(f"iat {args.command}: interrupted", file=sys.stderr)
            return 130


if __name__ == "__main__":
    sys.exit(main())
