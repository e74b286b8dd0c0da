"""The IAT desktop viewer: imgui-bundle (hello_imgui docking + implot) around a moderngl 3D view.

``main(path)`` opens a model or solution (default: the Cornell box) and runs the
window until it is closed (``iat view`` loads it through the ``iat.apps`` entry point).
:class:`ViewerApp` is the runner and its callbacks: the 3D view is drawn in hello_imgui's
``custom_background`` callback into the central dock node's rectangle (the viewport is set
every frame) by :class:`~viewer.view3d.View3D`, only when what it shows changed (else its last
image is copied); the window has no multisampling (``msaa``); the panels (:mod:`viewer.panels`)
dock around it and change the :class:`~viewer.state.AppState`; they are drawn only when they may
have changed (:mod:`viewer.panel_cache`: else the window keeps their pixels). Every frame the app:

1. picks up finished background work: an opened model (:class:`~viewer.jobs.OpenJob`)
   or a re-bake (:class:`~viewer.bake_worker.BakeWorker`), and uploads it to the
   :class:`~iat.render.renderer.Renderer` (GL happens on this thread only); a failure
   shows an error and keeps the last good model and bake;
2. submits a re-bake when the tuning panel changed the policy (the previous
   bake stays on screen until the new one arrives);
3. moves the camera (:mod:`viewer.controls`: keyboard, mouse, gamepad, or a
   camera path being played) and records it when a path is being recorded;
4. serves the panels' requests: open, export GLB, save solution / paths, screenshot.
5. lighting: hands light edits to the background re-solve (:class:`~iat.lighting.relight.Relighter`:
   resolve from the last converged solution, coarse step first) and shows every
   improvement as it arrives (mesh at once, the re-bake follows); solves the model's
   lighting states for the day cycle (:class:`~viewer.jobs.SetJob`) and blends them
   at the time-of-day slider (one pass on the GPU: ``Renderer.set_blend``).

Measurements and pictures that drive this app are in :mod:`viewer.bench`; ``iat view MODEL --play
NAME`` (:mod:`viewer.play`) plays a camera path and prints its frame times.
"""

from __future__ import annotations

import gc
import logging
import os
import sys
import threading
import time
from pathlib import Path

import imgui_bundle  # noqa: F401  # before glfw: points pyGLFW at imgui-bundle's own libglfw
import numpy as np
from imgui_bundle import hello_imgui, imgui, immapp

import glfw  # isort: skip

from iat.errors import IATError
from iat.radiosity import SolveOptions
from viewer import background_io, controls, faults_view, overlay, panels, sun_panel
from viewer.bake_worker import BakeSource, BakeWorker
from viewer.jobs import Opened, OpenJob, SetJob, error_text
from viewer.navigation import CameraPath, load_paths, paths_file, save_paths, walker
from viewer.panel_cache import PanelCache
from viewer.relight import options_in_force, result_line
from viewer.state import AppState, default_model
from viewer.view3d import View3D, auto_exposure, screenshot

log = logging.getLogger(__name__)

WINDOW_TITLE = "IAT viewer"


def screenshot_dir() -> Path:
    """Where F12 writes: ``$IAT_SCREENSHOT_DIR``, else ``./screenshots``."""
    return Path(os.environ.get("IAT_SCREENSHOT_DIR") or Path.cwd() / "screenshots")


def freeze_heap() -> float:
    """Collect, then freeze every object alive now (the opened model, its Baker, the modules): the
    full collections Python runs now and then no longer walk them, so none lands on a slider step
    (~20-25 ms on a 470 k-element model). The previous freeze is undone first, so a model
    replaced by this one is still collected. Returns the seconds it took."""
    t0 = time.perf_counter()
    gc.unfreeze()
    gc.collect()
    gc.freeze()
    return time.perf_counter() - t0


