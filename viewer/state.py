"""The viewer's state: one plain object that panels read and change; no GL here.

:class:`AppState` holds what is open (scene, solution, the bake on screen), the
tuning values, the view mode, the camera, camera paths, statistics and messages.
Panels change its fields; the app (``viewer/app.py``) notices the changes
(a new bake policy, a request to open a file, ...) and acts, touching GL only
through :class:`iat.render.Renderer`.

Long work runs off the UI thread:

- :class:`OpenJob` loads a model or solution, solves a model that has none
  (progress, ETA, cancel; solutions are cached under :func:`iat.radiosity.cache.cache_dir`), builds
  the :class:`~iat.bake.Baker` and makes the first bake;
- :class:`BakeWorker` re-bakes the latest requested :class:`~iat.bake.BakePolicy`
  on one worker thread (pure numpy); the UI thread picks the result up with
  :meth:`BakeWorker.poll` and uploads it. Requests made while a bake runs are
  coalesced: only the newest is baked next. A request may also bring a new source
  (a re-solved solution after a light moved, or a solution set for the day cycle).
  While no request waits it pre-warms: it bakes the sliders' neighbours of the policy
  just baked (:func:`neighbour_policies`), one per idle turn, so that the next step
  finds the Baker's caches warm; a request made meanwhile is served first;
- :class:`~iat.lighting.Relighter` re-solves after light edits (resolve from the last
  converged solution, coarse first), :class:`SetJob` solves the model's lighting states
  on one mesh for the day-cycle slider.

Light picking and dragging in the view is pure geometry here (:func:`project_points`,
:func:`pick_light`, :func:`drag_on_plane`), testable without a window.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from iat.bake.baker import BakePolicy, Baker
from iat.camera import Camera
from iat.errors import Cancelled, IATError, LoadError
from iat.radiosity import SolveOptions
from iat.radiosity.cache import load_cached, solution_cache_path
from iat.worker import LatestWorker
from viewer.navigation import CameraPath, Navigator, PathPlayer, PathRecorder

log = logging.getLogger(__name__)

MODES = ("mesh", "iat", "split", "diff")
MODE_LABELS = {"mesh": "Mesh", "iat": "IAT", "split": "Split", "diff": "Difference"}
METHODS = ("bilinear", "scan", "bicubic")
FRAME_HISTORY = 240  # frames kept for the frame-time plot


def default_model() -> Path:
    """The default sample scene: ``sample_models/cornell_box.glb`` of the repository."""
    return Path(__file__).resolve().parent.parent / "sample_models" / "cornell_box.glb"


def error_text(e: BaseException) -> str:
    """One line for the user: an IATError's own message, else the type and the message."""
    if isinstance(e, IATError):
        return str(e)
    return f"{type(e).__name__}: {e}"


# -- tuning ---------------------------------------------------------------------------------------
@dataclass
class Tuning:
    """What the tuning panel sets; :meth:`policy` turns it into a :class:`~iat.bake.BakePolicy`.

    threshold : patches with tree depth >= threshold are textured (0 .. deepest + 1)
    scale : texture side factor (0.125 .. 2)
    method : "bilinear" | "scan" | "bicubic"
    scale_mode : "clamped" | "naive"
    budget_on, budget_mb : texture budget in MiB; when on, threshold and scale are chosen by the baker
    detail : detail textures combined with incoming light (report §3.7)
    exposure : display multiplier on radiance before the tone map
    """

    threshold: int = 2
    scale: float = 1.0
    method: str = "bilinear"
    scale_mode: str = "clamped"
    budget_on: bool = False
    budget_mb: float = 4.0
    detail: bool = True
    exposure: float = 1.0

    def policy(self) -> BakePolicy:
        return BakePolicy(
            threshold=int(self.threshold),
            scale=float(self.scale),
            method=self.method,
            scale_mode=self.scale_mode,
            budget_mb=float(self.budget_mb) if self.budget_on else None,
            detail=bool(self.detail),
        )


