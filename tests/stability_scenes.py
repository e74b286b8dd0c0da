"""Small scenes and inputs that provoke the failure modes of ``docs/stability.md``.

Every builder is deterministic and cheap (a few patches, or a synthetic
solution made without solving), so that ``tests/test_stability_*.py`` run in a
few minutes on two cores. Geometry is in metres, +Y up; faces are single-sided,
their front (counter-clockwise corners) towards the space they light.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from iat.geometry import quadtree as qt
from iat.io.scene import Light, Material, Scene
from iat.radiosity.solution import Solution

GREY = Material("grey", albedo=np.full(3, 0.5))


# -- in-memory scenes ------------------------------------------------------------------------------
def make_scene(polys, material_ids, materials, lights=()) -> Scene:
    """Scene from a list of (3 or 4, 3) polygons (each its own vertices, not shared)."""
    verts, corners = [], []
    for q in polys:
        q = np.asarray(q, dtype=np.float64)
        idx = list(range(len(verts), len(verts) + len(q)))
        verts.extend(q)
        corners.append(idx + [-1] * (4 - len(q)))
    return Scene(
        np.array(verts, dtype=np.float64).reshape(-1, 3),
        np.array(corners, dtype=np.int64).reshape(-1, 4),
        np.array(material_ids, dtype=np.int64),
        list(materials),
        lights=list(lights),
    )


def quad_y(x0, x1, z0, z1, y=0.0, up=True) -> np.ndarray:
    """Horizontal quad at height y over [x0, x1] x [z0, z1], facing +Y (up) or -Y."""
    q = np.array([[x0, y, z0], [x0, y, z1], [x1, y, z1], [x1, y, z0]], dtype=np.float64)
    return q if up else q[::-1].copy()


def quad_x(x, y0, y1, z0, z1, towards_plus=True) -> np.ndarray:
    """Vertical quad in the plane x = const over [y0, y1] x [z0, z1], facing +X or -X."""
    q = np.array([[x, y0, z0], [x, y1, z0], [x, y1, z1], [x, y0, z1]], dtype=np.float64)
    n = np.cross(q[2] - q[0], q[3] - q[1])
    if (n[0] > 0) != towards_plus:
        q = q[::-1].copy()
    return q


def box_faces(lo, hi, inward=True, skip=()) -> list[np.ndarray]:
    """The six faces of an axis-aligned box as quads facing in (or out); ``skip``: names to leave out
    ("-x", "+x", "-y", "+y", "-z", "+z")."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre = (lo + hi) / 2
    out = []
    for axis in range(3):
        a, b = [x for x in range(3) if x != axis]
        for sign, side in (("-", lo[axis]), ("+", hi[axis])):
            if f"{sign}{'xyz'[axis]}" in skip:
                continue
            q = np.zeros((4, 3))
            q[:, axis] = side
            q[:, a] = [lo[a], hi[a], hi[a], lo[a]]
            q[:, b] = [lo[b], lo[b], hi[b], hi[b]]
            n = np.cross(q[2] - q[0], q[3] - q[1])
            if (n @ (centre - q.mean(axis=0)) > 0) != inward:
                q = q[::-1].copy()
            out.append(q)
    return out


def point_light(x, y, z, intensity=1.0) -> Light:
    return Light(kind="point", position=np.array([x, y, z], float), intensity=float(intensity))


def floor_under_light(height=1.0, half=1.0, albedo=0.5) -> Scene:
    """One 2 x 2 m floor quad under a point light of intensity height**2 (1 W/sr-ish at the foot)."""
    return make_scene(
        [quad_y(-half, half, -half, half)],
        [0],
        [Material("floor", albedo=np.full(3, albedo))],
        [point_light(0.0, height, 0.0, height**2)],
    )


def room_with_light(light_pos, albedo=0.5, size=1.0) -> Scene:
    """A closed cube room (6 inward quads) with a unit point light at ``light_pos``."""
    faces = box_faces([0, 0, 0], [size] * 3, inward=True)
    return make_scene(
        faces, [0] * 6, [Material("wall", albedo=np.full(3, albedo))], [point_light(*light_pos)]
    )


