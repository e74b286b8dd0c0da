"""A hall around a glowing lava pit as a GLB (after the report's *lavapit*):
``python sample_models/lavapit.py [-o PATH]``.

A stone hall 20 m x 16 m, 7 m high (x in [-10, 10], z in [-8, 8], floor at
y = 0). An 8 m x 6 m pit is sunk in the middle of the floor; 1.2 m down its
inward-facing walls lies the lava: a strongly emissive orange surface (radiance
well above 1, so written with ``KHR_materials_emissive_strength``), split into
panels like every large surface. A stone bridge crosses the pit along x = 0.
Six square pillars stand around the pit from floor to ceiling, shallow
pilasters line the walls, and four braziers (pedestals with a warm point light
above each) stand near the corners: the pillars and the bridge throw long
shadows of the lava glow onto the walls and the ceiling.

Every surface is a planar quad; room faces look into the hall, the pit walls
into the pit, pillars and pedestals out. Floors, walls and ceiling are panels
of at most 1.6 m. Three cameras and a 36-pose walk once around the pit (root
``extras["iat_camera_paths"]["default"]``). +Y is up, metres.

Output is deterministic: the same script gives the same bytes.
"""

from __future__ import annotations

import sys
from pathlib import Path

_HERE = Path(__file__).resolve().parent
if __package__ in (None, ""):  # run as a script: make `sample_models` and `iat` importable
    sys.path.insert(0, str(_HERE.parent))

from sample_models.common import Camera, ModelBuilder, assemble, loop_waypoints, script_main, walk_path  # noqa: E402

DEFAULT_PATH = _HERE / "lavapit.glb"

HX, HZ, H = 10.0, 8.0, 7.0  # hall half extents x, z and height
PX, PZ, PIT_DEPTH = 4.0, 3.0, 1.2  # pit half extents and depth (lava surface at y = -PIT_DEPTH)
BRIDGE_W, BRIDGE_T = 1.2, 0.3  # bridge width (x) and slab thickness
PILLAR = 0.8  # pillar side
PILLARS = [(-3.0, -4.6), (3.0, -4.6), (6.0, 0.0), (3.0, 4.6), (-3.0, 4.6), (-6.0, 0.0)]
BRAZIERS = [(-8.8, -6.8), (8.8, -6.8), (8.8, 6.8), (-8.8, 6.8)]
EYE = 1.7
YFOV = 60.0

STONE = (0.40, 0.37, 0.34)
STONE_FLOOR = (0.33, 0.30, 0.28)
CEILING = (0.45, 0.42, 0.40)
PIT_ROCK = (0.18, 0.12, 0.10)
BRONZE = (0.35, 0.22, 0.10)
LAVA_ALBEDO = (0.5, 0.2, 0.05)
#: emitted radiance of the lava, linear RGB
LAVA_RADIANCE = (9.0, 2.6, 0.35)
FIRE_COLOR = (1.0, 0.55, 0.22)