# -- background work --------------------------------------------------------------------------------
@dataclass
class BakeResult:
    """What a bake request came to: ``baked`` (a Baked, or a BakedSet for a solution set) or
    ``error`` (one line), how long it took, and the source generation it baked."""

    policy: BakePolicy
    baked: Any = None
    error: str | None = None
    seconds: float = 0.0
    source: int = 0


@dataclass
class BakeSource:
    """What a :class:`BakeWorker` bakes from: one solution, or a solution set (``solutions``),
    with the scene (detail textures). The Baker is built on the worker thread."""

    solution: Any
    scene: Any = None
    solutions: Any = None  # a SolutionSet: bake_set instead of bake

    def baker(self) -> Baker:
        return Baker(self.solution, self.scene)


SCALE_MIN, SCALE_MAX = 0.125, 2.0  # the Scale slider's range (viewer/panels.py)
SCALE_STEPS_PER_OCTAVE = 4  # the pre-warmed scales: 2**(k/4), the budget's ladder (iat.bake)


def snap_scale(scale: float) -> float:
    """``scale`` rounded to the ladder ``2**(k/4)`` inside the slider's range: the Scale slider's
    values, so every value it can reach is one the bake worker pre-warms (and 1, 1/2, 1/4, 1/8 are
    on it: the scales at which harmonised seams are exactly 0)."""
    n = SCALE_STEPS_PER_OCTAVE
    v = float(2.0 ** (round(n * float(np.log2(float(scale)))) / n))
    return min(max(v, SCALE_MIN), SCALE_MAX)


def scale_neighbours(scale: float) -> list[float]:
    """The scales next to ``scale`` on the ladder ``2**(k/4)`` within the slider's range: the
    ladder values on either side (its neighbours when ``scale`` is on the ladder itself), smaller
    first. Values are ``2.0 ** (k / 4)`` exactly, as the benchmark's and the budget's ladder."""
    n = SCALE_STEPS_PER_OCTAVE
    x = n * float(np.log2(float(scale))) if scale > 0 else float("-inf")
    if not np.isfinite(x):
        return []
    k = round(x)
    if abs(x - k) < 1e-9:  # on the ladder
        ks = (k - 1, k + 1)
    else:
        ks = (int(np.floor(x)), int(np.ceil(x)))
    lo, hi = SCALE_MIN * (1 - 1e-9), SCALE_MAX * (1 + 1e-9)
    return [float(2.0 ** (j / n)) for j in ks if lo <= 2.0 ** (j / n) <= hi]


def neighbour_policies(policy: BakePolicy, deepest: int, previous: BakePolicy | None = None) -> list:
    """What a slider can reach from ``policy`` in one step: threshold +-1 (within 0 .. deepest + 1)
    and the neighbouring scales (:func:`scale_neighbours`), everything else unchanged; the slider
    that moved last from ``previous`` first, in the direction it moved. Empty for a budget
    policy (the baker chooses threshold and scale then)."""
    if policy.budget_mb is not None:
        return []
    t, sc = int(policy.threshold), float(policy.scale)
    ts = [u for u in (t + 1, t - 1) if 0 <= u <= deepest + 1]
    ss = scale_neighbours(sc)
    if previous is not None and previous.threshold > t:
        ts.reverse()  # moving down: the lower threshold first
    if previous is not None and previous.scale < sc:
        ss.reverse()  # moving up: the larger scale first
    first_scale = previous is not None and previous.scale != sc and previous.threshold == t
    tpols = [dataclasses.replace(policy, threshold=u) for u in ts]
    spols = [dataclasses.replace(policy, scale=v) for v in ss]
    return spols + tpols if first_scale else tpols + spols


