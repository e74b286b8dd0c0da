"""A large IFC house for ``benchmarks/ifc_house_bench.py``, written with ifcopenshell's API (0.9).

:func:`large_ifc_house` writes a multi-storey house: per storey a floor slab with a stair opening,
exterior walls with windows (a door on the ground floor), a grid of ``rooms_per_side`` x
``rooms_per_side`` rooms whose interior walls each have a door, one row of skewed (trapezoid)
rooms per storey whose dividing walls run at an angle, a skewed lowered ceiling per storey, and a
pitched roof (two sloped slabs and two gables) over the top storey. The geometry kernel
triangulates it into about 35 000 triangles at the defaults (the voids cut by
``feature.add_feature`` fan the wall faces). ``furnished`` puts a round table with four chairs, a
sofa, a floor lamp and a cabinet (IfcFurniture, about 600 triangles) in every room but the skewed
row's and the stair's, as furniture comes from real tools: closed solids, and open sheets (the sofa:
its seen faces only; the lamp's shade; the chairs, whose boxes meet along edges: non-manifold). Two
storeys of 5 x 5 rooms: about 28 000 triangles.
GlobalIds and the header time stamp are fixed, so the bytes are the same on every run.

Coordinates are metres, Z up (as IFC is): the rooms cover ``x`` in ``[0, R * ROOM]``, ``y`` in
``[-R * ROOM, 0]``; storey ``k`` has its floor at ``z = k * STOREY``. :func:`light_positions` gives
points inside rooms (Z up) for the benchmark's lights.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.support.ifc_builder import IfcBuilder, prism

#: room side, storey height, wall height (floor to the slab above), wall thicknesses (m)
ROOM = 4.0
STOREY = 3.0
WALL_H = 2.8
OUTER_T, INNER_T = 0.25, 0.12
SLAB_T = 0.2
#: windows per room on each facade: width, sill and head heights (m)
WINDOW_W, SILL, HEAD = 0.8, 0.9, 2.1
DOOR_W, DOOR_H = 0.9, 2.1
#: the skewed rooms' dividing walls lean by this much over a room's depth (m)
SKEW = 1.2
ROOF_RISE = 3.0


def _windows(length: float, per_room: int, rooms: int, door_at: int | None = None) -> list:
    """Openings along an exterior wall of ``rooms`` rooms: ``per_room`` windows centred in equal
    shares of each room, a door instead of the middle window of room ``door_at``."""
    ops = []
    share = ROOM / per_room
    for r in range(rooms):
        for w in range(per_room):
            c = r * ROOM + (w + 0.5) * share + (length - rooms * ROOM) / 2
            if r == door_at and w == per_room // 2:
                ops.append((c - DOOR_W / 2, c + DOOR_W / 2, 0.0, DOOR_H))
            else:
                ops.append((c - WINDOW_W / 2, c + WINDOW_W / 2, SILL, HEAD))
    return ops


def skew_row(rooms_per_side: int) -> int:
    """The row (along y) of skewed rooms: their x-walls lean by :data:`SKEW`."""
    return rooms_per_side // 2


def box(lo, hi) -> tuple[list, list]:
    """A closed box from corner ``lo`` to ``hi`` (x, y, z), wound outwards: a :func:`prism` along x."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    return prism([(y0, z0), (y1, z0), (y1, z1), (y0, z1)], x0, x1)


def _merge(parts) -> tuple[list, list]:
    verts: list = []
    faces: list = []
    for v, f in parts:
        faces += [tuple(i + len(verts) for i in fc) for fc in f]
        verts += list(v)
    return verts, faces


def cylinder(cx: float, cy: float, z0: float, z1: float, r: float, seg: int, caps: bool = True):
    """A vertical cylinder of ``seg`` sides about (cx, cy) from z0 to z1, wound outwards; without
    ``caps`` an open sheet (a lamp shade)."""
    a = 2 * np.pi * np.arange(seg) / seg
    ring = [(cx + r * np.cos(t), cy + r * np.sin(t)) for t in a]
    v = [(x, y, z0) for x, y in ring] + [(x, y, z1) for x, y in ring]
    f = [(i, (i + 1) % seg, seg + (i + 1) % seg, seg + i) for i in range(seg)]
    if caps:
        f += [tuple(range(seg - 1, -1, -1)), tuple(range(seg, 2 * seg))]
    return v, f


