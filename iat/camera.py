"""Cameras: pure math, no GL.

A :class:`Camera` is a pinhole with an eye, a target and an up vector, in world
space (right-handed, +Y up, as glTF). Matrices follow OpenGL conventions
(column vectors, clip space z in [-1, 1]) and are returned as ``(4, 4) float64``
row-major arrays; upload them to GL transposed (``m.T.astype('f4').tobytes()``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Camera:
    """A perspective camera.

    eye, target, up : (3,) float64, world units
    yfov : vertical field of view in degrees (typical 45-70)
    znear, zfar : clip distances in world units
    name : label shown in the viewer
    """

    eye: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 3.0]))
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    yfov: float = 60.0
    znear: float = 0.01
    zfar: float = 1000.0
    name: str = ""

    def __post_init__(self):
        self.eye = np.asarray(self.eye, dtype=np.float64).reshape(3)
        self.target = np.asarray(self.target, dtype=np.float64).reshape(3)
        self.up = np.asarray(self.up, dtype=np.float64).reshape(3)

    @property
    def forward(self) -> np.ndarray:
        """(3,) float64 unit vector from eye to target."""
        d = self.target - self.eye
        return d / max(np.linalg.norm(d), 1e-300)

    def view_from_world(self) -> np.ndarray:
        """(4, 4) float64 view matrix (world -> camera, camera looks down -Z)."""
        f = self.forward
        s = np.cross(f, self.up)
        n = np.linalg.norm(s)
        if n < 1e-12:  # looking along up: pick any perpendicular
            s = np.cross(f, [1.0, 0.0, 0.0] if abs(f[0]) < 0.9 else [0.0, 0.0, 1.0])
            n = np.linalg.norm(s)
        s = s / n
        u = np.cross(s, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ self.eye
        return m

    def pixel_rays(self, size: tuple[int, int], k: int = 1) -> np.ndarray:
        """(h k, w k, 3) float64 unit directions through the centres of a (w k) x (h k) grid over a
        ``size`` (w, h) image: row 0 at the top, column 0 at the left, as the renderer's read-back
        (:meth:`clip_from_world` of aspect w / h). Rays start at :attr:`eye`."""
        w, h = int(size[0]) * int(k), int(size[1]) * int(k)
        v = self.view_from_world()
        s, u, f = v[0, :3], v[1, :3], -v[2, :3]
        t = np.tan(np.radians(self.yfov) / 2.0)
        x = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * t * (w / h)
        y = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * t
        d = f[None, None, :] + x[None, :, None] * s[None, None, :] + y[:, None, None] * u[None, None, :]
        return d / np.linalg.norm(d, axis=2, keepdims=True)

    def clip_from_view(self, aspect: float) -> np.ndarray:
        """(4, 4) float64 OpenGL perspective projection for width/height ``aspect``."""
        t = 1.0 / np.tan(np.radians(self.yfov) / 2.0)
        n, f = self.znear, self.zfar
        m = np.zeros((4, 4))
        m[0, 0] = t / aspect
        m[1, 1] = t
        m[2, 2] = (f + n) / (n - f)
        m[2, 3] = 2.0 * f * n / (n - f)
        m[3, 2] = -1.0
        return m

    def clip_from_world(self, aspect: float) -> np.ndarray:
        """(4, 4) float64 projection times view."""
        return self.clip_from_view(aspect) @ self.view_from_world()

    def to_dict(self) -> dict:
        return {
            "eye": self.eye.tolist(),
            "target": self.target.tolist(),
            "up": self.up.tolist(),
            "yfov": self.yfov,
            "znear": self.znear,
            "zfar": self.zfar,
            "name": self.name,
        }

    @classmethod
    def from_dict(cls, d: dict) -> Camera:
        return cls(**{k: d[k] for k in ("eye", "target", "up", "yfov", "znear", "zfar", "name") if k in d})
