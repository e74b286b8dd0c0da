"""The 3D view: drawn into an offscreen image only when something it shows changed, blitted otherwise.

:class:`View3D` is the GL side of the central dock node (called from hello_imgui's
``custom_background`` callback, on the UI thread). Every frame it works out the view's *key*:
the camera pose, the mode drawn, exposure, tone map, divider, difference gain, the viewport
and the renderer's upload generation (bumped by :meth:`View3D.invalidate` whenever the app
uploads a scene, solution, bake or blend). While the key changes (the camera moves) the
:class:`~iat.render.renderer.Renderer` draws straight into the window, as without a cache; on
the first frame the key stays the same it draws once more into an offscreen image, and from then
on that image is copied to the window (``glBlitFramebuffer``: one copy of the view's pixels).
Panels, sliders and menus that change nothing in the view therefore cost no 3D drawing, and a
moving camera pays nothing for the cache. (Drawing the moving view offscreen too and copying it,
as ``iat bench`` draws, was measured slower here: the copy costs more than the window's scissored
clear it saves; ``docs/benchmarks.md``.) With nothing to show, the empty rectangle is cleared
only when it or its label changed, or something was drawn over it (see :meth:`View3D.draw`).

A GLB that ``iat bake`` wrote is drawn as the file stores it (:meth:`View3D.show_export`: a
:class:`~iat.render.glb_view.GlbView` on the window's context), whatever the mode.

Counts for the Stats panel and the tests: :attr:`View3D.redraws` (3D draws) and
:attr:`View3D.blits` (frames that only copied).
"""

from __future__ import annotations

import ctypes
import logging
import time
from pathlib import Path

import imgui_bundle  # noqa: F401  # before glfw: points pyGLFW at imgui-bundle's own libglfw
import numpy as np

import glfw  # isort: skip

from viewer.false_color import FalseColorView
from viewer.jobs import error_text
from viewer.state import AppState

log = logging.getLogger(__name__)

BACKGROUND = (0.08, 0.08, 0.09)
_GL_READ_FRAMEBUFFER = 0x8CA8
_GL_DRAW_FRAMEBUFFER = 0x8CA9
_GL_COLOR_BUFFER_BIT = 0x4000
_GL_NEAREST = 0x2600
_GL_SCISSOR_TEST = 0x0C11


def _gl_function(name: str, *argtypes):
    """A GL entry point of the current context (through GLFW), or None."""
    addr = glfw.get_proc_address(name)
    if not addr:
        return None
    return ctypes.CFUNCTYPE(None, *argtypes)(addr)


