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


def add_daylight_flags(sp) -> None:
    """The daylight flags on the subparser ``sp``."""
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
    was chosen (``iat CMD: daylight: ...`` on stderr); returns the line."""
    from iat.lighting.daylight_default import apply_daylight

    line = apply_daylight(scene, daylight_request(args))
    if line:
        from tqdm import tqdm

        tqdm.write(f"iat {args.command}: {line}", file=sys.stderr)  # above a progress bar, if any
    return line


def check_solution_flags(args) -> None:
    """``--sun``/``--sky`` name a model's light: a solution keeps the light it was solved under."""
    from iat.errors import OptionError

    if getattr(args, "sun", None) or getattr(args, "sky", None):
        raise OptionError(
            "--sun and --sky light a model: a solution keeps the light it was solved under "
            "(solve its model again)"
        )