class BakeWorker(LatestWorker):
    """Bakes on one worker thread; :meth:`submit` never blocks, :meth:`poll` returns the newest result.

    baker : the :class:`~iat.bake.Baker` (used by this thread only: a Baker is not thread-safe)
    prewarm : while idle, bake the neighbours of the last policy baked (:func:`neighbour_policies`),
      one per idle turn, to warm the Baker's caches (their results are dropped, nothing is
      published or uploaded). A request made meanwhile is taken as soon as the neighbour's bake
      reaches its next stage (the bake is cancelled there; caches stay valid) and the remaining
      neighbours are dropped for the new policy's. Bounded: the immediate neighbours only, and
      none for a day-cycle set, a budget policy, a request that brought a new source (a re-solve
      after a light edit streams those; the next slider step pre-warms again) or a failed bake.
      Needs a real Baker (``baker.solution``); a stand-in without one is never pre-warmed.
    warm_from : the policy already baked (the viewer's first bake, made by :class:`OpenJob`): its
      neighbours are pre-warmed as soon as the thread starts, unless a request comes first.

    Counters: ``prewarmed`` (neighbour bakes finished), ``prewarm_cancelled`` (stopped for a
    request), ``prewarm_log`` (the last 256: ``(policy, seconds, finished)``).
    """

    def __init__(
        self,
        baker: Baker,
        name: str = "iat-bake",
        prewarm: bool = True,
        warm_from: BakePolicy | None = None,
    ):
        self.baker = baker
        self.solutions = None  # the set baked with bake_set, or None
        self.source = 0  # generation of the source baked from (0: the one given here)
        self._pending_source: tuple[int, BakeSource] | None = None
        self.prewarm = bool(prewarm)
        self.prewarmed = 0
        self.prewarm_cancelled = 0
        self.prewarm_log: list[tuple[BakePolicy, float, bool]] = []
        self._warm_queue: list[BakePolicy] = []  # neighbours still to bake (under the lock)
        self._seed = warm_from  # planned by the thread on its first idle turn
        self._warming = False  # a neighbour bake is running (read under the lock)
        self._last_policy: BakePolicy | None = None
        self._deepest: tuple[Any, int] | None = None
        super().__init__(name)

    @property
    def bakes(self) -> int:
        """Bakes finished so far (failed ones included)."""
        return self.published

    def submit(
        self, policy: BakePolicy, source: BakeSource | None = None, generation: int | None = None
    ) -> None:
        """Ask for a bake of ``policy``; replaces a request not started yet. ``source`` switches
        to another solution (or set) first; its ``generation`` comes back in the result."""
        with self._cv:
            if source is not None:
                gen = self.source + 1 if generation is None else int(generation)
                self._pending_source = (gen, source)
            self._request(policy)

    @property
    def warming(self) -> bool:
        """Pre-warming: a neighbour bake runs or more are queued (not counted as :attr:`busy`)."""
        with self._cv:
            return self._warming or (self.prewarm and (bool(self._warm_queue) or self._seed is not None))

    def wait_warm(self, timeout: float = 60.0) -> bool:
        """Block until idle and done pre-warming (tests and the benchmark); True when so."""
        end = time.monotonic() + timeout
        with self._cv:
            while (
                self._running
                or self._pending is not None
                or self._warming
                or (self.prewarm and (self._warm_queue or self._seed is not None))
            ):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(min(left, 0.05))
        return True

    def _take(self) -> tuple[BakePolicy, tuple[int, BakeSource] | None]:
        source, self._pending_source = self._pending_source, None
        self._warm_queue, self._seed = [], None  # the new policy gets its own neighbours
        return super()._take(), source

    def _deepest_tree(self) -> int | None:
        """Deepest patch tree of the baker's solution (cached per baker), None without one."""
        sol = getattr(self.baker, "solution", None)
        if sol is None or not hasattr(sol, "patch_depth"):
            return None
        if self._deepest is None or self._deepest[0] is not self.baker:
            depth = np.asarray(sol.patch_depth())
            self._deepest = (self.baker, int(depth.max()) if depth.size else 0)
        return self._deepest[1]

    def _plan_prewarm(self, policy: BakePolicy, previous: BakePolicy | None) -> None:
        deepest = self._deepest_tree() if self.prewarm and self.solutions is None else None
        queue = [] if deepest is None else neighbour_policies(policy, deepest, previous)
        with self._cv:
            if self._pending is None:  # a newer request replaces them anyway
                self._warm_queue = queue

    def _work(self, request) -> None:
        policy, source = request
        t0 = time.perf_counter()
        previous, self._last_policy = self._last_policy, None
        try:
            if source is not None:
                gen, src = source
                self.baker, self.solutions, self.source = src.baker(), src.solutions, gen
            if self.solutions is not None:
                r = BakeResult(policy, baked=self.baker.bake_set(self.solutions, policy))
            else:
                r = BakeResult(policy, baked=self.baker.bake(policy))
        except Exception as e:  # shown in the window; the viewer keeps the last good bake
            log.debug("bake failed", exc_info=True)
            r = BakeResult(policy, error=error_text(e))
        r.seconds = time.perf_counter() - t0
        r.source = self.source
        if r.error is None:
            self._last_policy = policy
            # a slider step; not a new source (a re-solve streams those: its neighbours would
            # compete with the re-solve for the CPU, and be stale at its next result)
            if source is None:
                self._plan_prewarm(policy, previous)
        self._publish(r)

    def _idle(self) -> bool:
        """Bake the next queued neighbour (its result only warms the Baker's caches)."""
        with self._cv:
            if not self.prewarm or self._pending is not None or self._stop:
                return False
            seed, self._seed = self._seed, None
            if seed is None and not self._warm_queue:
                return False
            self._warming = True
        policy, finished, t0 = None, False, time.perf_counter()
        try:
            if seed is not None:
                self._last_policy = seed
                self._plan_prewarm(seed, None)
            with self._cv:
                if not self._warm_queue or self._pending is not None or self._stop:
                    return True
                policy = self._warm_queue.pop(0)
            t0 = time.perf_counter()
            self.baker.bake(policy, progress=lambda _f, _m: not self._superseded())
            finished = True
        except Cancelled:
            pass
        except Exception:  # a neighbour that cannot be baked is no error: the slider may never go there
            log.debug("pre-warm bake of %s failed", policy, exc_info=True)
        finally:
            dt = time.perf_counter() - t0
            with self._cv:
                self._warming = False
                if policy is not None:
                    if finished:
                        self.prewarmed += 1
                    elif self._pending is not None:
                        self.prewarm_cancelled += 1
                    self.prewarm_log.append((policy, dt, finished))
                    del self.prewarm_log[:-256]
                self._cv.notify_all()
        return True


