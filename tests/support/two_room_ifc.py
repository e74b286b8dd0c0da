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


def living_room_twin():
    """The "Living" room of :func:`write_two_room_ifc` built in code as the loader should see it
    (scene coordinates, Y up: x in [0, 3.9], z in [-4, 0], floor at y = 0): floor, ceiling and walls
    facing in, the window x in [1, 3], y in [0.9, 2.1] in the wall z = 0 with its 0.2 m reveals, the
    materials' albedos (floor, ceiling, wall). Returns the scene and the room's box."""
    import numpy as np

    from iat.io.scene import Material, Scene
    from iat.io.spaces import Room

    w, h, d = 3.9, HEIGHT, 4.0
    centre = np.array([w / 2, h / 2, -d / 2])
    X, Y, Z = np.eye(3)
    polys, mats = [], []

    def add(quads, m):
        for q in quads:
            n = np.cross(q[1] - q[0], q[2] - q[0])
            polys.append(q if n @ (centre - q.mean(0)) > 0 else q[::-1])
            mats.append(m)

    def grid(p0, du, dv, nu, nv):
        return [
            np.array(
                [p0 + du * i / nu + dv * j / nv + o for o in (0 * du, du / nu, du / nu + dv / nv, dv / nv)]
            )
            for i in range(nu)
            for j in range(nv)
        ]

    o = np.zeros(3)
    add(grid(o - d * Z, w * X, d * Z, 4, 4), 0)  # floor
    add(grid(o - d * Z + h * Y, w * X, d * Z, 4, 4), 1)  # ceiling
    add(grid(o - d * Z, w * X, h * Y, 4, 3), 2)  # north wall
    add(grid(o - d * Z, d * Z, h * Y, 4, 3), 2)  # west wall
    add(grid(o - d * Z + w * X, d * Z, h * Y, 4, 3), 2)  # the partition
    (x0, x1), (y0, y1) = WINDOWS["Living"], (SILL, HEAD)
    for a, b, c, e in [(0, x0, 0, h), (x1, w, 0, h), (x0, x1, 0, y0), (x0, x1, y1, h)]:  # the wall z = 0
        add([np.array([[a, c, 0], [b, c, 0], [b, e, 0], [a, e, 0]], float)], 2)
    for q in (  # the reveals, 0.2 m out
        [[x0, y0, 0], [x1, y0, 0], [x1, y0, 0.2], [x0, y0, 0.2]],
        [[x0, y1, 0], [x1, y1, 0], [x1, y1, 0.2], [x0, y1, 0.2]],
        [[x0, y0, 0], [x0, y1, 0], [x0, y1, 0.2], [x0, y0, 0.2]],
        [[x1, y0, 0], [x1, y1, 0], [x1, y1, 0.2], [x1, y0, 0.2]],
    ):
        add([np.array(q, float)], 2)
    materials = [
        Material("floor", albedo=[0.45, 0.4, 0.35]),
        Material("ceiling", albedo=np.full(3, 0.85)),
        Material("wall", albedo=[0.8, 0.8, 0.78]),
    ]
    verts = np.concatenate(polys)
    corners = np.arange(len(verts)).reshape(-1, 4)
    return Scene(verts, corners, np.array(mats), materials), Room.box("Living", [0, 0, -d], [w, h, 0])
