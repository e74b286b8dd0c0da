"""The viewer's state: one plain object that panels read and change; no GL here.

:class:`AppState` holds a few parts, each a small dataclass:

- ``state.model`` (:class:`ModelState`): what is open (paths, scene, solution, the bake on
  screen), the solve options and where the solution came from;
- ``state.tuning`` (:class:`Tuning`): what the tuning panel sets (the bake policy, exposure);
- ``state.view`` (:class:`ViewState`): the view mode, the camera and its navigator, the split
  divider, the 3D view's rectangle;
- ``state.paths`` (:class:`PathsState`): camera paths, recording and playback;
- ``state.jobs`` (:class:`JobsState`): the open job, the bake worker and what they came to;
- ``state.lighting`` (:class:`LightingState`): the light editor, the background re-solve,
  the model's lighting states and the day cycle;
- ``state.messages`` (:class:`Messages`): the error shown, the status line;
- ``state.stats`` (:class:`FrameStats`): frame times and the renderer's counts;
- ``state.requests`` (:class:`Requests`): what panels ask the app to do next frame.

Panels change the fields; the app (``viewer/app.py``) notices the changes (a new bake policy,
a request to open a file, ...) and acts, touching GL only through :class:`iat.render.renderer.Renderer`.
The long work runs off the UI thread (:mod:`viewer.jobs`, :mod:`viewer.bake_worker`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.camera import Camera
from iat.radiosity import SolveOptions
from viewer.bake_worker import BakeWorker
from viewer.false_color import FalseColorSettings
from viewer.jobs import OpenJob, SetJob
from viewer.navigation import CameraPath, Navigator, PathPlayer, PathRecorder

log = logging.getLogger(__name__)

MODES = ("mesh", "iat", "split", "diff", "false")
MODE_LABELS = {"mesh": "Mesh", "iat": "IAT", "split": "Split", "diff": "Difference", "false": "False colour"}
FRAME_HISTORY = 240  # frames kept for the frame-time plot


def default_model() -> Path:
    """The default sample scene: ``sample_models/cornell_box.glb`` of the repository."""
    return Path(__file__).resolve().parent.parent / "sample_models" / "cornell_box.glb"


@dataclass
class Tuning:
    """What the tuning panel sets; :meth:`policy` turns it into a :class:`~iat.bake.policy.BakePolicy`.

    threshold : patches with tree depth >= threshold are textured (0 .. deepest + 1)
    scale : texture side factor (0.125 .. 2)
    method : "bilinear" | "scan" | "bicubic"
    scale_mode : "clamped" | "naive"
    budget_on, budget_mb : texture budget in MiB; when on, threshold and scale are chosen by the baker
    detail : detail textures combined with incoming light (report §3.7)
    lod, lod_stream : levels of detail (report §6.2.2; :mod:`iat.bake.lod`), and keeping only the
      levels the view needs resident (the budget, when on, caps them)
    exposure : display multiplier on radiance before the tone map
    """

    threshold: int = 2
    scale: float = 1.0
    method: str = "bilinear"
    scale_mode: str = "clamped"
    budget_on: bool = False
    budget_mb: float = 4.0
    detail: bool = True
    lod: bool = False
    lod_stream: bool = False
    exposure: float = 1.0

    def policy(self) -> BakePolicy:
        return BakePolicy(
            threshold=int(self.threshold),
            scale=float(self.scale),
            method=self.method,
            scale_mode=self.scale_mode,
            budget_mb=float(self.budget_mb) if self.budget_on else None,
            detail=bool(self.detail),
            lod=bool(self.lod),
            lod_stream=bool(self.lod and self.lod_stream),
        )


@dataclass
class ModelState:
    """What is open: the file, its scene and solution, the Baker and the bake on screen.

    path : the file opened (a model or a solution ``.npz``); "" before the first
    baked : the bake on screen (the last good one: a Baked, or a BakedSet in the day cycle)
    bake_source : generation of the bake source the bake on screen came from
    solve_options, use_cache : how models opened from now on are solved
    solve_seconds, from_cache : the solve's time, and the cache file it came from ("" if solved)
    """

    path: str = ""
    scene: Any = None
    solution: Any = None
    baker: Baker | None = None
    baked: Any = None
    bake_source: int = 0
    solve_options: SolveOptions = field(default_factory=lambda: SolveOptions())
    use_cache: bool = True
    solve_seconds: float = 0.0
    from_cache: str = ""
    #: what ``iat view --sun/--sky/--no-daylight`` asked for (a DaylightRequest; None: the default)
    daylight_request: Any = None
    #: the one line saying what daylight the model got ("" when none: it has lights of its own)
    daylight_line: str = ""
    _deepest: tuple[Any, int] | None = field(default=None, init=False, repr=False, compare=False)
    _mesh_calls: tuple[Any, int] | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def loaded(self) -> bool:
        return self.solution is not None

    @property
    def deepest(self) -> int:
        """Deepest patch tree of the solution (the threshold slider's top is one more)."""
        if self.solution is None:
            return 0
        if self._deepest is None or self._deepest[0] is not self.solution:
            depth = np.asarray(self.solution.patch_depth())
            self._deepest = (self.solution, int(depth.max()) if depth.size else 0)
        return self._deepest[1]

    @property
    def memory(self) -> dict:
        """The shown bake's :class:`~iat.bake.memory.MemoryReport` as a dict ({} when none); a day-cycle
        set's counts every state's texture layers (``solutions``)."""
        return self.baked.memory.to_dict() if self.baked is not None else {}

    @property
    def mesh_draw_calls(self) -> int:
        """Draw calls of mesh mode: one, plus one per detail material (:mod:`iat.render.mesh_detail`)."""
        if self.solution is None:
            return 0
        if self._mesh_calls is None or self._mesh_calls[0] is not self.solution:
            albedo = np.asarray(self.solution.patch_albedo).reshape(-1, 3)
            sc, n = self.scene, 1
            if sc is not None and sc.n_patches == len(albedo) and sc.patch_uv is not None:  # as mesh_detail
                on = sc.detail_patches(albedo)
                n = len(np.unique(np.asarray(self.solution.patch_material)[on])) + int(not on.all())
            self._mesh_calls = (self.solution, max(n, 1))
        return self._mesh_calls[1]

    @property
    def mesh_triangles(self) -> int:
        return 0 if self.solution is None else int(len(self.solution.drawn_mesh().triangles))

    @property
    def iat_triangles(self) -> int:
        m = self.memory
        return int(m.get("triangles_mesh_part", 0) + m.get("triangles_textured_part", 0))

    @property
    def cameras(self) -> list[Camera]:
        return list(self.scene.cameras) if self.scene is not None else []

    def policy_summary(self) -> str:
        b = self.baked
        if b is None:
            return ""
        p = b.policy
        return f"threshold {p.threshold}, scale {p.scale:.3g}, {p.method}"


@dataclass
class ViewState:
    """How the model is shown and from where.

    mode : one of :data:`MODES`; split : the divider's position (0..1 of the view's width);
    diff_gain : the difference view's gain; tonemap : sRGB tone map on
    dragging_split, looking : the mouse drags the divider / looks around
    nav, camera, camera_index : the navigator, the pose drawn this frame, the scene camera chosen
    walls : walls stop the walk (:mod:`viewer.collision`)
    rect : the 3D view's rectangle in window pixels (x, y from the top left, w, h), updated every
      frame from the central dock node; framebuffer_scale : framebuffer pixels per window pixel
    kept : with nothing shown, the view's rectangle kept last frame's pixels, label included
      (:meth:`viewer.view3d.View3D.draw`): nothing is drawn over it
    notices : why the view shows nothing (no light, camera outside, model out of view), as drawn
      over it this frame (:func:`viewer.overlay.view_notices`)
    """

    mode: str = "iat"
    split: float = 0.5
    diff_gain: float = 8.0
    tonemap: bool = True
    dragging_split: bool = False
    looking: bool = False
    nav: Navigator | None = None
    walls: bool = True
    camera: Camera | None = None
    camera_index: int = 0
    rect: tuple[int, int, int, int] = (0, 0, 0, 0)
    framebuffer_scale: tuple[float, float] = (1.0, 1.0)
    kept: bool = False
    notices: tuple[str, ...] = ()
    false_color: FalseColorSettings = field(default_factory=FalseColorSettings)  # the "false" mode's


@dataclass
class PathsState:
    """Camera paths: those known by name, the one selected, recording and playback.

    record_started, play_started : ``time.perf_counter()`` when they began
    playback_frames : 0 plays in real time; N plays exactly N frames (benchmark)
    play_frame_ms : frame times (ms) of the playback under way, one per frame that drew a pose of
      the path (N for "Frames N")
    posed : the frame being drawn shows a pose of the path (set by the controls, counted after the
      swap)
    """

    named: dict[str, CameraPath] = field(default_factory=dict)
    selected: str = ""
    recorder: PathRecorder | None = None
    record_started: float = 0.0
    player: PathPlayer | None = None
    play_started: float = 0.0
    playback_frames: int = 0
    play_frame_ms: list[float] = field(default_factory=list)
    posed: bool = False


@dataclass
class JobsState:
    """The background work of opening and re-baking, and what it came to.

    requested_policy : the policy last submitted to the bake worker
    bake_seconds : the last bake's time on the worker; rebakes, uploads : bakes shown, uploaded
    """

    open_job: OpenJob | None = None
    bake_worker: BakeWorker | None = None
    requested_policy: BakePolicy | None = None
    bake_seconds: float = 0.0
    rebakes: int = 0
    uploads: int = 0

    @property
    def rebaking(self) -> bool:
        return self.bake_worker is not None and self.bake_worker.busy

    @property
    def opening(self) -> bool:
        return self.open_job is not None and not self.open_job.done


@dataclass
class LightingState:
    """Light edits, the background re-solve and the day cycle.

    editor : the open model's :class:`iat.lighting.editor.LightEditor`
    relighter : the :class:`iat.lighting.relight.Relighter` that re-solves after edits
    relight_version : the editor version last submitted; relight_submitted : when (throttles drags)
    relight_step : (step, steps) of the last result shown; relight_seconds : edit to that result;
    relight_mode : its mode ("preview": a daylight edit's first look, the full solve under way)
    relights : results shown
    states : the model's named lighting states; set_job : their solve on one mesh
    solution_set : the day cycle's :class:`iat.lighting.solution_set.SolutionSet`
    day_cycle : show the set blended at ``day_time`` (0..1)
    """

    editor: Any = None
    relighter: Any = None
    relight_version: int = 0
    relight_step: tuple[int, int] = (0, 0)
    relight_seconds: float = 0.0
    relight_mode: str = ""
    relights: int = 0
    relight_submitted: float = 0.0
    selected_light: int = -1
    dragging_light: bool = False
    show_lights: bool = True
    states: dict = field(default_factory=dict)
    set_job: SetJob | None = None
    solution_set: Any = None
    day_cycle: bool = False
    day_time: float = 0.0

    @property
    def relighting(self) -> bool:
        return self.relighter is not None and self.relighter.busy

    @property
    def solving_day_cycle(self) -> bool:
        return self.set_job is not None and not self.set_job.done

    def day_blend(self) -> tuple[int, int, float]:
        """(a, b, w) of ``day_time`` in the day-cycle set ((0, 0, 0) without one)."""
        if self.solution_set is None or not self.day_cycle:
            return 0, 0, 0.0
        return self.solution_set.weights(self.day_time)

    def day_label(self) -> str:
        """'noon -> evening 40 %' at the day time (or the key state's name)."""
        if self.solution_set is None or not self.day_cycle:
            return ""
        a, b, w = self.day_blend()
        names = self.solution_set.names
        return names[a] if w == 0.0 else f"{names[a]} -> {names[b]} {100 * w:.0f} %"


@dataclass
class Messages:
    """What the user is told: ``error`` is shown until dismissed (the last 50 kept in ``errors``),
    ``status`` is the last status line, ``last_screenshot`` the last picture written."""

    error: str = ""
    errors: list[str] = field(default_factory=list)
    status: str = ""
    last_screenshot: str = ""

    def set_error(self, message: str) -> None:
        log.warning("%s", message)
        self.error = message
        self.errors.append(message)
        del self.errors[:-50]

    def clear_error(self) -> None:
        self.error = ""

    def set_status(self, message: str) -> None:
        log.info("%s", message)
        self.status = message


@dataclass
class FrameStats:
    """Frame times (rings of :data:`FRAME_HISTORY` values) and the renderer's last counts.

    frame_ms : swap-to-swap intervals; work_ms : the part of each spent on the frame (from the start
    of the frame to its swap: what an interval would be without idling); idle : hello_imgui was
    idling then (the interval is mostly the idle wait, not a frame's cost)
    """

    frame_ms: np.ndarray = field(default_factory=lambda: np.zeros(FRAME_HISTORY, np.float32))
    work_ms: np.ndarray = field(default_factory=lambda: np.zeros(FRAME_HISTORY, np.float32))
    idle: np.ndarray = field(default_factory=lambda: np.zeros(FRAME_HISTORY, bool))
    frames: int = 0
    render: dict = field(default_factory=dict)
    lod: dict = field(default_factory=dict)  # Renderer.lod_info() of the last frame ({} without LOD)
    view_redraws: int = 0  # frames that drew the 3D view (viewer.view3d)
    view_copies: int = 0  # frames that copied the last image of it
    panel_draws: int = 0  # frames that drew the docked panels (viewer.panel_cache)
    panel_skips: int = 0  # frames that kept their last pixels

    def add_frame_time(self, ms: float, work_ms: float | None = None, idle: bool = False) -> None:
        k = self.frames % FRAME_HISTORY
        self.frame_ms[k] = ms
        self.work_ms[k] = ms if work_ms is None else work_ms
        self.idle[k] = bool(idle)
        self.frames += 1

    def _recent(self, ring: np.ndarray, n: int = 60) -> np.ndarray:
        m = min(self.frames, FRAME_HISTORY)
        idx = (self.frames - 1 - np.arange(min(n, m))) % FRAME_HISTORY
        return ring[idx[::-1]]

    @property
    def idling(self) -> bool:
        """The last frame was an idle one (nothing moved; hello_imgui waits between frames)."""
        return bool(self.frames and self.idle[(self.frames - 1) % FRAME_HISTORY])

    @property
    def idle_fps(self) -> float:
        """The rate of the recent idle frames (what an untouched window runs at)."""
        f = self._recent(self.frame_ms)[self._recent(self.idle)]
        return 1000.0 / float(f.mean()) if f.size and f.mean() > 0 else 0.0

    @property
    def work_fps(self) -> float:
        """Frames per second the recent frames' own work allows (idle waits left out)."""
        f = self._recent(self.work_ms)
        return 1000.0 / float(f.mean()) if f.size and f.mean() > 0 else 0.0

    def frame_history(self) -> np.ndarray:
        """(n,) float32 frame times in ms, oldest first (n <= FRAME_HISTORY)."""
        n = min(self.frames, FRAME_HISTORY)
        if self.frames <= FRAME_HISTORY:
            return self.frame_ms[:n].copy()
        k = self.frames % FRAME_HISTORY
        return np.concatenate([self.frame_ms[k:], self.frame_ms[:k]])

    @property
    def fps(self) -> float:
        """The frame rate of the recent frames that did not idle (0 when all idled)."""
        f = self._recent(self.frame_ms)[~self._recent(self.idle)]
        m = float(np.mean(f)) if f.size else 0.0
        return 1000.0 / m if m > 0 else 0.0


@dataclass
class Requests:
    """What panels ask the app to do; the app consumes each on its next frame.

    open, export, save_solution, save_lights : a file path, or None
    screenshot : a file path, "" for the default name (F12), or None
    save_paths, day_cycle, remesh, quit : flags
    auto_exposure : set the exposure from the view on screen at the next draw
      (:func:`iat.color.auto_exposure`, as ``iat render`` does); set when a model is opened
    dialogs : native file dialogs in flight (portable_file_dialogs objects) by kind
    file_fields : the text of the panels' path fields ("open", "export", "solution", "lights")
    """

    open: str | None = None
    export: str | None = None
    screenshot: str | None = None
    save_paths: bool = False
    save_solution: str | None = None
    save_lights: str | None = None
    day_cycle: bool = False
    remesh: bool = False
    auto_exposure: bool = False
    quit: bool = False
    dialogs: dict = field(default_factory=dict)
    file_fields: dict = field(
        default_factory=lambda: {"open": "", "export": "", "solution": "", "lights": ""}
    )


@dataclass
class AppState:
    """Everything the viewer shows and the panels change, in parts (see the module docstring).

    Its methods start and stop the recording and playback of camera paths, which touch the
    paths, the view and the messages together.
    """

    model: ModelState = field(default_factory=ModelState)
    tuning: Tuning = field(default_factory=Tuning)
    view: ViewState = field(default_factory=ViewState)
    paths: PathsState = field(default_factory=PathsState)
    jobs: JobsState = field(default_factory=JobsState)
    lighting: LightingState = field(default_factory=LightingState)
    messages: Messages = field(default_factory=Messages)
    stats: FrameStats = field(default_factory=FrameStats)
    requests: Requests = field(default_factory=Requests)

    def start_recording(self, name: str | None = None) -> None:
        p = self.paths
        p.player = None
        n = 1
        while name is None or name in p.named:
            name, n = f"recorded {n}", n + 1
        p.recorder = PathRecorder(name)
        p.record_started = time.perf_counter()

    def stop_recording(self) -> CameraPath | None:
        p = self.paths
        rec, p.recorder = p.recorder, None
        if rec is None or not rec.cameras:
            return None
        path = rec.path()
        p.named[path.name] = path
        p.selected = path.name
        self.messages.set_status(f"recorded path {path.name!r}: {len(path)} poses, {path.duration():.1f} s")
        return path

    def start_playback(self, name: str | None = None, frames: int | None = None) -> None:
        p = self.paths
        name = name or p.selected
        if name not in p.named:
            self.messages.set_error(f"no camera path named {name!r}")
            return
        p.recorder = None
        frames = p.playback_frames if frames is None else frames
        p.player = PathPlayer(p.named[name], frames=frames or None)
        p.play_started = time.perf_counter()
        p.play_frame_ms = []
        p.selected = name

    def stop_playback(self) -> None:
        """Stop playing; walking goes on from the last pose shown."""
        p, v = self.paths, self.view
        player, p.player = p.player, None
        if player is not None and v.nav is not None and v.camera is not None:
            v.nav.set_camera(v.camera)
        if player is not None and p.play_frame_ms:
            f = np.asarray(p.play_frame_ms)
            self.messages.set_status(
                f"played {player.path.name!r}: {len(f)} frames, mean {f.mean():.1f} ms, "
                f"max {f.max():.1f} ms ({1000.0 / max(f.mean(), 1e-9):.0f} fps)"
            )