class _Job:
    """One piece of work on a daemon thread: progress (``fraction``, ``message``), :meth:`cancel`,
    then ``result`` or ``error`` (one line). Subclasses set their fields, call
    ``super().__init__(label, thread_name)`` (it starts the thread) and implement :meth:`_work`."""

    def __init__(self, label: str, thread_name: str):
        self.label = label  # names the job in its error line
        self.fraction = 0.0
        self.message = "starting"
        self.started = time.perf_counter()
        self.result: Any = None
        self.error: str | None = None
        self._cancel = threading.Event()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)
        self._thread.start()

    # -- UI side -------------------------------------------------------------------------
    def cancel(self) -> None:
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def join(self, timeout: float | None = None) -> bool:
        return self._done.wait(timeout)

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    # -- worker side -----------------------------------------------------------------------
    def _progress(self, fraction: float, message: str) -> bool:
        self.fraction = float(min(max(fraction, 0.0), 1.0))
        self.message = str(message)
        return not self._cancel.is_set()

    def _work(self) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def _error_line(self, e: Exception) -> str:
        return f"{self.label}: {error_text(e)}"

    def _run(self) -> None:
        try:
            self.result = self._work()
        except Cancelled:
            self.error = f"{self.label}: cancelled"
        except Exception as e:
            log.debug("%s failed:\n%s", self.label, traceback.format_exc())
            self.error = self._error_line(e)
        finally:
            self._done.set()


@dataclass
class Opened:
    """A model or solution ready to show (made by :class:`OpenJob`)."""

    path: str
    scene: Any
    solution: Any
    baker: Baker
    baked: Any
    policy: BakePolicy
    solve_seconds: float = 0.0
    from_cache: str = ""
    bake_seconds: float = 0.0
    bake_error: str | None = None


