"""Where a model stands on Earth: an IFC file's site location and true north.

:func:`read_ifc_site` reads, with ifcopenshell (the ``iat[ifc]`` extra), what every IFC file from
Revit or ArchiCAD carries instead of lights:

- ``IfcSite.RefLatitude`` / ``RefLongitude``: ``IfcCompoundPlaneAngleMeasure`` lists of
  degrees, minutes, seconds and (optionally) millionths of a second, all of one sign (south and
  west negative: Madrid's longitude is ``(-3, -42, -20, -772056)``; :func:`compound_angle`);
  ``RefElevation`` in metres. A site without them has no location (``Site.has_location`` False).
- ``IfcGeometricRepresentationContext.TrueNorth``: a 2-D direction in the model's plan (x, y)
  that points to geographic north (absent: +Y). Its angle ``true_north_deg`` is measured from
  +Y, anticlockwise seen from above (ifcopenshell's ``get_true_north`` convention: (-0.5, 0.866)
  is +30).

The loader turns IFC's Z-up into Y-up, ``(x, y, z) -> (x, z, -y)`` (:mod:`iat.io.ifc`), so the plan's
+Y is the scene's -Z (the scene's default north, :mod:`iat.lighting.sun`) and true north in the scene is
``(tx, 0, -ty)`` (:meth:`Site.north_vector`). The context's own world coordinate system and
an IFC4 ``IfcMapConversion`` (grid north) are not applied.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: the divisors of an IfcCompoundPlaneAngleMeasure's components: degrees, minutes, seconds, millionths
_DMS_SCALE = (1.0, 60.0, 3600.0, 3600.0e6)


@dataclass(frozen=True)
class Site:
    """A model's place.

    latitude, longitude : degrees north / east (south, west negative), or None (no location)
    elevation : metres above sea level, or None
    true_north_deg : degrees from the plan's +Y (the scene's -Z) to true north, anticlockwise seen
      from above (0: +Y is north)
    name : the site's name ("" when none)
    source : what it was read from, for messages ("IfcSite #148 'Default'")
    """

    latitude: float | None
    longitude: float | None
    elevation: float | None = None
    true_north_deg: float = 0.0
    name: str = ""
    source: str = ""

    @property
    def has_location(self) -> bool:
        return self.latitude is not None and self.longitude is not None

    def north_vector(self) -> np.ndarray:
        """(3,) float64 unit vector of true north in the scene (Y up): ``(tx, 0, -ty)`` for the plan's
        true-north direction ``(tx, ty) = (-sin a, cos a)``, a = ``true_north_deg``."""
        return north_vector(self.true_north_deg)


def north_vector(true_north_deg: float) -> np.ndarray:
    """(3,) float64 true north in a Y-up scene for an angle from -Z, anticlockwise seen from above
    (0: -Z, 90: -X, -90: +X)."""
    a = math.radians(float(true_north_deg))
    return np.array([-math.sin(a), 0.0, -math.cos(a)])


def north_angle(north) -> float:
    """Inverse of :func:`north_vector`: degrees from -Z, anticlockwise seen from above, of a scene
    vector's horizontal part (its Y is ignored)."""
    n = np.asarray(north, dtype=np.float64).reshape(3)
    return math.degrees(math.atan2(-n[0], -n[2]))


def compound_angle(value) -> float | None:
    """Decimal degrees of an ``IfcCompoundPlaneAngleMeasure`` (3 or 4 integers: degrees, minutes,
    seconds, millionths of a second), or None when absent or malformed. IFC asks for one sign on
    every component; a writer that signs only the degrees (``(-3, 42, 20)``) is read as meant:
    the angle is negative when any component is."""
    if value is None:
        return None
    try:
        parts = [float(x) for x in value]
    except (TypeError, ValueError):
        return None
    if not 3 <= len(parts) <= 4 or not all(math.isfinite(x) for x in parts):
        return None
    sign = -1.0 if any(x < 0 for x in parts) else 1.0
    return sign * sum(abs(x) / s for x, s in zip(parts, _DMS_SCALE, strict=False))


def _true_north(f) -> float:
    """Degrees (anticlockwise from +Y) of the first 3-D model context's TrueNorth, 0 when none."""
    contexts = f.by_type("IfcGeometricRepresentationContext", include_subtypes=False)
    contexts = sorted(contexts, key=lambda c: (c.ContextType != "Model", c.id()))
    for c in contexts:
        tn = getattr(c, "TrueNorth", None)
        if tn is None:
            continue
        ratios = list(tn.DirectionRatios or ())
        if len(ratios) < 2 or not math.hypot(ratios[0], ratios[1]) > 0:
            continue
        a = math.degrees(math.atan2(float(ratios[1]), float(ratios[0]))) - 90.0
        return (a + 180.0) % 360.0 - 180.0
    return 0.0


@functools.lru_cache(maxsize=16)
def _read(path: str, mtime_ns: int, size: int) -> Site | None:
    import ifcopenshell

    f = ifcopenshell.open(path)
    sites = f.by_type("IfcSite")
    north = _true_north(f)
    if not sites:
        return Site(None, None, None, north, "", "no IfcSite")
    chosen = None
    for s in sites:
        lat, lon = compound_angle(s.RefLatitude), compound_angle(s.RefLongitude)
        if lat is not None and lon is not None:
            if -90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0:
                chosen = (s, lat, lon)
                break
            log.info("%s: IfcSite #%d location (%s, %s) out of range, ignored", path, s.id(), lat, lon)
    if chosen is None:
        s = sites[0]
        return Site(None, None, None, north, s.Name or "", f"IfcSite #{s.id()} (no RefLatitude/RefLongitude)")
    s, lat, lon = chosen
    elev = getattr(s, "RefElevation", None)
    name = s.Name or ""
    return Site(lat, lon, None if elev is None else float(elev), north, name, f"IfcSite #{s.id()} {name!r}")


def read_ifc_site(path: str | Path) -> Site | None:
    """The :class:`Site` of an IFC file (cached per path, size and modification time), or None
    for a file that is not IFC or that ifcopenshell cannot read (the loader says why)."""
    p = Path(path)
    if p.suffix.lower() != ".ifc" or not p.is_file():
        return None
    try:
        import ifcopenshell  # noqa: F401
    except ImportError:
        return None
    st = p.stat()
    try:
        return _read(str(p.resolve()), st.st_mtime_ns, st.st_size)
    except Exception as e:  # noqa: BLE001 - ifcopenshell's errors: the loader reports a bad file
        log.info("%s: site not read: %s", p, e)
        return None