def furnish(b: IfcBuilder, k: int, x: float, y: float, z: float, style_wood, style_cloth) -> None:
    """A round table with four chairs, a sofa, a floor lamp and a cabinet in the room whose corner
    (smallest x, largest y) is (x, y), its floor at ``z``: about 600 triangles."""
    name = f"{k} {x:g} {y:g}"
    furniture = {"ifc_class": "IfcFurniture", "storey": k}
    tx, ty = x + 2.6, y - 2.4  # the table: a round top on a pedestal
    table = _merge([cylinder(tx, ty, z + 0.72, z + 0.76, 0.6, 32), cylinder(tx, ty, z, z + 0.72, 0.06, 16)])
    b.mesh(f"table {name}", *table, style_wood, **furniture)
    for c, (dx, dy) in enumerate(((-0.85, 0.0), (0.85, 0.0), (0.0, -0.85), (0.0, 0.85))):
        cx, cy = tx + dx - 0.2, ty + dy - 0.2  # a chair: four legs, a seat, a back away from the table
        legs = [
            box((cx + u, cy + w, z), (cx + u + 0.04, cy + w + 0.04, z + 0.45))
            for u in (0, 0.36)
            for w in (0, 0.36)
        ]
        bx, by = (cx + (0.36 if dx > 0 else 0.0), cy) if dx else (cx, cy + (0.36 if dy > 0 else 0.0))
        back = box((bx, by, z + 0.45), (bx + (0.04 if dx else 0.4), by + (0.4 if dx else 0.04), z + 0.9))
        seat = box((cx, cy, z + 0.45), (cx + 0.4, cy + 0.4, z + 0.49))
        b.mesh(f"chair {c} {name}", *_merge([*legs, seat, back]), style_wood, **furniture)
    sx, sy = x + 0.4, y - 0.45  # the sofa along the wall y = y: what is seen of it, open below and behind
    s1, s2, h, top = sx + 1.6, sy - 0.9, z + 0.42, z + 0.85
    v = [(sx, s2, z), (s1, s2, z), (s1, s2, h), (sx, s2, h), (s1, sy - 0.2, h), (sx, sy - 0.2, h)]
    v += [(s1, sy - 0.2, top), (sx, sy - 0.2, top), (s1, sy, top), (sx, sy, top)]
    f = [(0, 1, 2, 3), (3, 2, 4, 5), (5, 4, 6, 7), (7, 6, 8, 9)]  # front, seat, back rest, its top
    b.mesh(f"sofa {name}", v, f, style_cloth, **furniture)
    lamp = _merge(
        [
            cylinder(x + 0.25, y - 0.3, z, z + 1.5, 0.02, 12),
            cylinder(x + 0.25, y - 0.3, z + 1.5, z + 1.75, 0.2, 24, caps=False),
        ]
    )
    b.mesh(f"floor lamp {name}", *lamp, style_cloth, **furniture)  # its shade an open sheet
    cx, cy = x + ROOM - 0.7, y - ROOM + 0.9  # a cabinet in the far corner
    b.mesh(f"cabinet {name}", *box((cx, cy, z), (cx + 0.5, cy + 0.45, z + 1.8)), style_wood, **furniture)