class View3D:
    """The 3D view of a :class:`~viewer.app.ViewerApp`: key, offscreen image, blit.

    ctx : the window's moderngl context; renderer : its :class:`~iat.render.renderer.Renderer`
    """

    def __init__(self, ctx, renderer):
        self.ctx = ctx
        self.renderer = renderer
        self.generation = 0  # bumped on every upload to the renderer
        self.redraws = 0
        self.blits = 0
        self.last_draw_ms = 0.0  # CPU time of the last 3D draw call (the GL work runs on)
        self._key = None  # the view the offscreen image holds
        self._screen_key = None  # the view drawn straight into the window last
        self._fbo = None
        self._color = None
        self._depth = None
        self._size = (0, 0)
        self._clear_frames = 3  # clear the whole window for a few frames after a layout change
        self._rect = None
        self._empty = None  # (viewport, text) of the empty view last cleared and labelled
        i, u = ctypes.c_int, ctypes.c_uint
        self._blit = _gl_function("glBlitFramebuffer", i, i, i, i, i, i, i, i, u, u)
        self._bind = _gl_function("glBindFramebuffer", u, u)
        self._disable = _gl_function("glDisable", u)
        self.draw_error = ""
        self._dirty = True
        self.export = None  # a GlbView of an exported bake, drawn instead of the renderer
        self.false_color: FalseColorView | None = None  # the false-colour mode's drawer

    def show_export(self, document) -> None:
        """Draw ``document`` (a :class:`~iat.render.glb_view.GlbDocument`) from now on; None: the
        renderer again. The previous file's GL objects are freed."""
        from iat.render.glb_view import GlbView

        view = GlbView(document, self.ctx) if document is not None else None
        if self.export is not None:
            self.export.release()
        self.export = view
        self.invalidate()

    # -- state ---------------------------------------------------------------------------------
    def invalidate(self) -> None:
        """Something the renderer draws changed (a new scene, solution, bake, blend): draw again."""
        self.generation += 1

    @property
    def dirty(self) -> bool:
        """The view was drawn anew in the last frame (False: the last image was copied)."""
        return self._dirty

    def release(self) -> None:
        """Free the offscreen image (the export's view stays: :meth:`show_export` ``(None)`` frees it)."""
        for o in (self._fbo, self._color, self._depth):
            if o is not None:
                try:
                    o.release()
                except Exception:  # the context may already be gone
                    log.debug("release failed", exc_info=True)
        self._fbo = self._color = self._depth = None

    def _target(self, w: int, h: int):
        if self._fbo is None or self._size != (w, h):
            self.release()
            self._color = self.ctx.texture((w, h), 4)
            self._depth = self.ctx.depth_renderbuffer((w, h))
            self._fbo = self.ctx.framebuffer(color_attachments=[self._color], depth_attachment=self._depth)
            self._size = (w, h)
            self._key = None
        return self._fbo

    @staticmethod
    def key(state: AppState, cam, mode: str, vp, generation: int, blend) -> tuple:
        """What the image depends on (equal keys: the same pixels)."""
        s = state
        pose = tuple(np.round(np.concatenate([cam.eye, cam.target, cam.up]), 12).tolist())
        return (
            pose,
            float(cam.yfov),
            float(cam.znear),
            float(cam.zfar),
            mode,
            float(s.tuning.exposure),
            bool(s.view.tonemap),
            float(s.view.split) if mode == "split" else 0.0,
            float(s.view.diff_gain) if mode == "diff" else 0.0,
            tuple(vp),
            generation,
            tuple(blend),
            s.view.false_color.key() if mode == "false" else None,
        )

    # -- per frame -----------------------------------------------------------------------------
    def draw(self, state: AppState, mode: str | None, vp, cam, keep: str | None = None) -> bool:
        """Show the view for this frame; True when it was drawn anew (False: copied or nothing).

        keep : with nothing to show, the text drawn over the empty view; while it and the view's
          rectangle stay the same, the rectangle keeps last frame's pixels (``state.view.kept``: the
          text is not drawn again). None (the default): cleared every frame; the caller passes it
          only when nothing else was drawn over the view last frame (a floating window, a software
          cursor) and the window keeps its pixels across a swap (:mod:`viewer.panel_cache`)."""
        ctx = self.ctx
        fw, fh = glfw.get_framebuffer_size(glfw.get_current_context())
        ctx.screen.use()
        ctx.viewport = (0, 0, fw, fh)
        rect = (tuple(state.view.rect), (fw, fh))
        if rect != self._rect:
            self._rect, self._clear_frames = rect, 3
        cleared = self._clear_frames > 0 or vp is None
        if cleared:  # the panels cover the rest once laid out
            self._clear_frames = max(self._clear_frames - 1, 0)
            ctx.clear(*BACKGROUND)
        state.view.kept = False
        if mode is None or vp is None or cam is None:
            empty = (tuple(vp) if vp is not None else None, keep)
            state.view.kept = keep is not None and not cleared and empty == self._empty
            if vp is not None and not state.view.kept:  # only the view's rectangle is cleared
                ctx.scissor = tuple(int(v) for v in vp)
                ctx.clear(*BACKGROUND)
                ctx.scissor = None
            self._empty = empty
            self._dirty = False
            return False
        self._empty = None
        x, y, w, h = (int(v) for v in vp)
        fbo = self._target(w, h)
        key = self.key(state, cam, mode, vp, self.generation, self.renderer.blend)
        if key == self._key:  # the image holds this view: copy it
            self.blits += 1
            self._copy_to_screen(fbo, x, y, w, h)
            drew = False
        elif key == self._screen_key and self._blit is not None:
            # the view stopped changing: draw it once more into the image, then copy from there on
            self._render(state, cam, mode, fbo, (0, 0, w, h))
            self._key = key if not self.draw_error else None
            self._copy_to_screen(fbo, x, y, w, h)
            drew = True
        else:  # the view changes (camera, mode, ...): draw straight into the window, no copy
            ctx.screen.use()
            self._render(state, cam, mode, ctx.screen, (x, y, w, h))
            self._screen_key = key if not self.draw_error else None
            drew = True
        ctx.screen.use()
        ctx.viewport = (0, 0, fw, fh)
        self._dirty = drew
        state.stats.view_redraws, state.stats.view_copies = self.redraws, self.blits
        return drew

    def _render(self, state: AppState, cam, mode: str, target, viewport) -> None:
        t0 = time.perf_counter()
        try:
            if self.export is not None:
                self._draw_export(state, cam, target, viewport)
            elif mode == "false":  # lux or cd/m² in false colour, its legend (viewer.false_color)
                self.false_color = self.false_color or FalseColorView(self.ctx)
                self.false_color.draw(state, cam, target, viewport)
            else:
                self.renderer.draw(
                    cam,
                    mode,
                    viewport=viewport,
                    exposure=state.tuning.exposure,
                    tonemap=state.view.tonemap,
                    split=state.view.split,
                    diff_gain=state.view.diff_gain,
                    target=target,
                )
                state.stats.render = self.renderer.stats()
                state.stats.lod = self.renderer.lod_info()
            self.draw_error = ""
        except Exception as e:
            msg = f"cannot draw: {error_text(e)}"
            if msg != self.draw_error:  # once, not every frame
                self.draw_error = msg
                state.messages.set_error(msg)
        self.last_draw_ms = (time.perf_counter() - t0) * 1000.0
        self.redraws += 1

    def _draw_export(self, state: AppState, cam, target, viewport) -> None:
        x, y, w, h = (int(v) for v in viewport)
        target.use()
        target.clear(*BACKGROUND, 1.0, depth=1.0, viewport=(x, y, w, h))
        self.ctx.viewport = (x, y, w, h)
        self.export.draw(cam, (w, h), exposure=state.tuning.exposure, tonemap=state.view.tonemap)
        state.stats.render = {"triangles": self.export.triangles, "draw_calls": self.export.draw_calls}

    def render(self, cam, size: tuple[int, int], mode: str) -> np.ndarray:
        """``(h, w, 3) float32`` linear radiance of what the view shows in ``mode``, drawn offscreen."""
        if self.export is not None:
            return self.export.render(cam, size)
        return self.renderer.render(cam, size=size, mode=mode)

    def _copy_to_screen(self, fbo, x: int, y: int, w: int, h: int) -> None:
        if self._blit is not None and self._bind is not None:
            self.ctx.scissor = None
            self._disable(_GL_SCISSOR_TEST)
            self._bind(_GL_READ_FRAMEBUFFER, fbo.glo)
            self._bind(_GL_DRAW_FRAMEBUFFER, self.ctx.screen.glo)
            self._blit(0, 0, w, h, x, y, x + w, y + h, _GL_COLOR_BUFFER_BIT, _GL_NEAREST)
            self._bind(_GL_READ_FRAMEBUFFER, 0)
            self._bind(_GL_DRAW_FRAMEBUFFER, 0)
        else:  # no entry point: the view is drawn straight into the window every frame
            self._key = None

    # -- pixels --------------------------------------------------------------------------------
    def read(self, vp) -> np.ndarray:
        """(h, w, 3) uint8 of the 3D view as shown (the window's pixels inside ``vp``)."""
        x, y, w, h = vp
        raw = self.ctx.screen.read(viewport=(x, y, w, h), components=3, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()


def screenshot(state: AppState, view: View3D, vp, mode: str, directory: Path) -> None:
    """Write the 3D view to ``state.requests.screenshot`` (consumed; "" names it by model, mode and
    time in ``directory``) and tell the user."""
    from PIL import Image

    s = state
    path, s.requests.screenshot = s.requests.screenshot, None
    if not path:
        stem = Path(s.model.path).stem or "iat"
        path = str(directory / f"{stem}-{mode}-{time.strftime('%Y%m%d-%H%M%S')}.png")
    try:
        img = view.read(vp)
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(img).save(path)
        s.messages.last_screenshot = path
        s.messages.set_status(f"wrote {path}")
    except Exception as e:
        s.messages.set_error(f"cannot write the screenshot {path}: {error_text(e)}")


def auto_exposure(state: AppState, view: View3D, cam, mode: str, vp) -> None:
    """Set ``state.tuning.exposure`` to what ``iat render`` would pick for this view:
    :func:`iat.color.auto_exposure` of its linear radiance, drawn offscreen at the view's size (the
    split and difference views are exposed as the mesh)."""
    from iat.color import auto_exposure as exposure_of

    w, h = int(vp[2]), int(vp[3])
    scale = min(1.0, 512.0 / max(w, h))  # the 99th percentile does not need every pixel
    size = (max(int(round(w * scale)), 1), max(int(round(h * scale)), 1))
    try:
        img = view.render(cam, size, mode if mode in ("mesh", "iat", "preview") else "mesh")
    except Exception as e:
        state.messages.set_error(f"cannot measure the exposure: {error_text(e)}")
        return
    state.tuning.exposure = float(exposure_of(img))
