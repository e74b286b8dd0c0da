"""A furnished house as a GLB (after the report's *maus*): ``python sample_models/house.py [-o PATH]``.

One storey, 12 m x 9 m inside, 2.7 m high, split by two 12 cm interior walls
into four rooms joined by four door openings (0.9 m x 2.1 m, with jambs, lintel
and threshold): living room (south-west), kitchen (south-east), study
(north-east), bedroom (north-west). +Y is up, x runs east, z runs north, the
origin is the south-west inside corner.

Every surface is a planar quad: room faces look into their room, furniture
(sofa, armchair, tables with legs, chairs, shelves with books, counters and
cabinets, bed, wardrobe, desk) looks out. Floors, ceilings and walls are split
into panels of at most 1.25 m (the report's pre-radiosity polygons); openings
are cut out on panel lines.

Light: a point light under the ceiling of the living room, bedroom and study,
a spot light over the study desk, a 0.8 m square emissive ceiling panel in the
kitchen, and two daylight windows (emissive quads filling holes in the outer
walls, materials ``window_south`` in the living room and ``window_north`` in the
bedroom). Three cameras and a 36-pose walk through all four rooms (root
``extras["iat_camera_paths"]["default"]``).

A day cycle (root ``extras["iat_lighting_states"]``, read by :mod:`iat.lighting`):
``morning`` (low warm sun through the south window, cool sky in the north one,
the kitchen panel at half strength, lamps off), ``noon`` (both windows bright and
neutral, everything else off) and ``evening`` (a dim orange dusk, every lamp on),
at key times 0, 0.5 and 1. The file's own lighting (what :func:`iat.io.load.load_scene`
gives) is everything on at once.

The daylight variant (``python sample_models/house.py --daylight``, ``house_day.glb``) glazes
the two windows (``KHR_materials_transmission`` 0.85) and lights the house by a real sun and sky
instead: the house stands in Paris (48.85 N, 2.35 E) with north at +Z (so the living room's
window faces south), and its day cycle is an equinox day, 2026-09-22, at 08:00, 11:00, 14:00,
17:00 and 20:00 local time: each state places the sun by :func:`iat.lighting.sun.sun_states`
(clear-sky direct light, warm when low) under a Preetham sky of the same sun; at 20:00 the sun
has set, a dim blue sky is left and every lamp is on. The file's own lighting is the 14:00 sun
and sky (the sky as root ``extras["iat_sky"]``) with every lamp on.

Output is deterministic: the same script gives the same bytes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
if __package__ in (None, ""):  # run as a script: make `sample_models` and `iat` importable
    sys.path.insert(0, str(_HERE.parent))

from sample_models.common import Camera, ModelBuilder, assemble, script_main, walk_path  # noqa: E402

DEFAULT_PATH = _HERE / "house.glb"
DAYLIGHT_PATH = _HERE / "house_day.glb"

# plan (metres)
W, D, H = 12.0, 9.0, 2.7  # inside extents x, z, height
XW, ZW, T = 6.0, 4.5, 0.12  # interior walls: x = XW (north-south), z = ZW (east-west); thickness
DOOR_W, DOOR_H = 0.9, 2.1
EYE = 1.6
YFOV = 60.0

ROOMS = {  # name: (x0, x1, z0, z1)
    "living": (0.0, XW - T / 2, 0.0, ZW - T / 2),
    "kitchen": (XW + T / 2, W, 0.0, ZW - T / 2),
    "bedroom": (0.0, XW - T / 2, ZW + T / 2, D),
    "study": (XW + T / 2, W, ZW + T / 2, D),
}

# door openings: (name, wall axis, centre along the wall) - "x" walls sit at x = XW, "z" walls at z = ZW
DOORS = [
    ("living_kitchen", "x", 2.0),
    ("bedroom_study", "x", 7.0),
    ("living_bedroom", "z", 2.5),
    ("kitchen_study", "z", 9.5),
]

# windows (emissive daylight panes): (room, wall face, (lo, hi) box of the hole)
WINDOWS = [
    ("living", "-z", ((1.0, 0.9, 0.0), (2.6, 2.2, 0.0))),
    ("bedroom", "+z", ((3.7, 0.9, D), (5.1, 2.2, D))),
]

# linear RGB albedos
PLASTER = (0.72, 0.70, 0.66)
CEILING = (0.78, 0.78, 0.76)
WOOD_FLOOR = (0.42, 0.28, 0.16)
TILE_FLOOR = (0.55, 0.55, 0.52)
CARPET = (0.35, 0.30, 0.38)
WOOD = (0.45, 0.30, 0.17)
DARK_WOOD = (0.22, 0.14, 0.08)
FABRIC_BLUE = (0.12, 0.20, 0.42)
FABRIC_RED = (0.50, 0.12, 0.10)
LINEN = (0.80, 0.78, 0.72)
WHITE_LACQUER = (0.80, 0.80, 0.78)
BOOKS = [(0.55, 0.10, 0.08), (0.10, 0.25, 0.50), (0.15, 0.40, 0.15), (0.60, 0.50, 0.15)]

#: emitted radiance (linear RGB) of the daylight windows and the kitchen panel
WINDOW_RADIANCE = (3.0, 3.6, 4.8)
PANEL_RADIANCE = (16.0, 14.5, 12.0)
LAMP_COLOR = (1.0, 0.85, 0.65)

#: the day cycle: lighting states by name (see iat.lighting): window radiance in linear RGB,
#: lamp intensities in W/sr, the kitchen panel's strength as a multiplier of PANEL_RADIANCE
LAMPS_OFF = {"living_lamp": 0.0, "bedroom_lamp": 0.0, "study_lamp": 0.0, "desk_lamp": 0.0}
LIGHTING_STATES = {
    "morning": {
        "time": 0.0,
        "lights": LAMPS_OFF,
        "emission": {"window_south": [6.0, 4.8, 3.2], "window_north": [1.2, 1.5, 2.2], "lamp_panel": 0.5},
    },
    "noon": {
        "time": 0.5,
        "lights": LAMPS_OFF,
        "emission": {"window_south": [5.0, 5.4, 6.0], "window_north": [2.6, 3.0, 3.8], "lamp_panel": 0.0},
    },
    "evening": {
        "time": 1.0,
        "lights": {"living_lamp": 10.0, "bedroom_lamp": 8.0, "study_lamp": 8.0, "desk_lamp": 12.0},
        "emission": {"window_south": [1.4, 0.7, 0.3], "window_north": [0.3, 0.35, 0.5], "lamp_panel": 1.0},
    },
}


#: the daylight variant: where and when (see the module docstring)
PLACE = {"latitude": 48.85, "longitude": 2.35, "tz": "Europe/Paris", "north": (0.0, 0.0, 1.0)}
DAY = "2026-09-22"
DAY_TIMES = ["08:00", "11:00", "14:00", "17:00", "20:00"]
GLASS_TRANSMISSION = 0.85
#: the clear sky's diffuse light on the ground as a fraction of the sun's direct normal light
#: (a clear day: about 100 W/m² of diffuse light with the sun high)
SKY_FRACTION = 0.12
#: after sunset: a uniform blue sky, W/(m² sr)
DUSK_SKY = (0.25, 0.35, 0.6)
LAMPS_ON = {"living_lamp": 10.0, "bedroom_lamp": 8.0, "study_lamp": 8.0, "desk_lamp": 12.0}


def daylight_states() -> dict[str, dict]:
    """The daylight variant's day cycle: {'HH:MM': state} (sun, sky, lamps, kitchen panel)."""
    from iat.io.scene import Sky
    from iat.lighting.sun import sun_states
    from iat.radiosity.sky import sky_irradiance

    states = sun_states(
        PLACE["latitude"], PLACE["longitude"], DAY, DAY_TIMES, PLACE["tz"], north=PLACE["north"], warm=True
    )
    for st in states.values():
        sun = st["sun"]
        if sun["intensity"] > 0:
            to_sun = [-c for c in sun["direction"]]
            unit = sky_irradiance(Sky(kind="preetham", sun_direction=to_sun))[1]  # zenith radiance 1
            diffuse = SKY_FRACTION * sun["intensity"]
            st["sky"] = {"kind": "preetham", "sun_direction": to_sun, "radiance": round(diffuse / unit, 4)}
            st["lights"], st["emission"] = LAMPS_OFF, {"lamp_panel": 0.0}
        else:
            st["sky"] = {"kind": "uniform", "radiance": list(DUSK_SKY)}
            st["lights"], st["emission"] = LAMPS_ON, {"lamp_panel": 1.0}
    return _rounded(states)


