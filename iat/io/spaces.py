"""Rooms of a model: an IFC file's ``IfcSpace`` volumes, in the scene's coordinates (Y up).

:func:`read_ifc_spaces` meshes each space with ifcopenshell's geometry kernel (world coordinates,
turned Z-up to Y-up as :mod:`iat.io.ifc` turns the building); a :class:`Room` is a name and its
triangles, or a box. :meth:`Room.contains_xz` says which plan points lie inside its footprint.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iat.errors import LoadError
from iat.io.dae import UP_TO_Y
from iat.io.messages import one_line

log = logging.getLogger(__name__)


@dataclass
class Room:
    """A room: ``name``; ``lo``, ``hi`` (3,) its bounds (scene units, Y up; the floor at ``lo[1]``);
    ``triangles`` (T, 3, 3) its volume's surface, or None for a box (its footprint is the box's)."""

    name: str
    lo: np.ndarray
    hi: np.ndarray
    triangles: np.ndarray | None = None

    @classmethod
    def box(cls, name: str, lo, hi) -> Room:
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        return cls(name, np.minimum(lo, hi), np.maximum(lo, hi))

    def contains_xz(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(n,) bool: the plan points (x, z) lie inside the footprint (the box's, or the projection
        of the volume's triangles onto the floor plane)."""
        x, z = np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64)
        inside = (x >= self.lo[0]) & (x <= self.hi[0]) & (z >= self.lo[2]) & (z <= self.hi[2])
        if self.triangles is None or not inside.any():
            return inside
        t = self.triangles[:, :, [0, 2]]
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        ok = np.abs(det) > 1e-12
        a, b, c, det = a[ok], b[ok], c[ok], det[ok]
        idx = np.flatnonzero(inside)
        px, pz = x[idx][:, None], z[idx][:, None]
        l1 = ((b[:, 0] - px) * (c[:, 1] - pz) - (b[:, 1] - pz) * (c[:, 0] - px)) / det
        l2 = ((c[:, 0] - px) * (a[:, 1] - pz) - (c[:, 1] - pz) * (a[:, 0] - px)) / det
        l3 = 1.0 - l1 - l2
        eps = -1e-9
        hit = ((l1 >= eps) & (l2 >= eps) & (l3 >= eps)).any(axis=1)
        out = np.zeros(len(x), dtype=bool)
        out[idx[hit]] = True
        return out


def read_ifc_spaces(path) -> list[Room]:
    """The ``IfcSpace`` volumes of an IFC file as rooms (named by ``LongName``, else ``Name``, else
    ``#id``), in file order; [] when the file has none or ifcopenshell is missing. A space the
    kernel cannot mesh is skipped with a warning."""
    path = Path(path)
    try:
        import ifcopenshell
        import ifcopenshell.geom
    except ImportError:
        return []
    try:
        f = ifcopenshell.open(str(path))
    except Exception as e:  # noqa: BLE001 - ifcopenshell's errors
        raise LoadError(f"cannot read IFC file: {one_line(e)}", path) from e
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    rooms = []
    for sp in sorted(f.by_type("IfcSpace"), key=lambda e: e.id()):
        if sp.Representation is None:
            continue
        try:
            g = ifcopenshell.geom.create_shape(settings, sp).geometry
        except Exception as e:  # noqa: BLE001 - the geometry kernel's errors
            log.warning("%s: IfcSpace #%d not meshed: %s", path.name, sp.id(), one_line(e))
            continue
        v = np.asarray(g.verts, dtype=np.float64).reshape(-1, 3) @ UP_TO_Y[b"Z"].T
        faces = np.asarray(g.faces, dtype=np.int64).reshape(-1, 3)
        if not len(faces):
            continue
        name = sp.LongName or sp.Name or f"#{sp.id()}"
        rooms.append(Room(str(name), v.min(axis=0), v.max(axis=0), v[faces]))
    return rooms
