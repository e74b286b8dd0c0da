"""An irregular rock cave as a GLB (after the report's *cave*): ``python sample_models/cave.py [-o PATH]``.

A winding tunnel about 30 m long, closed at both ends, that widens into two
chambers. Its wall is a displaced tube: rings of :data:`RING` vertices around a
curved centre line, every ring point pushed in or out by deterministic fractal
value noise (:func:`common.fbm3`, no random generator) and the bottom squashed
into a bumpy floor. Each cell of the tube is split into two triangles along its
shorter diagonal, so the surface is made of (non-coplanar) TRIANGLE roots with
normals pointing into the cave. The ends are domed caps (triangle fans), and a
handful of stalagmites and stalactites (five-sided cones, also triangles) stand
in the chambers and cast shadows.

Light: four warm point lights ("torches") near the walls. Three cameras and a
30-pose walk from one end to the other along the floor (root
``extras["iat_camera_paths"]["default"]``). +Y is up, metres.

Output is deterministic: the same script gives the same bytes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
if __package__ in (None, ""):  # run as a script: make `sample_models` and `iat` importable
    sys.path.insert(0, str(_HERE.parent))

from sample_models.common import Camera, ModelBuilder, assemble, fbm3, script_main, walk_path  # noqa: E402

DEFAULT_PATH = _HERE / "cave.glb"

LENGTH = 30.0  # centre-line length (metres, along x before bending)
SEGMENTS = 34  # rings - 1 along the tunnel
RING = 26  # vertices per ring
FLOOR_DEPTH = 1.2  # floor level below the centre line (metres)
EYE = 1.6
YFOV = 65.0
SEED = 7

ROCK = (0.42, 0.37, 0.31)
ROCK_DARK = (0.30, 0.27, 0.24)
TORCH_COLOR = (1.0, 0.62, 0.30)


def centre(s: np.ndarray) -> np.ndarray:
    """``(n, 3)`` centre-line points at arc parameters ``s`` in [0, LENGTH] (a gentle S in plan)."""
    s = np.asarray(s, dtype=np.float64)
    x = s
    z = 3.2 * np.sin(s / LENGTH * 1.6 * math.pi)
    y = 2.0 + 0.35 * np.sin(s / LENGTH * 2.3 * math.pi + 0.4)
    return np.column_stack([x, y, z])


def side(s: np.ndarray) -> np.ndarray:
    """``(n, 3)`` horizontal unit vectors to the left of the centre line (perpendicular, y = 0)."""
    eps = 1e-3
    t = centre(np.asarray(s) + eps) - centre(np.asarray(s) - eps)
    n = np.column_stack([t[:, 2], np.zeros(len(t)), -t[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def radius(s: np.ndarray) -> np.ndarray:
    """Horizontal base radius along the tunnel: two chambers around s = 9 and s = 21."""
    s = np.asarray(s, dtype=np.float64)
    return 2.0 + 1.8 * np.exp(-(((s - 9.0) / 3.2) ** 2)) + 2.3 * np.exp(-(((s - 21.0) / 3.6) ** 2))


def floor_height(s: np.ndarray) -> np.ndarray:
    """Mean floor level (y) along the tunnel (before the bumps)."""
    return centre(s)[:, 1] - FLOOR_DEPTH


def tube_vertices() -> np.ndarray:
    """``(SEGMENTS + 1, RING, 3)`` displaced ring vertices (theta runs from the left side upwards)."""
    s = np.linspace(0.0, LENGTH, SEGMENTS + 1)
    c, n, r = centre(s), side(s), radius(s)
    up = np.array([0.0, 1.0, 0.0])
    theta = np.linspace(0.0, 2 * math.pi, RING, endpoint=False) + math.pi / RING
    rv = 1.9 + 0.4 * (r - 2.0)  # vertical radius: higher vaults in the chambers
    pts = (
        c[:, None]
        + np.cos(theta)[None, :, None] * r[:, None, None] * n[:, None]
        + np.sin(theta)[None, :, None] * rv[:, None, None] * up
    )
    # noise: displace along the direction away from the centre line (smooth in space, so the
    # displacement is periodic around each ring and continuous between rings)
    noise = fbm3(pts.reshape(-1, 3) * 0.4, octaves=4, seed=SEED).reshape(pts.shape[:2])
    out = pts - c[:, None]
    out /= np.linalg.norm(out, axis=2, keepdims=True)
    pts = pts + out * (0.75 * noise)[..., None]
    # floor: everything below the floor level is squashed (monotonically) onto a bumpy floor
    fl = floor_height(s)[:, None]
    bump = 0.10 * fbm3(pts.reshape(-1, 3) * 1.3, octaves=2, seed=SEED + 1).reshape(pts.shape[:2])
    knee = 0.25
    low = pts[..., 1] < fl + knee
    squash = fl + knee * np.tanh((pts[..., 1] - fl) / knee)
    pts[..., 1] = np.where(low, squash + bump, pts[..., 1])
    return pts


def _wound(tris: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """``tris`` ``(m, 3, 3)`` of one consistently wound surface, all flipped if most of them
    face away from their ``inside`` points ``(m, 3)`` (the vote ignores the ambiguous ones)."""
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    v = inside - tris.mean(axis=1)
    cos = np.einsum("ij,ij->i", n, v) / (np.linalg.norm(n, axis=1) * np.linalg.norm(v, axis=1))
    return tris if np.sum(cos > 0.3) >= np.sum(cos < -0.3) else tris[:, [0, 2, 1]]


def build_geometry(mb: ModelBuilder) -> None:
    mb.material("rock", ROCK)
    mb.material("rock_dark", ROCK_DARK)
    s = np.linspace(0.0, LENGTH, SEGMENTS + 1)
    c = centre(s)
    p = tube_vertices()
    # tube: each cell (a b / d e) split along its shorter diagonal, wound the same way everywhere
    tris, inside = [], []
    for i in range(SEGMENTS):
        for j in range(RING):
            a, b = p[i, j], p[i, (j + 1) % RING]
            d, e = p[i + 1, j], p[i + 1, (j + 1) % RING]
            if np.linalg.norm(a - e) <= np.linalg.norm(b - d):
                tris += [(a, b, e), (a, e, d)]
            else:
                tris += [(a, b, d), (b, e, d)]
            inside += [0.5 * (c[i] + c[i + 1])] * 2
    for t in _wound(np.array(tris), np.array(inside)):
        mb.tri("cave_wall", "rock", t)
    # domed end caps: a fan from the ring over an intermediate ring to an apex pushed outward
    for i, direction in ((0, -1.0), (SEGMENTS, 1.0)):
        tangent = centre(np.array([s[i] + 0.01])) - centre(np.array([s[i] - 0.01]))
        tangent = tangent[0] / np.linalg.norm(tangent)
        ring_c = p[i].mean(axis=0)
        apex = ring_c + tangent * direction * 1.2
        mid = 0.5 * (p[i] + apex) + tangent * direction * 0.35
        cap = []
        for j in range(RING):
            k = (j + 1) % RING
            cap += [(p[i, j], p[i, k], mid[k]), (p[i, j], mid[k], mid[j]), (mid[j], mid[k], apex)]
        cap = np.array(cap)
        for t in _wound(cap, np.repeat((ring_c - tangent * direction * 3.0)[None], len(cap), axis=0)):
            mb.tri("cave_ends", "rock", t)
    # stalagmites (up) and stalactites (down): five-sided cones, faces looking out
    for name, sv, off, height, rad, grows_up in FORMATIONS:
        base_c = centre(np.array([sv]))[0] + side(np.array([sv]))[0] * off
        if grows_up:
            base_y = floor_height(np.array([sv]))[0] - 0.45
            tip_y = base_y + height + 0.45
        else:
            base_y = _ceiling_at(p, sv, off) + 0.4
            tip_y = base_y - height - 0.4
        ang = np.linspace(0.0, 2 * math.pi, 5, endpoint=False) + sv
        base = np.column_stack(
            [base_c[0] + rad * np.cos(ang), np.full(5, base_y), base_c[2] + rad * np.sin(ang)]
        )
        tip = np.array([base_c[0] + 0.1 * rad, tip_y, base_c[2] - 0.1 * rad])
        axis_pt = np.array([base_c[0], 0.5 * (base_y + tip_y), base_c[2]])
        for j in range(5):
            t = np.array([base[j], base[(j + 1) % 5], tip])
            n = np.cross(t[1] - t[0], t[2] - t[0])
            if float(n @ (t.mean(axis=0) - axis_pt)) < 0:  # outward: away from the cone's axis
                t = t[[0, 2, 1]]
            mb.tri(name, "rock_dark", t)


def _ceiling_at(p: np.ndarray, sv: float, off: float) -> float:
    """Approximate ceiling height at arc parameter ``sv``, ``off`` metres left of the centre line."""
    i = int(round(sv / LENGTH * SEGMENTS))
    ring = p[i]
    top = ring[ring[:, 1] > centre(np.array([sv]))[0, 1]]
    target = centre(np.array([sv]))[0] + side(np.array([sv]))[0] * off
    k = np.argmin(np.hypot(top[:, 0] - target[0], top[:, 2] - target[2]))
    return float(top[k, 1])


#: (object name, s, offset to the left of the centre line, height, base radius, grows up)
FORMATIONS = [
    ("stalagmites", 4.6, -1.5, 1.2, 0.35, True),
    ("stalagmites", 7.5, 2.1, 1.6, 0.45, True),
    ("stalagmites", 10.5, -2.3, 1.1, 0.35, True),
    ("stalagmites", 12.3, 2.2, 1.3, 0.40, True),
    ("stalagmites", 17.2, -1.5, 1.0, 0.35, True),
    ("stalagmites", 19.0, 2.6, 2.0, 0.55, True),
    ("stalagmites", 22.5, -2.8, 1.4, 0.40, True),
    ("stalagmites", 23.5, 2.4, 0.9, 0.30, True),
    ("stalagmites", 27.8, -1.3, 1.0, 0.30, True),
    ("stalactites", 4.0, 0.6, 0.7, 0.25, False),
    ("stalactites", 9.0, 1.0, 0.9, 0.30, False),
    ("stalactites", 13.5, -0.9, 0.8, 0.30, False),
    ("stalactites", 20.5, -1.2, 1.1, 0.35, False),
    ("stalactites", 21.8, 1.4, 0.8, 0.28, False),
    ("stalactites", 26.0, -0.6, 0.7, 0.25, False),
]

#: torches: (s, offset left of the centre line, height above the floor, intensity)
TORCHES = [(3.0, -1.0, 1.3, 6.0), (11.0, 1.5, 1.4, 9.0), (18.5, -2.0, 1.5, 10.0), (26.5, 0.8, 1.3, 6.0)]


def lights(mb: ModelBuilder) -> None:
    for k, (sv, off, h, intensity) in enumerate(TORCHES):
        pos = centre(np.array([sv]))[0] + side(np.array([sv]))[0] * off
        pos[1] = floor_height(np.array([sv]))[0] + h
        mb.glb.add_point_light(f"torch_{k}", TORCH_COLOR, intensity, np.round(pos, 4))


def _walk_points() -> np.ndarray:
    s = np.linspace(1.2, LENGTH - 1.5, 9)
    pts = centre(s)
    pts[:, 1] = floor_height(s) + EYE
    return pts


def camera_path() -> list[dict]:
    """30 poses from the west end to the east end along the centre of the floor."""
    return walk_path(_walk_points(), 30, yfov=YFOV, look_ahead=2.0, look_down=0.35)


def _eye(sv: float, off: float = 0.0, h: float = EYE) -> np.ndarray:
    p = centre(np.array([sv]))[0] + side(np.array([sv]))[0] * off
    p[1] = floor_height(np.array([sv]))[0] + h
    return np.round(p, 4)


def cameras() -> list[Camera]:
    return [
        Camera(eye=_eye(1.5), target=_eye(9.0, 0.0, 0.8), yfov=YFOV, znear=0.05, zfar=80.0, name="entrance"),
        Camera(
            eye=_eye(14.0, 0.5), target=_eye(21.0, 0.0, 1.0), yfov=YFOV, znear=0.05, zfar=80.0, name="chamber"
        ),
        Camera(
            eye=_eye(28.0, 0.0, 1.8),
            target=_eye(20.0, 0.0, 0.8),
            yfov=YFOV,
            znear=0.05,
            zfar=80.0,
            name="back",
        ),
    ]


def build(path: str | Path = DEFAULT_PATH) -> Path:
    """Write the cave GLB to ``path`` (atomically); returns the path."""
    return assemble(build_geometry, lights, cameras(), camera_path()).glb.write(path)


if __name__ == "__main__":
    sys.exit(
        script_main(build, DEFAULT_PATH, "Write the cave sample scene (after the report's cave) as a GLB.")
    )