def _rounded(x):
    """``x`` with every float to 12 significant digits: the file's bytes then do not depend on the
    last bit of a numpy build's exp and pow (the sun's colour and place)."""
    if isinstance(x, float):
        return float(f"{x:.12g}")
    if isinstance(x, dict):
        return {k: _rounded(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_rounded(v) for v in x]
    return x


def _door_box(kind: str, c: float) -> tuple[tuple, tuple]:
    """(lo, hi) of the opening's volume through its wall."""
    if kind == "x":
        return (XW - T / 2, 0.0, c - DOOR_W / 2), (XW + T / 2, DOOR_H, c + DOOR_W / 2)
    return (c - DOOR_W / 2, 0.0, ZW - T / 2), (c + DOOR_W / 2, DOOR_H, ZW + T / 2)


def _room_holes(room: str) -> dict:
    """Openings per wall face of a room (inward box face names)."""
    x0, x1, z0, z1 = ROOMS[room]
    holes: dict[str, list] = {}
    for _, kind, c in DOORS:
        lo, hi = _door_box(kind, c)
        if kind == "x":
            if abs(x1 - lo[0]) < 1e-9 and z0 < c < z1:
                holes.setdefault("+x", []).append((lo, hi))
            if abs(x0 - hi[0]) < 1e-9 and z0 < c < z1:
                holes.setdefault("-x", []).append((lo, hi))
        else:
            if abs(z1 - lo[2]) < 1e-9 and x0 < c < x1:
                holes.setdefault("+z", []).append((lo, hi))
            if abs(z0 - hi[2]) < 1e-9 and x0 < c < x1:
                holes.setdefault("-z", []).append((lo, hi))
    for r, fname, box in WINDOWS:
        if r == room:
            holes.setdefault(fname, []).append(box)
    return holes


def _table(
    mb: ModelBuilder,
    obj: str,
    mat: str,
    x0,
    x1,
    z0,
    z1,
    top: float,
    thick: float = 0.04,
    leg: float = 0.06,
    skip=(),
) -> None:
    """A table: top slab (``skip``: its faces against a wall) and four legs."""
    mb.box(obj, mat, (x0, top - thick, z0), (x1, top, z1), skip=skip)
    for lx, lz in (
        (x0 + 0.05, z0 + 0.05),
        (x1 - 0.05 - leg, z0 + 0.05),
        (x1 - 0.05 - leg, z1 - 0.05 - leg),
        (x0 + 0.05, z1 - 0.05 - leg),
    ):
        mb.box(obj, mat, (lx, 0.0, lz), (lx + leg, top - thick, lz + leg), skip=("-y", "+y"))


def _chair(mb: ModelBuilder, obj: str, mat: str, x, z, facing: str) -> None:
    """A chair 0.45 m square centred at (x, z), facing ``facing``; its back is on the other side."""
    s, seat = 0.225, 0.45
    _table(mb, obj, mat, x - s, x + s, z - s, z + s, seat, thick=0.04, leg=0.04)
    back = {
        "+x": (x - s, x - s + 0.04, z - s, z + s),
        "-x": (x + s - 0.04, x + s, z - s, z + s),
        "+z": (x - s, x + s, z - s, z - s + 0.04),
        "-z": (x - s, x + s, z + s - 0.04, z + s),
    }[facing]
    mb.box(obj, mat, (back[0], seat, back[2]), (back[1], seat + 0.45, back[3]), skip=("-y",))


def _shelf(
    mb: ModelBuilder,
    obj: str,
    mat: str,
    x0,
    x1,
    z0,
    z1,
    height: float,
    boards: int,
    back: str,
    books_seed: int,
) -> None:
    """An open shelf standing against a wall: two sides, ``boards`` boards, rows of books.

    back : the box face against the wall, ``"-z"`` or ``"+z"`` (the shelf runs along x).
    Faces hidden against the wall or against each other are left out.
    """
    th = 0.025
    mb.box(obj, mat, (x0, 0.0, z0), (x0 + th, height, z1), skip=("-y", back))
    mb.box(obj, mat, (x1 - th, 0.0, z0), (x1, height, z1), skip=("-y", back))
    lo_x, hi_x = x0 + th, x1 - th
    ys = np.linspace(0.08, height - th, boards)
    depth = (z1 - z0) * 0.8
    zb0, zb1 = (z0, z0 + depth) if back == "-z" else (z1 - depth, z1)
    for k, y in enumerate(ys):
        mb.box(obj, mat, (lo_x, y, z0), (hi_x, y + th, z1), skip=("-x", "+x", back))
        if k == len(ys) - 1:
            continue
        gap = ys[k + 1] - (y + th)
        pos, n = lo_x + 0.04, 0
        while True:  # a row of books: deterministic widths, heights and gaps
            w = 0.16 + 0.06 * ((books_seed + 3 * k + 5 * n) % 4)
            if pos + w > hi_x - 0.04:
                break
            h = gap * (0.6 + 0.08 * ((books_seed + k + 2 * n) % 4))
            if (books_seed + k + n) % 3 != 2:
                colour = (books_seed + 2 * k + n) % len(BOOKS)
                mb.box(
                    f"{obj}_books_{colour}",
                    f"books_{colour}",
                    (pos, y + th, zb0),
                    (pos + w, y + th + h, zb1),
                    skip=("-y", back),
                )
            pos += w + 0.02
            n += 1


def build_geometry(mb: ModelBuilder, daylight: bool = False) -> None:
    """Rooms, door openings, windows (emissive panes, or glass when ``daylight``) and furniture."""
    mb.material("plaster", PLASTER)
    mb.material("ceiling", CEILING)
    mb.material("wood_floor", WOOD_FLOOR)
    mb.material("tile_floor", TILE_FLOOR)
    mb.material("carpet", CARPET)
    mb.material("wood", WOOD)
    mb.material("dark_wood", DARK_WOOD)
    mb.material("fabric_blue", FABRIC_BLUE)
    mb.material("fabric_red", FABRIC_RED)
    mb.material("linen", LINEN)
    mb.material("lacquer", WHITE_LACQUER)
    for name in ("window_south", "window_north"):
        if daylight:
            mb.material(name, (0.8, 0.85, 0.85), transmission=GLASS_TRANSMISSION)
        else:
            mb.material(name, (0.8, 0.8, 0.8), emissive=WINDOW_RADIANCE)
    mb.material("lamp_panel", (0.8, 0.8, 0.8), emissive=PANEL_RADIANCE)
    for k, c in enumerate(BOOKS):
        mb.material(f"books_{k}", c)
    floors = {"living": "wood_floor", "kitchen": "tile_floor", "bedroom": "carpet", "study": "wood_floor"}

    # rooms: floor, ceiling and walls with openings, all looking inward
    for room, (x0, x1, z0, z1) in ROOMS.items():
        holes = _room_holes(room)
        mb.face(f"{room}_floor", floors[room], (x0, 0.0, z0), (x1, 0.0, z1), +1)
        mb.face(f"{room}_ceiling", "ceiling", (x0, H, z0), (x1, H, z1), -1)
        for fname, (lo, hi, sign) in {
            "-x": ((x0, 0.0, z0), (x0, H, z1), +1),
            "+x": ((x1, 0.0, z0), (x1, H, z1), -1),
            "-z": ((x0, 0.0, z0), (x1, H, z0), +1),
            "+z": ((x0, 0.0, z1), (x1, H, z1), -1),
        }.items():
            mb.face(f"{room}_walls", "plaster", lo, hi, sign, holes=holes.get(fname, ()))

    # door openings: jambs, lintel underside, threshold
    for _name, kind, c in DOORS:
        lo, hi = _door_box(kind, c)
        lo, hi = np.array(lo), np.array(hi)
        a = 2 if kind == "x" else 0  # axis along the wall
        for side, sign in ((lo[a], +1), (hi[a], -1)):
            flo, fhi = lo.copy(), hi.copy()
            flo[a] = fhi[a] = side
            mb.face("door_jambs", "plaster", flo, fhi, sign)
        mb.face("door_jambs", "plaster", (lo[0], DOOR_H, lo[2]), (hi[0], DOOR_H, hi[2]), -1)
        mb.face("door_thresholds", "wood", (lo[0], 0.0, lo[2]), (hi[0], 0.0, hi[2]), +1)

    # windows: emissive panes (or glass) filling the holes, facing into the room
    for _, fname, (lo, hi) in WINDOWS:
        sign = +1 if fname.startswith("-") else -1
        mat = "window_south" if fname == "-z" else "window_north"
        mb.face(mat, mat, lo, hi, sign, panel=2.0)

    # -- living room (x 0..5.94, z 0..4.44): sofa against the west wall, armchair, coffee table, shelf
    mb.box("sofa", "fabric_blue", (0.0, 0.0, 1.2), (0.9, 0.42, 3.4), skip=("-y", "-x"))
    mb.box("sofa", "fabric_blue", (0.0, 0.42, 1.2), (0.25, 0.85, 3.4), skip=("-y", "-x"))
    mb.box("sofa", "fabric_blue", (0.25, 0.42, 1.2), (0.9, 0.62, 1.42), skip=("-y", "-x"))
    mb.box("sofa", "fabric_blue", (0.25, 0.42, 3.18), (0.9, 0.62, 3.4), skip=("-y", "-x"))
    _table(mb, "coffee_table", "dark_wood", 1.3, 1.9, 1.8, 2.8, 0.45)
    mb.box("armchair", "fabric_red", (1.6, 0.0, 3.5), (2.4, 0.42, 4.3), skip=("-y",))
    mb.box("armchair", "fabric_red", (1.6, 0.42, 4.1), (2.4, 0.9, 4.3), skip=("-y",))
    _shelf(mb, "living_shelf", "wood", 3.4, 5.4, 0.0, 0.35, 2.0, 5, "-z", books_seed=1)

    # -- kitchen (x 6.06..12, z 0..4.44): counters along the east and south walls, table, chairs
    mb.box("counter", "lacquer", (11.4, 0.0, 0.6), (12.0, 0.9, 4.0), skip=("-y", "+x", "-z"))
    mb.box(
        "counter",
        "lacquer",
        (8.2, 0.0, 0.0),
        (12.0, 0.9, 0.6),
        skip=("-y", "-z", "+x"),
        holes={"+z": [((11.4, 0.0, 0.6), (12.0, 0.9, 0.6))]},
    )
    mb.box("cabinets", "lacquer", (11.65, 1.5, 0.6), (12.0, 2.2, 4.0), skip=("+x",))
    mb.box("cabinets", "lacquer", (8.2, 1.5, 0.0), (12.0, 2.2, 0.35), skip=("-z", "+x"))
    _table(mb, "kitchen_table", "wood", 7.0, 8.4, 0.5, 1.3, 0.75)
    _chair(mb, "kitchen_chairs", "wood", 7.7, 0.2 + 0.05, "+z")
    _chair(mb, "kitchen_chairs", "wood", 6.55, 0.9, "+x")

    # -- study (x 6.06..12, z 4.56..9): desk against the east wall, chair, shelf on the north wall
    _table(mb, "desk", "dark_wood", 11.2, 12.0, 6.0, 7.8, 0.75, skip=("+x",))
    _chair(mb, "desk_chair", "fabric_blue", 10.7, 6.9, "+x")
    _shelf(mb, "study_shelf", "wood", 6.6, 9.0, 8.65, 9.0, 2.2, 6, "+z", books_seed=2)
    mb.box("cabinet", "wood", (11.5, 0.0, 4.56), (12.0, 1.1, 5.6), skip=("-y", "+x", "-z"))

    # -- bedroom (x 0..5.94, z 4.56..9): bed with headboard against the north wall, nightstands, wardrobe
    mb.box("bed", "dark_wood", (1.0, 0.0, 7.0), (2.6, 0.3, 8.9), skip=("-y", "+z"))
    mb.box("bed_linen", "linen", (1.05, 0.3, 7.05), (2.55, 0.5, 8.9), skip=("-y", "+z"))
    mb.box("bed", "dark_wood", (1.0, 0.0, 8.9), (2.6, 1.0, 9.0), skip=("-y", "+z"))
    mb.box("nightstands", "wood", (0.45, 0.0, 8.5), (0.95, 0.55, 9.0), skip=("-y", "+z"))
    mb.box("nightstands", "wood", (2.65, 0.0, 8.5), (3.15, 0.55, 9.0), skip=("-y", "+z"))
    mb.box("wardrobe", "wood", (0.0, 0.0, 4.9), (0.6, 2.0, 6.6), skip=("-y", "-x"))


def lights(mb: ModelBuilder) -> None:
    """Point lights in three rooms, a desk spot light and the kitchen's emissive ceiling panel."""
    mb.glb.add_point_light("living_lamp", LAMP_COLOR, 10.0, (3.0, 2.35, 2.0))
    mb.glb.add_point_light("bedroom_lamp", LAMP_COLOR, 8.0, (3.2, 2.35, 6.6))
    mb.glb.add_point_light("study_lamp", LAMP_COLOR, 8.0, (8.8, 2.35, 6.5))
    mb.glb.add_spot_light(
        "desk_lamp", (1.0, 0.95, 0.85), 12.0, (10.9, 1.7, 6.9), (0.45, -1.0, 0.0), inner=0.35, outer=0.6
    )
    mb.face("kitchen_lamp", "lamp_panel", (8.6, H - 0.02, 2.2), (9.4, H - 0.02, 3.0), -1)


def camera_path() -> list[dict]:
    """36 poses: a loop living room -> kitchen -> study -> bedroom -> living room through the doors."""
    y = EYE
    wp = [
        (3.0, y, 0.9),
        (4.3, y, 1.6),
        (5.2, y, 2.0),  # living room, towards the kitchen door
        (6.8, y, 2.0),
        (8.6, y, 2.3),
        (9.5, y, 3.5),  # kitchen, towards the study door
        (9.5, y, 5.5),
        (9.0, y, 7.0),
        (6.9, y, 7.0),  # study, towards the bedroom door
        (5.1, y, 7.0),
        (3.6, y, 6.2),
        (2.5, y, 5.3),  # bedroom, towards the living room door
        (2.5, y, 3.7),
        (3.0, y, 2.5),  # back into the living room
    ]
    return walk_path(wp, 36, yfov=YFOV, look_ahead=1.6, look_down=0.3)


def cameras() -> list[Camera]:
    return [
        Camera(eye=(5.6, EYE, 0.7), target=(1.2, 0.8, 3.2), yfov=YFOV, znear=0.05, zfar=50.0, name="living"),
        Camera(
            eye=(6.6, EYE, 4.1), target=(11.0, 0.8, 1.0), yfov=YFOV, znear=0.05, zfar=50.0, name="kitchen"
        ),
        Camera(eye=(5.5, EYE, 5.0), target=(1.5, 0.6, 8.5), yfov=YFOV, znear=0.05, zfar=50.0, name="bedroom"),
    ]


def build(path: str | Path = DEFAULT_PATH, daylight: bool = False) -> Path:
    """Write the house GLB to ``path`` (atomically); returns the path. ``daylight``: the glazed,
    sun-and-sky-lit variant (the module docstring)."""
    if not daylight:
        return assemble(
            build_geometry,
            lights,
            cameras(),
            camera_path(),
            panel=1.25,
            extras={"iat_lighting_states": LIGHTING_STATES},
        ).glb.write(path)
    states = daylight_states()
    own = states["14:00"]

    def day_lights(mb: ModelBuilder) -> None:
        lights(mb)
        sun = own["sun"]
        mb.glb.add_directional_light("sun", sun["color"], sun["intensity"], sun["direction"])

    return assemble(
        lambda mb: build_geometry(mb, daylight=True),
        day_lights,
        cameras(),
        camera_path(),
        panel=1.25,
        extras={"iat_lighting_states": states, "iat_sky": own["sky"]},
    ).glb.write(path)


def _main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    daylight = "--daylight" in args
    if daylight:
        args.remove("--daylight")
    return script_main(
        lambda p: build(p, daylight=daylight),
        DAYLIGHT_PATH if daylight else DEFAULT_PATH,
        "Write the house sample scene (after the report's maus) as a GLB; --daylight: the glazed, "
        "sun-and-sky-lit variant.",
        args,
    )


if __name__ == "__main__":
    sys.exit(_main())
