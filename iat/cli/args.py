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


def add_sides_flags(sp) -> None:
    """``--sides`` and ``--cut`` (the loader's ``sides`` and ``cut``) on a subcommand's parser."""
    sp.add_argument(
        "--sides",
        choices=["auto", "both", "front"],
        default="auto",
        help="auto: IFC's inside-out solids turned outward and its open sheets given a back face "
        "(other formats: glTF doubleSided materials only); both: every format so; "
        "front: faces as the file has them (all count them)",
    )
    sp.add_argument(
        "--cut",
        choices=["auto", "crossings", "all", "none"],  # iat.geometry.pierce.CUTS (not imported: start-up)
        default="auto",
        help="cut faces along other objects crossing them (all: and resting on them; none: not; "
        "auto: all for IFC and --sides both, crossings for the rest)",
    )