def wall_through_floor(wall_x=0.1, depth_below=0.3) -> Scene:
    """A 2 x 2 m floor (one patch, x and z in [-1, 1]) crossed by a wall at x = ``wall_x`` that goes
    through it down to y = -depth_below (intersecting geometry), a point light on the x < wall_x side.
    The floor beyond the wall must stay dark. The default ``wall_x`` = 0.1 is on no lattice line
    (x = -1 + 2 k / 2**D), so the wall always cuts through floor elements."""
    floor = quad_y(-1, 1, -1, 1)
    wall = quad_x(wall_x, -depth_below, 1.0, -1.0, 1.0, towards_plus=False)  # lit face towards -x
    return make_scene(
        [floor, wall],
        [0, 0],
        [Material("white", albedo=np.full(3, 0.5))],
        [point_light(wall_x - 0.5, 0.5, 0.0, 0.25)],
    )


def small_object_in_large_scene(big=100.0, cube=0.01) -> Scene:
    """A 1 cm cube standing on a 10 x 10 cm floor tile (patch 0), a point light 5 cm above the
    cube's top and 3 cm to its side, and -- when ``big`` > 0 -- a ``big`` x ``big`` m ground 1 m
    below (patch 1), which makes the scene 10**4 times larger than the cube. The cube's shadow on
    the tile is about 1.5 cm long; patch 0's lattice is what the tests sample."""
    polys = [quad_y(-0.05, 0.05, -0.05, 0.05)]
    if big > 0:
        polys.append(quad_y(-big / 2, big / 2, -big / 2, big / 2, y=-1.0))
    polys += box_faces([0, 0, 0], [cube, cube, cube], inward=False, skip=("-y",))
    mats = [0] * len(polys)
    light = point_light(-0.03, cube + 0.05, cube / 2, 0.01)
    return make_scene(polys, mats, [Material("white", albedo=np.full(3, 0.5))], [light])


def coplanar_overlap(albedo_a=0.8, albedo_b=0.2) -> Scene:
    """Two overlapping coplanar floor quads (z-fighting) of different albedo under a point light."""
    a = quad_y(-1.0, 0.5, -1.0, 1.0)
    b = quad_y(-0.5, 1.0, -1.0, 1.0)
    return make_scene(
        [a, b],
        [0, 1],
        [Material("a", albedo=np.full(3, albedo_a)), Material("b", albedo=np.full(3, albedo_b))],
        [point_light(0.0, 1.0, 0.0, 1.0)],
    )


def t_junction_scene() -> Scene:
    """A 1 x 1 quad next to two 1 x 0.5 quads: the middle vertex of the pair lies on the big quad's
    edge (a T-junction between root patches), under a point light off-centre."""
    big = quad_y(0.0, 1.0, 0.0, 1.0)
    s1 = quad_y(1.0, 2.0, 0.0, 0.5)
    s2 = quad_y(1.0, 2.0, 0.5, 1.0)
    return make_scene([big, s1, s2], [0, 0, 0], [GREY], [point_light(1.0, 0.6, 0.5, 0.36)])


def emitter_facing_away() -> Scene:
    """A floor and, above it, an emissive quad whose front faces up, away from everything."""
    floor = quad_y(-1, 1, -1, 1)
    lamp = quad_y(-0.2, 0.2, -0.2, 0.2, y=1.0, up=True)
    return make_scene(
        [floor, lamp],
        [0, 1],
        [GREY, Material("lamp", albedo=np.full(3, 0.5), emission=np.full(3, 10.0))],
    )


def bright_and_dim(bright=5.0e4, dim_intensity=1.0e-3) -> Scene:
    """Radiance over 8+ decades in one scene: a ``bright`` emitter facing up (it lights nothing, it
    is only seen), a floor under a 10 W/sr point light, and a floor 10 m away under a
    ``dim_intensity`` one (radiance ~1.6e-4)."""
    a = quad_y(-1, 1, -1, 1)
    b = quad_y(9, 11, -1, 1)
    lamp = quad_y(-0.1, 0.1, -0.1, 0.1, y=3.0, up=True)
    return make_scene(
        [a, b, lamp],
        [0, 0, 1],
        [GREY, Material("lamp", albedo=np.full(3, 0.5), emission=np.full(3, bright))],
        [point_light(0.0, 1.0, 0.0, 10.0), point_light(10.0, 1.0, 0.0, dim_intensity)],
    )


