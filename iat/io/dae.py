"""COLLADA (``.dae``, zipped ``.zae``): the asset's up axis and unit, which trimesh ignores.

trimesh (with pycollada) reads the geometry, node transforms and materials
(``diffuse`` -> albedo, ``emission``); :func:`dae_frame` is the matrix that turns the
file's coordinates into IAT's: Y up, metres.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np

_HEAD = 1 << 16  # the <asset> element opens the file
_UP = re.compile(rb"<up_axis>\s*([XYZ])_UP\s*</up_axis>")
_UNIT = re.compile(rb"<unit\b[^>]*\bmeter\s*=\s*[\"']([^\"']+)[\"']")
_MANIFEST_ROOT = re.compile(rb"<dae_root>\s*([^<]+?)\s*</dae_root>")

#: new_from_file rotations to Y up (right-handed, determinant +1, so windings stay)
UP_TO_Y = {
    b"Y": np.eye(3),
    b"Z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),  # (x, y, z) -> (x, z, -y)
    b"X": np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),  # (x, y, z) -> (-y, x, z)
}


def _head(path: Path) -> bytes:
    """The first bytes of the COLLADA document (inside the archive for ``.zae``)."""
    if path.suffix.lower() != ".zae":
        with open(path, "rb") as f:
            return f.read(_HEAD)
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        root = None
        if "manifest.xml" in names:
            m = _MANIFEST_ROOT.search(z.read("manifest.xml"))
            root = m.group(1).decode("utf-8", "replace") if m else None
        if root not in names:
            root = next((n for n in names if n.lower().endswith(".dae")), None)
        if root is None:
            return b""
        with z.open(root) as f:
            return f.read(_HEAD)


def dae_frame(path: Path) -> np.ndarray:
    """(3, 3) float64 iat_from_file: the ``<up_axis>`` turned to Y and ``<unit meter>`` to metres."""
    try:
        head = _head(path)
    except (OSError, zipfile.BadZipFile):
        return np.eye(3)  # trimesh reports the unreadable file
    head = head.split(b"</asset>", 1)[0]
    up = _UP.search(head)
    unit = _UNIT.search(head)
    scale = 1.0
    if unit:
        try:
            scale = float(unit.group(1))
        except ValueError:
            scale = 1.0
        if not (np.isfinite(scale) and scale > 0):
            scale = 1.0
    return UP_TO_Y[up.group(1) if up else b"Y"] * scale
