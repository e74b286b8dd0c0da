"""Driving the real viewer for measurements and pictures (both need a display).

:func:`benchmark_rebake_frames` measures frame times while the threshold, scale and method
sliders move (``python -m viewer --bench``); :func:`capture_screenshots` writes the README's
pictures (``python -m viewer --screenshots DIR``).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from imgui_bundle import hello_imgui, imgui

from iat.bake.flatten import METHODS
from iat.radiosity import SolveOptions
from viewer.app import ViewerApp
from viewer.jobs import OpenJob
from viewer.state import AppState, ModelState, default_model


def _sweep_values(name: str, deepest: int, steps: int) -> list:
    """The slider positions a sweep visits, in order (a drag back and forth)."""

    if name == "threshold":
        up = list(range(deepest + 2))
        seq = up + up[-2:0:-1]
    elif name == "scale":
        half = [float(0.25 * 8.0 ** (k / 7)) for k in range(8)]
        seq = half + half[-2:0:-1]
    elif name == "method":
        seq = list(METHODS)
    else:
        raise ValueError(f"unknown sweep {name!r} (threshold, scale, method)")
    return [seq[k % len(seq)] for k in range(steps)]


def benchmark_rebake_frames(
    path: str | os.PathLike | None = None,
    *,
    sweeps: tuple[str, ...] = ("threshold", "scale", "method"),
    steps: int = 24,
    drag_frames: int = 40,
    quiet_frames: int = 3,
    size: tuple[int, int] = (1280, 800),
    max_depth: int = 4,
    limit_ms: float = 50.0,
) -> dict:
    """Frame times while the tuning sliders move: what a re-bake costs the UI thread.

    Runs the real viewer (idling and vsync off) on ``path`` (default: the Cornell box, solved at
    ``max_depth``, cached). For each sweep ("threshold": 0 .. deepest + 1 and back; "scale":
    0.25 .. 2 and back; "method": bilinear / scan / bicubic):

    - **steps**: ``steps`` times, move the slider one position, let the frames run until the
      worker's bake is uploaded, then ``quiet_frames`` frames with nothing changing. A step's
      *re-bake cost* is how much slower its frames from the change to the upload were than the
      slowest quiet frame drawing the same bake (the previous step's quiet frames for the frames
      before the upload, its own for the upload frame): what the re-bake added beyond the
      frame-to-frame jitter, whatever the machine's load and whatever the bake costs to draw (an
      all-mesh bake draws slower; that is the mesh's cost, not the re-bake's).
    - **drag**: ``drag_frames`` frames with a new slider position every frame (a real drag;
      bakes overlap and coalesce), reported as frame-time statistics.

    Returns ``{sweep: {...}}`` with, per sweep: ``steps``; ``step_ms_max`` (slowest change-to-
    upload frame); ``quiet_ms_median``; ``cost_ms_median`` and ``cost_ms_max`` (re-bake cost);
    ``over_limit`` (steps whose slowest frame exceeds ``limit_ms``); ``cost_over_limit`` (steps
    whose re-bake cost exceeds ``limit_ms``); ``bake_ms_median`` (worker time per bake);
    ``set_baked_ms_median`` / ``set_baked_ms_max`` (the GL upload on the UI thread); and
    ``drag`` (``frames``, ``median_ms``, ``p95_ms``, ``max_ms``). Top level: ``ok`` (no
    step over the limit when every quiet frame is under it, "absolute"; else no re-bake
    cost over the limit, "cost": the machine itself is too slow or busy for the absolute test),
    ``judged_by``, ``limit_ms``, the model. Needs a display (xvfb-run); raises RuntimeError
    without one.
    """
    target = Path(path) if path else default_model()
    opts = SolveOptions(max_depth=max_depth)
    state = AppState(model=ModelState(solve_options=opts))
    state.tuning.threshold = 0
    job = OpenJob(target, opts, state.tuning.policy())
    job.join()
    if job.error:
        raise RuntimeError(f"benchmark: {job.error}")
    opened = job.result
    deepest = int(np.asarray(opened.solution.patch_depth()).max())
    fields = {"threshold": "threshold", "scale": "scale", "method": "method"}
    script: list[tuple[str, str, int, object]] = []  # (sweep, kind, step, value) per action
    for name in sweeps:
        script += [(name, "step", k, v) for k, v in enumerate(_sweep_values(name, deepest, steps))]
        script += [(name, "drag", k, v) for k, v in enumerate(_sweep_values(name, deepest, drag_frames))]
    run = {"i": -1, "warmup": 10, "wait": 0, "quiet": 0, "uploads": 0, "label": ("warmup", "quiet", -1)}

    def hook(app: ViewerApp) -> None:
        s = app.state
        if run["i"] == -1 and run["warmup"] == 10:
            app.adopt_next_draw(opened)
        if run["warmup"] > 0:
            run["warmup"] -= 1
            run["label"] = ("warmup", "quiet", -1)
            if run["warmup"] == 0:
                run["i"] = 0
            return
        i = run["i"]
        if i >= len(script):
            run["label"] = ("end", "quiet", -1)
            hello_imgui.get_runner_params().app_shall_exit = True
            return
        name, kind, k, value = script[i]
        if run["wait"]:  # a step waits for its upload (drawn in this frame), then its quiet frames
            run["label"] = (name, "change", k)
            if s.jobs.uploads > run["uploads"] or run["wait"] > 120:
                run["wait"] = 0
                run["quiet"] = quiet_frames
            else:
                run["wait"] += 1
            return
        if run["quiet"]:
            run["quiet"] -= 1
            run["label"] = (name, "quiet", k)
            if run["quiet"] == 0:
                run["i"] += 1
            return
        setattr(s.tuning, fields[name], value)
        run["label"] = (name, "change" if kind == "step" else "drag", k)
        if kind == "step":
            if s.tuning.policy() == s.jobs.requested_policy:  # nothing to re-bake at this position
                run["i"] += 1
                return
            run["uploads"] = s.jobs.uploads
            run["wait"] = 1
        else:
            run["i"] += 1

    labels: list[tuple[str, str, int]] = []

    def swap_hook(app: ViewerApp, record: dict) -> None:
        labels.append(run["label"])
        record["bake_ms"] = app.state.jobs.bake_seconds * 1000.0

    app = ViewerApp(None, size=size, state=state, frame_hook=hook, swap_hook=swap_hook, idle=False)
    app.frame_log = []
    app.run()

    # the label of a frame is set in its hook; its time is logged after its swap
    rows = list(zip(app.frame_log, labels, strict=False))
    out: dict = {"model": str(target), "max_depth": max_depth, "limit_ms": limit_ms, "size": list(size)}
    all_quiet_under = True
    for name in sweeps:
        by_step: dict[int, dict[str, list]] = {}
        for r, (sw, kind, k) in rows:
            if sw == name and kind in ("change", "quiet"):
                by_step.setdefault(k, {"change": [], "quiet": []})[kind].append(r)
        steps_ms, quiet_ms, costs = [], [], []
        prev_ref = None
        for k in sorted(by_step):
            rec = by_step[k]
            if not rec["change"] or not rec["quiet"]:
                continue
            ref = float(max(r["ms"] for r in rec["quiet"]))  # the slowest frame with nothing to re-bake
            # frames before the upload still draw the previous bake: compare them with its quiet frames
            before = [r["ms"] for r in rec["change"] if not r["upload"]]
            upload = [r["ms"] for r in rec["change"] if r["upload"]]
            old_ref = prev_ref if prev_ref is not None else ref
            cost = max([u - ref for u in upload] + [b - old_ref for b in before])
            steps_ms.append(max(r["ms"] for r in rec["change"]))
            quiet_ms += [r["ms"] for r in rec["quiet"]]
            costs.append(cost)
            prev_ref = ref
        ups = [r for r, (sw, kind, _) in rows if sw == name and kind == "change" and r["upload"]]
        drag = np.array([r["ms"] for r, (sw, kind, _) in rows if sw == name and kind == "drag"])
        steps_ms_a, costs_a, quiet_a = np.array(steps_ms), np.array(costs), np.array(quiet_ms)
        out[name] = {
            "steps": int(costs_a.size),
            "step_ms_max": float(steps_ms_a.max()) if steps_ms_a.size else None,
            "quiet_ms_median": float(np.median(quiet_a)) if quiet_a.size else None,
            "quiet_ms_max": float(quiet_a.max()) if quiet_a.size else None,
            "cost_ms_median": float(np.median(costs_a)) if costs_a.size else None,
            "cost_ms_max": float(costs_a.max()) if costs_a.size else None,
            "over_limit": int((steps_ms_a > limit_ms).sum()),
            "cost_over_limit": int((costs_a > limit_ms).sum()),
            "bake_ms_median": float(np.median([r["bake_ms"] for r in ups])) if ups else None,
            "set_baked_ms_median": float(np.median([r["upload_ms"] for r in ups])) if ups else None,
            "set_baked_ms_max": float(max(r["upload_ms"] for r in ups)) if ups else None,
            "drag": {
                "frames": int(drag.size),
                "median_ms": float(np.median(drag)) if drag.size else None,
                "p95_ms": float(np.percentile(drag, 95)) if drag.size else None,
                "max_ms": float(drag.max()) if drag.size else None,
            },
        }
        all_quiet_under &= bool(quiet_a.size) and float(quiet_a.max()) < limit_ms
    out["judged_by"] = "absolute" if all_quiet_under else "cost"
    key = "over_limit" if all_quiet_under else "cost_over_limit"
    out["ok"] = all(out[n][key] == 0 for n in sweeps)
    return out


def capture_screenshots(
    out_dir: str | os.PathLike,
    path: str | os.PathLike | None = None,
    *,
    size: tuple[int, int] = (1280, 800),
    solve_options: SolveOptions | None = None,
    threshold: int = 2,
) -> list[Path]:
    """Write the README's pictures: the whole window in each mode and the tuning panel.

    Drives the real app with the test engine (needs a display). Files: ``viewer-mesh.png``,
    ``viewer-iat.png``, ``viewer-split.png``, ``viewer-diff.png`` (gain 8) and
    ``viewer-tuning.png`` (the Tuning window alone). Returns the paths written.
    """
    from imgui_bundle.immapp import testing

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    app = ViewerApp(path or default_model(), size=size, solve_options=solve_options, idle=False)
    s = app.state
    s.tuning.threshold = threshold
    s.view.diff_gain = 8.0
    written: list[Path] = []

    def shoot(ctx, name: str, window: str | None = None) -> None:
        ctx.yield_(3)
        p = out / f"viewer-{name}.png"
        testing.capture(ctx, str(p), window=window)
        written.append(p)

    def tour(ctx) -> None:
        end = time.monotonic() + 600
        while (s.model.baked is None or s.jobs.rebaking or s.jobs.opening) and time.monotonic() < end:
            ctx.yield_()
        if s.model.baked is None:
            raise RuntimeError(f"capture_screenshots: nothing baked ({s.messages.error or 'timed out'})")
        for label, mode in (("Mesh", "mesh"), ("IAT", "iat"), ("Split", "split"), ("Difference", "diff")):
            ctx.item_click(f"//**/{label}")
            shoot(ctx, mode)
        ctx.item_click("//**/IAT")
        shoot(ctx, "tuning", window="Tuning")

    def relaxed_watchdog() -> None:
        io = imgui.test_engine.get_io(hello_imgui.get_imgui_test_engine())
        io.config_watchdog_warning = io.config_watchdog_kill_test = 900.0
        io.config_mouse_draw_cursor = False  # no test-engine cursor in the pictures

    params = app.runner_params()
    params.callbacks.register_tests = relaxed_watchdog
    testing.run(test_function=tour, runner_params=params, add_ons_params=app.addons())
    return written