def large_ifc_house(
    path, storeys: int = 5, rooms_per_side: int = 9, windows_per_room: int = 4, furnished: bool = False
) -> Path:
    """Write the house to ``path`` (a file name, or a directory: ``large_house.ifc`` in it); returns
    the file's path. ``storeys`` floors of ``rooms_per_side``\\ ² rooms of :data:`ROOM` metres."""
    path = Path(path)
    if path.is_dir():
        path = path / "large_house.ifc"
    n = int(rooms_per_side)
    side = n * ROOM
    b = IfcBuilder("iat large house")
    wall_s = b.style("wall", (0.78, 0.74, 0.66))
    inner_s = b.style("inner wall", (0.70, 0.76, 0.80))
    floor_s = b.style("floor", (0.50, 0.38, 0.26))
    roof_s = b.style("roof", (0.62, 0.22, 0.16))
    ceiling_s = b.style("ceiling", (0.85, 0.85, 0.82))
    wood_s, cloth_s = b.style("wood", (0.55, 0.40, 0.28)), b.style("cloth", (0.35, 0.42, 0.55))
    t = OUTER_T
    lo, hi = -t, side + t  # outer faces of the exterior walls (x; y runs -hi .. -lo)
    stair = (ROOM * 0.25, -ROOM * 0.25 - 2.5, 1.2, 2.5)  # x, y, width, depth of the stair hole (room 0)
    srow = skew_row(n)
    for k in range(storeys):
        z = k * STOREY
        # floor slab (the ground floor's below z = 0), a stair hole on the upper floors
        slab = b.slab(
            f"floor {k}",
            k,
            [(lo, t), (lo, -side - t), (hi, -side - t), (hi, t)],
            z - SLAB_T,
            SLAB_T,
            floor_s,
            predefined="FLOOR",
        )
        if k > 0:
            x, y, w, d = stair
            b.void(slab, f"stair hole {k}", (x, y, z - SLAB_T - 0.1), 0.0, w, SLAB_T + 0.2, d)
        # exterior walls
        door = n // 2 if k == 0 else None
        length = side + 2 * t
        ring = (
            ("south", (lo, 0.0), (hi, 0.0)),
            ("east", (side, t), (side, -side - t)),
            ("north", (hi, -side), (lo, -side)),
            ("west", (0.0, -side - t), (0.0, t)),
        )
        for name, a, e in ring:
            # the axis on the inner face, clockwise seen from above: the thickness lies outside
            b.wall(
                f"{name} wall {k}",
                k,
                a,
                e,
                z,
                WALL_H,
                t,
                wall_s,
                _windows(length, windows_per_room, n, door if name == "south" else None),
            )
        # interior walls along y (constant x) per room segment, a door in each; the skewed row leans
        for i in range(1, n):
            for j in range(n):
                y0, y1 = -j * ROOM, -(j + 1) * ROOM
                lean = SKEW if j == srow else 0.0
                x0, x1 = i * ROOM - lean / 2, i * ROOM + lean / 2
                seg = float(np.hypot(x1 - x0, ROOM))
                door_c = seg * (0.3 if (i + j) % 2 else 0.7)
                b.wall(
                    f"wall x{i} y{j} s{k}",
                    k,
                    (x0 - INNER_T / 2, y0),
                    (x1 - INNER_T / 2, y1),
                    z,
                    WALL_H,
                    INNER_T,
                    inner_s,
                    [(door_c - DOOR_W / 2, door_c + DOOR_W / 2, 0.0, DOOR_H)],
                )
        # interior walls along x (constant y), one per room segment, each with a door
        for j in range(1, n):
            for i in range(n):
                x0, x1 = i * ROOM, (i + 1) * ROOM
                door_c = ROOM * (0.35 if (i + j + k) % 2 else 0.65)
                y = -j * ROOM - INNER_T / 2
                b.wall(
                    f"wall y{j} x{i} s{k}",
                    k,
                    (x0, y),
                    (x1, y),
                    z,
                    WALL_H,
                    INNER_T,
                    inner_s,
                    [(door_c - DOOR_W / 2, door_c + DOOR_W / 2, 0.0, DOOR_H)],
                )
        if furnished:
            for i in range(n):
                for j in range(n):
                    if j != srow and not (k and i == j == 0):  # (leaning walls; the stair hole)
                        furnish(b, k, i * ROOM, -j * ROOM, z, wood_s, cloth_s)
        # a skewed lowered ceiling in a room of the skewed row
        cx = ROOM * (k % max(n - 1, 1))
        cy = -srow * ROOM
        outline = [
            (cx + 0.3, cy - 0.3),
            (cx + 0.3, cy - ROOM + 0.3),
            (cx + ROOM - 0.3, cy - ROOM * 0.55),
            (cx + ROOM - 0.6, cy - 0.4),
        ]
        b.slab(
            f"lowered ceiling {k}", k, outline, z + WALL_H - 0.35, 0.08, ceiling_s, predefined="USERDEFINED"
        )
    # the roof: gables over the west and east walls, two sloped slabs meeting at the ridge
    z_top = storeys * STOREY - SLAB_T
    ridge_y, ridge_z = -side / 2, z_top + ROOF_RISE
    gable = [(-side - t, z_top), (t, z_top), (ridge_y, ridge_z)]
    top = storeys - 1
    for name, x0 in (("west gable", lo), ("east gable", hi - t)):
        v, fc = prism(gable, x0, x0 + t)
        b.mesh(name, v, fc, wall_s, ifc_class="IfcWall", storey=top)
    roof = b.run("root.create_entity", b.f, ifc_class="IfcRoof", name="roof", predefined_type="GABLE_ROOF")
    b.run("spatial.assign_container", b.f, products=[roof], relating_structure=b.storey(top))
    slope = ROOF_RISE / (side / 2 + t)
    halves = []
    for side_name, y_eave in (("south", t + 0.4), ("north", -side - t - 0.4)):
        z_eave = z_top - slope * 0.4
        prof = [(y_eave, z_eave), (ridge_y, ridge_z), (ridge_y, ridge_z + 0.18), (y_eave, z_eave + 0.18)]
        v, fc = prism(prof, lo - 0.3, hi + 0.3)
        halves.append(b.mesh(f"roof {side_name}", v, fc, roof_s, predefined="ROOF"))
    b.run("aggregate.assign_object", b.f, products=halves, relating_object=roof)
    # a ceiling under the roof (the top storey's upper slab)
    b.slab(
        "attic floor",
        top,
        [(lo, t), (lo, -side - t), (hi, -side - t), (hi, t)],
        z_top,
        SLAB_T * 0.5,
        ceiling_s,
        predefined="FLOOR",
    )
    b.write(path, "iat-large-house")
    return path


def light_positions(storeys: int = 5, rooms_per_side: int = 9, per_storey: int = 1) -> list[tuple]:
    """Points (Z up) 2.2 m above the floor in the middle of rooms: ``per_storey`` per storey, in
    rooms along the diagonal (the skewed row's room on every storey)."""
    n = int(rooms_per_side)
    out = []
    for k in range(storeys):
        for m in range(per_storey):
            i = (k + m * max(n // per_storey, 1)) % n
            j = skew_row(n) if m == 0 else (i + k) % n
            out.append(((i + 0.5) * ROOM, -(j + 0.5) * ROOM, k * STOREY + 2.2))
    return out