class OpenJob(_Job):
    """Open ``path`` (model or ``.npz`` solution) on a worker thread.

    A model is solved with ``options`` unless a cached solution of the same file and options
    exists (``use_cache``); the load, then the solve, report progress (``fraction``, ``message``,
    :attr:`eta`, each stage from 0 to 1) and stop when :meth:`cancel` is called. Then the
    Baker is built and ``policy`` baked. When done, ``result`` (an :class:`Opened`) or ``error``
    (one line) is set.
    """

    def __init__(self, path: str | os.PathLike, options: SolveOptions, policy: BakePolicy, use_cache=True):
        self.path = str(path)
        self.options = options
        self.policy = policy
        self.use_cache = use_cache
        self.load_started: float | None = None
        self.solve_started: float | None = None
        super().__init__(self.path, "iat-open")

    @property
    def solving(self) -> bool:
        return self.solve_started is not None and not self.done

    @property
    def eta(self) -> float | None:
        """Seconds left for the stage under way (the load, then the solve), from its progress so
        far (None until it is measurable)."""
        started = self.solve_started if self.solve_started is not None else self.load_started
        if started is None or self.fraction < 0.02:
            return None
        spent = time.perf_counter() - started
        return spent * (1.0 - self.fraction) / self.fraction

    # -- worker side -----------------------------------------------------------------------
    def _load_progress(self, fraction: float, message: str) -> bool:
        return self._progress(fraction, f"loading: {message}")

    def _error_line(self, e: Exception) -> str:
        text = error_text(e)  # an IATError names its file already
        return text if isinstance(e, IATError) or self.path in text else f"{self.path}: {text}"

    def _work(self) -> Opened:
        from iat.io.scene import load_scene
        from iat.radiosity import solve
        from iat.radiosity.inputs import is_solution_path, open_solution

        p = Path(self.path)
        if not p.exists():
            raise LoadError("no such file", p)
        solve_seconds, cached = 0.0, ""
        if is_solution_path(p):
            self.message = "loading solution"
            self.load_started = time.perf_counter()
            scene, solution = open_solution(p, load_progress=self._load_progress)
            solve_seconds = float(solution.stats.get("time", 0.0) or 0.0)
        else:
            self.message = "loading model"
            self.load_started = time.perf_counter()
            scene = load_scene(p, max_edge=self.options.max_edge, progress=self._load_progress)
            solution = None
            cpath = solution_cache_path(p, self.options) if self.use_cache else None
            solution = load_cached(cpath, scene.n_patches) if cpath is not None else None
            if solution is not None:
                cached = str(cpath)
                solve_seconds = float(solution.stats.get("time", 0.0) or 0.0)
            if solution is None:
                self.message, self.fraction = "solving", 0.0
                self.solve_started = time.perf_counter()
                t0 = time.perf_counter()
                solution = solve(scene, self.options, progress=self._progress)
                solve_seconds = time.perf_counter() - t0
                if solution.stats.get("cancelled") or self._cancel.is_set():
                    raise Cancelled("solve cancelled")
                solution.model_path = solution.model_path or str(p)
                if cpath is not None:
                    try:
                        solution.save(cpath)
                    except OSError as e:  # a cache that cannot be written is no error
                        log.info("cannot cache the solution at %s: %s", cpath, e)
        if self._cancel.is_set():
            raise Cancelled("cancelled")
        self.message = "baking"
        self.fraction = 1.0
        baker = Baker(solution, scene)
        t0 = time.perf_counter()
        baked, bake_error = None, None
        try:
            baked = baker.bake(self.policy)
        except Exception as e:  # the model opens anyway; mesh mode works without a bake
            bake_error = error_text(e)
        return Opened(
            path=self.path,
            scene=scene,
            solution=solution,
            baker=baker,
            baked=baked,
            policy=self.policy,
            solve_seconds=solve_seconds,
            from_cache=cached,
            bake_seconds=time.perf_counter() - t0,
            bake_error=bake_error,
        )


