"""A small IFC4 building at a known place, written with ifcopenshell's API (issue 38's tests): its
IfcSite at Boulder, Colorado (40 deg 0' 54" N, 105 deg 16' 13.8" W, as the files write the compound
angles) and TrueNorth turned :data:`NORTH_DEG` anticlockwise."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

# Boulder, Colorado: 40 deg 0' 54" N, 105 deg 16' 13.8" W
LAT_DMS, LON_DMS = [40, 0, 54, 0], [-105, -16, -13, -800000]
LAT, LON = 40.015, -(105 + 16 / 60 + 13.8 / 3600)
#: IFC gives no time zone: the longitude's (round(lon / 15) hours)
TZ_HOURS = -7.0
NORTH_DEG = 30.0
#: the skylit hall of :func:`site_ifc` (``skylight=True``): plan size, wall height, roof thickness,
#: and the skylight's square (x0, x1, y0, y1) in the plan
HALL = (10.0, 10.0)
HALL_WALL = 1.8
ROOF = 0.2
SKYLIGHT = (4.5, 5.5, 4.5, 5.5)


def angle_deg(a, b) -> float:
    """The angle between two vectors, degrees."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
    return math.degrees(math.acos(min(max(c, -1.0), 1.0)))


def expected_to_sun(lat, lon, when, north_deg) -> np.ndarray:
    """Towards the sun in the Y-up scene, worked out in IFC's plan: true north (-sin a, cos a),
    east its clockwise quarter turn, Z up; then (x, y, z) -> (x, z, -y)."""
    from iat.lighting.sun import solar_position

    az, el = solar_position(lat, lon, when)
    a = math.radians(north_deg)
    n = np.array([-math.sin(a), math.cos(a)])
    e = np.array([n[1], -n[0]])
    h = math.cos(math.radians(az)) * n + math.sin(math.radians(az)) * e
    x, y, z = math.cos(math.radians(el)) * h[0], math.cos(math.radians(el)) * h[1], math.sin(math.radians(el))
    return np.array([x, z, -y])


def site_ifc(tmp_path: Path, located: bool = True, skylight: bool = False) -> Path:
    """Write the test building and return its path.

    located : the site has RefLatitude / RefLongitude (else it is a site with no location)
    skylight : False: a 4 x 3 m room, 2.5 m high, with a window in its south wall and no roof (a
      floor slab); True: a 10 x 10 m hall (:data:`HALL`), walls :data:`HALL_WALL` high, a roof slab
      :data:`ROOF` thick with a 1 x 1 m skylight (:data:`SKYLIGHT`) in its middle: the sun through it
      makes one lit patch on the floor, where the sun's direction says
    """
    import ifcopenshell.api

    from tests.support.ifc_builder import IfcBuilder

    b = IfcBuilder("site test")
    s = b.style("wall", (0.7, 0.7, 0.7))
    floor = b.style("floor", (0.5, 0.4, 0.3))
    if skylight:
        (w, d), h = HALL, HALL_WALL
        b.wall("south", 0, (0.0, 0.0), (w, 0.0), 0.0, h, 0.2, s)
        b.wall("east", 0, (w, 0.0), (w, d), 0.0, h, 0.2, s)
        b.wall("north", 0, (w, d), (0.0, d), 0.0, h, 0.2, s)
        b.wall("west", 0, (0.0, d), (0.0, 0.0), 0.0, h, 0.2, s)
        b.slab("floor", 0, [(0, 0), (w, 0), (w, d), (0, d)], -0.2, 0.2, floor)
        roof = b.slab("roof", 0, [(0, 0), (w, 0), (w, d), (0, d)], h, ROOF, b.style("roof", (0.6, 0.6, 0.6)))
        x0, x1, y0, y1 = SKYLIGHT
        b.void(roof, "skylight", (x0, y0, h - 0.1), 0.0, x1 - x0, ROOF + 0.2, y1 - y0)
    else:
        b.wall("south", 0, (0.0, 0.0), (4.0, 0.0), 0.0, 2.5, 0.2, s, openings=[(1.0, 3.0, 0.8, 2.0)])
        b.wall("east", 0, (4.0, 0.0), (4.0, 3.0), 0.0, 2.5, 0.2, s)
        b.wall("north", 0, (4.0, 3.0), (0.0, 3.0), 0.0, 2.5, 0.2, s)
        b.wall("west", 0, (0.0, 3.0), (0.0, 0.0), 0.0, 2.5, 0.2, s)
        b.slab("floor", 0, [(0, 0), (4, 0), (4, 3), (0, 3)], -0.2, 0.2, floor)
    (site,) = b.f.by_type("IfcSite")
    if located:
        ifcopenshell.api.run(
            "attribute.edit_attributes",
            b.f,
            product=site,
            attributes={"RefLatitude": LAT_DMS, "RefLongitude": LON_DMS, "RefElevation": 1655.0},
        )
    ifcopenshell.api.run("georeference.edit_true_north", b.f, true_north=NORTH_DEG)
    name = "hall.ifc" if skylight else ("site.ifc" if located else "nowhere.ifc")
    out = tmp_path / name
    b.write(out, "site-test-hall" if skylight else "site-test")
    return out
