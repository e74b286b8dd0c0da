"""``iat render --false-color`` and ``iat analyse``: light in photometric units for architects.

``iat render MODEL|SOL --false-color illuminance|luminance|daylight-factor [--color-scale log|linear]
[--color-range LO,HI]`` draws the quantity in false colour with its legend (:mod:`iat.render.false_color`);
the daylight factor solves the model under the CIE overcast sky alone
(:func:`iat.measure.daylight.overcast_scene`).

``iat analyse MODEL [--grid 0.5] [--height 0.75] [--room NAME:X0,Y0,Z0,X1,Y1,Z1 ...]
[--only illuminance|daylight-factor] -o report.json|csv``: per room (an IFC's IfcSpaces, the boxes
given, else the model's bounds) a work-plane grid, read by sensors (:mod:`iat.measure.sensors`)
in the model's own light (lux) and under the CIE overcast sky (daylight factor %); mean, min, max and
uniformity per room.

The helpers of :mod:`iat.cli.commands` (loading with a progress bar, the solve options, printing)
come in as arguments: this module does not import that one.
"""

from __future__ import annotations

import json
import sys
from functools import partial
from pathlib import Path

import numpy as np

from iat.errors import OptionError

QUANTITIES = ("illuminance", "luminance", "daylight-factor")


def add_false_color_flags(sp) -> None:
    """``--false-color``, ``--color-scale``, ``--color-range`` on ``iat render``."""
    sp.add_argument(
        "--false-color",
        dest="false_color",
        choices=QUANTITIES,
        help="draw lux, cd/m2 or the daylight factor (%%, solved under the CIE overcast sky) in false "
        "colour with a legend",
    )
    sp.add_argument(
        "--color-scale", dest="color_scale", choices=["log", "linear"], help="false-colour scale (default: "
        "log for lux and cd/m2, linear for the daylight factor)"
    )  # fmt: skip
    sp.add_argument(
        "--color-range", dest="color_range", metavar="LO,HI", help="false-colour range (default: auto)"
    )


def _scale(args, values, quantity: str):
    from iat.render.false_color import Scale, auto_scale

    log = None if args.color_scale is None else args.color_scale == "log"
    if not args.color_range:
        return auto_scale(values, quantity, log)
    try:
        lo, hi = (float(x) for x in args.color_range.split(","))
    except ValueError:
        raise OptionError(f"--color-range must be LO,HI, got {args.color_range!r}") from None
    try:
        return Scale(quantity, lo, hi, quantity != "daylight-factor" if log is None else log)
    except ValueError as e:
        raise OptionError(f"--color-range: {e}") from None


def _analysis_options(args, solve_options):
    """The solve options of a measurement: ``--max-edge`` ANALYSIS_MAX_EDGE unless given."""
    from dataclasses import replace

    from iat.measure.daylight import ANALYSIS_MAX_EDGE

    opts = solve_options(args)
    return opts if opts.max_edge is not None else replace(opts, max_edge=ANALYSIS_MAX_EDGE)


def open_overcast(args, load, solve_options, bar):
    """(overcast scene, its solution) of ``args.input``, a model: the daylight factor's solve."""
    from iat.measure.daylight import overcast_scene
    from iat.radiosity import solve
    from iat.radiosity.inputs import is_solution_path

    if is_solution_path(args.input):
        raise OptionError("the daylight factor solves the model under the CIE overcast sky: give the model")
    opts = _analysis_options(args, solve_options)
    scene = overcast_scene(load(args, args.input, max_edge=opts.max_edge))
    with bar(args, f"solve {Path(args.input).name} (CIE overcast)") as b:
        return scene, solve(scene, opts, progress=b)


def false_color_values(quantity: str, scene, sol) -> np.ndarray:
    """(V,) lux, cd/m² or daylight factor % at the solution's vertices."""
    from iat.measure import photometry as ph
    from iat.measure.daylight import vertex_daylight_factor

    if quantity == "luminance":
        return ph.vertex_luminance(sol)
    if quantity == "illuminance":
        return ph.vertex_illuminance(sol, scene.patch_emission)
    return vertex_daylight_factor(sol, scene)


def render_false_color(args, scene, sol, cam, size, out: Path) -> dict:
    """Render the ``--false-color`` quantity of ``sol`` to ``out`` (.png with its legend, or .npy:
    (h, w) float32 values, NaN where nothing is known); returns what ``iat render`` prints."""
    from PIL import Image

    from iat.fsutil import atomic_write
    from iat.io.images import save_npy
    from iat.render.false_color import false_color_image, quantity_image

    if getattr(args, "set", None):
        raise OptionError("--false-color draws one solution, not a --set")
    if sol is None:
        raise OptionError("--false-color reads a solution: give a model or a solution, not an export")
    values = false_color_values(args.false_color, scene, sol)
    scale = _scale(args, values, args.false_color)
    if out.suffix.lower() == ".npy":
        save_npy(out, quantity_image(sol, values, cam, size)[0].astype(np.float32))
    else:
        pil = Image.fromarray(false_color_image(sol, values, cam, size, scale)[0])
        atomic_write(out, lambda f: pil.save(f, format="PNG"))
    finite = values[np.isfinite(values)]
    return {
        "output": str(out),
        "false_color": scale.describe(),
        "vertex_range": [float(finite.min()), float(finite.max())] if len(finite) else None,
        "size": list(size),
    }