class ViewerApp:
    """The viewer. ``ViewerApp(path).run()`` opens a window; tests pass :meth:`runner_params` to
    ``imgui_bundle.immapp.testing.run``.

    path : model or solution to open once the window is up (None: nothing)
    size : window size in pixels
    solve_options : options for models that need a solve (default :class:`SolveOptions`)
    frame_hook : called as ``frame_hook(app)`` at the start of every frame (scripts, benchmarks)
    swap_hook : called as ``swap_hook(app, record)`` after each buffer swap that added a
      ``record`` to :attr:`frame_log` (when measuring: the benchmark labels its frames)
    idle : let hello_imgui idle to a few fps when nothing moves (False for measurements)
    msaa : samples of the window's framebuffer (0: none; hello_imgui's default of 8 costs a
      software rasteriser such as llvmpipe most of every frame: 8 samples to clear and resolve)
    """

    def __init__(
        self,
        path: str | os.PathLike | None = None,
        *,
        size: tuple[int, int] = (1280, 800),
        solve_options: SolveOptions | None = None,
        state: AppState | None = None,
        frame_hook=None,
        swap_hook=None,
        idle: bool = True,
        msaa: int = 0,
        daylight=None,
    ):
        self.state = state or AppState()
        if solve_options is not None:
            self.state.model.solve_options = solve_options
        if daylight is not None:  # a DaylightRequest (iat view --sun/--sky/--no-daylight)
            self.state.model.daylight_request = daylight
        self.initial_path = None if path is None else str(path)
        self.size = (int(size[0]), int(size[1]))
        self.frame_hook = frame_hook
        self.swap_hook = swap_hook
        self.idle = idle
        self.msaa = int(msaa)
        self.view3d: View3D | None = None
        self.panel_cache = PanelCache()  # the docked panels are drawn only when they may have changed
        self.ctx = None
        self.renderer = None
        self.frame_log: list[dict] | None = None  # per-frame records when measuring
        self._pending_open: Opened | None = None  # opened, waiting for the next draw to upload it
        self._preview = None  # a loaded scene to show unlit while it solves (next draw)
        self._to_upload = None  # a BakeResult waiting for the next draw
        self._uploaded_this_frame = False
        self._upload_ms = 0.0
        self._bg_threads: list[threading.Thread] = []
        self._messages: list[tuple[str, str]] = []  # (kind, text) from background threads
        self._last_swap: float | None = None
        self._frame_t0: float | None = None  # when this frame started (pre_new_frame)
        self._frame_idle = False
        self.frames_drawn = 0
        self._relit = None  # a re-solved solution waiting for the next draw
        self._day_shown = False  # the renderer holds the day-cycle set (not the single solution)
        self._source_gen = 0  # generation of the last bake source submitted

    # -- setup -----------------------------------------------------------------------------------
    def runner_params(self) -> hello_imgui.RunnerParams:
        rp = hello_imgui.RunnerParams()
        rp.app_window_params.window_title = WINDOW_TITLE
        rp.app_window_params.window_geometry.size = self.size
        rp.app_window_params.restore_previous_geometry = False
        iw = rp.imgui_window_params
        iw.default_imgui_window_type = hello_imgui.DefaultImGuiWindowType.provide_full_screen_dock_space
        iw.show_menu_bar = True
        iw.show_menu_app = False
        iw.show_menu_view = True
        iw.show_status_bar = False
        rp.ini_disable = True  # the layout is the app's, not the last session's
        rp.fps_idling.enable_idling = bool(self.idle)
        rp.fps_idling.vsync_to_monitor = bool(self.idle)
        rp.renderer_backend_options.open_gl_options.anti_aliasing_samples = self.msaa
        cb = rp.callbacks
        cb.post_init = self._guard(self._post_init)
        cb.before_exit = self._before_exit
        cb.show_gui = self._guard(self._frame)
        cb.show_menus = self._guard(lambda: panels.menus(self.state))
        cb.custom_background = self._guard(self._draw)
        cb.post_render_dockable_windows = self._guard(self._central_rect)
        cb.after_swap = self._after_swap
        cb.pre_new_frame = self._frame_start
        cb.before_imgui_render = self._guard(self._before_render)
        cb.before_swap = self._guard(lambda: self.panel_cache.before_swap(self.ctx))
        dp = rp.docking_params
        dp.docking_splits = [
            hello_imgui.DockingSplit("MainDockSpace", "LeftSpace", imgui.Dir.left, 0.25),
            hello_imgui.DockingSplit("LeftSpace", "LeftBottom", imgui.Dir.down, 0.45),
            hello_imgui.DockingSplit("MainDockSpace", "RightSpace", imgui.Dir.right, 0.27),
            hello_imgui.DockingSplit("RightSpace", "RightBottom", imgui.Dir.down, 0.55),
        ]
        dp.dockable_windows = [
            self._window("Tuning", "LeftSpace", panels.tuning_panel),
            self._window("View", "LeftBottom", panels.view_panel),
            self._window("Model", "LeftBottom", panels.file_panel),
            self._window("Model faults", "LeftBottom", faults_view.panel),
            self._window("Stats", "RightSpace", panels.stats_panel),
            self._window("Lighting", "RightBottom", panels.lighting_panel),
            self._window("Sun & sky", "RightSpace", sun_panel.sun_sky_panel),
        ]
        return rp

    def _window(self, label, space, fn) -> hello_imgui.DockableWindow:
        draw = self._guard(lambda: self.panel_cache.panel(label, lambda: fn(self.state)))
        w = hello_imgui.DockableWindow(label, space, draw)
        w.can_be_closed = True
        return w

    @staticmethod
    def addons() -> immapp.AddOnsParams:
        return immapp.AddOnsParams(with_implot=True)

    def run(self) -> None:
        """Open the window and run until it is closed. Raises RuntimeError without a display."""
        immapp.run(self.runner_params(), self.addons())

    def _guard(self, fn):
        """Callbacks never raise into hello_imgui: an exception becomes an error message."""

        def wrapped():
            try:
                fn()
            except Exception as e:
                msg = f"internal error: {error_text(e)}"
                if msg != self.state.messages.error:  # once, not every frame
                    log.exception("viewer callback failed")
                    self.state.messages.set_error(msg)

        return wrapped

    # -- lifetime ----------------------------------------------------------------------------------
    def _post_init(self) -> None:
        import moderngl

        from iat.render.renderer import Renderer

        self.ctx = moderngl.create_context()
        self.renderer = Renderer(self.ctx)
        self.view3d = View3D(self.ctx, self.renderer)
        if self.initial_path:
            self.open(self.initial_path)

    def _before_exit(self) -> None:
        s = self.state
        if s.jobs.open_job is not None:
            s.jobs.open_job.cancel()
            s.jobs.open_job.join(30.0)
        if s.lighting.set_job is not None:
            s.lighting.set_job.cancel()
            s.lighting.set_job.join(30.0)
        if s.lighting.relighter is not None:
            s.lighting.relighter.close()
        if s.jobs.bake_worker is not None:
            s.jobs.bake_worker.close()
        for t in self._bg_threads:
            t.join(30.0)
        if self.view3d is not None:
            self.view3d.release()  # (its counts stay readable)
        if self.renderer is not None:
            try:
                self.renderer.release()
            except Exception:  # the context may already be gone
                log.debug("renderer release failed", exc_info=True)
            self.renderer = None

    # -- opening -----------------------------------------------------------------------------------
    def open(self, path: str | os.PathLike) -> None:
        """Start opening ``path`` in the background (an open in progress is cancelled)."""
        s = self.state
        if s.jobs.open_job is not None and not s.jobs.open_job.done:
            s.jobs.open_job.cancel()
        s.jobs.open_job = OpenJob(
            path,
            s.model.solve_options,
            s.tuning.policy(),
            use_cache=s.model.use_cache,
            daylight=s.model.daylight_request,
        )
        s.messages.set_status(f"opening {path}")

    def adopt_next_draw(self, opened: Opened) -> None:
        """Show ``opened`` from the next draw on (:meth:`adopt` runs there, where GL may be used)."""
        self._pending_open = opened

    @property
    def pending_relit(self):
        """The re-solved lighting (a Relighter result) waiting for the next draw, or None."""
        return self._relit

    def adopt(self, opened: Opened) -> None:
        """Make ``opened`` the shown model: upload it, then swap it into the state.

        On a GL failure the previous model stays (its data is uploaded again)."""
        s, r = self.state, self.renderer
        try:
            r.set_scene(opened.scene)
            r.set_sky(opened.scene.sky)  # the model's own sky behind it
            if opened.solution is not None:
                r.set_solution(opened.solution)
            if opened.baked is not None:
                r.set_baked(opened.baked)
            self.view3d.show_export(opened.export)
        except Exception as e:
            s.messages.set_error(f"{opened.path}: cannot show it: {error_text(e)}")
            self._restore()
            return
        if s.jobs.bake_worker is not None:
            s.jobs.bake_worker.close()
        s.model.path = opened.path
        for key in ("export", "solution"):  # derived from the model shown: re-derived from this one
            s.requests.file_fields[key] = ""
        s.requests.file_fields["open"] = str(opened.path)
        s.requests.auto_exposure = True
        s.model.scene, s.model.solution, s.model.baker = opened.scene, opened.solution, opened.baker
        s.model.baked = opened.baked
        warm = opened.policy if opened.baked is not None else None
        s.jobs.bake_worker = BakeWorker(opened.baker, warm_from=warm) if opened.baker is not None else None
        s.jobs.requested_policy = opened.policy
        s.model.solve_seconds = opened.solve_seconds
        s.model.from_cache = opened.from_cache
        s.model.daylight_line = opened.daylight_line
        s.jobs.bake_seconds = opened.bake_seconds
        s.jobs.rebakes += 1
        if opened.bake_error:
            s.messages.set_error(f"bake failed: {opened.bake_error}")
        if s.tuning.threshold > s.model.deepest + 1:
            s.tuning.threshold = s.model.deepest + 1
        cam = opened.scene.default_camera()
        s.view.nav = walker(opened.scene, cam)
        s.view.camera = s.view.nav.camera
        s.view.camera_index = 0
        s.paths.recorder = s.paths.player = None
        s.paths.named = {
            name: CameraPath(name, list(cams)) for name, cams in opened.scene.camera_paths.items()
        }
        try:
            s.paths.named.update(load_paths(paths_file(self._model_file())))
        except IATError as e:
            s.messages.set_error(str(e))
        s.paths.selected = next(iter(s.paths.named), "")
        self._reset_lighting(opened)
        freeze_heap()
        s.messages.set_status(opened.status(s.model.mesh_triangles))

    def _reset_lighting(self, opened: Opened) -> None:
        """A new model: a fresh light editor, background re-solve and day-cycle state."""
        from iat.lighting.editor import LightEditor
        from iat.lighting.states import lighting_states
        from viewer.relight import ProgressRelighter

        s = self.state
        if s.lighting.relighter is not None:
            s.lighting.relighter.close(5.0)
        if s.lighting.set_job is not None:
            s.lighting.set_job.cancel()
        lit = opened.solution is not None  # an exported bake has its light in its textures
        s.lighting.editor = LightEditor(opened.scene) if lit else None
        s.lighting.relighter = ProgressRelighter(opened.solution, opened.scene) if lit else None
        lt = s.lighting
        lt.relight_version, lt.relights, lt.relight_step, lt.relight_seconds = 0, 0, (0, 0), 0.0
        s.lighting.selected_light = 0 if opened.scene.lights else -1
        s.lighting.dragging_light = False
        s.lighting.set_job, s.lighting.solution_set, s.lighting.day_cycle, s.lighting.day_time = (
            None,
            None,
            False,
            0.0,
        )
        self._relit, self._day_shown = None, False
        s.requests.file_fields["lights"] = ""
        try:
            s.lighting.states = lighting_states(opened.scene)
        except IATError as e:
            s.lighting.states = {}
            s.messages.set_error(f"lighting states ignored: {e}")

    def _restore(self) -> None:
        """Upload the state's model and bake again (after a failed upload)."""
        s, r = self.state, self.renderer
        try:
            if s.model.scene is not None:
                r.set_scene(s.model.scene)
                r.set_sky(s.model.scene.sky)
            if s.model.solution is not None:
                r.set_solution(s.model.solution)
            if s.model.baked is not None:
                self._set_baked(s.model.baked)
        except Exception:
            log.exception("cannot restore the previous model")

    def _model_file(self) -> str:
        """The model a camera-paths file belongs to (a solution's model, else the opened file)."""
        s = self.state
        p = Path(s.model.path)
        if p.suffix.lower() == ".npz" and s.model.solution is not None and s.model.solution.model_path:
            return s.model.solution.model_path
        return str(p)

    # -- per frame: logic (show_gui) ------------------------------------------------------------------
    def _frame(self) -> None:
        s = self.state
        if self.frame_hook is not None:
            self.frame_hook(self)
        panels.poll_dialogs(s)
        while self._messages:
            kind, text = self._messages.pop(0)
            (s.messages.set_error if kind == "error" else s.messages.set_status)(text)
        self._serve_requests()
        self._poll_work()
        self._poll_lighting()
        self._submit_policy()
        controls.navigate(s, self.idle)
        controls.shortcuts(s)
        panels.error_window(s)
        overlay.view_overlay(s)
        sun_panel.frame(self)  # the Sun & sky panel's change to the re-solve, the sky, the sun's disc
        faults_view.frame(self)  # the Model faults panel's choices to the view's tint
        busy = s.jobs.opening or s.jobs.rebaking or s.lighting.relighting or s.lighting.solving_day_cycle
        moving = s.paths.player or s.paths.recorder or s.view.looking or s.lighting.dragging_light
        if self.idle and (busy or moving or (self.view3d is not None and self.view3d.dirty)):
            hello_imgui.request_refresh()  # no idling while the view changes

    def _poll_work(self) -> None:
        """Collect finished background work; the GL upload waits for the next draw (see _upload)."""
        s = self.state
        job = s.jobs.open_job
        if job is not None and not job.done and job.scene is not None and s.model.scene is None:
            self._preview = job.scene  # nothing shown yet: the model unlit while it solves
        if job is not None and job.done:
            s.jobs.open_job = None
            if job.result is not None:
                self.adopt_next_draw(job.result)
            elif job.error:
                s.messages.set_error(job.error)
                s.messages.set_status(f"could not open {job.path}; still showing {s.model.path or 'nothing'}")
        w = s.jobs.bake_worker
        res = w.poll() if w is not None else None
        if res is None:
            return
        s.jobs.bake_seconds = res.seconds
        if res.baked is not None and _is_set(res.baked) != bool(
            s.lighting.day_cycle and s.lighting.solution_set is not None
        ):
            return  # a bake of the mode just left (single solution / day-cycle set)
        if res.error is not None:
            pol = res.policy
            s.messages.set_error(f"re-bake failed ({pol.method}, threshold {pol.threshold}): {res.error}")
            return
        self._to_upload = res  # a newer result replaces one not uploaded yet

    def _upload(self) -> None:
        """Upload what arrived, at the start of the draw: the previous frame is on screen then, so
        writing buffers and textures does not wait for a draw that still reads them."""
        s = self.state
        if self._pending_open is not None:
            opened, self._pending_open = self._pending_open, None
            self._to_upload = None  # results of the previous model's worker
            self.adopt(opened)
            self._uploaded_this_frame = True
            self.view3d.invalidate()
        if self._preview is not None:
            self._show_preview(self._preview)
            self._preview = None
        if self._upload_lighting():
            self.view3d.invalidate()
        res, self._to_upload = self._to_upload, None
        if res is None:
            return
        self.view3d.invalidate()
        try:
            t0 = time.perf_counter()
            if _is_set(res.baked):
                self.renderer.set_baked_set(res.baked)
            else:
                self.renderer.set_baked(res.baked)
            self._upload_ms = (time.perf_counter() - t0) * 1000.0
        except Exception as e:
            s.messages.set_error(f"cannot upload the new bake: {error_text(e)}")
            if s.model.baked is not None:
                try:
                    self._set_baked(s.model.baked)
                except Exception:
                    log.exception("cannot restore the previous bake")
            return
        s.model.baked = res.baked
        s.model.bake_source = res.source
        s.jobs.rebakes += 1
        s.jobs.uploads += 1
        self._uploaded_this_frame = True

    def _show_preview(self, scene) -> None:
        """Show ``scene`` unlit (preview mode) while its solve runs (nothing else is on screen)."""
        s = self.state
        if s.model.scene is not None:
            return
        try:
            self.renderer.set_scene(scene)
        except Exception as e:
            s.messages.set_error(f"cannot show the preview: {error_text(e)}")
            return
        s.model.scene = scene
        s.view.nav = walker(scene, scene.default_camera())
        s.view.camera = s.view.nav.camera
        s.requests.auto_exposure = True
        self.view3d.invalidate()

    def _submit_policy(self) -> None:
        s = self.state
        if s.jobs.bake_worker is None:
            return
        p = s.tuning.policy()
        if p != s.jobs.requested_policy:
            s.jobs.requested_policy = p
            s.jobs.bake_worker.submit(p)

    # -- lighting -------------------------------------------------------------------------------------
    def _set_baked(self, baked) -> None:
        if _is_set(baked):
            self.renderer.set_baked_set(baked)
        else:
            self.renderer.set_baked(baked)

    def _submit_source(self, source: BakeSource) -> None:
        """Re-bake the current policy from a new solution (or set)."""
        s = self.state
        if s.jobs.bake_worker is None:
            return
        self._source_gen += 1
        p = s.tuning.policy()
        s.jobs.requested_policy = p
        s.jobs.bake_worker.submit(p, source, generation=self._source_gen)

    def _poll_lighting(self) -> None:
        """Hand light edits to the re-solve, pick up its results and the day cycle's solve."""
        s = self.state
        ed, rl = s.lighting.editor, s.lighting.relighter
        if ed is not None and rl is not None and not s.lighting.day_cycle:
            now = time.perf_counter()
            if ed.version != s.lighting.relight_version and (
                not s.lighting.dragging_light or now - s.lighting.relight_submitted > 0.1
            ):
                rl.submit(ed.scene, ed.version)
                s.lighting.relight_version, s.lighting.relight_submitted = ed.version, now
            if s.requests.remesh:
                s.requests.remesh = False
                rl.submit(ed.scene, ed.version, remesh=True)
                s.lighting.relight_version = ed.version
                s.messages.set_status("solving afresh: the mesh follows the new lights")
        if rl is not None:
            r = rl.poll()
            if r is not None:
                if r.error is not None:
                    s.messages.set_error(f"re-solve failed: {r.error}")
                elif r.version >= (self._relit.version if self._relit is not None else -1):
                    self._relit = r
        if s.requests.day_cycle:
            s.requests.day_cycle = False
            if s.lighting.solution_set is not None:
                s.lighting.day_cycle = True
            elif s.lighting.states and ed is not None and s.model.solution is not None:
                s.lighting.set_job = SetJob(ed.base, s.lighting.states, options_in_force(s))
                s.messages.set_status(f"solving {len(s.lighting.states)} lighting states on one mesh")
        job = s.lighting.set_job
        if job is not None and job.done:
            s.lighting.set_job = None
            if job.result is not None:
                s.lighting.solution_set = job.result
                s.lighting.day_cycle = True
                secs = sum(float(x.stats.get("time_s", 0.0)) for x in job.result.solutions)
                n = len(job.result)
                s.messages.set_status(f"day cycle: {n} lighting states solved on one mesh ({secs:.1f} s)")
            elif job.error:
                s.messages.set_error(job.error)

    def _upload_lighting(self) -> bool:
        """GL side of the lighting (during the draw): a re-solved solution, entering or leaving the
        day cycle, and the blend of the time-of-day slider. True when the renderer got new data."""
        s, r = self.state, self.renderer
        want_day = bool(s.lighting.day_cycle and s.lighting.solution_set is not None)
        res = self._relit
        changed = want_day != self._day_shown or res is not None
        if want_day != self._day_shown:
            try:
                if want_day:
                    r.set_solution_set(s.lighting.solution_set.solutions)
                    self._submit_source(
                        BakeSource(s.lighting.solution_set.first, s.model.scene, s.lighting.solution_set)
                    )
                else:
                    r.set_solution(s.model.solution)
                    self._submit_source(BakeSource(s.model.solution, s.model.scene))
                self._day_shown = want_day
            except Exception as e:
                s.messages.set_error(f"cannot show the day cycle: {error_text(e)}")
                s.lighting.day_cycle = False
        res, self._relit = self._relit, None
        if res is not None and not want_day:
            try:
                r.set_solution(res.solution)
            except Exception as e:
                s.messages.set_error(f"cannot show the re-solved lighting: {error_text(e)}")
            else:
                s.model.solution, s.model.scene = res.solution, res.scene
                s.lighting.relight_step, s.lighting.relight_seconds = (res.step, res.steps), res.total_seconds
                s.lighting.relight_mode = res.mode
                s.lighting.relights += 1
                self._submit_source(BakeSource(res.solution, res.scene))
                if res.final or res.mode == "preview":
                    s.messages.set_status(result_line(res))
        r.set_blend(*s.lighting.day_blend())
        return changed

    def _serve_requests(self) -> None:
        s = self.state
        if s.requests.open:
            path, s.requests.open = s.requests.open, None
            self.open(path)
        if s.requests.export:
            path, s.requests.export = s.requests.export, None
            background_io.export(self, path)
        if s.requests.save_solution:
            path, s.requests.save_solution = s.requests.save_solution, None
            sol = s.model.solution
            background_io.in_background(self, f"saved the solution to {path}", lambda: sol.save(path))
        if s.requests.save_lights:
            path, s.requests.save_lights = s.requests.save_lights, None
            ed = s.lighting.editor
            if ed is None or not ed.base.path:
                s.messages.set_error("nothing open to save lights of")
            else:
                from iat.lighting.save import save_gltf

                scene, sources, src = ed.scene, list(ed.sources), ed.base.path  # a snapshot: edits go on
                background_io.in_background(
                    self, f"saved the lights to {path}", lambda: save_gltf(scene, src, path, sources=sources)
                )
        if s.requests.save_paths:
            s.requests.save_paths = False
            try:
                f = save_paths(paths_file(self._model_file()), s.paths.named)
                s.messages.set_status(f"saved {len(s.paths.named)} camera path(s) to {f}")
            except OSError as e:
                s.messages.set_error(f"cannot save camera paths: {e}")
        if s.requests.quit:
            s.requests.quit = False
            hello_imgui.get_runner_params().app_shall_exit = True

    # -- per frame: layout and drawing --------------------------------------------------------------
    def _central_rect(self) -> None:
        """The central dock node is the 3D view: remember its rectangle for the next draw."""
        did = hello_imgui.get_runner_params().docking_params.dock_space_id_from_name("MainDockSpace")
        if did is None:
            return
        node = imgui.internal.dock_builder_get_central_node(did)
        if node is None:
            return
        self.state.view.rect = (int(node.pos.x), int(node.pos.y), int(node.size.x), int(node.size.y))
        sc = imgui.get_io().display_framebuffer_scale
        self.state.view.framebuffer_scale = (float(sc.x), float(sc.y))

    def shown_mode(self) -> str | None:
        """The mode actually drawn: the chosen one, or mesh until a bake exists, or preview."""
        s = self.state
        if s.model.solution is None:
            return "preview" if s.model.scene is not None else None
        if s.view.mode in ("iat", "split", "diff") and s.model.baked is None:
            return "mesh"
        return s.view.mode

    def gl_viewport(self) -> tuple[int, int, int, int] | None:
        """The 3D view in framebuffer pixels, GL convention (x, y from the bottom, w, h)."""
        win = glfw.get_current_context()
        fw, fh = glfw.get_framebuffer_size(win)
        x, y, w, h = self.state.view.rect
        sx, sy = self.state.view.framebuffer_scale
        if w <= 0 or h <= 0:
            x, y, w, h, sx, sy = 0, 0, fw, fh, 1.0, 1.0
        vx, vw = int(round(x * sx)), int(round(w * sx))
        vy, vh = int(round(y * sy)), int(round(h * sy))
        vw, vh = min(vw, fw - vx), min(vh, fh - vy)
        if vw <= 0 or vh <= 0:
            return None
        return vx, fh - vy - vh, vw, vh

    def _draw(self) -> None:
        s = self.state
        if self.ctx is None or self.view3d is None:
            return
        self.panel_cache.frame_start(self.ctx)  # (before anything is drawn: the back buffer's check)
        self._upload()
        mode, vp = self.shown_mode(), self.gl_viewport()
        cam = s.view.camera if s.view.camera is not None else (s.view.nav.camera if s.view.nav else None)
        if mode is not None and vp is not None and cam is not None and s.requests.auto_exposure:
            s.requests.auto_exposure = False
            auto_exposure(s, self.view3d, cam, mode, vp)
        keep = None  # the empty view keeps its pixels while only its label lies over it
        if self.panel_cache.keeps_view and not s.model.loaded:
            keep = overlay.empty_label(s)
        self.view3d.draw(s, mode, vp, cam, keep=keep)
        if mode is None or vp is None or cam is None:
            return
        self.frames_drawn += 1
        if s.requests.screenshot is not None:
            screenshot(s, self.view3d, vp, mode, screenshot_dir())

    def _before_render(self) -> None:
        """Just before ``ImGui::Render``: the docked panels are drawn only when they may have changed."""
        did = hello_imgui.get_runner_params().docking_params.dock_space_id_from_name("MainDockSpace")
        pc = self.panel_cache
        pc.before_render(self.state.view.rect, did)
        self.state.stats.panel_draws, self.state.stats.panel_skips = pc.full_frames, pc.skipped_frames

    def read_view(self, vp=None) -> np.ndarray:
        """(h, w, 3) uint8 of the 3D view as shown this frame (call during the background callback)."""
        return self.view3d.read(vp or self.gl_viewport())

    def _idling(self) -> bool:
        try:
            return bool(hello_imgui.get_runner_params().fps_idling.is_idling)
        except Exception:  # outside a run
            return False

    def _frame_start(self) -> None:
        self._frame_t0 = time.perf_counter()
        self._frame_idle = self._idling()
        dp = hello_imgui.get_runner_params().docking_params
        if dp.layout_reset:  # View > Restore default layout (before it is applied): closed panels too
            for w in dp.dockable_windows:
                w.is_visible = True

    def _after_swap(self) -> None:
        now = time.perf_counter()
        if self._last_swap is not None:
            ms = (now - self._last_swap) * 1000.0
            s = self.state
            t0 = self._frame_t0
            work = (now - t0) * 1000.0 if t0 is not None else ms
            s.stats.add_frame_time(ms, work_ms=work, idle=self._frame_idle or self._idling())
            if s.paths.player is not None and s.paths.posed:  # only frames that drew a pose
                s.paths.play_frame_ms.append(ms)
            if self.frame_log is not None:
                self.frame_log.append(
                    {
                        "ms": ms,
                        "upload": self._uploaded_this_frame,
                        "upload_ms": self._upload_ms,
                        "baking": s.jobs.rebaking,
                        "rebakes": s.jobs.rebakes,
                        "triangles": int(s.stats.render.get("triangles", 0)),
                    }
                )
                if self.swap_hook is not None:
                    self.swap_hook(self, self.frame_log[-1])
        self._last_swap = now
        self.state.paths.posed = False
        self._uploaded_this_frame = False
        self._upload_ms = 0.0