# -- lighting: the day cycle's solve, light picking -------------------------------------------------
class SetJob(_Job):
    """Solve a model's lighting states on one mesh (:func:`iat.solution_set.solve_set`) on a worker
    thread, with progress (``fraction``, ``message``) and :meth:`cancel`; ``result`` (a
    :class:`~iat.solution_set.SolutionSet`) or ``error`` (one line) when done."""

    def __init__(self, scene, states: dict, options: SolveOptions, mesh: str = "merge"):
        self.scene, self.states, self.options, self.mesh = scene, states, options, mesh
        super().__init__("day cycle", "iat-day-cycle")

    def _work(self):
        from iat.lighting.solution_set import solve_set

        return solve_set(self.scene, self.states, self.options, self._progress, mesh=self.mesh)


def project_points(camera: Camera, points, rect) -> tuple[np.ndarray, np.ndarray]:
    """Window pixel positions of world ``points`` (k, 3) seen by ``camera`` in the view ``rect``
    (x, y from the top left, w, h): (k, 2) float64 and (k,) bool in front of the camera and inside."""
    x, y, w, h = (float(v) for v in rect)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if w <= 0 or h <= 0 or not len(p):
        return np.zeros((len(p), 2)), np.zeros(len(p), dtype=bool)
    c = np.concatenate([p, np.ones((len(p), 1))], axis=1) @ np.asarray(camera.clip_from_world(w / h)).T
    front = c[:, 3] > 1e-9
    ndc = c[:, :3] / np.where(front, c[:, 3], 1.0)[:, None]
    px = np.stack([x + (ndc[:, 0] + 1) * 0.5 * w, y + (1 - ndc[:, 1]) * 0.5 * h], axis=1)
    inside = front & (np.abs(ndc[:, :2]) <= 1.0).all(axis=1) & (np.abs(ndc[:, 2]) <= 1.0)
    return px, inside


def pick_light(camera: Camera, lights, rect, mouse, radius: float = 12.0) -> int:
    """Index of the light whose marker is nearest to ``mouse`` (window pixels) within ``radius``, or -1."""
    if not lights:
        return -1
    px, ok = project_points(camera, [lt.position for lt in lights], rect)
    d = np.linalg.norm(px - np.asarray(mouse, dtype=np.float64)[None, :], axis=1)
    d[~ok] = np.inf
    k = int(np.argmin(d))
    return k if d[k] <= radius else -1


def mouse_ray(camera: Camera, rect, mouse) -> tuple[np.ndarray, np.ndarray]:
    """World origin and unit direction of the ray through window pixel ``mouse``."""
    x, y, w, h = (float(v) for v in rect)
    nx = (float(mouse[0]) - x) / w * 2.0 - 1.0
    ny = 1.0 - (float(mouse[1]) - y) / h * 2.0
    inv = np.linalg.inv(np.asarray(camera.clip_from_world(w / h), dtype=np.float64))
    a = inv @ np.array([nx, ny, -1.0, 1.0])
    b = inv @ np.array([nx, ny, 1.0, 1.0])
    a, b = a[:3] / a[3], b[:3] / b[3]
    d = b - a
    return a, d / max(float(np.linalg.norm(d)), 1e-300)


def drag_on_plane(camera: Camera, rect, mouse, height: float, bounds=None, margin: float = 0.02):
    """Where the ray through ``mouse`` meets the horizontal plane ``y = height`` (a light dragged at
    its height), kept inside ``bounds`` (2, 3) shrunk by ``margin`` of its size; None when the ray
    runs away from the plane (or parallel to it)."""
    o, d = mouse_ray(camera, rect, mouse)
    if abs(d[1]) < 1e-9:
        return None
    t = (float(height) - o[1]) / d[1]
    if t <= 0:
        return None
    p = o + t * d
    if bounds is not None:
        lo, hi = np.asarray(bounds, dtype=np.float64)
        m = margin * (hi - lo)
        p = np.clip(p, lo + m, hi - m)
        p[1] = float(height)
    return p


