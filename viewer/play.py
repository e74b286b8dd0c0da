"""``iat view MODEL --play NAME --frames N --json``: play a camera path in the real viewer, no input.

:func:`play_path` opens the model in the real app (window, panels, idling off), waits for the
model, its bake and the exposure, then for each mode plays the camera path ``NAME`` (a path of
the model or of its ``MODEL.paths.json``, as listed in the View panel; or a ``.paths.json``
file, whose ``default`` or first path is played) over exactly ``frames`` frames, and returns
frame-time statistics per mode (:func:`frame_statistics`) with the window and viewport sizes.
A frame's time is the interval between two buffer swaps: everything the app does in a frame,
panels and present included (what the user waits for). ``cpu_ms`` is the process's CPU time per
frame over the playback (every thread, llvmpipe's included): on a machine shared with other work
it shows the cost where wall-clock times show the load.
"""

from __future__ import annotations

import os
import resource
import sys
import time
from pathlib import Path

import numpy as np
from imgui_bundle import hello_imgui

from iat.errors import IATError, OptionError
from viewer.navigation import load_paths

#: frames played before each mode's measured playback (shader variants, texture residency)
WARMUP_FRAMES = 5


def cpu_seconds() -> float:
    """User + system CPU seconds of this process, all threads."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return float(r.ru_utime + r.ru_stime)


def frame_statistics(ms) -> dict:
    """``{"frames", "mean_ms", "p50_ms", "p95_ms", "max_ms", "fps"}`` of frame times in ms
    (``fps`` = 1000 / mean)."""
    f = np.asarray(ms, dtype=np.float64)
    if f.size == 0:
        return {"frames": 0, "mean_ms": None, "p50_ms": None, "p95_ms": None, "max_ms": None, "fps": None}
    mean = float(f.mean())
    return {
        "frames": int(f.size),
        "mean_ms": mean,
        "p50_ms": float(np.median(f)),
        "p95_ms": float(np.percentile(f, 95)),
        "max_ms": float(f.max()),
        "fps": 1000.0 / mean if mean > 0 else None,
    }


def path_file_choice(name: str):
    """``(file, path name)`` when ``name`` is a ``.paths.json`` file (its ``default`` path, else its
    first), else None. Raises OptionError for a file without paths."""
    p = Path(name)
    if not (name.endswith(".json") or p.is_file()):
        return None
    paths = load_paths(p)
    if not p.is_file() or not paths:
        raise OptionError(f"{name}: no camera paths in it")
    return paths, ("default" if "default" in paths else next(iter(paths)))


class _Script:
    """The frame hook that drives the playback: open, settle, then one playback per mode."""

    def __init__(self, name: str, frames: int, modes, timeout_s: float):
        self.name, self.frames, self.modes = name, int(frames), list(modes)
        self.timeout_s = float(timeout_s)
        self.stage = "open"
        self.k = -1  # index into modes
        self.settle = 0
        self.started = time.monotonic()
        self.cpu0 = 0.0
        self.results: dict = {}
        self.error: str | None = None
        self.exit_code = 0
        self.viewport = (0, 0)
        self.solving_told = False

    def finish(self, error: str | None = None, code: int = 0) -> None:
        self.error, self.exit_code = error, code
        self.stage = "done"
        hello_imgui.get_runner_params().app_shall_exit = True

    def __call__(self, app) -> None:
        s = app.state
        if self.stage == "done":
            return
        if time.monotonic() - self.started > self.timeout_s:
            self.finish(f"timed out after {self.timeout_s:.0f} s ({self.stage})", 1)
            return
        if self.stage == "open":
            job = s.jobs.open_job
            if job is not None and job.solving and not self.solving_told:
                self.solving_told = True
                print(f"iat view: solving {job.path} (no cached solution)...", file=sys.stderr)
            if job is None and s.model.solution is None and s.messages.error:
                self.finish(s.messages.error, 1)
                return
            w = s.jobs.bake_worker
            warming = w is not None and w.warming  # the slider neighbours' bakes after an open
            busy = s.jobs.opening or s.jobs.rebaking or warming or app.pending_relit is not None
            shown = s.model.baked is not None or app.view3d.export is not None  # a bake, or an exported one
            if not shown or busy:
                return
            choice = None
            try:
                choice = path_file_choice(self.name)
            except IATError as e:
                self.finish(str(e), 2)
                return
            if choice is not None:
                paths, self.name = choice
                s.paths.named.update(paths)
            if self.name not in s.paths.named:
                known = ", ".join(s.paths.named) or "none"
                self.finish(f"no camera path named {self.name!r} (the model has: {known})", 2)
                return
            self.stage, self.settle = "settle", 3  # the first draws set the exposure
            return
        if self.stage == "settle":
            self.settle -= 1
            if self.settle <= 0:
                self._next_mode(s)
            return
        if self.stage in ("warmup", "play") and s.paths.player is None:
            if self.stage == "warmup":
                self.stage = "play"
                self.cpu0 = cpu_seconds()
                s.paths.playback_frames = self.frames  # as the View panel's "Frames N"
                s.start_playback(self.name, frames=self.frames)
                return
            cpu = (cpu_seconds() - self.cpu0) * 1000.0
            m = self.modes[self.k]
            stats = frame_statistics(s.paths.play_frame_ms)
            stats["cpu_ms"] = cpu / max(stats["frames"], 1)
            stats["shown_mode"] = app.shown_mode()
            self.results[m] = stats
            self._next_mode(s)

    def _next_mode(self, s) -> None:
        self.k += 1
        if self.k >= len(self.modes):
            self.finish()
            return
        s.view.mode = self.modes[self.k]
        self.stage = "warmup"
        s.paths.playback_frames = WARMUP_FRAMES
        s.start_playback(self.name, frames=WARMUP_FRAMES)


def play_path(
    make_app,
    path: str | os.PathLike,
    name: str = "default",
    *,
    frames: int = 120,
    modes=("mesh", "iat"),
    size: tuple[int, int] = (1280, 800),
    timeout_s: float = 1800.0,
) -> dict:
    """Play camera path ``name`` of ``path`` in the real viewer once per mode.

    make_app : ``make_app(frame_hook=..., idle=False)`` -> the :class:`~viewer.app.ViewerApp` that
      opens ``path`` (passed in: this module is below the app)

    Returns
    ``{"model", "path", "frames", "window": [w, h], "viewport": [w, h], "msaa", "modes": {mode:
    {"frames", "mean_ms", "p50_ms", "p95_ms", "max_ms", "fps", "cpu_ms", "shown_mode"}},
    "redraws", "blits", "error", "exit_code"}``. Needs a display; raises RuntimeError without."""
    frames = int(frames)
    if frames < 1:
        raise OptionError(f"--frames must be >= 1, got {frames}")
    bad = [m for m in modes if m not in ("mesh", "iat", "split", "diff")]
    if bad or not modes:
        raise OptionError(f"--modes: unknown mode(s) {', '.join(bad) or '(none)'} (mesh, iat, split, diff)")
    script = _Script(name, frames, modes, timeout_s)
    app = make_app(frame_hook=script, idle=False)
    app.run()
    if script.stage != "done":
        script.error, script.exit_code = "the window was closed before the playback ended", 1
    x, y, w, h = app.state.view.rect
    sx, sy = app.state.view.framebuffer_scale
    v3 = app.view3d
    return {
        "model": str(path),
        "path": script.name,
        "frames": frames,
        "window": list(size),
        "viewport": [int(round(w * sx)), int(round(h * sy))],
        "msaa": app.msaa,
        "modes": script.results,
        "redraws": v3.redraws if v3 is not None else None,
        "blits": v3.blits if v3 is not None else None,
        "error": script.error,
        "exit_code": script.exit_code,
    }


def format_play(res: dict) -> str:
    """The result of :func:`play_path` as a few lines for the terminal."""
    vw, vh = res["viewport"]
    lines = [f"{res['model']}: path {res['path']!r}, {res['frames']} frames, viewport {vw}x{vh}"]
    for m, st in res["modes"].items():
        if st["frames"]:
            lines.append(
                f"  {m:>5}: {st['fps']:6.1f} fps  mean {st['mean_ms']:6.1f} ms  p95 {st['p95_ms']:6.1f} ms"
                f"  cpu {st['cpu_ms']:6.1f} ms/frame"
            )
    return "\n".join(lines)
