"""The Cornell box as a GLB: ``python sample_models/cornell_box.py [-o PATH]``.

Geometry after the Cornell Program of Computer Graphics' measured data
(https://www.graphics.cornell.edu/online/box/data.html), converted to metres and
made exactly planar: the room is the box ``[0, 0.556] x [0, 0.5488] x [0, 0.5592]``
(x, y up, z towards the back wall), open at the front (z = 0). The red wall is at
x = 0.556 (on the left as seen from the camera), the green one at x = 0. The two
blocks keep the original footprints and heights (short: 0.165 m, tall: 0.33 m).

Every face is a planar quad written as the triangles ``[0, 1, 2], [2, 3, 0]``
with its corners counter-clockwise seen from the lit side, so its normal (and
the flat vertex normals stored) faces into the room; the blocks' faces look
outwards. 16 quads in all: 5 room faces, 5 + 5 block faces, 1 light.

The area light is a 0.13 m x 0.105 m quad 1 mm below the ceiling, facing down,
emitting :data:`LIGHT_RADIANCE` (a warm white in linear RGB, written as a
normalised ``emissiveFactor`` times ``KHR_materials_emissive_strength``). The
strength is chosen so the mean radiance of the room faces comes out near 0.6 in
luminance, about (0.81, 0.57, 0.24) in RGB (estimated with a 12 x 12 element
point-to-point radiosity). The camera is the original's (at z = -0.8 m, 39.3
degree vertical field of view), and the root
``extras["iat_camera_paths"]["default"]`` holds a short walkthrough of 8 poses.

Output is deterministic: the same script gives the same bytes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make `iat` importable from the checkout
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from iat.camera import Camera  # noqa: E402
from iat.io.glb import GlbBuilder

DEFAULT_PATH = Path(__file__).resolve().with_name("cornell_box.glb")

# room extents (metres)
W, H, D = 0.556, 0.5488, 0.5592

# linear RGB albedos
WHITE = (0.73, 0.73, 0.73)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.09)
LIGHT_ALBEDO = (0.78, 0.78, 0.78)

#: emitted radiance of the light, linear RGB (W / (sr m^2) per unit colour)
LIGHT_COLOR = (1.0, 0.8, 0.5)
LIGHT_STRENGTH = 120.0
LIGHT_RADIANCE = tuple(LIGHT_STRENGTH * c for c in LIGHT_COLOR)

#: the original camera: 35 mm focal length, 25 mm film -> 2 atan(12.5 / 35)
YFOV_DEG = math.degrees(2.0 * math.atan(12.5 / 35.0))
CAMERA = Camera(
    eye=(W / 2, 0.273, -0.8),
    target=(W / 2, 0.273, 0.0),
    up=(0.0, 1.0, 0.0),
    yfov=YFOV_DEG,
    znear=0.01,
    zfar=10.0,
    name="front",
)


def _q(*corners_mm) -> np.ndarray:
    """(4, 3) float64 corners in metres from millimetre triples."""
    return np.array(corners_mm, dtype=np.float64) / 1000.0


def _box(footprint_mm, height_mm) -> list[np.ndarray]:
    """The top and four sides of a block standing on the floor (no bottom face).

    footprint_mm : four (x, z) corners in mm, in order around the block.
    Orientation is fixed later by :func:`_oriented`.
    """
    h = height_mm
    faces = [_q(*[(x, h, z) for x, z in footprint_mm])]
    for k in range(4):
        (x0, z0), (x1, z1) = footprint_mm[k], footprint_mm[(k + 1) % 4]
        faces.append(_q((x0, 0, z0), (x0, h, z0), (x1, h, z1), (x1, 0, z1)))
    return faces


def _normal(c: np.ndarray) -> np.ndarray:
    """(3,) unit normal of a quad with counter-clockwise corners (as ``iat.io.scene.Scene.patch_normal``)."""
    n = np.cross(c[2] - c[0], c[3] - c[1])
    return n / np.linalg.norm(n)


def _oriented(c: np.ndarray, point: np.ndarray, towards: bool) -> np.ndarray:
    """The quad ``c`` (4, 3), its corner order reversed if needed so its normal points
    towards ``point`` (``towards=True``) or away from it."""
    facing = float(_normal(c) @ (point - c.mean(axis=0))) > 0
    return c if facing == towards else c[[0, 3, 2, 1]]


def quads() -> list[tuple[str, int, list[np.ndarray]]]:
    """The scene as ``(object name, material slot, [(4, 3) corners in metres, ...])``.

    Material slot: 0 white, 1 red, 2 green, 3 light. Room faces look into the room,
    block faces out of their block, the light down.
    """
    w, h, d = W * 1000, H * 1000, D * 1000
    y_light = h - 1.0
    short_fp = [(130.0, 65.0), (82.0, 225.0), (240.0, 272.0), (290.0, 114.0)]
    tall_fp = [(423.0, 247.0), (265.0, 296.0), (314.0, 456.0), (472.0, 406.0)]
    room_centre = np.array([W / 2, H / 2, D / 2])
    objects = [
        ("floor", 0, [_q((w, 0, 0), (0, 0, 0), (0, 0, d), (w, 0, d))], room_centre, True),
        ("ceiling", 0, [_q((w, h, 0), (w, h, d), (0, h, d), (0, h, 0))], room_centre, True),
        ("back_wall", 0, [_q((w, 0, d), (0, 0, d), (0, h, d), (w, h, d))], room_centre, True),
        ("red_wall", 1, [_q((w, 0, 0), (w, 0, d), (w, h, d), (w, h, 0))], room_centre, True),
        ("green_wall", 2, [_q((0, 0, d), (0, 0, 0), (0, h, 0), (0, h, d))], room_centre, True),
        ("short_block", 0, _box(short_fp, 165.0), np.array([0.186, 0.0825, 0.169]), False),
        ("tall_block", 0, _box(tall_fp, 330.0), np.array([0.3685, 0.165, 0.35125]), False),
        (
            "light",
            3,
            [_q((343, y_light, 227), (343, y_light, 332), (213, y_light, 332), (213, y_light, 227))],
            room_centre,
            True,
        ),
    ]
    return [
        (name, slot, [_oriented(c, p, towards) for c in faces]) for name, slot, faces, p, towards in objects
    ]


def camera_path() -> list[Camera]:
    """8 poses: the eye drifts a few centimetres right, up and in while looking at the room."""
    poses = []
    for k in range(8):
        t = k / 7.0
        eye = np.array([W / 2 + 0.06 * math.sin(math.pi * t), 0.273 + 0.03 * t, -0.8 + 0.25 * t])
        target = np.array([W / 2 - 0.03 * math.sin(math.pi * t), 0.26, D / 2])
        poses.append(
            Camera(
                eye=np.round(eye, 6),
                target=np.round(target, 6),
                up=(0.0, 1.0, 0.0),
                yfov=round(YFOV_DEG, 4),
                znear=CAMERA.znear,
                zfar=CAMERA.zfar,
                name=f"default_{k}",
            )
        )
    return poses


def make_builder() -> GlbBuilder:
    """A :class:`iat.glb.GlbBuilder` holding the whole Cornell box (not yet written)."""
    b = GlbBuilder()
    mats = [
        b.add_material("white", WHITE),
        b.add_material("red", RED),
        b.add_material("green", GREEN),
        b.add_material("light", LIGHT_ALBEDO, emissive=LIGHT_RADIANCE),
    ]
    tri = np.array([[0, 1, 2], [2, 3, 0]], dtype=np.uint32)
    for name, slot, faces in quads():
        pos, nrm, idx = [], [], []
        for i, c in enumerate(faces):
            pos.append(c)
            nrm.append(np.repeat(_normal(c)[None], 4, axis=0))
            idx.append(tri + 4 * i)
        mesh = b.add_mesh(
            name, np.concatenate(pos), np.concatenate(idx), mats[slot], normals=np.concatenate(nrm)
        )
        b.add_node(name, mesh=mesh)
    b.add_camera_node(CAMERA, aspect=1.0)
    keys = ("eye", "target", "up", "yfov")
    b.extras["iat_camera_paths"] = {"default": [{k: c.to_dict()[k] for k in keys} for c in camera_path()]}
    return b


def build(path: str | Path = DEFAULT_PATH) -> Path:
    """Write the Cornell box GLB to ``path`` (atomically); returns the path."""
    return make_builder().write(path)


if __name__ == "__main__":
    from sample_models.common import script_main

    sys.exit(script_main(build, DEFAULT_PATH, "Write the Cornell box sample scene as a GLB."))