# -- the state ---------------------------------------------------------------------------------------
@dataclass
class AppState:
    """Everything the viewer shows and the panels change (see the module docstring).

    Requests (``request_*``) are set by panels and consumed by the app on its next frame.
    ``view_rect`` is the 3D view's rectangle in window pixels (x, y from the top left, w, h),
    updated every frame from the central dock node.
    """

    # what is open
    model_path: str = ""
    scene: Any = None
    solution: Any = None
    baker: Baker | None = None
    baked: Any = None  # the bake on screen (the last good one)
    solve_options: SolveOptions = field(default_factory=lambda: SolveOptions())
    use_cache: bool = True
    tuning: Tuning = field(default_factory=Tuning)
    # view
    mode: str = "iat"
    split: float = 0.5
    diff_gain: float = 8.0
    tonemap: bool = True
    dragging_split: bool = False
    looking: bool = False
    nav: Navigator | None = None
    camera: Camera | None = None
    camera_index: int = 0
    # camera paths
    paths: dict[str, CameraPath] = field(default_factory=dict)
    path_name: str = ""
    recorder: PathRecorder | None = None
    record_started: float = 0.0
    player: PathPlayer | None = None
    play_started: float = 0.0
    playback_frames: int = 0  # 0: real time; N: exactly N frames (benchmark)
    play_frame_ms: list[float] = field(default_factory=list)
    # background work
    open_job: OpenJob | None = None
    bake_worker: BakeWorker | None = None
    requested_policy: BakePolicy | None = None
    bake_seconds: float = 0.0
    solve_seconds: float = 0.0
    solution_from_cache: str = ""
    rebakes: int = 0
    uploads: int = 0
    # lighting: edits, the background re-solve, the day cycle
    editor: Any = None  # iat.lighting.LightEditor of the open model
    relighter: Any = None  # iat.lighting.Relighter (re-solves after edits)
    relight_version: int = 0  # the editor version last submitted
    relight_step: tuple[int, int] = (0, 0)  # (step, steps) of the last result shown
    relight_seconds: float = 0.0  # time from the edit to the last result shown
    relights: int = 0  # results shown
    relight_submitted: float = 0.0  # when the last edit was submitted (throttles drags)
    selected_light: int = -1
    dragging_light: bool = False
    show_lights: bool = True
    lighting_states: dict = field(default_factory=dict)  # the model's named states
    set_job: SetJob | None = None
    solution_set: Any = None  # iat.solution_set.SolutionSet of the day cycle
    day_cycle: bool = False  # show the set blended at day_time
    day_time: float = 0.0
    bake_source: int = 0  # generation of the source the bake on screen came from
    # messages
    error: str = ""  # shown until dismissed
    errors: list[str] = field(default_factory=list)
    status: str = ""
    last_screenshot: str = ""
    # statistics
    frame_ms: np.ndarray = field(default_factory=lambda: np.zeros(FRAME_HISTORY, np.float32))
    frames: int = 0
    render_stats: dict = field(default_factory=dict)
    view_rect: tuple[int, int, int, int] = (0, 0, 0, 0)
    framebuffer_scale: tuple[float, float] = (1.0, 1.0)
    # requests from panels
    request_open: str | None = None
    request_export: str | None = None
    request_screenshot: str | None = None
    request_save_paths: bool = False
    request_save_solution: str | None = None
    request_save_lights: str | None = None
    request_day_cycle: bool = False
    request_remesh: bool = False
    request_quit: bool = False
    # file dialogs in flight (portable_file_dialogs objects) and the Model panel's path fields
    dialogs: dict = field(default_factory=dict)
    file_fields: dict = field(
        default_factory=lambda: {"open": "", "export": "", "solution": "", "lights": ""}
    )

    # -- derived ---------------------------------------------------------------------------
    def policy(self) -> BakePolicy:
        return self.tuning.policy()

    @property
    def loaded(self) -> bool:
        return self.solution is not None

    @property
    def deepest(self) -> int:
        """Deepest patch tree of the solution (the threshold slider's top is one more)."""
        if self.solution is None:
            return 0
        d = getattr(self, "_deepest_cache", None)
        if d is None or d[0] is not self.solution:
            depth = np.asarray(self.solution.patch_depth())
            d = (self.solution, int(depth.max()) if depth.size else 0)
            self._deepest_cache = d
        return d[1]

    @property
    def memory(self) -> dict:
        """The shown bake's :class:`~iat.bake.MemoryReport` as a dict ({} when none); a day-cycle
        set's counts every state's texture layers (``solutions``)."""
        return self.baked.memory.to_dict() if self.baked is not None else {}

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

    @property
    def mesh_triangles(self) -> int:
        return 0 if self.solution is None else int(len(self.solution.tri_vertices))

    @property
    def iat_triangles(self) -> int:
        m = self.memory
        return int(m.get("triangles_mesh_part", 0) + m.get("triangles_textured_part", 0))

    @property
    def rebaking(self) -> bool:
        return self.bake_worker is not None and self.bake_worker.busy

    @property
    def opening(self) -> bool:
        return self.open_job is not None and not self.open_job.done

    @property
    def cameras(self) -> list[Camera]:
        return list(self.scene.cameras) if self.scene is not None else []

    # -- messages --------------------------------------------------------------------------
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

    # -- frames ----------------------------------------------------------------------------
    def add_frame_time(self, ms: float) -> None:
        self.frame_ms[self.frames % FRAME_HISTORY] = ms
        self.frames += 1

    def frame_history(self) -> np.ndarray:
        """(n,) float32 frame times in ms, oldest first (n <= FRAME_HISTORY)."""
        n = min(self.frames, FRAME_HISTORY)
        if self.frames <= FRAME_HISTORY:
            return self.frame_ms[:n].copy()
        k = self.frames % FRAME_HISTORY
        return np.concatenate([self.frame_ms[k:], self.frame_ms[:k]])

    @property
    def fps(self) -> float:
        h = self.frame_history()[-60:]
        m = float(np.mean(h)) if h.size else 0.0
        return 1000.0 / m if m > 0 else 0.0

    # -- paths -----------------------------------------------------------------------------
    def start_recording(self, name: str | None = None) -> None:
        self.player = None
        n = 1
        while name is None or name in self.paths:
            name, n = f"recorded {n}", n + 1
        self.recorder = PathRecorder(name)
        self.record_started = time.perf_counter()

    def stop_recording(self) -> CameraPath | None:
        rec, self.recorder = self.recorder, None
        if rec is None or not rec.cameras:
            return None
        path = rec.path()
        self.paths[path.name] = path
        self.path_name = path.name
        self.set_status(f"recorded path {path.name!r}: {len(path)} poses, {path.duration():.1f} s")
        return path

    def start_playback(self, name: str | None = None, frames: int | None = None) -> None:
        name = name or self.path_name
        if name not in self.paths:
            self.set_error(f"no camera path named {name!r}")
            return
        self.recorder = None
        frames = self.playback_frames if frames is None else frames
        self.player = PathPlayer(self.paths[name], frames=frames or None)
        self.play_started = time.perf_counter()
        self.play_frame_ms = []
        self.path_name = name

    def stop_playback(self) -> None:
        """Stop playing; walking goes on from the last pose shown."""
        p, self.player = self.player, None
        if p is not None and self.nav is not None and self.camera is not None:
            self.nav.set_camera(self.camera)
        if p is not None and self.play_frame_ms:
            f = np.asarray(self.play_frame_ms)
            self.set_status(
                f"played {p.path.name!r}: {len(f)} frames, mean {f.mean():.1f} ms, "
                f"max {f.max():.1f} ms ({1000.0 / max(f.mean(), 1e-9):.0f} fps)"
            )

    def policy_summary(self) -> str:
        b = self.baked
        if b is None:
            return ""
        p = b.policy
        return f"threshold {p.threshold}, scale {p.scale:.3g}, {p.method}"


def replace_tuning(state: AppState, **kw) -> None:
    """Set tuning fields by name (tests and scripts): ``replace_tuning(state, threshold=3)``."""
    state.tuning = dataclasses.replace(state.tuning, **kw)
