"""An indoor swimming pool hall as a GLB (after the report's *pool*):
``python sample_models/pool.py [-o PATH]``.

A hall 25 m x 16 m, 6 m high (x in [-12.5, 12.5], z in [-8, 8], floor at
y = 0) with a drained 12.5 m x 6 m pool basin, 1.6 m deep, sunk in the middle,
a flight of four steps into it at the west end and three starting blocks at the
east end. Two rows of five tiled columns run along the long sides, benches
stand by the south wall, and four tall daylight windows (emissive quads) open
the north wall, so the columns throw shadows across the floor.

Surfaces carry repeating DETAIL textures (procedural PNGs, report section 3.7):
floor tiles, white wall tiles (walls up to 2.2 m and the columns) and small
blue pool tiles (basin and steps), each a ``baseColorTexture`` with
``TEXCOORD_0`` in metres divided by the texture's period, so the UVs run far
beyond [0, 1] and the sampler repeats. Plaster above the tiles and the ceiling
are plain.

Light: six point lights under the ceiling over the pool sides, two spot lights
at the ends aimed into the basin, and the windows. Three cameras and a 36-pose
walk once around the pool (root ``extras["iat_camera_paths"]["default"]``).
Every surface is a planar quad (panels of at most 1.5 m) facing the viewer side.

Output is deterministic: the same script gives the same bytes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
if __package__ in (None, ""):  # run as a script: make `sample_models` and `iat` importable
    sys.path.insert(0, str(_HERE.parent))

from sample_models import common  # noqa: E402
from sample_models.common import Camera, ModelBuilder, assemble, loop_waypoints, script_main, walk_path  # noqa: E402

DEFAULT_PATH = _HERE / "pool.glb"

HX, HZ, H = 12.5, 8.0, 6.0  # hall half extents and height
PX, PZ, DEPTH = 6.25, 3.0, 1.6  # basin half extents and depth
TILE_H = 2.2  # height of the wall tiles
COLUMN = 0.6
COLUMNS = [(x, z) for z in (-5.2, 5.2) for x in (-10.0, -5.0, 0.0, 5.0, 10.0)]
WINDOWS = [(x - 1.25, x + 1.25) for x in (-7.5, -2.5, 2.5, 7.5)]  # x ranges on the north wall
WIN_Y = (2.6, 5.4)
STEP_W, STEP_D, STEP_H = 2.0, 0.35, 0.3  # step width (z), depth (x), rise
EYE = 1.7
YFOV = 60.0

TEX = 128  # texture size (pixels)
#: (tiles per texture side, period in metres) per detail texture
FLOOR_TILES, FLOOR_PERIOD = 4, 1.2
WALL_TILES, WALL_PERIOD = 4, 0.6
POOL_TILES, POOL_PERIOD = 8, 0.8

PLASTER = (0.70, 0.70, 0.68)
CEILING = (0.75, 0.76, 0.78)
BENCH = (0.40, 0.26, 0.14)
BLOCK = (0.70, 0.70, 0.72)
#: emitted radiance of the daylight windows, linear RGB
WINDOW_RADIANCE = (3.2, 3.8, 5.0)
LAMP_COLOR = (1.0, 0.93, 0.82)


def textures() -> dict[str, bytes]:
    """The three detail textures as PNG bytes (deterministic)."""
    return {
        "floor_tiles": common.png_bytes(
            common.tile_texture(
                TEX,
                FLOOR_TILES,
                (0.62, 0.55, 0.44),
                (0.30, 0.28, 0.25),
                grout_width=0.05,
                variation=0.07,
                seed=11,
            )
        ),
        "wall_tiles": common.png_bytes(
            common.tile_texture(
                TEX,
                WALL_TILES,
                (0.80, 0.81, 0.80),
                (0.45, 0.45, 0.45),
                grout_width=0.07,
                variation=0.03,
                seed=12,
            )
        ),
        "pool_tiles": common.png_bytes(
            common.tile_texture(
                TEX,
                POOL_TILES,
                (0.10, 0.38, 0.62),
                (0.55, 0.60, 0.62),
                grout_width=0.10,
                variation=0.10,
                seed=13,
            )
        ),
    }


def build_geometry(mb: ModelBuilder) -> None:
    tex = textures()
    mb.material("floor_tiles", (1.0, 1.0, 1.0), texture=tex["floor_tiles"], period=FLOOR_PERIOD)
    mb.material("wall_tiles", (1.0, 1.0, 1.0), texture=tex["wall_tiles"], period=WALL_PERIOD)
    mb.material("pool_tiles", (1.0, 1.0, 1.0), texture=tex["pool_tiles"], period=POOL_PERIOD)
    mb.material("plaster", PLASTER)
    mb.material("ceiling", CEILING)
    mb.material("bench", BENCH)
    mb.material("block", BLOCK)
    mb.material("window", (0.8, 0.8, 0.8), emissive=WINDOW_RADIANCE)

    basin = ((-PX, 0.0, -PZ), (PX, 0.0, PZ))
    columns = [
        ((x - COLUMN / 2, 0.0, z - COLUMN / 2), (x + COLUMN / 2, H, z + COLUMN / 2)) for x, z in COLUMNS
    ]
    mb.face("floor", "floor_tiles", (-HX, 0.0, -HZ), (HX, 0.0, HZ), +1, holes=[basin, *columns])
    mb.face("ceiling", "ceiling", (-HX, H, -HZ), (HX, H, HZ), -1, holes=columns)
    # walls: tiles below TILE_H, plaster above (windows cut out of the north wall)
    windows = [((x0, WIN_Y[0], HZ), (x1, WIN_Y[1], HZ)) for x0, x1 in WINDOWS]
    mb.box("wall_tiles", "wall_tiles", (-HX, 0.0, -HZ), (HX, TILE_H, HZ), skip=("-y", "+y"), inward=True)
    mb.box(
        "walls",
        "plaster",
        (-HX, TILE_H, -HZ),
        (HX, H, HZ),
        skip=("-y", "+y"),
        inward=True,
        holes={"+z": windows},
    )
    for lo, hi in windows:
        mb.face("windows", "window", lo, hi, -1, panel=3.0)

    # basin: inward walls and bottom (the steps' footprint and back cut out)
    steps_x = [-PX + STEP_D * k for k in range(5)]
    tops = [-STEP_H * (k + 1) for k in range(4)]
    mb.face(
        "basin",
        "pool_tiles",
        (-PX, -DEPTH, -PZ),
        (PX, -DEPTH, PZ),
        +1,
        holes=[((steps_x[0], 0.0, -STEP_W / 2), (steps_x[4], 0.0, STEP_W / 2))],
    )
    mb.box(
        "basin",
        "pool_tiles",
        (-PX, -DEPTH, -PZ),
        (PX, 0.0, PZ),
        skip=("-y", "+y"),
        inward=True,
        holes={"-x": [((-PX, -DEPTH, -STEP_W / 2), (-PX, tops[0], STEP_W / 2))]},
    )
    # steps: four blocks side by side, each riser cut where the next block hides it
    for k in range(4):
        lo = (steps_x[k], -DEPTH, -STEP_W / 2)
        hi = (steps_x[k + 1], tops[k], STEP_W / 2)
        holes = {}
        if k < 3:
            holes["+x"] = [((steps_x[k + 1], -DEPTH, -STEP_W / 2), (steps_x[k + 1], tops[k + 1], STEP_W / 2))]
        mb.box("steps", "pool_tiles", lo, hi, skip=("-y", "-x"), holes=holes)

    # columns (tiled), benches, starting blocks
    for lo, hi in columns:
        mb.box("columns", "wall_tiles", lo, hi, skip=("-y", "+y"))
    for x0 in (-9.0, -1.5, 6.0):
        mb.box("benches", "bench", (x0, 0.40, -HZ + 0.15), (x0 + 3.0, 0.45, -HZ + 0.6), skip=())
        for x in (x0 + 0.2, x0 + 2.7):
            mb.box("benches", "bench", (x, 0.0, -HZ + 0.2), (x + 0.1, 0.40, -HZ + 0.55), skip=("-y", "+y"))
    for z in (-2.0, 0.0, 2.0):
        mb.box("starting_blocks", "block", (PX + 0.15, 0.0, z - 0.3), (PX + 0.75, 0.7, z + 0.3))


def lights(mb: ModelBuilder) -> None:
    for i, x in enumerate((-8.0, 0.0, 8.0)):
        for j, z in enumerate((-4.0, 4.0)):
            mb.glb.add_point_light(f"lamp_{i}{j}", LAMP_COLOR, 45.0, (x, H - 0.6, z))
    for k, sx in enumerate((-1.0, 1.0)):
        pos = np.array([sx * (HX - 1.0), H - 1.0, 0.0])
        aim = np.array([sx * 2.0, -DEPTH, 0.0])
        mb.glb.add_spot_light(f"spot_{k}", (1.0, 1.0, 1.0), 120.0, pos, aim - pos, inner=0.25, outer=0.45)


def camera_path() -> list[dict]:
    """36 poses once around the pool, between the basin and the columns, looking ahead and at the water."""
    ax, az, rc = 8.5, 4.1, 1.2
    eyes = loop_waypoints(ax, az, rc, EYE)
    return walk_path(
        eyes, 36, yfov=YFOV, look_ahead=4.0, look_down=1.0, lean_towards=(0.0, EYE, 0.0), lean=0.3
    )


def cameras() -> list[Camera]:
    return [
        Camera(
            eye=(-12.0, 4.5, -2.5),
            target=(0.0, -1.0, 0.5),
            yfov=YFOV,
            znear=0.05,
            zfar=100.0,
            name="overview",
        ),
        Camera(
            eye=(9.0, EYE, -1.0),
            target=(-3.0, -1.0, 0.5),
            yfov=YFOV,
            znear=0.05,
            zfar=100.0,
            name="starting_blocks",
        ),
        Camera(
            eye=(2.5, EYE, -7.2), target=(-1.0, 2.5, 8.0), yfov=YFOV, znear=0.05, zfar=100.0, name="windows"
        ),
    ]


def build(path: str | Path = DEFAULT_PATH) -> Path:
    """Write the pool hall GLB to ``path`` (atomically); returns the path."""
    return assemble(build_geometry, lights, cameras(), camera_path(), panel=1.5).glb.write(path)


if __name__ == "__main__":
    sys.exit(
        script_main(
            build, DEFAULT_PATH, "Write the pool hall sample scene (after the report's pool) as a GLB."
        )
    )