def _is_set(baked) -> bool:
    """A BakedSet (day cycle) rather than a single Baked."""
    from iat.bake.baked import BakedSet

    return isinstance(baked, BakedSet)


# -- entry points ----------------------------------------------------------------------------------------
def main(
    path: str | None = None,
    *,
    size=(1280, 800),
    solve_options: SolveOptions | None = None,
    play: str | None = None,
    frames: int = 120,
    modes=("mesh", "iat"),
    as_json: bool = False,
    daylight=None,
) -> int:
    """``iat view [SOL|MODEL]``: run the viewer; 0 when closed, 2 when there is no display.

    path : a model or a solution ``.npz``; None opens the Cornell box sample
    solve_options : how to solve a model that has no (cached) solution; default ``SolveOptions()``
    play : ``--play NAME``: play camera path NAME (or a ``.paths.json`` file) over ``frames`` frames
      in each of ``modes``, print frame-time statistics (JSON when ``as_json``) and exit
      (:func:`viewer.play.play_path`); 1 when the playback failed, 2 for a path that is not there
    daylight : a :class:`~iat.lighting.daylight_default.DaylightRequest` (``--sun``, ``--sky``,
      ``--no-daylight``); None: the default (daylight for a model without light sources)
    """
    target = Path(path) if path else default_model()
    try:
        if play is not None:
            import json

            from viewer.play import format_play, play_path

            def make_app(**kw) -> ViewerApp:
                return ViewerApp(target, size=size, solve_options=solve_options, daylight=daylight, **kw)

            res = play_path(make_app, target, play, frames=frames, modes=modes, size=size)
            if res["error"]:
                print(f"iat view: {res['error']}", file=sys.stderr)
            if as_json:
                print(json.dumps(res, indent=1))
            elif res["modes"]:
                print(format_play(res))
            return int(res["exit_code"])
        ViewerApp(target, size=size, solve_options=solve_options, daylight=daylight).run()
    except RuntimeError as e:
        print(f"iat view: cannot open a window ({e}); try 'iat render' or xvfb-run", file=sys.stderr)
        return 2
    return 0
