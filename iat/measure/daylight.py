"""Daylight factor and per-room work-plane analysis.

**Daylight factor** (CIE): the illuminance at a point inside as a fraction (%) of the illuminance on
an unobstructed horizontal plane outside, both under the CIE standard overcast sky (no sun, no
lamps). :func:`overcast_scene` is the model under that sky alone (zenith radiance 1; the ratio does
not depend on it), so that its solution holds sky component plus inter-reflections;
:func:`vertex_daylight_factor` reads it at the solution's vertices, the work-plane sensors
(:mod:`iat.measure.sensors`) at grid points.

**Rooms** (:class:`iat.io.spaces.Room`: an IFC's ``IfcSpace``, a box the user gives, or the model's
bounds) get a grid of ``spacing`` at ``height`` (0.75 m) over their floor, cells centred (the first
point half a spacing from the walls), points outside the room's footprint or inside furniture (a
closed solid) dropped; each point's
illuminance (lux, under the model's own light) and daylight factor, and per room ``mean``, ``min``,
``max`` and ``uniformity`` (min / mean).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field, replace

import numpy as np

from iat.color import LUMINANCE_WEIGHTS
from iat.io.scene import Scene, Sky
from iat.io.spaces import Room
from iat.measure import photometry as ph
from iat.measure.sensors import SENSOR_SIDE, SensorScene, inside_solids, irradiance_at
from iat.radiosity.sky import cie_overcast_irradiance

#: the work plane's height over a room's floor, m
WORK_PLANE = 0.75
#: the loader's pre-split (``max_edge``, m) of an analysis when none is given: a floor or ceiling
#: slab that runs under the walls has all its corners inside them, and unsplit it stays one black
#: element (the adaptive meshing sees no light at any of its vertices to refine on); on the two-room
#: test building the living room's mean daylight factor is 4.55 % without, 6.11 % with 1 m, 6.23 %
#: with 0.5 m (at twice the solve time)
ANALYSIS_MAX_EDGE = 1.0


def overcast_scene(scene: Scene) -> Scene:
    """The model under the CIE overcast sky alone: its lights and emission off, the sky CIE overcast
    of zenith radiance 1 W/(m² sr) per unit colour (white; black below the horizon). Geometry,
    albedo and glass are the model's (shared, not copied)."""
    mats = [replace(m, emission=np.zeros(3)) for m in scene.materials]
    sky = Sky(kind="cie_overcast", radiance=np.ones(3), ground=np.zeros(3), name="CIE overcast")
    return replace(scene, materials=mats, lights=[], sky=sky)


def horizontal_irradiance(sky: Sky) -> float:
    """The luminance (Rec. 709) of the irradiance an unobstructed horizontal plane gets from a CIE
    overcast ``sky`` (``7 pi L_z / 9``)."""
    return float(cie_overcast_irradiance(sky.radiance) @ LUMINANCE_WEIGHTS)


def daylight_factor(irradiance, sky: Sky) -> np.ndarray:
    """(...) % : the luminance of ``irradiance`` (..., 3) over the sky's unobstructed horizontal."""
    return 100.0 * (np.asarray(irradiance, dtype=np.float64) @ LUMINANCE_WEIGHTS) / horizontal_irradiance(sky)


def vertex_daylight_factor(solution, scene: Scene) -> np.ndarray:
    """(V,) % at a solution of :func:`overcast_scene` ``scene`` (NaN where the albedo is 0)."""
    return daylight_factor(ph.vertex_irradiance(solution, scene.patch_emission), scene.sky)


def model_room(scene: Scene) -> Room:
    """The whole model as one room (its bounds)."""
    lo, hi = scene.bounds
    return Room.box("model", lo, hi)


def grid_points(room: Room, spacing: float, height: float = WORK_PLANE) -> np.ndarray:
    """(n, 3) work-plane points of a room: a ``spacing`` grid over its footprint at ``height`` over
    its floor, cell centres (at least one point a side)."""
    if not spacing > 0:
        raise ValueError(f"the grid spacing must be > 0, got {spacing}")

    def axis(lo: float, hi: float) -> np.ndarray:
        n = max(1, int(math.floor((hi - lo) / spacing + 1e-9)))
        return (lo + hi) / 2 + (np.arange(n) - (n - 1) / 2) * spacing

    xs, zs = axis(room.lo[0], room.hi[0]), axis(room.lo[2], room.hi[2])
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    x, z = X.ravel(), Z.ravel()
    keep = room.contains_xz(x, z)
    return np.stack([x[keep], np.full(int(keep.sum()), room.lo[1] + height), z[keep]], axis=1)