def build_geometry(mb: ModelBuilder) -> None:
    mb.material("stone", STONE)
    mb.material("stone_floor", STONE_FLOOR)
    mb.material("ceiling", CEILING)
    mb.material("pit_rock", PIT_ROCK)
    mb.material("bronze", BRONZE)
    mb.material("lava", LAVA_ALBEDO, emissive=LAVA_RADIANCE)

    pit = ((-PX, 0.0, -PZ), (PX, 0.0, PZ))
    bridge = ((-BRIDGE_W / 2, 0.0, -PZ), (BRIDGE_W / 2, 0.0, PZ))
    pillars = [
        ((x - PILLAR / 2, 0.0, z - PILLAR / 2), (x + PILLAR / 2, H, z + PILLAR / 2)) for x, z in PILLARS
    ]
    # hall: floor with the pit cut out (pillar footprints too: hidden), ceiling, walls
    mb.face("floor", "stone_floor", (-HX, 0.0, -HZ), (HX, 0.0, HZ), +1, holes=[pit, *pillars], panel=1.6)
    mb.face("bridge_top", "stone_floor", bridge[0], bridge[1], +1, panel=1.6)
    mb.face("ceiling", "ceiling", (-HX, H, -HZ), (HX, H, HZ), -1, holes=pillars, panel=1.6)
    mb.box("walls", "stone", (-HX, 0.0, -HZ), (HX, H, HZ), skip=("-y", "+y"), inward=True, panel=1.6)

    # pit: inward walls down to the lava (the bridge's ends cut out), lava panels
    ends = [
        ((-BRIDGE_W / 2, -BRIDGE_T, -PZ), (BRIDGE_W / 2, 0.0, -PZ)),
        ((-BRIDGE_W / 2, -BRIDGE_T, PZ), (BRIDGE_W / 2, 0.0, PZ)),
    ]
    mb.box(
        "pit_walls",
        "pit_rock",
        (-PX, -PIT_DEPTH, -PZ),
        (PX, 0.0, PZ),
        skip=("-y", "+y"),
        inward=True,
        holes={"-z": ends[:1], "+z": ends[1:]},
        panel=1.6,
    )
    mb.face("lava", "lava", (-PX, -PIT_DEPTH, -PZ), (PX, -PIT_DEPTH, PZ), +1, panel=1.6)
    # bridge slab: sides and underside (its top is part of the floor)
    mb.box(
        "bridge",
        "stone",
        (-BRIDGE_W / 2, -BRIDGE_T, -PZ),
        (BRIDGE_W / 2, 0.0, PZ),
        skip=("+y", "-z", "+z"),
        panel=1.6,
    )

    # pillars (floor to ceiling), pilasters along the walls
    for lo, hi in pillars:
        mb.box("pillars", "stone", lo, hi, skip=("-y", "+y"), panel=1.6)
    for x in (-6.0, -2.0, 2.0, 6.0):
        mb.box(
            "pilasters",
            "stone",
            (x - 0.35, 0.0, -HZ),
            (x + 0.35, H, -HZ + 0.3),
            skip=("-y", "+y", "-z"),
            panel=1.6,
        )
        mb.box(
            "pilasters",
            "stone",
            (x - 0.35, 0.0, HZ - 0.3),
            (x + 0.35, H, HZ),
            skip=("-y", "+y", "+z"),
            panel=1.6,
        )
    for z in (-4.0, 0.0, 4.0):
        mb.box(
            "pilasters",
            "stone",
            (-HX, 0.0, z - 0.35),
            (-HX + 0.3, H, z + 0.35),
            skip=("-y", "+y", "-x"),
            panel=1.6,
        )
        mb.box(
            "pilasters",
            "stone",
            (HX - 0.3, 0.0, z - 0.35),
            (HX, H, z + 0.35),
            skip=("-y", "+y", "+x"),
            panel=1.6,
        )

    # braziers: a pedestal and a bowl
    for x, z in BRAZIERS:
        mb.box("braziers", "stone", (x - 0.3, 0.0, z - 0.3), (x + 0.3, 0.9, z + 0.3), skip=("-y", "+y"))
        mb.box("brazier_bowls", "bronze", (x - 0.45, 0.9, z - 0.45), (x + 0.45, 1.05, z + 0.45), skip=())


def lights(mb: ModelBuilder) -> None:
    for k, (x, z) in enumerate(BRAZIERS):
        mb.glb.add_point_light(f"brazier_{k}", FIRE_COLOR, 14.0, (x, 1.45, z))


def camera_path() -> list[dict]:
    """36 poses once around the pit on a rounded rectangle between the pillars and the walls,
    looking ahead and a little towards the pit."""
    ax, az, rc = 7.6, 6.3, 1.5  # half extents of the walk and its corner radius
    eyes = loop_waypoints(ax, az, rc, EYE)
    return walk_path(
        eyes, 36, yfov=YFOV, look_ahead=4.0, look_down=0.6, lean_towards=(0.0, EYE, 0.0), lean=0.3
    )


def cameras() -> list[Camera]:
    return [
        Camera(
            eye=(-8.8, 2.2, -7.0), target=(0.0, -0.3, 0.0), yfov=YFOV, znear=0.05, zfar=100.0, name="corner"
        ),
        Camera(
            eye=(0.0, EYE, -7.5), target=(0.0, 0.5, 4.0), yfov=YFOV, znear=0.05, zfar=100.0, name="bridge"
        ),
        Camera(
            eye=(8.8, 4.5, -3.0), target=(-3.0, 0.0, 1.0), yfov=YFOV, znear=0.05, zfar=100.0, name="gallery"
        ),
    ]


def build(path: str | Path = DEFAULT_PATH) -> Path:
    """Write the lava pit GLB to ``path`` (atomically); returns the path."""
    return assemble(build_geometry, lights, cameras(), camera_path(), panel=1.6).glb.write(path)


if __name__ == "__main__":
    sys.exit(
        script_main(
            build, DEFAULT_PATH, "Write the lava pit sample scene (after the report's lavapit) as a GLB."
        )
    )
