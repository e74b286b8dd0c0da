"""The viewer against the offscreen benchmark, in one run (issue 20).

    xvfb-run -a -s "-screen 0 1280x800x24" .venv/bin/python benchmarks/viewer_bench.py [--frames 120]

What it measures, each in its own process (Mesa aborts when a window context and an EGL context
share one), rounds interleaved so that the load of a shared machine hits all alike:

- **viewer**: ``iat view SOLUTION --play default --frames N --json`` on the house (the real app,
  1280x800 window, panels docked, idling off): frame time = swap to swap, per mode; and the same
  with the panel cache off (``IAT_VIEWER_PANEL_CACHE=0``: every frame draws the panels, as before
  :mod:`viewer.panel_cache`);
- **offscreen**: what ``iat bench`` times (:class:`iat.tools.bench.FrameTimer`: ``Renderer.draw``
  into an RGBA8 framebuffer, ``ctx.finish()`` per frame, EGL) over the same path
  (:func:`iat.tools.bench.interpolate_path` of the same poses) at the viewer's viewport size, with
  the viewer's bake policy;
- **empty app**: the viewer with nothing open (panel cache on and off) and a bare imgui-bundle
  window (one text line), at 1280x800, without multisampling (``--msaa8``: also at hello_imgui's
  default of 8 samples);
- **profile**: the viewer's frame in phases, ``ctx.finish()`` at each boundary (so each phase's GL
  work is counted in it; the sum exceeds an unprofiled frame), in hello_imgui's order: new frame
  (events, ``ImGui::NewFrame``), 3D view, panels and app logic (``show_gui`` and the docked
  windows: Python and imgui's widgets), ``ImGui::Render`` and drawing its lists, buffer swap;
  playing the path in IAT mode, and with nothing moving; with the panel cache's counts.

Also the process CPU time per frame (every thread, llvmpipe's rasteriser threads included): on a
machine shared with other work, wall-clock rates show the load, CPU time the work.

The house is solved once (cached, content-keyed) and the viewer opens that solution file, so a
solver change made meanwhile does not start a new solve in the middle of the run.
Writes ``benchmarks/viewer_bench.json`` (``--out``: elsewhere); prints a Markdown summary.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
HOUSE = ROOT / "sample_models" / "house.glb"
OUT = ROOT / "benchmarks" / "viewer_bench.json"
WINDOW = (1280, 800)


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return float(r.ru_utime + r.ru_stime)


def child(args: list[str], timeout: float = 1800.0, cache: bool = True) -> dict:
    """Run this script in ``--child`` mode (or a command) and parse the JSON it prints last.
    ``cache=False``: the viewer without its panel cache (``IAT_VIEWER_PANEL_CACHE=0``)."""
    env = dict(os.environ, IAT_VIEWER_PANEL_CACHE="1" if cache else "0")
    r = subprocess.run(args, capture_output=True, text=True, timeout=timeout, cwd=ROOT, env=env)
    if r.returncode != 0:
        raise RuntimeError(
            f"{' '.join(args)} failed ({r.returncode}):\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}"
        )
    out = r.stdout
    return json.loads(out[out.index("{") :])


# -- children ------------------------------------------------------------------------------------------
def run_offscreen(solution: str, frames: int, size: tuple[int, int], rounds: int) -> dict:
    """iat bench's frame timing of the solution's default path at ``size``, mesh and IAT."""
    import moderngl

    from iat.radiosity.inputs import open_solution
    from iat.render.renderer import Renderer
    from iat.tools.bench import FrameTimer, interpolate_path, path_poses
    from viewer.state import AppState

    scene, sol = open_solution(Path(solution))
    from iat.bake.baker import Baker

    baked = Baker(sol, scene).bake(AppState().tuning.policy())
    ctx = moderngl.create_standalone_context(backend="egl")
    r = Renderer(ctx)
    r.set_scene(scene)
    r.set_solution(sol)
    r.set_baked(baked)
    cams = interpolate_path(path_poses(scene), frames)
    timer = FrameTimer(r, size)
    out: dict = {"size": list(size), "frames": frames, "gl_renderer": ctx.info.get("GL_RENDERER", "")}
    try:
        for m in ("mesh", "iat"):
            timer.run(cams[:3], m)
        for m in ("mesh", "iat"):
            walls, cpus = [], []
            for _ in range(rounds):
                c0 = cpu_seconds()
                walls.append(timer.run(cams, m))
                cpus.append(cpu_seconds() - c0)
            k = int(np.argmin(walls))
            out[m] = {
                "fps": frames / walls[k],
                "mean_ms": 1000.0 * walls[k] / frames,
                "cpu_ms": 1000.0 * cpus[k] / frames,
                "rounds_s": walls,
            }
    finally:
        timer.release()
        r.release()
    return out


def run_window(kind: str, frames: int, msaa: int) -> dict:
    """Frame times of an empty window: ``kind`` "app" (the viewer, nothing open) or "bare"."""
    from imgui_bundle import hello_imgui, imgui, immapp

    times, cpus, last = [], [], [None, None]
    warm = 10

    def after_swap(extra=None):
        now, c = time.perf_counter(), cpu_seconds()
        if last[0] is not None:
            times.append((now - last[0]) * 1000.0)
            cpus.append((c - last[1]) * 1000.0)
        last[:] = [now, c]
        if extra is not None:
            extra()
        if len(times) >= frames + warm:
            hello_imgui.get_runner_params().app_shall_exit = True

    if kind == "bare":
        rp = hello_imgui.RunnerParams()
        rp.app_window_params.window_geometry.size = WINDOW
        rp.ini_disable = True  # no imgui.ini left in the working folder
        rp.fps_idling.enable_idling = False
        rp.fps_idling.vsync_to_monitor = False
        rp.renderer_backend_options.open_gl_options.anti_aliasing_samples = msaa
        rp.callbacks.show_gui = lambda: imgui.text("hello")
        rp.callbacks.after_swap = after_swap
        immapp.run(rp, immapp.AddOnsParams(with_implot=True))
    else:
        from viewer.app import ViewerApp

        app = ViewerApp(None, size=WINDOW, idle=False, msaa=msaa)
        rp = app.runner_params()
        own = rp.callbacks.after_swap
        rp.callbacks.after_swap = lambda: after_swap(own)
        immapp.run(rp, app.addons())
    t, c = np.array(times[warm:]), np.array(cpus[warm:])
    return {
        "kind": kind,
        "msaa": msaa,
        "frames": int(t.size),
        "mean_ms": float(t.mean()),
        "p95_ms": float(np.percentile(t, 95)),
        "fps": 1000.0 / float(t.mean()),
        "cpu_ms": float(c.mean()),
    }


def run_profile(solution: str | None, frames: int) -> dict:
    """The viewer's frame in phases (``ctx.finish()`` at each boundary): playing the default path in
    IAT mode (``moving``), then the same number of frames with nothing moving (``still``)."""
    from imgui_bundle import hello_imgui

    from viewer.app import ViewerApp

    st = {"stage": "open", "n": 0}
    rows: dict[str, list[dict]] = {"moving": [], "still": []}
    cur: dict[str, float] = {}
    app = None

    def mark(name: str) -> None:
        if app is not None and app.ctx is not None:
            app.ctx.finish()
        cur[name] = time.perf_counter()

    def hook(a) -> None:
        s = a.state
        if st["stage"] == "open":
            if solution is None or (s.model.baked is not None and not s.jobs.opening and not s.jobs.rebaking):
                s.view.mode = "iat"
                st["stage"], st["n"] = "moving", 0
                if solution is not None and "default" in s.paths.named:
                    s.paths.playback_frames = 10**6
                    s.start_playback("default", frames=frames + 5)
            return
        st["n"] += 1
        if st["stage"] == "moving" and st["n"] > frames:
            s.stop_playback()
            st["stage"], st["n"] = "still", 0
        elif st["stage"] == "still" and st["n"] > frames:
            st["stage"] = "done"
            hello_imgui.get_runner_params().app_shall_exit = True

    app = ViewerApp(solution, size=WINDOW, idle=False, frame_hook=hook)
    rp = app.runner_params()
    cb = rp.callbacks
    draw = cb.custom_background  # the app's own callbacks, wrapped in phase marks

    def background() -> None:
        mark("view0")
        draw()
        mark("view1")

    def after_swap(own) -> None:
        mark("end")
        if st["stage"] in rows and st["n"] > 5 and len(cur) == 6:
            rows[st["stage"]].append(dict(cur))
        own()

    own_start, own_render, own_swap = cb.pre_new_frame, cb.before_imgui_render, cb.before_swap

    def chain(name, own):
        def f():
            if own is not None and name != "swap":
                own()
            mark(name)
            if own is not None and name == "swap":
                own()

        return f

    cb.pre_new_frame = lambda: (mark("start"), own_start())
    cb.custom_background = background
    cb.before_imgui_render = chain("imgui", own_render)
    cb.before_swap = chain("swap", own_swap)
    own = cb.after_swap
    cb.after_swap = lambda: after_swap(own)
    from imgui_bundle import immapp

    immapp.run(rp, app.addons())
    phases = {  # hello_imgui's order: NewFrame, custom_background (3D), show_gui + panels, Render
        "new_frame": ("start", "view0"),
        "view_3d": ("view0", "view1"),
        "panels_and_logic": ("view1", "imgui"),
        "imgui_render": ("imgui", "swap"),
        "swap": ("swap", "end"),
    }
    out = {}
    for stage, rs in rows.items():
        out[stage] = {
            k: float(np.mean([r[b] - r[a] for r in rs]) * 1000.0) if rs else None
            for k, (a, b) in phases.items()
        }
        out[stage]["frames"] = len(rs)
    out["redraws"], out["blits"] = app.view3d.redraws, app.view3d.blits
    pc = app.panel_cache
    out["panel_cache"] = {
        "partial": pc.partial_frames,
        "preserved": pc.preserved,
        "full": pc.full_frames,
        "skipped": pc.skipped_frames,
        "lean": pc.lean_frames,
    }
    return out


# -- the run -------------------------------------------------------------------------------------------
def solve_house(cache: Path) -> Path:
    """The house's solution (solver defaults, cached), written as ``cache/house.npz``."""
    from iat.radiosity.cache import cached_solve

    _, sol, info = cached_solve(HOUSE, None, cache)
    out = cache / "house.npz"
    sol.save(out)
    print(f"house: {'cached' if info['cached'] else 'solved'} ({info['solve_s']:.0f} s)", file=sys.stderr)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=120)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--cache", default=str(ROOT / "out" / "viewer_bench"))
    p.add_argument("--child", choices=["offscreen", "app", "bare", "profile"])
    p.add_argument("--solution")
    p.add_argument("--size", default="698x779")
    p.add_argument("--msaa", type=int, default=0)
    p.add_argument("--msaa8", action="store_true", help="also the empty windows at 8 samples")
    p.add_argument("--out", default=str(OUT), help="where the results go (JSON)")
    a = p.parse_args(argv)
    if a.child:
        if a.child == "offscreen":
            w, h = (int(v) for v in a.size.split("x"))
            res = run_offscreen(a.solution, a.frames, (w, h), a.rounds)
        elif a.child == "profile":
            res = run_profile(a.solution, a.frames)
        else:
            res = run_window(a.child, a.frames, a.msaa)
        print(json.dumps(res))
        return 0
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        print("run under xvfb-run -a -s '-screen 0 1280x800x24'", file=sys.stderr)
        return 2
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    sol = Path(a.solution) if a.solution else solve_house(cache)  # --solution: a house solution made earlier
    me = [sys.executable, str(Path(__file__).resolve())]
    iat = [str(Path(sys.executable).with_name("iat"))]
    result: dict = {
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "loadavg_start": list(os.getloadavg()),
        },
        "frames": a.frames,
        "window": list(WINDOW),
        "rounds": [],
    }
    view = iat + ["view", str(sol), "--play", "default", "--frames", str(a.frames), "--json"]
    for k in range(a.rounds):
        rnd: dict = {"loadavg_start": list(os.getloadavg())}
        rnd["viewer"] = child(view)
        rnd["viewer_nocache"] = child(view, cache=False)
        vw, vh = rnd["viewer"]["viewport"]
        off = [
            "--child",
            "offscreen",
            "--solution",
            str(sol),
            "--frames",
            str(a.frames),
            "--size",
            f"{vw}x{vh}",
        ]
        rnd["offscreen"] = child(me + off)
        for kind in ("app", "bare"):
            for msaa in (0, 8) if a.msaa8 else (0,):
                args = me + ["--child", kind, "--frames", str(max(a.frames, 200)), "--msaa", str(msaa)]
                rnd[f"{kind}_msaa{msaa}"] = child(args)
                if kind == "app" and msaa == 0:
                    rnd["app_msaa0_nocache"] = child(args, cache=False)
        rnd["loadavg"] = list(os.getloadavg())
        o = rnd["offscreen"]
        for key in ("viewer", "viewer_nocache"):
            v = rnd[key]["modes"]
            rnd[f"ratio_fps{key[6:]}"] = {m: v[m]["fps"] / o[m]["fps"] for m in ("mesh", "iat")}
            rnd[f"ratio_cpu{key[6:]}"] = {m: o[m]["cpu_ms"] / v[m]["cpu_ms"] for m in ("mesh", "iat")}
        result["rounds"].append(rnd)
        print(
            f"round {k + 1}: fps ratio {json.dumps(rnd['ratio_fps'])}, "
            f"no panel cache {json.dumps(rnd['ratio_fps_nocache'])}",
            file=sys.stderr,
        )
    result["profile_house"] = child(me + ["--child", "profile", "--solution", str(sol), "--frames", "60"])
    result["profile_empty"] = child(me + ["--child", "profile", "--frames", "60"])
    result["machine"]["loadavg_end"] = list(os.getloadavg())
    Path(a.out).write_text(json.dumps(result, indent=1))
    print(summary(result))
    return 0