# -- synthetic solutions (no solve) -------------------------------------------------------------------
def grid_corners(nx, ny, size=1.0, z=0.0) -> np.ndarray:
    """(nx*ny, 4, 3) unit quads tiling the plane z = const, facing +Z, row by row."""
    out = np.zeros((nx * ny, 4, 3))
    k = 0
    for gy in range(ny):
        for gx in range(nx):
            x0, y0 = gx * size, gy * size
            out[k] = [[x0, y0, z], [x0 + size, y0, z], [x0 + size, y0 + size, z], [x0, y0 + size, z]]
            k += 1
    return out


def synthetic_solution(corners, radiance_of, max_depth=3, depth_of=None, albedo=0.5) -> Solution:
    """A solution over quad patches ``corners`` (P, 4, 3) refined along one corner to ``depth_of[p]``
    (default max_depth; a chain of splits, 2:1 balanced), radiance = ``radiance_of(patch, world)``."""
    corners = np.asarray(corners, dtype=np.float64)
    p = len(corners)
    depth = np.full(p, max_depth) if depth_of is None else np.asarray(depth_of)
    forest = qt.roots(np.ones(p, dtype=bool), max_depth)
    for level in range(max_depth):
        # split the leaf at the lattice origin of every patch that must go deeper than `level`
        m = (forest.leaf_level == level) & (forest.leaf_i == 0) & (forest.leaf_j == 0)
        m &= depth[forest.leaf_patch] > level
        if not m.any():
            break
        forest = qt.split(forest, m)
    forest = qt.balance(forest)
    keys = qt.vertex_keys(forest)
    pos = qt.keys_to_world(corners, forest.patch_is_quad, keys, forest.n)
    patch = qt.decode_key(keys, forest.n)[0]
    rad = np.asarray(radiance_of(patch, pos), dtype=np.float32).reshape(-1, 3)
    alb = np.full((p, 3), albedo)
    return Solution.from_forest(forest, corners, np.zeros(p, dtype=np.int64), alb, keys, rad)


def uniform_depth_solution(corners, depth, radiance_of) -> Solution:
    """Every patch split uniformly to ``depth`` (4**depth leaves per patch)."""
    corners = np.asarray(corners, dtype=np.float64)
    p = len(corners)
    forest = qt.roots(np.ones(p, dtype=bool), depth)
    for _ in range(depth):
        forest = qt.split(forest, np.ones(forest.n_leaves, dtype=bool))
    keys = qt.vertex_keys(forest)
    pos = qt.keys_to_world(corners, forest.patch_is_quad, keys, forest.n)
    patch = qt.decode_key(keys, forest.n)[0]
    rad = np.asarray(radiance_of(patch, pos), dtype=np.float32).reshape(-1, 3)
    return Solution.from_forest(forest, corners, np.zeros(p, dtype=np.int64), np.full((p, 3), 0.5), keys, rad)


# -- files ---------------------------------------------------------------------------------------
def write_obj(path: Path, vertices, faces, extra: str = "") -> Path:
    """A plain OBJ (1-based faces) with optional extra text (materials, comments) at the top."""
    lines = [extra] if extra else []
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, dtype=float).tolist()]
    lines += ["f " + " ".join(str(int(i) + 1) for i in f) for f in faces]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def grid_mesh(n: int, size: float = 1.0, jitter: float = 0.0, seed: int = 0):
    """An n x n grid of quads split into 2 n**2 triangles in z = 0 (optionally bumped in z so that
    no pair merges: ``jitter`` > 0). Returns (vertices (m, 3) float64, faces (2 n**2, 3) int64)."""
    x = np.linspace(0.0, size, n + 1)
    X, Y = np.meshgrid(x, x, indexing="xy")
    Z = np.zeros_like(X)
    if jitter:
        Z = np.random.default_rng(seed).random(X.shape) * jitter
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    a = (j * (n + 1) + i).ravel()
    b, c, d = a + 1, a + n + 2, a + n + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([c, d, a], 1)])
    return V, F


def write_binary_stl(path: Path, vertices, faces) -> Path:
    """A binary STL (the cheapest format to write and read for a million triangles)."""
    V = np.asarray(vertices, dtype=np.float32)
    F = np.asarray(faces, dtype=np.int64)
    rec = np.zeros(len(F), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = V[F]
    with open(path, "wb") as f:
        f.write(b"IAT stability test".ljust(80, b" "))
        f.write(np.uint32(len(F)).tobytes())
        f.write(rec.tobytes())
    return Path(path)
