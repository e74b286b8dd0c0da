"""The daylight flags, one definition for ``iat solve``, ``bake``, ``render``, ``view`` and ``batch``:
``--sun``, ``--north``, ``--sky``, ``--sky-scale``, ``--no-daylight``
(:class:`iat.lighting.daylight_default.DaylightRequest`; what they do:
:func:`iat.lighting.daylight_default.apply_daylight`, docs/lighting.md "Daylight by default")."""

from __future__ import annotations

import sys

SUN_HELP = (
    "the sun at LAT,LON,YYYY-MM-DDTHH:MM[,TZ], at the model's place on YYYY-MM-DDTHH:MM[,TZ], "
    "at HH:MM on the default date, or off (TZ: hours from UTC or an IANA name)"
)
SKY_HELP = (
    "clear[:T] (default for a model without lights), overcast, none, or uniform[:R,G,B], "
    "overcast:R,G,B, preetham[:T], hdr:FILE (absolute radiance)"
)


def add_daylight_flags(sp, study: bool = False) -> None:
    """The daylight flags on the subparser ``sp`` (``study``: also ``--sun-study`` and ``--hours``,
    ``iat solve``'s)."""
    sp.add_argument("--sun", metavar="[LAT,LON,]DATETIME[,TZ]|HH:MM|off", help=SUN_HELP)
    sp.add_argument(
        "--north", metavar="X,Y,Z", help="the model's north (default: the IFC's true north, else 0,0,-1)"
    )
    sp.add_argument("--sky", metavar="KIND[:ARG]", help=SKY_HELP)
    sp.add_argument("--sky-scale", type=float, default=1.0, dest="sky_scale", help="sky brightness factor")
    sp.add_argument(
        "--no-daylight",
        action="store_false",
        dest="daylight",
        help="no sun and sky for a model without light sources (it solves black)",
    )
    if study:
        sp.add_argument(
            "--sun-study",
            metavar="YYYY-MM-DD",
            dest="sun_study",
            help="solve the day's hours (--hours) at the model's place as lighting states on one mesh: "
            "OUT-HHhMM.npz each (iat.lighting.sun_study)",
        )
        sp.add_argument(
            "--hours", default="8-18", help="with --sun-study: H-H[/STEP] or H,H,... (default 8-18)"
        )


def daylight_request(args):
    """The :class:`~iat.lighting.daylight_default.DaylightRequest` of parsed ``args``."""
    from iat.lighting.daylight_default import DaylightRequest

    return DaylightRequest(
        sun=getattr(args, "sun", None),
        sky=getattr(args, "sky", None),
        sky_scale=float(getattr(args, "sky_scale", 1.0)),
        north=getattr(args, "north", None),
        enabled=bool(getattr(args, "daylight", True)),
    )


def apply_to(args, scene) -> str | None:
    """Give a loaded model the daylight the flags ask for and print the one line that says what
    was chosen (``iat CMD: daylight: ...`` on stderr); returns the line. With ``--sun-study`` the
    model gets no daylight: ``args.study`` holds the study's lighting states instead."""
    from iat.lighting.daylight_default import apply_daylight

    if getattr(args, "sun_study", None):  # the states bring the sun and sky of every hour
        line = study_line(args, scene)
        args.study = study_states(args, scene)  # (solve_set's states, read by cmd_solve)
    else:
        line = apply_daylight(scene, daylight_request(args))
    if line:
        from tqdm import tqdm

        tqdm.write(f"iat {args.command}: {line}", file=sys.stderr)  # above a progress bar, if any
    return line


def cut_after_daylight(scene, opts):
    """``scene`` cut along the hard shadows of the sun :func:`apply_to` gave it
    (:func:`iat.geometry.discontinuity.cut_new_lights`) when ``opts`` (SolveOptions) mesh
    discontinuities, as the loader cuts along the file's own lights; else ``scene``."""
    from iat.geometry.discontinuity import cut_new_lights

    return cut_new_lights(scene) if opts.discontinuity else scene


def check_solution_flags(args) -> None:
    """``--sun``/``--sky`` name a model's light: a solution keeps the light it was solved under."""
    from iat.errors import OptionError

    if getattr(args, "sun", None) or getattr(args, "sky", None):
        raise OptionError(
            "--sun and --sky light a model: a solution keeps the light it was solved under "
            "(solve its model again)"
        )


def study_states(args, scene) -> dict | None:
    """``--sun-study DATE --hours H-H``: the lighting states of the study (one per hour, the sun and
    the sky of the model's place then: :func:`iat.lighting.sun_study.sun_study_states`); None
    without ``--sun-study``."""
    if not getattr(args, "sun_study", None):
        return None
    from iat.lighting.sun_study import parse_hours, study_daylight, sun_study_states

    d = study_daylight(scene, daylight_request(args), args.sun_study)
    return sun_study_states(d, d.date, parse_hours(args.hours))


def study_line(args, scene) -> str:
    """The one line of a sun study: where, which date and hours, the sky."""
    from iat.lighting.sun_study import parse_hours, study_daylight

    if getattr(args, "states", False):
        from iat.errors import OptionError

        raise OptionError("--sun-study makes the lighting states: it goes without --states")
    d = study_daylight(scene, daylight_request(args), args.sun_study)
    hours = parse_hours(args.hours)
    north = f", true north {d.north_deg:+.1f} deg" if abs(d.north_deg) > 1e-9 else ""
    first, last = (d.with_changes(hour=h).clock_text() for h in (hours[0], hours[-1]))
    return (
        f"{scene.path or 'model'}: sun study at {d.place_text()}{north}: {len(hours)} hours, "
        f"{first} to {last[11:]}; {d.with_changes(hour=hours[len(hours) // 2]).sky_text()} at mid-study"
    )