def summary(res: dict) -> str:
    """Markdown tables of a run."""
    lines = [
        f"{res['frames']} frames of the house's default path; window {res['window'][0]}x{res['window'][1]}; "
        f"load average {res['machine']['loadavg_start'][0]:.1f} at the start, "
        f"{res['machine']['loadavg_end'][0]:.1f} at the end ({res['machine']['cpus']} cores).",
        "",
        "| round (load) | mode | viewer fps | viewer fps, no panel cache | offscreen fps | ratio | ratio, no"
        " cache | viewer CPU ms/frame | no cache | offscreen CPU ms/frame |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for k, r in enumerate(res["rounds"]):
        load = r.get("loadavg_start", r["loadavg"])[0]
        for m in ("mesh", "iat"):
            v, n, o = r["viewer"]["modes"][m], r["viewer_nocache"]["modes"][m], r["offscreen"][m]
            lines.append(
                f"| {k + 1} ({load:.1f}) | {m} | {v['fps']:.1f} | {n['fps']:.1f} | {o['fps']:.1f} |"
                f" {r['ratio_fps'][m]:.2f} | {r['ratio_fps_nocache'][m]:.2f} | {v['cpu_ms']:.1f} |"
                f" {n['cpu_ms']:.1f} | {o['cpu_ms']:.1f} |"
            )
    lines += [
        "",
        "| round | window | MSAA | fps | mean ms | p95 ms | CPU ms/frame |",
        "|---|---|---|---|---|---|---|",
    ]
    names = {"app": "viewer, nothing open", "app_nocache": "viewer, nothing open, no panel cache"}
    for k, r in enumerate(res["rounds"]):
        for key in sorted(x for x in r if x.startswith(("app_", "bare_"))):
            e = r[key]
            kind = key.split("_msaa")[0] + ("_nocache" if key.endswith("_nocache") else "")
            name = names.get(kind, "bare imgui-bundle")
            lines.append(
                f"| {k + 1} | {name} | {e['msaa']} | {e['fps']:.1f} | {e['mean_ms']:.1f} |"
                f" {e['p95_ms']:.1f} | {e['cpu_ms']:.1f} |"
            )
    lines += [
        "",
        "| profile (ms, ctx.finish() per phase) | new frame | 3D view | panels + logic | imgui render"
        " | swap | redraws / blits | panels drawn (partly) / kept (lean) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name in ("profile_house", "profile_empty"):
        pr = res[name]
        for stage in ("moving", "still"):
            ph = pr[stage]
            if not ph["frames"]:
                continue
            vals = " | ".join(
                f"{ph[k]:.1f}" for k in ("new_frame", "view_3d", "panels_and_logic", "imgui_render", "swap")
            )
            pc = pr.get("panel_cache", {})
            g = {k: pc.get(k, "-") for k in ("full", "partial", "skipped", "lean")}
            cache = f"{g['full']} ({g['partial']}) / {g['skipped']} ({g['lean']})"
            lines.append(
                f"| {name.split('_')[1]} {stage} | {vals} | {pr['redraws']} / {pr['blits']} | {cache} |"
            )
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
