"""Walkthrough navigation: pure camera logic, no window, no GL (tested without a display).

A :class:`Navigator` turns input states into camera poses, one frame at a time::

    nav = Navigator(scene.default_camera(), speed=navigation_speed(scene.bounds))
    camera = nav.update(dt, InputState(keys={"w"}, gamepad_axes=(0, -1, 0, 0, 0, 0)))

Controls (perfjoy-style; "walk" moves stay horizontal, +Y is up as in glTF):

=====================  ==========================================================
gamepad left stick     up/down: walk forward/back; left/right: turn
gamepad right stick    look (yaw and pitch)
gamepad triggers       right trigger rises, left trigger falls
gamepad A              next speed gear (x1 -> x4 -> x1/4 -> x1 ...)
gamepad B / START      reset the view
W/S, Up/Down           walk forward/back
A/D                    strafe left/right
Left/Right             turn
E / Q                  rise / fall
Shift                  x4 faster while held
mouse drag             look (the app sends the drag delta in pixels)
mouse wheel            speed x1.25 per notch up, /1.25 down
=====================  ==========================================================

Camera paths (demo sessions and the benchmark) are lists of poses with optional
times; :class:`PathRecorder` records one pose per frame, :class:`PathPlayer`
plays a path back by time or at a fixed number of frames, and
:func:`save_paths` / :func:`load_paths` keep them as JSON next to the model
(``MODEL.paths.json``: ``{name: [camera dict, ...]}``, each dict a
:meth:`iat.camera.Camera.to_dict` plus ``"t"``, seconds from the start).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iat.camera import Camera
from iat.errors import LoadError

__all__ = [
    "CameraPath",
    "InputState",
    "NavConfig",
    "Navigator",
    "PathPlayer",
    "PathRecorder",
    "interpolate",
    "load_paths",
    "navigation_speed",
    "paths_file",
    "save_paths",
]

#: gamepad axes in GLFW order: left x, left y (up = -1), right x, right y (up = -1), triggers
AXES = ("left_x", "left_y", "right_x", "right_y", "left_trigger", "right_trigger")
WORLD_UP = np.array([0.0, 1.0, 0.0])


@dataclass
class InputState:
    """What the user does during one frame.

    keys : names of the keys held: "w" "a" "s" "d" "q" "e" "up" "down" "left" "right" "shift"
    mouse_dx, mouse_dy : drag-to-look motion this frame in pixels (x right, y down); 0 when not dragging
    wheel : mouse wheel notches this frame (+ = away from the user)
    gamepad_axes : 6 floats in GLFW order (:data:`AXES`): sticks in [-1, 1] (y = -1 when pushed up),
      triggers in [0, 1] (0 released; the app maps GLFW's -1..1 to that)
    gamepad_buttons : names of the gamepad buttons held: "a" "b" "x" "y" "lb" "rb" "back" "start" ...
    """

    keys: frozenset[str] | set[str] = frozenset()
    mouse_dx: float = 0.0
    mouse_dy: float = 0.0
    wheel: float = 0.0
    gamepad_axes: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    gamepad_buttons: frozenset[str] | set[str] = frozenset()

    def axis(self, name: str) -> float:
        i = AXES.index(name)
        return float(self.gamepad_axes[i]) if i < len(self.gamepad_axes) else 0.0


@dataclass
class NavConfig:
    """Navigation constants; each with its unit and typical value.

    turn_rate : deg/s of yaw at full left stick or with Left/Right held (typical 90)
    look_rate : deg/s at full right stick (typical 120)
    mouse_sensitivity : degrees per dragged pixel (typical 0.2)
    shift_factor : speed multiplier while Shift is held (typical 4)
    wheel_factor : speed multiplier per wheel notch (typical 1.25)
    gears : speed multipliers the gamepad A button cycles through
    deadzone : stick values below this magnitude are ignored (typical 0.15)
    max_pitch : degrees; looking straight up or down is clamped short of the pole (typical 89)
    min_speed, max_speed : bounds of the speed in scene units per second
    """

    turn_rate: float = 90.0
    look_rate: float = 120.0
    mouse_sensitivity: float = 0.2
    shift_factor: float = 4.0
    wheel_factor: float = 1.25
    gears: tuple[float, ...] = (1.0, 4.0, 0.25)
    deadzone: float = 0.15
    max_pitch: float = 89.0
    min_speed: float = 1e-4
    max_speed: float = 1e6


def navigation_speed(bounds: np.ndarray) -> float:
    """A walking speed (units/s) for a model with ``bounds`` ((2, 3) min/max): a quarter of its
    diagonal per second, so crossing the model takes a few seconds whatever its units."""
    b = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    d = float(np.linalg.norm(b[1] - b[0]))
    return d / 4.0 if np.isfinite(d) and d > 0 else 1.0


def _deadzone(v: float, dz: float) -> float:
    """Rescale so the response starts at 0 just outside the dead zone and reaches 1 at full tilt."""
    a = abs(v)
    if a <= dz:
        return 0.0
    return math.copysign(min((a - dz) / (1.0 - dz), 1.0), v)


class Navigator:
    """First-person walkthrough camera driven by :class:`InputState` frames.

    camera : the starting pose (its field of view and clip planes are kept)
    speed : walking speed in scene units per second (see :func:`navigation_speed`)
    config : :class:`NavConfig`

    State: ``eye`` (3,) float64, ``yaw`` and ``pitch`` in radians (yaw 0 looks down -Z,
    positive yaw turns left; positive pitch looks up), ``speed`` and ``gear``. ``collide``: None,
    or ``collide(eye, step) -> step`` clipping each frame's move (:class:`viewer.collision.Collider`).
    """

    def __init__(self, camera: Camera, speed: float = 1.0, config: NavConfig | None = None):
        self.config = config or NavConfig()
        self.base_speed = float(speed)
        self.speed = float(speed)
        self.gear = 0
        self._home = camera
        self._prev_buttons: frozenset[str] = frozenset()
        self.collide = None
        self.set_camera(camera)

    # -- pose ------------------------------------------------------------------------------
    def set_camera(self, camera: Camera) -> None:
        """Jump to ``camera`` (a file camera, a path pose); keeps the speed."""
        self._template = camera
        self.eye = np.array(camera.eye, dtype=np.float64)
        f = camera.forward
        self.yaw = math.atan2(-f[0], -f[2])
        lim = math.radians(self.config.max_pitch)
        self.pitch = min(max(math.asin(max(-1.0, min(1.0, float(f[1])))), -lim), lim)
        self.focus = max(float(np.linalg.norm(camera.target - camera.eye)), 1e-6)

    def reset(self, camera: Camera | None = None) -> Camera:
        """Back to the starting pose (or to ``camera``, which becomes the new home), at base speed."""
        if camera is not None:
            self._home = camera
        self.speed = self.base_speed
        self.gear = 0
        self.set_camera(self._home)
        return self.camera

    @property
    def forward(self) -> np.ndarray:
        """(3,) unit view direction from yaw and pitch."""
        cp = math.cos(self.pitch)
        return np.array([-math.sin(self.yaw) * cp, math.sin(self.pitch), -math.cos(self.yaw) * cp])

    @property
    def walk_forward(self) -> np.ndarray:
        """(3,) unit horizontal direction of travel."""
        return np.array([-math.sin(self.yaw), 0.0, -math.cos(self.yaw)])

    @property
    def right(self) -> np.ndarray:
        """(3,) unit horizontal right direction."""
        return np.array([math.cos(self.yaw), 0.0, -math.sin(self.yaw)])

    @property
    def camera(self) -> Camera:
        t = self._template
        return Camera(
            eye=self.eye.copy(),
            target=self.eye + self.focus * self.forward,
            up=WORLD_UP.copy(),
            yfov=t.yfov,
            znear=t.znear,
            zfar=t.zfar,
            name=t.name,
        )

    @property
    def effective_gear(self) -> float:
        g = self.config.gears
        return g[self.gear % len(g)] if g else 1.0

    # -- one frame -------------------------------------------------------------------------
    def update(self, dt: float, inp: InputState, walls: bool = True) -> Camera:
        """Advance by ``dt`` seconds under input ``inp``; returns the new camera. ``walls``: let
        :attr:`collide` clip the move (when there is one)."""
        c = self.config
        dt = max(float(dt), 0.0)
        keys = {k.lower() for k in inp.keys}
        buttons = frozenset(b.lower() for b in inp.gamepad_buttons)
        pressed = buttons - self._prev_buttons  # edge-triggered buttons
        self._prev_buttons = buttons

        if "b" in pressed or "start" in pressed:
            self.reset()
        if "a" in pressed:
            self.gear = (self.gear + 1) % max(len(c.gears), 1)
        if inp.wheel:
            self.speed *= c.wheel_factor ** float(inp.wheel)
        self.speed = min(max(self.speed, c.min_speed), c.max_speed)

        speed = self.speed * self.effective_gear * (c.shift_factor if "shift" in keys else 1.0)

        # turning and looking
        lx = _deadzone(inp.axis("left_x"), c.deadzone)
        ly = _deadzone(inp.axis("left_y"), c.deadzone)
        rx = _deadzone(inp.axis("right_x"), c.deadzone)
        ry = _deadzone(inp.axis("right_y"), c.deadzone)
        turn = (("left" in keys) - ("right" in keys)) - lx
        self.yaw += math.radians(c.turn_rate) * turn * dt
        self.yaw -= math.radians(c.look_rate) * rx * dt
        self.pitch -= math.radians(c.look_rate) * ry * dt
        self.yaw -= math.radians(c.mouse_sensitivity) * float(inp.mouse_dx)
        self.pitch -= math.radians(c.mouse_sensitivity) * float(inp.mouse_dy)
        self.yaw = math.remainder(self.yaw, 2 * math.pi)
        lim = math.radians(c.max_pitch)
        self.pitch = min(max(self.pitch, -lim), lim)

        # moving (after turning: the move goes where the camera now faces)
        fwd = (("w" in keys) or ("up" in keys)) - (("s" in keys) or ("down" in keys)) - ly
        side = ("d" in keys) - ("a" in keys)
        lift = ("e" in keys) - ("q" in keys)
        lift += max(inp.axis("right_trigger"), 0.0) - max(inp.axis("left_trigger"), 0.0)
        move = self.walk_forward * fwd + self.right * side
        n = float(np.linalg.norm(move))
        if n > 1.0:  # diagonal moves are not faster
            move /= n
        step = speed * dt * (move + WORLD_UP * max(-1.0, min(1.0, lift)))
        if walls and self.collide is not None and step.any():
            step = self.collide(self.eye, step)
        self.eye = self.eye + step
        return self.camera


def walker(scene, camera: Camera) -> Navigator:
    """A :class:`Navigator` for ``scene`` starting at ``camera``: its speed from the model's size and
    its walls stopping the walk (:class:`viewer.collision.Collider`; ``nav.collide = None`` lets
    you through)."""
    from viewer.collision import Collider, collision_radius

    nav = Navigator(camera, speed=navigation_speed(scene.bounds))
    nav.collide = Collider(scene, collision_radius(scene.bounds)).clip
    return nav


# -- camera paths -------------------------------------------------------------------------------
@dataclass
class CameraPath:
    """A named list of camera poses; ``times`` (seconds from the start, increasing) or None
    (poses evenly spaced ``seconds_per_pose`` apart when played by time)."""

    name: str
    cameras: list[Camera] = field(default_factory=list)
    times: list[float] | None = None

    def __len__(self) -> int:
        return len(self.cameras)

    def pose_times(self, seconds_per_pose: float = 2.0) -> np.ndarray:
        """(n,) float64 time of each pose."""
        if self.times is not None and len(self.times) == len(self.cameras):
            return np.asarray(self.times, dtype=np.float64)
        return np.arange(len(self.cameras), dtype=np.float64) * float(seconds_per_pose)

    def duration(self, seconds_per_pose: float = 2.0) -> float:
        t = self.pose_times(seconds_per_pose)
        return float(t[-1] - t[0]) if len(t) else 0.0

    def to_json(self) -> list[dict]:
        out = []
        for k, cam in enumerate(self.cameras):
            d = cam.to_dict()
            if self.times is not None:
                d["t"] = float(self.times[k])
            out.append(d)
        return out

    @classmethod
    def from_json(cls, name: str, poses: Iterable[dict]) -> CameraPath:
        poses = list(poses)
        cams = [Camera.from_dict(p) for p in poses]
        times = [float(p["t"]) for p in poses] if poses and all("t" in p for p in poses) else None
        return cls(name, cams, times)


def interpolate(a: Camera, b: Camera, s: float) -> Camera:
    """Camera between ``a`` (s = 0) and ``b`` (s = 1): eye, target, up and field of view lerped."""
    s = float(s)
    if s <= 0.0:
        return a
    if s >= 1.0:
        return b
    up = (1 - s) * a.up + s * b.up
    n = np.linalg.norm(up)
    return Camera(
        eye=(1 - s) * a.eye + s * b.eye,
        target=(1 - s) * a.target + s * b.target,
        up=up / n if n > 1e-12 else a.up,
        yfov=(1 - s) * a.yfov + s * b.yfov,
        znear=min(a.znear, b.znear),
        zfar=max(a.zfar, b.zfar),
        name=a.name,
    )


class PathRecorder:
    """Records one pose per frame: ``add(camera, t)`` with ``t`` the time since recording started."""

    def __init__(self, name: str = "recorded"):
        self.name = name
        self.cameras: list[Camera] = []
        self.times: list[float] = []

    def add(self, camera: Camera, t: float) -> None:
        if self.times and t < self.times[-1]:
            raise ValueError(f"path times must not decrease ({t} after {self.times[-1]})")
        self.cameras.append(
            Camera(camera.eye, camera.target, camera.up, camera.yfov, camera.znear, camera.zfar, camera.name)
        )
        self.times.append(float(t))

    def path(self) -> CameraPath:
        t0 = self.times[0] if self.times else 0.0
        return CameraPath(self.name, list(self.cameras), [t - t0 for t in self.times])


class PathPlayer:
    """Plays a :class:`CameraPath` back.

    By time: ``pose_at(t)`` interpolates between the poses around ``t`` (exactly the recorded
    pose at a recorded time). By frames (the benchmark): ``frame(k)`` for ``k`` in
    ``0..frames-1`` samples the path at ``k / (frames - 1)`` of its duration, so the first and
    last frames are the first and last poses. ``frames=None`` plays one recorded pose per frame.
    """

    def __init__(self, path: CameraPath, frames: int | None = None, seconds_per_pose: float = 2.0):
        if not len(path):
            raise ValueError(f"camera path {path.name!r} is empty")
        self.path = path
        self.times = path.pose_times(seconds_per_pose)
        self.frames = int(frames) if frames is not None else len(path)
        if self.frames < 1:
            raise ValueError(f"frames must be >= 1, got {frames}")
        self._fixed = frames is not None
        self.index = 0

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0])

    def pose_at(self, t: float) -> Camera:
        """The pose at ``t`` seconds from the start (clamped to the path)."""
        cams, times = self.path.cameras, self.times
        t = float(t) + float(times[0])
        k = int(np.searchsorted(times, t, side="right")) - 1
        if k < 0:
            return cams[0]
        if k >= len(cams) - 1:
            return cams[-1]
        span = times[k + 1] - times[k]
        return cams[k] if span <= 0 else interpolate(cams[k], cams[k + 1], (t - times[k]) / span)

    def frame(self, k: int) -> Camera:
        """Pose of frame ``k`` of ``frames``."""
        k = min(max(int(k), 0), self.frames - 1)
        if not self._fixed:
            return self.path.cameras[k]
        if self.frames == 1:
            return self.path.cameras[0]
        return self.pose_at(self.duration * k / (self.frames - 1))

    @property
    def done(self) -> bool:
        return self.index >= self.frames

    def next(self) -> Camera | None:
        """The next frame's pose, or None once all frames were played."""
        if self.done:
            return None
        cam = self.frame(self.index)
        self.index += 1
        return cam


def paths_file(model_path: str | os.PathLike) -> Path:
    """Where a model's camera paths live: ``MODEL.paths.json`` next to it (``cornell_box.glb`` ->
    ``cornell_box.paths.json``)."""
    p = Path(model_path)
    return p.with_name(p.stem + ".paths.json")


def save_paths(file: str | os.PathLike, paths: dict[str, CameraPath] | Iterable[CameraPath]) -> Path:
    """Write ``{name: [camera dict, ...]}`` as JSON, atomically; returns the path."""
    items = paths.values() if isinstance(paths, dict) else paths
    doc = {p.name: p.to_json() for p in items}
    from iat.fsutil import atomic_write

    return atomic_write(file, lambda f: f.write(json.dumps(doc, indent=1).encode("utf-8")))


def load_paths(file: str | os.PathLike) -> dict[str, CameraPath]:
    """Read a paths file; a missing file gives ``{}``; a damaged one raises LoadError naming it."""
    file = Path(file)
    if not file.exists():
        return {}
    try:
        doc = json.loads(file.read_text(encoding="utf-8"))
        if not isinstance(doc, dict):
            raise ValueError("the top level is not an object {name: [camera, ...]}")
        out = {}
        for name, poses in doc.items():
            if not isinstance(poses, list):
                raise ValueError(f"path {name!r} is not a list of cameras")
            out[str(name)] = CameraPath.from_json(str(name), poses)
        return out
    except (OSError, ValueError, TypeError, KeyError) as e:
        raise LoadError(f"not a camera paths file: {e}", file) from e
