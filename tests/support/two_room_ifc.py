"""A generated two-room IFC (ifcopenshell.api, :class:`IfcBuilder`): an 8 x 4 m single-storey
building 3 m high, split by a wall at x = 4 into "Living" (west, a 2 x 1.2 m window in its south
wall) and "Study" (east, a 1 x 1.2 m window), each room an ``IfcSpace``; unglazed openings, light
walls, a grey floor. Coordinates in the file are Z up; the scene has them Y up, (x, y, z) -> (x, z, -y)."""

from __future__ import annotations

from pathlib import Path

from tests.support.ifc_builder import IfcBuilder

HEIGHT = 3.0
#: the rooms' footprints (x0, y0, x1, y1) in the file's plan, and their windows' x spans
ROOMS = {"Living": (0.0, 0.0, 3.9, 4.0), "Study": (4.0, 0.0, 8.0, 4.0)}
WINDOWS = {"Living": (1.0, 3.0), "Study": (5.5, 6.5)}
SILL, HEAD = 0.9, 2.1


def write_two_room_ifc(path: Path) -> Path:
    b = IfcBuilder("two rooms")
    wall = b.style("wall", (0.8, 0.8, 0.78))
    floor = b.style("floor", (0.45, 0.4, 0.35))
    ceiling = b.style("ceiling", (0.85, 0.85, 0.85))
    b.slab("floor", 0, [(-0.2, -0.2), (8.2, -0.2), (8.2, 4.2), (-0.2, 4.2)], -0.2, 0.2, floor)
    b.slab("roof", 0, [(-0.2, -0.2), (8.2, -0.2), (8.2, 4.2), (-0.2, 4.2)], HEIGHT, 0.2, ceiling)
    # the south wall runs from x = 8.2 to -0.2 (thickness to its left: y in [-0.2, 0]); u from its start
    south = [(8.2 - x1, 8.2 - x0, SILL, HEAD) for x0, x1 in WINDOWS.values()]
    b.wall("south", 0, (8.2, 0.0), (-0.2, 0.0), 0.0, HEIGHT, 0.2, wall, openings=south)
    b.wall("north", 0, (-0.2, 4.0), (8.2, 4.0), 0.0, HEIGHT, 0.2, wall)
    b.wall("west", 0, (0.0, -0.2), (0.0, 4.2), 0.0, HEIGHT, 0.2, wall)
    b.wall("east", 0, (8.0, 4.2), (8.0, -0.2), 0.0, HEIGHT, 0.2, wall)
    b.wall("partition", 0, (4.0, 0.0), (4.0, 4.0), 0.0, HEIGHT, 0.1, wall)
    for name, (x0, y0, x1, y1) in ROOMS.items():
        rep = b.run(
            "geometry.add_slab_representation",
            b.f,
            context=b.body,
            depth=HEIGHT,
            polyline=[(x0, y0), (x1, y0), (x1, y1), (x0, y1)],
        )
        space = b.product("IfcSpace", name.lower(), rep, (0.0, 0.0, 0.0))
        space.LongName = name
        b.run("aggregate.assign_object", b.f, products=[space], relating_object=b.storey(0))
    b.write(path, "two-rooms")
    return path
