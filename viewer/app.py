"""The IAT desktop viewer: imgui-bundle (hello_imgui docking + implot) around a moderngl 3D view.

``main(path)`` opens a model or solution (default: the Cornell box) and runs the
window until it is closed. The 3D view is drawn in hello_imgui's
``custom_background`` callback into the central dock node's rectangle (the
viewport is set every frame); the panels (``viewer/panels.py``) dock around it
and change the :class:`~viewer.state.AppState`. Every frame the app:

1. picks up finished background work: an opened model (:class:`~viewer.state.OpenJob`)
   or a re-bake (:class:`~viewer.state.BakeWorker`), and uploads it to the
   :class:`~iat.render.Renderer` (GL happens on this thread only); a failure
   shows an error and keeps the last good model and bake;
2. submits a re-bake when the tuning panel changed the policy (the previous
   bake stays on screen until the new one arrives);
3. moves the camera (:mod:`viewer.navigation`: keyboard, mouse, gamepad, or a
   camera path being played) and records it when a path is being recorded;
4. serves the panels' requests: open, export GLB, save solution / paths, screenshot.

:func:`benchmark_rebake_frames` measures frame times while the threshold and
scale sliders are dragged (``iat bench`` calls it).
"""

from __future__ import annotations

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

from . import panels
from .navigation import (
    CameraPath,
    InputState,
    Navigator,
    load_paths,
    navigation_speed,
    paths_file,
    save_paths,
)
from .state import AppState, BakeWorker, Opened, OpenJob, default_model, error_text

log = logging.getLogger(__name__)

WINDOW_TITLE = "IAT viewer"
BACKGROUND = (0.08, 0.08, 0.09)
#: keyboard keys the navigator understands, and the imgui keys that press them
NAV_KEYS = {
    "w": ("w",),
    "a": ("a",),
    "s": ("s",),
    "d": ("d",),
    "q": ("q",),
    "e": ("e",),
    "up": ("up_arrow",),
    "down": ("down_arrow",),
    "left": ("left_arrow",),
    "right": ("right_arrow",),
    "shift": ("left_shift", "right_shift"),
}
#: GLFW gamepad button index -> navigator button name
PAD_BUTTONS = {
    glfw.GAMEPAD_BUTTON_A: "a",
    glfw.GAMEPAD_BUTTON_B: "b",
    glfw.GAMEPAD_BUTTON_X: "x",
    glfw.GAMEPAD_BUTTON_Y: "y",
    glfw.GAMEPAD_BUTTON_LEFT_BUMPER: "lb",
    glfw.GAMEPAD_BUTTON_RIGHT_BUMPER: "rb",
    glfw.GAMEPAD_BUTTON_BACK: "back",
    glfw.GAMEPAD_BUTTON_START: "start",
}
DIVIDER_GRAB_PX = 8.0


def screenshot_dir() -> Path:
    """Where F12 writes: ``$IAT_SCREENSHOT_DIR``, else ``./screenshots``."""
    return Path(os.environ.get("IAT_SCREENSHOT_DIR") or Path.cwd() / "screenshots")


def read_gamepad() -> tuple[tuple[float, ...], frozenset[str]]:
    """Axes (triggers mapped to 0..1) and held buttons of the first connected gamepad, or rest."""
    for jid in range(glfw.JOYSTICK_1, glfw.JOYSTICK_LAST + 1):
        try:
            if not glfw.joystick_is_gamepad(jid):
                continue
            st = glfw.get_gamepad_state(jid)
        except Exception:  # no joystick support in this GLFW build / platform
            return (0.0,) * 6, frozenset()
        if st is None:
            continue
        ax = [float(a) for a in st.axes]
        ax[4] = (ax[4] + 1.0) * 0.5  # GLFW triggers rest at -1
        ax[5] = (ax[5] + 1.0) * 0.5
        held = frozenset(name for i, name in PAD_BUTTONS.items() if i < len(st.buttons) and st.buttons[i])
        return tuple(ax), held
    return (0.0,) * 6, frozenset()


