"""Parsers of the ``iat`` command's option values; each raises :class:`~iat.errors.OptionError`
with a one-line message."""

from __future__ import annotations

import re

import numpy as np

from iat.errors import OptionError


def parse_vec(text: str, name: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise OptionError(f"{name} must be three numbers X,Y,Z, got {text!r}") from None
    if v.shape != (3,) or not np.isfinite(v).all():
        raise OptionError(f"{name} must be three finite numbers X,Y,Z, got {text!r}")
    return v


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise OptionError(f"--size must be WxH, got {text!r}") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise OptionError(f"--size out of range: {text}")
    return w, h


_NEGATIVE_VALUE = re.compile(r"^-\.?\d[\d.,eE+-]*$")  # -12,5,-22 or -0.5


def join_negative_values(argv: list[str]) -> list[str]:
    """``["--eye", "-12,5,-22"]`` -> ``["--eye=-12,5,-22"]``: argparse would take a value that
    starts with ``-`` (and is not one plain number) for an option."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        tok = argv[i]
        nxt = argv[i + 1] if i + 1 < len(argv) else None
        if tok.startswith("--") and "=" not in tok and nxt is not None and _NEGATIVE_VALUE.match(nxt):
            out.append(f"{tok}={nxt}")
            i += 2
        else:
            out.append(tok)
            i += 1
    return out


def parse_sky(text: str, scale: float = 1.0):
    """``--sky``: ``uniform[:R,G,B]``, ``overcast[:R,G,B]`` (the zenith's radiance),
    ``preetham[:TURBIDITY]`` (towards the scene's sun), ``hdr:FILE`` -> :class:`iat.io.scene.Sky`,
    its radiance (W/(m² sr) per unit colour; 1 when not given) times ``scale``."""
    from iat.io.scene import Sky

    kind, _, arg = text.partition(":")
    kinds = {"uniform": "uniform", "overcast": "cie_overcast", "preetham": "preetham", "hdr": "hdr"}
    if kind not in kinds:
        raise OptionError(
            f"--sky must be uniform[:R,G,B], overcast[:R,G,B], preetham[:T] or hdr:FILE, got {text!r}"
        )
    if not (np.isfinite(scale) and scale >= 0):
        raise OptionError(f"--sky-scale must be a number >= 0, got {scale!r}")
    if kind == "hdr":
        from iat.radiosity.sky import load_hdr

        if not arg:
            raise OptionError("--sky hdr needs a file: hdr:FILE.hdr")
        return Sky(kind="hdr", image=load_hdr(arg), radiance=np.full(3, scale))
    if kind == "preetham":
        try:
            turbidity = float(arg or 3.0)
        except ValueError:
            raise OptionError(f"--sky preetham: turbidity must be a number, got {arg!r}") from None
        if not 1.0 <= turbidity <= 20.0:
            raise OptionError(f"--sky preetham: turbidity must be in [1, 20], got {turbidity:g}")
        return Sky(kind="preetham", turbidity=turbidity, radiance=np.full(3, scale))
    try:
        x = [float(t) for t in (arg or "1").split(",")]
    except ValueError:
        raise OptionError(f"--sky {kind}: radiance must be R,G,B or one number, got {arg!r}") from None
    if len(x) not in (1, 3) or not np.isfinite(x).all() or min(x) < 0:
        raise OptionError(f"--sky {kind}: radiance must be one or three numbers >= 0, got {arg!r}")
    return Sky(kind=kinds[kind], radiance=np.resize(np.array(x), 3) * scale)


def parse_sun(text: str, north_text: str | None = None):
    """``--sun LAT,LON,YYYY-MM-DDTHH:MM[,TZ]`` (TZ an IANA name or hours from UTC; default UTC)
    -> (a directional :class:`iat.io.scene.Light` named sun: NOAA position, clear-sky
    intensity; azimuth and elevation in degrees)."""
    from iat.lighting.sun import day_times, solar_position, sun_direction, sun_light

    parts = text.split(",")
    if len(parts) not in (3, 4):
        raise OptionError(f"--sun must be LAT,LON,YYYY-MM-DDTHH:MM[,TZ], got {text!r}")
    try:
        lat, lon = float(parts[0]), float(parts[1])
        date, _, clock = parts[2].partition("T")
        tz: str | float = parts[3] if len(parts) == 4 else 0.0
        try:
            tz = float(tz)
        except ValueError:
            pass
        when = day_times(date, [clock or "12:00"], tz)[0]
    except (ValueError, KeyError) as e:
        raise OptionError(f"--sun: {e}") from None
    north = parse_vec(north_text, "--north") if north_text else (0.0, 0.0, -1.0)
    az, el = solar_position(lat, lon, when)
    return sun_light(sun_direction(az, el, north=north)), float(az), float(el)