# -- iat analyse ------------------------------------------------------------------------------
def _rooms(args, scene):
    from iat.io.spaces import Room, read_ifc_spaces
    from iat.measure.daylight import model_room

    if args.room:
        rooms = []
        for spec in args.room:
            name, _, box = spec.rpartition(":")
            try:
                v = [float(x) for x in box.split(",")]
            except ValueError:
                v = []
            if len(v) != 6 or not name:
                raise OptionError(f"--room must be NAME:X0,Y0,Z0,X1,Y1,Z1 (Y up), got {spec!r}")
            rooms.append(Room.box(name, v[:3], v[3:]))
        return rooms, "boxes given"
    if Path(args.input).suffix.lower() == ".ifc":
        spaces = read_ifc_spaces(args.input)
        if spaces:
            return spaces, "IfcSpace"
    return [model_room(scene)], "the model's bounds"


def cmd_analyse(args, load, solve_options, bar, emit) -> int:
    from iat.cli.daylight import apply_to, cut_after_daylight
    from iat.measure.daylight import measure_rooms, overcast_scene, report, report_csv
    from iat.radiosity import solve
    from iat.radiosity.inputs import is_solution_path

    out = Path(args.output)
    if out.suffix.lower() not in (".json", ".csv"):
        raise OptionError(f"output must end in .json or .csv, got {out.name}")
    if not args.grid > 0:
        raise OptionError(f"--grid must be > 0, got {args.grid}")
    if is_solution_path(args.input):
        raise OptionError(
            "iat analyse solves the model (its own light and the CIE overcast sky): give the model"
        )
    opts = _analysis_options(args, solve_options)
    scene = load(args, args.input, max_edge=opts.max_edge)
    rooms, source = _rooms(args, scene)
    name = Path(args.input).name
    overcast = lit = None
    if args.only != "illuminance":
        oc = overcast_scene(scene)
        with bar(args, f"solve {name} (CIE overcast)") as b:
            overcast = (oc, solve(oc, opts, progress=b))
    if args.only != "daylight-factor":
        line = apply_to(args, scene)
        scene = cut_after_daylight(scene, opts)
        with bar(args, f"solve {name}") as b:
            lit = (scene, solve(scene, opts, progress=b))
    else:
        line = None
    results = measure_rooms(rooms, args.grid, args.height, lit=lit, overcast=overcast)
    meta = {
        "model": str(args.input),
        "rooms_from": source,
        "grid_m": args.grid,
        "work_plane_m": args.height,
        "illuminance_under": (line or "the model's own light") if lit else None,
        "daylight_factor_sky": "CIE standard overcast (no sun, no lamps)" if overcast else None,
        "max_edge_m": opts.max_edge,
        "luminous_efficacy_lm_per_w": 179.0,
    }
    doc = report(results, meta)
    if out.suffix.lower() == ".csv":
        out.write_text(report_csv(results))
    else:
        out.write_text(json.dumps(doc, indent=1))
    summary = {"output": str(out), "rooms_from": source}
    for r in doc["rooms"]:
        parts = [f"{r['points']} points"]
        lux, df = r.get("illuminance_lux"), r.get("daylight_factor_percent")
        if lux and lux["mean"] is not None:
            parts.append(f"{lux['mean']:.0f} lx mean, {lux['min']:.0f} min, U0 {lux['uniformity'] or 0:.2f}")
        if df and df["mean"] is not None:
            parts.append(f"DF {df['mean']:.2f} % mean, {df['min']:.2f} % min, U0 {df['uniformity'] or 0:.2f}")
        summary[r["name"]] = "; ".join(parts)
    if getattr(args, "json", False):
        print(json.dumps({k: v for k, v in doc.items() if k != "rooms"} | {"rooms": summary}, indent=2))
    else:
        emit(args, summary)
    sys.stdout.flush()
    return 0


def add_analyse_parser(sub, solve_flags, sides_flag, load, solve_options, bar, emit):
    """The ``iat analyse`` subcommand (helpers of :mod:`iat.cli.commands` passed in)."""
    from iat.cli.daylight import add_daylight_flags

    s = sub.add_parser("analyse", help="per-room work-plane illuminance and daylight factor (JSON or CSV)")
    s.add_argument("input", metavar="MODEL")
    s.add_argument("-o", "--output", required=True, metavar="REPORT.json|REPORT.csv")
    s.add_argument("--grid", type=float, default=0.5, help="grid spacing, m (default 0.5)")
    s.add_argument("--height", type=float, default=0.75, help="work plane over the floor, m (default 0.75)")
    s.add_argument(
        "--room",
        action="append",
        metavar="NAME:X0,Y0,Z0,X1,Y1,Z1",
        help="a room as a box (scene coordinates, Y up, floor at Y0); repeatable (default: IfcSpaces, "
        "else the model's bounds)",
    )
    s.add_argument(
        "--only", choices=["illuminance", "daylight-factor"], help="measure only one (default: both)"
    )
    add_daylight_flags(s)
    solve_flags(s)
    sides_flag(s)
    s.add_argument("--json", action="store_true", help="the summary as JSON")
    s.set_defaults(func=partial(cmd_analyse, load=load, solve_options=solve_options, bar=bar, emit=emit))