def stats(values) -> dict:
    """``{"mean", "min", "max", "uniformity"}`` of finite values (uniformity = min / mean)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if not len(v):
        return {"mean": None, "min": None, "max": None, "uniformity": None}
    mean = float(v.mean())
    return {
        "mean": mean,
        "min": float(v.min()),
        "max": float(v.max()),
        "uniformity": float(v.min() / mean) if mean > 0 else None,
    }


@dataclass
class RoomResult:
    """A room's grid and its readings: points (n, 3); lux (n,) under the model's light and df (n,)
    daylight factor %, each None when not measured."""

    name: str
    points: np.ndarray
    lux: np.ndarray | None = None
    df: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    def to_dict(self, with_points: bool = True) -> dict:
        d = {"name": self.name, "points": len(self.points), **self.extra}
        if self.lux is not None:
            d["illuminance_lux"] = stats(self.lux)
        if self.df is not None:
            d["daylight_factor_percent"] = stats(self.df)
        if with_points:
            d["grid"] = [
                {
                    "x": float(p[0]),
                    "y": float(p[1]),
                    "z": float(p[2]),
                    **({"lux": float(self.lux[k])} if self.lux is not None else {}),
                    **({"df": float(self.df[k])} if self.df is not None else {}),
                }
                for k, p in enumerate(self.points)
            ]
        return d


def measure_rooms(
    rooms: list[Room],
    spacing: float,
    height: float = WORK_PLANE,
    lit: tuple | None = None,
    overcast: tuple | None = None,
    side: int = SENSOR_SIDE,
) -> list[RoomResult]:
    """Each room's grid (:func:`grid_points`) read by upward sensors in ``lit`` = (scene, solution)
    (lux) and in ``overcast`` = (overcast scene, its solution) (daylight factor %). Grid points inside
    a closed solid (furniture: :func:`~iat.measure.sensors.inside_solids`) are left out, counted in
    each room's ``inside_solids`` (unless all of a room's points are: then none is)."""
    grids = [grid_points(r, spacing, height) for r in rooms]
    pairs = [("lux", lit), ("df", overcast)]
    first = next((pair for _, pair in pairs if pair is not None), None)
    if first is not None and sum(map(len, grids)):
        sc = SensorScene.build(*first)
        try:
            # (a room all of whose points look inside is a room modelled inside out: kept whole)
            inside = [(k := inside_solids(sc, g)) & ~k.all() for g in grids]
        finally:
            sc.close()
        grids = [g[~k] for g, k in zip(grids, inside, strict=True)]
        results = [
            RoomResult(r.name, g, extra={"inside_solids": int(k.sum())})
            for r, g, k in zip(rooms, grids, inside, strict=True)
        ]
    else:
        results = [RoomResult(r.name, g) for r, g in zip(rooms, grids, strict=True)]
    pts = np.concatenate([r.points for r in results]) if results else np.zeros((0, 3))
    split = np.cumsum([len(r.points) for r in results])[:-1]
    for which, pair in pairs:
        if pair is None or not len(pts):
            continue
        scene, sol = pair
        sc = SensorScene.build(scene, sol)
        try:
            e = irradiance_at(scene, sol, pts, side=side, sensors=sc)
        finally:
            sc.close()
        vals = ph.illuminance(e) if which == "lux" else daylight_factor(e, scene.sky)
        for r, v in zip(results, np.split(vals, split), strict=True):
            setattr(r, which, v)
    return results


def report(results: list[RoomResult], meta: dict) -> dict:
    """The JSON report: ``meta`` (model, grid, height, sky, ...) and each room with its statistics
    and grid points."""
    return {**meta, "rooms": [r.to_dict() for r in results]}


def report_csv(results: list[RoomResult]) -> str:
    """One row per grid point: ``room, x, y, z, lux, daylight_factor_percent`` (empty when not
    measured)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["room", "x", "y", "z", "lux", "daylight_factor_percent"])
    for r in results:
        for k, p in enumerate(r.points):
            lux = "" if r.lux is None else f"{r.lux[k]:.6g}"
            df = "" if r.df is None else f"{r.df[k]:.6g}"
            w.writerow([r.name, f"{p[0]:.4f}", f"{p[1]:.4f}", f"{p[2]:.4f}", lux, df])
    return buf.getvalue()
