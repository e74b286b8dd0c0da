"""The viewer's background jobs: opening a model or solution, and the day cycle's solve.

Each job runs once on its own daemon thread and reports progress (``fraction``, ``message``)
that the panels show; :meth:`~_Job.cancel` stops it at its next progress report. When done it
holds ``result`` or ``error`` (one line for the user, :func:`error_text`).

- :class:`OpenJob` loads a model or solution, solves a model that has none (progress, ETA,
  cancel; solutions are cached under :func:`iat.radiosity.cache.cache_dir`), builds the
  :class:`~iat.bake.baker.Baker` and makes the first bake: an :class:`Opened`. A GLB that
  ``iat bake`` wrote is not solved: it is read as it is (:func:`iat.render.glb_view.load_glb`)
  and shown as baked;
- :class:`SetJob` solves the model's lighting states on one mesh for the day-cycle slider.

The re-bakes run on :class:`viewer.bake_worker.BakeWorker`, the re-solves after light edits on
:class:`iat.lighting.relight.Relighter`.
"""

from __future__ import annotations

import hashlib
import logging
import os
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.errors import Cancelled, IATError, LoadError
from iat.radiosity import SolveOptions
from iat.radiosity.cache import load_cached, solution_cache_path

log = logging.getLogger(__name__)


def error_text(e: BaseException) -> str:
    """One line for the user: an IATError's own message, else the type and the message."""
    if isinstance(e, IATError):
        return str(e)
    return f"{type(e).__name__}: {e}"


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
    """A model or solution ready to show (made by :class:`OpenJob`).

    export : for a GLB that ``iat bake`` wrote, its :class:`~iat.render.glb_view.GlbDocument` (drawn
    as baked; ``solution``, ``baker`` and ``baked`` are None, ``scene`` is its geometry and cameras)
    """

    path: str
    scene: Any
    solution: Any
    baker: Baker | None
    baked: Any
    policy: BakePolicy
    solve_seconds: float = 0.0
    from_cache: str = ""
    bake_seconds: float = 0.0
    bake_error: str | None = None
    export: Any = None
    daylight_line: str = ""

    def status(self, mesh_triangles: int) -> str:
        """The status line once shown."""
        if self.export is not None:
            return (
                f"opened {self.path}: an exported bake ({self.export.triangles:,} triangles), drawn as the "
                "file stores it; open its model to tune or relight it"
            )
        what = "cached solution" if self.from_cache else f"solved in {self.solve_seconds:.1f} s"
        n = self.scene.n_patches
        opened = f"opened {self.path} ({n} patches, {mesh_triangles:,} mesh triangles, {what})"
        return f"{opened}; {self.daylight_line}" if self.daylight_line else opened


class OpenJob(_Job):
    """Open ``path`` (model or ``.npz`` solution) on a worker thread.

    A model is solved with ``options`` unless a cached solution of the same file and options
    exists (``use_cache``); the load, then the solve, report progress (``fraction``, ``message``,
    :attr:`eta`, each stage from 0 to 1) and stop when :meth:`cancel` is called. Then the
    Baker is built and ``policy`` baked. When done, ``result`` (an :class:`Opened`) or ``error``
    (one line) is set.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        options: SolveOptions,
        policy: BakePolicy,
        use_cache=True,
        daylight=None,
    ):
        self.path = str(path)
        self.daylight = daylight  # a DaylightRequest for a model (None: the default one)
        self.daylight_line = ""
        self.options = options
        self.policy = policy
        self.use_cache = use_cache
        self.load_started: float | None = None
        self.solve_started: float | None = None
        self.scene = None  # set once a model is loaded (before its solve)
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
    def load_progress(self, fraction: float, message: str) -> bool:
        """The model load's progress callback: ``message`` shown as ``loading: message``; False
        once cancelled."""
        return self._progress(fraction, f"loading: {message}")

    def _error_line(self, e: Exception) -> str:
        text = error_text(e)  # an IATError names its file already
        return text if isinstance(e, IATError) or self.path in text else f"{self.path}: {text}"

    def _work(self) -> Opened:
        from iat.geometry.discontinuity import cut_new_lights
        from iat.io.load import load_scene
        from iat.lighting.daylight_default import apply_daylight
        from iat.radiosity import solve
        from iat.radiosity.inputs import is_solution_path, open_solution
        from iat.render.glb_view import is_iat_export

        p = Path(self.path)
        if not p.exists():
            raise LoadError("no such file", p)
        if is_iat_export(p):
            return self._open_export(p)
        solve_seconds, cached = 0.0, ""
        if is_solution_path(p):
            self.message = "loading solution"
            self.load_started = time.perf_counter()
            scene, solution = open_solution(p, load_progress=self.load_progress)
            solve_seconds = float(solution.stats.get("time", 0.0) or 0.0)
        else:
            self.message = "loading model"
            self.load_started = time.perf_counter()
            scene = load_scene(p, progress=self.load_progress, **self.options.load_kwargs())
            self.daylight_line = apply_daylight(scene, self.daylight) or ""  # a model without lights
            if self.options.discontinuity:  # a sun the daylight added: its shadows cut as the file's
                scene = cut_new_lights(scene)
            self.scene = scene  # the model, before its solve: the viewer shows it unlit meanwhile
            solution = None
            cpath = solution_cache_path(p, self.options) if self.use_cache else None
            if cpath is not None and self.daylight_line:  # the daylight chosen is part of the key
                tag = hashlib.sha1(self.daylight_line.encode()).hexdigest()[:10]
                cpath = cpath.with_name(f"{cpath.stem}-daylight-{tag}{cpath.suffix}")
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
            daylight_line=self.daylight_line,
        )

    def _open_export(self, p: Path) -> Opened:
        """An exported bake: its geometry and cameras as a scene, its primitives and textures to draw."""
        from iat.io.load import load_scene
        from iat.render.glb_view import load_glb

        self.message = "loading exported bake"
        self.load_started = time.perf_counter()
        scene = load_scene(p, progress=self.load_progress)
        doc = load_glb(p)
        if self._cancel.is_set():
            raise Cancelled("cancelled")
        return Opened(self.path, scene, None, None, None, self.policy, export=doc)


# -- the day cycle's solve ---------------------------------------------------------------------------
class SetJob(_Job):
    """Solve a model's lighting states on one mesh (:func:`iat.lighting.solution_set.solve_set`) on a worker
    thread, with progress (``fraction``, ``message``) and :meth:`cancel`; ``result`` (a
    :class:`~iat.lighting.solution_set.SolutionSet`) or ``error`` (one line) when done."""

    def __init__(self, scene, states: dict, options: SolveOptions, mesh: str = "merge"):
        self.scene, self.states, self.options, self.mesh = scene, states, options, mesh
        super().__init__("day cycle", "iat-day-cycle")

    def _work(self):
        from iat.lighting.solution_set import solve_set

        return solve_set(self.scene, self.states, self.options, self._progress, mesh=self.mesh)
