"""Daylit rooms for the tests: a 4 x 3 x 5 m room with a 1.6 x 1.2 m window in the wall at x = 4 (open,
or glazed), lit by a sun and a sky; and the window-lit room of issue 37 (:func:`window_room`)."""

from __future__ import annotations

import numpy as np

from iat.camera import Camera
from iat.io.scene import Light, Material, Scene, Sky

W, H, D = 4.0, 3.0, 5.0
WINDOW = (1.7, 3.3, 0.9, 2.1)  # z0, z1, y0, y1 on the wall x = W
#: where the sun's light travels (down through the window towards -x)
SUN_DIRECTION = -np.array([1.0, 1.2, 0.2]) / np.linalg.norm([1.0, 1.2, 0.2])
CAMERA = Camera(eye=[0.6, 1.6, 4.6], target=[3.0, 0.6, 1.5], yfov=75.0, znear=0.05, zfar=50.0)


def daylit_room(glass: float | None = None, sun: float = 600.0, sky=(30.0, 35.0, 45.0)) -> Scene:
    """The room as quads facing inwards; ``glass``: the window's transmittance (None: open)."""
    V: list = []
    C: list = []
    M: list = []

    def quad(p, mat):
        C.append([len(V), len(V) + 1, len(V) + 2, len(V) + 3])
        V.extend(p)
        M.append(mat)

    quad([(0, 0, 0), (0, 0, D), (W, 0, D), (W, 0, 0)], 0)  # floor
    quad([(0, H, 0), (W, H, 0), (W, H, D), (0, H, D)], 1)  # ceiling
    quad([(0, 0, 0), (W, 0, 0), (W, H, 0), (0, H, 0)], 2)
    quad([(0, 0, D), (0, H, D), (W, H, D), (W, 0, D)], 2)
    quad([(0, 0, 0), (0, H, 0), (0, H, D), (0, 0, D)], 2)
    z0, z1, y0, y1 = WINDOW
    for za, zb, ya, yb in [(0, D, 0, y0), (0, D, y1, H), (0, z0, y0, y1), (z1, D, y0, y1)]:
        quad([(W, ya, za), (W, ya, zb), (W, yb, zb), (W, yb, za)], 2)
    if glass is not None:
        quad([(W, y0, z0), (W, y0, z1), (W, y1, z1), (W, y1, z0)], 3)
    mats = [
        Material("floor", albedo=[0.5, 0.45, 0.4]),
        Material("ceiling", albedo=[0.8, 0.8, 0.8]),
        Material("wall", albedo=[0.7, 0.7, 0.7]),
        Material("glass", albedo=[0.0, 0.0, 0.0], transmission=float(glass or 0.0)),
    ]
    scene = Scene(
        vertices=np.array(V, float), patch_corners=np.array(C), patch_material=np.array(M), materials=mats
    )
    if sun:
        scene.lights = [Light(kind="directional", direction=SUN_DIRECTION, intensity=sun, name="sun")]
    if sky is not None:
        scene.sky = Sky(kind="uniform", radiance=sky)
    return scene


ROOM_W, ROOM_H, ROOM_D = 5.0, 3.0, 5.0  # the window-lit room of issue 37
ROOM_WINDOW = (1.5, 3.5, 0.9, 2.1)  # z0, z1, y0, y1 on the wall x = ROOM_W (2 x 1.2 m)
ROOM_SKY = (30.0, 35.0, 45.0)  # W / (m^2 sr)
ROOM_GROUND = 0.3  # the ground's radiance, a fraction of the sky's
ROOM_CAMERA = Camera(eye=[4.4, 1.5, 4.6], target=[0.0, 1.2, 1.0], yfov=70.0, znear=0.05, zfar=50.0)
ROOM_SIZE = (96, 72)
#: the walls the noise is measured on: the patch indices of window_room()
ROOM_WALLS = {"back (x=0)": 4, "side (z=0)": 2, "floor": 0}


def window_room() -> Scene:
    """The room as inward quads: floor 0, ceiling 1, walls z=0 2, z=D 3, x=0 4, and the window wall
    x=W in four quads around the opening."""
    Wr, Hr, Dr = ROOM_W, ROOM_H, ROOM_D
    V: list = []
    C: list = []
    M: list = []

    def quad(p, mat):
        C.append([len(V), len(V) + 1, len(V) + 2, len(V) + 3])
        V.extend(p)
        M.append(mat)

    quad([(0, 0, 0), (0, 0, Dr), (Wr, 0, Dr), (Wr, 0, 0)], 0)
    quad([(0, Hr, 0), (Wr, Hr, 0), (Wr, Hr, Dr), (0, Hr, Dr)], 1)
    quad([(0, 0, 0), (Wr, 0, 0), (Wr, Hr, 0), (0, Hr, 0)], 2)
    quad([(0, 0, Dr), (0, Hr, Dr), (Wr, Hr, Dr), (Wr, 0, Dr)], 2)
    quad([(0, 0, 0), (0, Hr, 0), (0, Hr, Dr), (0, 0, Dr)], 2)
    z0, z1, y0, y1 = ROOM_WINDOW
    for za, zb, ya, yb in [(0, Dr, 0, y0), (0, Dr, y1, Hr), (0, z0, y0, y1), (z1, Dr, y0, y1)]:
        quad([(Wr, ya, za), (Wr, ya, zb), (Wr, yb, zb), (Wr, yb, za)], 2)
    mats = [
        Material("floor", albedo=[0.5, 0.45, 0.4]),
        Material("ceiling", albedo=[0.8, 0.8, 0.8]),
        Material("wall", albedo=[0.7, 0.7, 0.7]),
    ]
    scene = Scene(
        vertices=np.array(V, float), patch_corners=np.array(C), patch_material=np.array(M), materials=mats
    )
    scene.sky = Sky(kind="uniform", radiance=ROOM_SKY, ground=ROOM_GROUND * np.asarray(ROOM_SKY))
    return scene