class ViewerApp:
    """The viewer. ``ViewerApp(path).run()`` opens a window; tests pass :meth:`runner_params` to
    ``imgui_bundle.immapp.testing.run``.

    path : model or solution to open once the window is up (None: nothing)
    size : window size in pixels
    solve_options : options for models that need a solve (default :class:`SolveOptions`)
    frame_hook : called as ``frame_hook(app)`` at the start of every frame (scripts, benchmarks)
    idle : let hello_imgui idle to a few fps when nothing moves (False for measurements)
    """

    def __init__(
        self,
        path: str | os.PathLike | None = None,
        *,
        size: tuple[int, int] = (1280, 800),
        solve_options: SolveOptions | None = None,
        state: AppState | None = None,
        frame_hook=None,
        idle: bool = True,
    ):
        self.state = state or AppState()
        if solve_options is not None:
            self.state.solve_options = solve_options
        self.initial_path = None if path is None else str(path)
        self.size = (int(size[0]), int(size[1]))
        self.frame_hook = frame_hook
        self.idle = idle
        self.ctx = None
        self.renderer = None
        self.frame_log: list[dict] | None = None  # per-frame records when measuring
        self._adopt: Opened | None = None
        self._to_upload = None
        self._uploaded_this_frame = False
        self._bg_threads: list[threading.Thread] = []
        self._last_swap: float | None = None
        self._draw_error = ""
        self.frames_drawn = 0

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
        cb = rp.callbacks
        cb.post_init = self._guard(self._post_init)
        cb.before_exit = self._before_exit
        cb.show_gui = self._guard(self._frame)
        cb.show_menus = self._guard(lambda: panels.menus(self.state))
        cb.custom_background = self._guard(self._draw)
        cb.post_render_dockable_windows = self._guard(self._central_rect)
        cb.after_swap = self._after_swap
        dp = rp.docking_params
        dp.docking_splits = [
            hello_imgui.DockingSplit("MainDockSpace", "LeftSpace", imgui.Dir.left, 0.25),
            hello_imgui.DockingSplit("LeftSpace", "LeftBottom", imgui.Dir.down, 0.45),
            hello_imgui.DockingSplit("MainDockSpace", "RightSpace", imgui.Dir.right, 0.27),
        ]
        dp.dockable_windows = [
            self._window("Tuning", "LeftSpace", panels.tuning_panel),
            self._window("View", "LeftBottom", panels.view_panel),
            self._window("Model", "LeftBottom", panels.file_panel),
            self._window("Stats", "RightSpace", panels.stats_panel),
        ]
        return rp

    def _window(self, label, space, fn) -> hello_imgui.DockableWindow:
        w = hello_imgui.DockableWindow(label, space, self._guard(lambda: fn(self.state)))
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
                log.exception("viewer callback failed")
                self.state.set_error(f"internal error: {error_text(e)}")

        return wrapped

    # -- lifetime ----------------------------------------------------------------------------------
    def _post_init(self) -> None:
        import moderngl

        from iat.render import Renderer

        self.ctx = moderngl.create_context()
        self.renderer = Renderer(self.ctx)
        if self.initial_path:
            self.open(self.initial_path)

    def _before_exit(self) -> None:
        s = self.state
        if s.open_job is not None:
            s.open_job.cancel()
            s.open_job.join(30.0)
        if s.bake_worker is not None:
            s.bake_worker.close()
        for t in self._bg_threads:
            t.join(30.0)
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
        if s.open_job is not None and not s.open_job.done:
            s.open_job.cancel()
        s.open_job = OpenJob(path, s.solve_options, s.policy(), use_cache=s.use_cache)
        s.set_status(f"opening {path}")

    def adopt(self, opened: Opened) -> None:
        """Make ``opened`` the shown model: upload it, then swap it into the state.

        On a GL failure the previous model stays (its data is uploaded again)."""
        s, r = self.state, self.renderer
        try:
            r.set_scene(opened.scene)
            r.set_solution(opened.solution)
            if opened.baked is not None:
                r.set_baked(opened.baked)
        except Exception as e:
            s.set_error(f"{opened.path}: cannot show it: {error_text(e)}")
            self._restore()
            return
        if s.bake_worker is not None:
            s.bake_worker.close()
        s.model_path = opened.path
        s.scene, s.solution, s.baker = opened.scene, opened.solution, opened.baker
        s.baked = opened.baked
        s.bake_worker = BakeWorker(opened.baker)
        s.requested_policy = opened.policy
        s.solve_seconds = opened.solve_seconds
        s.solution_from_cache = opened.from_cache
        s.bake_seconds = opened.bake_seconds
        s.rebakes += 1
        if opened.bake_error:
            s.set_error(f"bake failed: {opened.bake_error}")
        if s.tuning.threshold > s.deepest + 1:
            s.tuning.threshold = s.deepest + 1
        cam = opened.scene.default_camera()
        s.nav = Navigator(cam, speed=navigation_speed(opened.scene.bounds))
        s.camera = s.nav.camera
        s.camera_index = 0
        s.recorder = s.player = None
        s.paths = {name: CameraPath(name, list(cams)) for name, cams in opened.scene.camera_paths.items()}
        try:
            s.paths.update(load_paths(paths_file(self._model_file())))
        except IATError as e:
            s.set_error(str(e))
        s.path_name = next(iter(s.paths), "")
        what = "cached solution" if opened.from_cache else f"solved in {opened.solve_seconds:.1f} s"
        n = opened.scene.n_patches
        s.set_status(f"opened {opened.path} ({n} patches, {s.mesh_triangles:,} mesh triangles, {what})")

    def _restore(self) -> None:
        """Upload the state's model and bake again (after a failed upload)."""
        s, r = self.state, self.renderer
        try:
            if s.scene is not None:
                r.set_scene(s.scene)
            if s.solution is not None:
                r.set_solution(s.solution)
            if s.baked is not None:
                r.set_baked(s.baked)
        except Exception:
            log.exception("cannot restore the previous model")

    def _model_file(self) -> str:
        """The model a camera-paths file belongs to (a solution's model, else the opened file)."""
        s = self.state
        p = Path(s.model_path)
        if p.suffix.lower() == ".npz" and s.solution is not None and s.solution.model_path:
            return s.solution.model_path
        return str(p)

    # -- per frame: logic (show_gui) ------------------------------------------------------------------
    def _frame(self) -> None:
        s = self.state
        self._uploaded_this_frame = False
        if self.frame_hook is not None:
            self.frame_hook(self)
        panels.poll_dialogs(s)
        self._serve_requests()
        self._poll_work()
        self._submit_policy()
        self._navigate()
        self._shortcuts()
        panels.error_window(s)
        panels.view_overlay(s)
        if self.idle and (s.opening or s.rebaking or s.player or s.recorder or s.looking):
            hello_imgui.request_refresh()

    def _poll_work(self) -> None:
        s = self.state
        job = s.open_job
        if job is not None and job.done:
            s.open_job = None
            if job.result is not None:
                self.adopt(job.result)
                self._uploaded_this_frame = True
            elif job.error:
                s.set_error(job.error)
                s.set_status(f"could not open {job.path}; still showing {s.model_path or 'nothing'}")
        w = s.bake_worker
        res = w.poll() if w is not None else None
        if res is None:
            return
        s.bake_seconds = res.seconds
        if res.error is not None:
            s.set_error(
                f"re-bake failed ({res.policy.method}, threshold {res.policy.threshold}): {res.error}"
            )
            return
        try:
            self.renderer.set_baked(res.baked)
        except Exception as e:
            s.set_error(f"cannot upload the new bake: {error_text(e)}")
            if s.baked is not None:
                try:
                    self.renderer.set_baked(s.baked)
                except Exception:
                    log.exception("cannot restore the previous bake")
            return
        s.baked = res.baked
        s.rebakes += 1
        s.uploads += 1
        self._uploaded_this_frame = True

    def _submit_policy(self) -> None:
        s = self.state
        if s.bake_worker is None:
            return
        p = s.policy()
        if p != s.requested_policy:
            s.requested_policy = p
            s.bake_worker.submit(p)

    def _input(self) -> InputState:
        s = self.state
        io = imgui.get_io()
        keys: set[str] = set()
        if not io.want_capture_keyboard and not io.want_text_input:
            for name, ikeys in NAV_KEYS.items():
                if any(imgui.is_key_down(getattr(imgui.Key, k)) for k in ikeys):
                    keys.add(name)
        x, y, w, h = s.view_rect
        mx, my = io.mouse_pos.x, io.mouse_pos.y
        over = (not io.want_capture_mouse) and w > 0 and x <= mx < x + w and y <= my < y + h
        near = s.mode == "split" and abs(mx - (x + s.split * w)) <= DIVIDER_GRAB_PX
        if over and (near or s.dragging_split):
            imgui.set_mouse_cursor(imgui.MouseCursor_.resize_ew)
        if over and imgui.is_mouse_clicked(imgui.MouseButton_.left):
            s.dragging_split, s.looking = (True, False) if near else (False, True)
        if over and imgui.is_mouse_clicked(imgui.MouseButton_.right):
            s.looking = True
        if not (
            imgui.is_mouse_down(imgui.MouseButton_.left) or imgui.is_mouse_down(imgui.MouseButton_.right)
        ):
            s.dragging_split = s.looking = False
        dx = dy = 0.0
        if s.dragging_split and w > 0:
            s.split = float(min(max((mx - x) / w, 0.0), 1.0))
        elif s.looking:
            dx, dy = io.mouse_delta.x, io.mouse_delta.y
        wheel = io.mouse_wheel if over else 0.0
        axes, buttons = read_gamepad()
        if self.idle and (any(abs(a) > 0.15 for a in axes) or buttons or keys):
            hello_imgui.request_refresh()
        return InputState(
            keys=keys, mouse_dx=dx, mouse_dy=dy, wheel=wheel, gamepad_axes=axes, gamepad_buttons=buttons
        )

    def _navigate(self) -> None:
        s = self.state
        dt = float(imgui.get_io().delta_time)
        inp = self._input()
        if s.nav is None:
            return
        if s.player is not None:
            if s.playback_frames:
                cam = s.player.next()
            else:
                t = time.perf_counter() - s.play_started
                cam = s.player.pose_at(t) if t <= s.player.duration else None
                s.player.index += 1
            if cam is None:
                s.stop_playback()
            else:
                s.camera = cam
                return
        s.camera = s.nav.update(dt, inp)
        if s.recorder is not None:
            s.recorder.add(s.camera, time.perf_counter() - s.record_started)

    def _shortcuts(self) -> None:
        s = self.state
        io = imgui.get_io()
        if imgui.is_key_pressed(imgui.Key.f12, False):
            s.request_screenshot = ""
        if io.want_text_input or io.want_capture_keyboard:
            return
        for k, m in zip(("_1", "_2", "_3", "_4"), ("mesh", "iat", "split", "diff"), strict=True):
            if imgui.is_key_pressed(getattr(imgui.Key, k), False):
                s.mode = m
        if imgui.is_key_pressed(imgui.Key.r, False) and s.nav is not None:
            s.nav.reset()
        if io.key_ctrl and imgui.is_key_pressed(imgui.Key.o, False):
            if panels.has_native_dialogs():
                panels.open_dialog(s)

    def _serve_requests(self) -> None:
        s = self.state
        if s.request_open:
            path, s.request_open = s.request_open, None
            self.open(path)
        if s.request_export:
            path, s.request_export = s.request_export, None
            self._export(path)
        if s.request_save_solution:
            path, s.request_save_solution = s.request_save_solution, None
            sol = s.solution
            self._in_background(f"saved the solution to {path}", lambda: sol.save(path))
        if s.request_save_paths:
            s.request_save_paths = False
            try:
                f = save_paths(paths_file(self._model_file()), s.paths)
                s.set_status(f"saved {len(s.paths)} camera path(s) to {f}")
            except OSError as e:
                s.set_error(f"cannot save camera paths: {e}")
        if s.request_quit:
            s.request_quit = False
            hello_imgui.get_runner_params().app_shall_exit = True

    def _export(self, path: str) -> None:
        from iat.export import export_glb

        s = self.state
        if s.baked is None:
            s.set_error("nothing baked to export yet")
            return
        baked, scene = s.baked, s.scene
        self._in_background(f"exported the bake to {path}", lambda: export_glb(baked, path, scene))

    def _in_background(self, done: str, fn) -> None:
        s = self.state

        def run():
            try:
                fn()
                s.set_status(done)
            except Exception as e:
                s.set_error(error_text(e))

        t = threading.Thread(target=run, name="iat-io", daemon=True)
        self._bg_threads = [b for b in self._bg_threads if b.is_alive()] + [t]
        t.start()

    # -- per frame: layout and drawing --------------------------------------------------------------
    def _central_rect(self) -> None:
        """The central dock node is the 3D view: remember its rectangle for the next draw."""
        did = hello_imgui.get_runner_params().docking_params.dock_space_id_from_name("MainDockSpace")
        if did is None:
            return
        node = imgui.internal.dock_builder_get_central_node(did)
        if node is None:
            return
        self.state.view_rect = (int(node.pos.x), int(node.pos.y), int(node.size.x), int(node.size.y))
        sc = imgui.get_io().display_framebuffer_scale
        self.state.framebuffer_scale = (float(sc.x), float(sc.y))

    def shown_mode(self) -> str | None:
        """The mode actually drawn: the chosen one, or mesh until a bake exists, or preview."""
        s = self.state
        if s.solution is None:
            return "preview" if s.scene is not None else None
        if s.mode in ("iat", "split", "diff") and s.baked is None:
            return "mesh"
        return s.mode

    def gl_viewport(self) -> tuple[int, int, int, int] | None:
        """The 3D view in framebuffer pixels, GL convention (x, y from the bottom, w, h)."""
        win = glfw.get_current_context()
        fw, fh = glfw.get_framebuffer_size(win)
        x, y, w, h = self.state.view_rect
        sx, sy = self.state.framebuffer_scale
        if w <= 0 or h <= 0:
            x, y, w, h, sx, sy = 0, 0, fw, fh, 1.0, 1.0
        vx, vw = int(round(x * sx)), int(round(w * sx))
        vy, vh = int(round(y * sy)), int(round(h * sy))
        vw, vh = min(vw, fw - vx), min(vh, fh - vy)
        if vw <= 0 or vh <= 0:
            return None
        return vx, fh - vy - vh, vw, vh

    def _draw(self) -> None:
        s, ctx = self.state, self.ctx
        if ctx is None:
            return
        fw, fh = glfw.get_framebuffer_size(glfw.get_current_context())
        ctx.screen.use()
        ctx.viewport = (0, 0, fw, fh)
        ctx.clear(*BACKGROUND)
        mode = self.shown_mode()
        vp = self.gl_viewport()
        if mode is None or vp is None or s.camera is None and s.nav is None:
            return
        cam = s.camera if s.camera is not None else s.nav.camera
        try:
            self.renderer.draw(
                cam,
                mode,
                viewport=vp,
                exposure=s.tuning.exposure,
                tonemap=s.tonemap,
                split=s.split,
                diff_gain=s.diff_gain,
            )
            s.render_stats = self.renderer.stats()
            self._draw_error = ""
        except Exception as e:
            msg = f"cannot draw: {error_text(e)}"
            if msg != self._draw_error:  # once, not every frame
                self._draw_error = msg
                s.set_error(msg)
        finally:
            ctx.screen.use()
            ctx.viewport = (0, 0, fw, fh)
        self.frames_drawn += 1
        if s.request_screenshot is not None:
            path, s.request_screenshot = s.request_screenshot, None
            self._screenshot(path, vp, mode)

    def read_view(self, vp=None) -> np.ndarray:
        """(h, w, 3) uint8 of the 3D view as drawn this frame (call during the background callback)."""
        vp = vp or self.gl_viewport()
        x, y, w, h = vp
        raw = self.ctx.screen.read(viewport=(x, y, w, h), components=3, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()

    def _screenshot(self, path: str, vp, mode: str) -> None:
        from PIL import Image

        s = self.state
        if not path:
            stem = Path(s.model_path).stem or "iat"
            path = str(screenshot_dir() / f"{stem}-{mode}-{time.strftime('%Y%m%d-%H%M%S')}.png")
        try:
            img = self.read_view(vp)
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(img).save(path)
            s.last_screenshot = path
            s.set_status(f"wrote {path}")
        except Exception as e:
            s.set_error(f"cannot write the screenshot {path}: {error_text(e)}")

    def _after_swap(self) -> None:
        now = time.perf_counter()
        if self._last_swap is not None:
            ms = (now - self._last_swap) * 1000.0
            s = self.state
            s.add_frame_time(ms)
            if s.player is not None:
                s.play_frame_ms.append(ms)
            if self.frame_log is not None:
                self.frame_log.append(
                    {
                        "ms": ms,
                        "upload": self._uploaded_this_frame,
                        "baking": s.rebaking,
                        "rebakes": s.rebakes,
                    }
                )
        self._last_swap = now


# -- entry points ----------------------------------------------------------------------------------------
def main(path: str | None = None, *, size=(1280, 800), solve_options: SolveOptions | None = None) -> int:
    """``iat view [SOL|MODEL]``: run the viewer; 0 when closed, 2 when there is no display.

    path : a model or a solution ``.npz``; None opens the Cornell box sample
    solve_options : how to solve a model that has no (cached) solution; default ``SolveOptions()``
    """
    target = Path(path) if path else default_model()
    app = ViewerApp(target, size=size, solve_options=solve_options)
    try:
        app.run()
    except RuntimeError as e:
        print(f"iat view: cannot open a window ({e}); try 'iat render' or xvfb-run", file=sys.stderr)
        return 2
    return 0


def benchmark_rebake_frames(
    path: str | os.PathLike | None = None,
    *,
    sweeps: tuple[str, ...] = ("threshold", "scale", "method"),
    blocks: int = 6,
    block_frames: int = 15,
    size: tuple[int, int] = (1280, 800),
    max_depth: int = 4,
    limit_ms: float = 50.0,
) -> dict:
    """Frame times while the tuning sliders are dragged (a new value every frame).

    Runs the real viewer (idling and vsync off) on ``path`` (default: the Cornell box, solved at
    ``max_depth``, cached). Each sweep alternates ``blocks`` times ``block_frames`` quiet frames
    (nothing changes: the reference, measured in the same minutes so a busy machine affects both
    alike) and ``block_frames`` drag frames: "threshold" steps 0 .. deepest + 1 and back,
    "scale" glides over 0.25 .. 2 (new texture sizes), "method" cycles bilinear / scan / bicubic
    every 2 frames. Every change requests a re-bake on the worker thread; the GL upload happens
    on the UI thread in the frame the result arrives.

    Returns ``{sweep: {"quiet": stats, "drag": stats, ...}}`` with stats ``frames``,
    ``median_ms``, ``p95_ms``, ``max_ms``; per sweep also ``uploads`` (drag frames that uploaded
    a bake), ``max_upload_ms``, ``bake_ms_median`` (worker time per bake), ``extra_median_ms``
    (drag - quiet median), ``over_limit`` (drag frames over ``limit_ms``) and
    ``excess_over_limit`` (drag frames more than ``limit_ms`` above the quiet median). ``ok``:
    no drag frame over the limit when the quiet frames stay under it ("absolute"), else no drag
    frame more than the limit above the quiet median ("excess": the machine itself is too slow
    or busy for the absolute test); ``judged_by`` says which. Needs a display (xvfb-run);
    raises RuntimeError without one.
    """
    from .state import METHODS, OpenJob

    target = Path(path) if path else default_model()
    opts = SolveOptions(max_depth=max_depth)
    state = AppState(solve_options=opts)
    state.tuning.threshold = 0
    job = OpenJob(target, opts, state.policy())
    job.join()
    if job.error:
        raise RuntimeError(f"benchmark: {job.error}")
    opened = job.result
    deepest = int(np.asarray(opened.solution.patch_depth()).max())
    plan: list[tuple[str, str, int]] = [("warmup", "quiet", k) for k in range(10)]
    for name in sweeps:
        for b in range(blocks):
            plan += [(name, "quiet", 0)] * block_frames
            plan += [(name, "drag", b * block_frames + k) for k in range(block_frames)]
    plan += [("end", "quiet", 0)] * 2
    labels: list[tuple[str, str]] = []
    bake_ms: dict[str, list[float]] = {}
    cur = {"i": -1}

    def hook(app: ViewerApp) -> None:
        s = app.state
        if cur["i"] == -1:
            app.adopt(opened)
        cur["i"] += 1
        i = cur["i"]
        if i >= len(plan):
            hello_imgui.get_runner_params().app_shall_exit = True
            return
        phase, kind, k = plan[i]
        app.frame_label = (phase, kind)
        if kind != "drag":
            return
        t = s.tuning
        if phase == "threshold":
            period = 2 * (deepest + 1)
            q = k % period
            t.threshold = q if q <= deepest + 1 else period - q
        elif phase == "scale":
            x = (k % 40) / 39.0
            x = 2 * x if x < 0.5 else 2 - 2 * x
            t.scale = float(0.25 * 8.0**x)
        elif phase == "method":
            t.method = METHODS[(k // 2) % len(METHODS)]

    app = ViewerApp(None, size=size, state=state, frame_hook=hook, idle=False)
    app.frame_log = []
    base_after = app._after_swap

    def after_swap() -> None:
        n = len(app.frame_log)
        base_after()
        if len(app.frame_log) > n:
            label = getattr(app, "frame_label", ("start", "quiet"))
            labels.append(label)
            if app.frame_log[-1]["upload"]:
                bake_ms.setdefault(label[0], []).append(app.state.bake_seconds * 1000.0)

    app._after_swap = after_swap
    app.run()

    def stats(ms: np.ndarray) -> dict:
        if not ms.size:
            return {"frames": 0, "median_ms": None, "p95_ms": None, "max_ms": None}
        return {
            "frames": int(ms.size),
            "median_ms": float(np.median(ms)),
            "p95_ms": float(np.percentile(ms, 95)),
            "max_ms": float(ms.max()),
        }

    out: dict = {"model": str(target), "max_depth": max_depth, "limit_ms": limit_ms, "size": list(size)}
    rows = list(zip(app.frame_log, labels, strict=False))
    absolute = True
    for name in sweeps:
        quiet = np.array([r["ms"] for r, (p, k) in rows if p == name and k == "quiet"])
        drag = np.array([r["ms"] for r, (p, k) in rows if p == name and k == "drag"])
        up = np.array([r["ms"] for r, (p, k) in rows if p == name and k == "drag" and r["upload"]])
        q, d = stats(quiet), stats(drag)
        qm = q["median_ms"] or 0.0
        bt = np.array(bake_ms.get(name, []))
        out[name] = {
            "quiet": q,
            "drag": d,
            "uploads": int(up.size),
            "max_upload_ms": float(up.max()) if up.size else None,
            "bake_ms_median": float(np.median(bt)) if bt.size else None,
            "extra_median_ms": (d["median_ms"] or 0.0) - qm,
            "over_limit": int((drag > limit_ms).sum()),
            "excess_over_limit": int((drag > qm + limit_ms).sum()),
        }
        absolute &= q["p95_ms"] is not None and q["p95_ms"] < limit_ms
    out["judged_by"] = "absolute" if absolute else "excess"
    key = "over_limit" if absolute else "excess_over_limit"
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
    s.diff_gain = 8.0
    written: list[Path] = []

    def shoot(ctx, name: str, window: str | None = None) -> None:
        ctx.yield_(3)
        p = out / f"viewer-{name}.png"
        testing.capture(ctx, str(p), window=window)
        written.append(p)

    def tour(ctx) -> None:
        end = time.monotonic() + 600
        while (s.baked is None or s.rebaking or s.opening) and time.monotonic() < end:
            ctx.yield_()
        if s.baked is None:
            raise RuntimeError(f"capture_screenshots: nothing baked ({s.error or 'timed out'})")
        for label, mode in (("Mesh", "mesh"), ("IAT", "iat"), ("Split", "split"), ("Difference", "diff")):
            ctx.item_click(f"//**/{label}")
            shoot(ctx, mode)
        ctx.item_click("//**/IAT")
        shoot(ctx, "tuning", window="Tuning")

    def relaxed_watchdog() -> None:
        io = imgui.test_engine.get_io(hello_imgui.get_imgui_test_engine())
        io.config_watchdog_warning = io.config_watchdog_kill_test = 900.0

    params = app.runner_params()
    params.callbacks.register_tests = relaxed_watchdog
    testing.run(test_function=tour, runner_params=params, add_ons_params=app.addons())
    return written
