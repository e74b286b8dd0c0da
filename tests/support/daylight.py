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


def room_scene(size, window, materials: list, glass: bool = False) -> Scene:
    """A room of ``size`` (w, h, d) as quads facing inwards: floor (material 0), ceiling (1), the walls
    z = 0, z = d, x = 0 and the window wall x = w in four quads around ``window`` (z0, z1, y0, y1)
    (2), and with ``glass`` a pane in the opening (3)."""
    w, h, d = size
    V: list = []
    C: list = []
    M: list = []

    def quad(p, mat):
        C.append([len(V), len(V) + 1, len(V) + 2, len(V) + 3])
        V.extend(p)
        M.append(mat)

    quad([(0, 0, 0), (0, 0, d), (w, 0, d), (w, 0, 0)], 0)  # floor
    quad([(0, h, 0), (w, h, 0), (w, h, d), (0, h, d)], 1)  # ceiling
    quad([(0, 0, 0), (w, 0, 0), (w, h, 0), (0, h, 0)], 2)
    quad([(0, 0, d), (0, h, d), (w, h, d), (w, 0, d)], 2)
    quad([(0, 0, 0), (0, h, 0), (0, h, d), (0, 0, d)], 2)
    z0, z1, y0, y1 = window
    for za, zb, ya, yb in [(0, d, 0, y0), (0, d, y1, h), (0, z0, y0, y1), (z1, d, y0, y1)]:
        quad([(w, ya, za), (w, ya, zb), (w, yb, zb), (w, yb, za)], 2)
    if glass:
        quad([(w, y0, z0), (w, y0, z1), (w, y1, z1), (w, y1, z0)], 3)
    V, C, M = np.array(V, float), np.array(C), np.array(M)
    return Scene(vertices=V, patch_corners=C, patch_material=M, materials=materials)


def daylit_room(glass: float | None = None, sun: float = 600.0, sky=(30.0, 35.0, 45.0)) -> Scene:
    """The room as quads facing inwards; ``glass``: the window's transmittance (None: open)."""
    mats = [
        Material("floor", albedo=[0.5, 0.45, 0.4]),
        Material("ceiling", albedo=[0.8, 0.8, 0.8]),
        Material("wall", albedo=[0.7, 0.7, 0.7]),
        Material("glass", albedo=[0.0, 0.0, 0.0], transmission=float(glass or 0.0)),
    ]
    scene = room_scene((W, H, D), WINDOW, mats, glass is not None)
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
    """The window-lit room (:func:`room_scene`), no glass, under a uniform sky over a grey ground."""
    mats = [
        Material("floor", albedo=[0.5, 0.45, 0.4]),
        Material("ceiling", albedo=[0.8, 0.8, 0.8]),
        Material("wall", albedo=[0.7, 0.7, 0.7]),
    ]
    scene = room_scene((ROOM_W, ROOM_H, ROOM_D), ROOM_WINDOW, mats)
    scene.sky = Sky(kind="uniform", radiance=ROOM_SKY, ground=ROOM_GROUND * np.asarray(ROOM_SKY))
    return scene
