"""The viewer's false-colour view mode: illuminance (lux) or luminance (cd/m²) of the solution in
false colour, with the legend drawn into the view (so screenshots hold it too).

:class:`FalseColorSettings` (``state.view.false_color``) is what the View panel changes;
:class:`FalseColorView` draws it: a renderer of its own on the window's context holding the
solution with each vertex's colour as its radiance (:func:`iat.render.false_color.vertex_colors`:
colours interpolated between vertices, where ``iat render --false-color`` maps every pixel), drawn
in mesh mode with exposure 1 and the sRGB tone map, then the legend
(:func:`iat.render.false_color.legend_image`) as a textured quad at the view's right edge.
The daylight factor needs a solve under the CIE overcast sky: ``iat render --false-color
daylight-factor`` or ``iat analyse``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

#: the quantities the viewer shows, and their labels
QUANTITIES = {"illuminance": "Illuminance (lux)", "luminance": "Luminance (cd/m2)"}
#: the legend's height, at most, in framebuffer pixels
LEGEND_MAX_HEIGHT = 480


@dataclass
class FalseColorSettings:
    """quantity : "illuminance" or "luminance"; log : a log10 scale (else linear);
    auto : the range from the values (:func:`iat.render.false_color.auto_scale`), else ``lo``..``hi``;
    shown : the :class:`~iat.render.false_color.Scale` last drawn (None before), its line in the panel
    """

    quantity: str = "illuminance"
    log: bool = True
    auto: bool = True
    lo: float = 10.0
    hi: float = 10000.0
    shown: object = None
    probe: bool = True
    probed: dict | None = None

    def key(self) -> tuple:
        """What the picture depends on, besides the solution and the camera (with the probe on,
        the mouse: its readout is drawn into the view)."""
        return (
            self.quantity,
            self.log,
            self.auto,
            float(self.lo),
            float(self.hi),
            self.mouse() if self.probe else None,
        )

    @staticmethod
    def mouse() -> tuple[int, int]:
        """The mouse in window pixels (imgui's)."""
        from imgui_bundle import imgui

        m = imgui.get_io().mouse_pos
        return (int(round(m.x)), int(round(m.y))) if abs(m.x) < 1e6 and abs(m.y) < 1e6 else (-1, -1)

    def scale(self, values):
        from iat.render.false_color import Scale, auto_scale

        if self.auto:
            return auto_scale(values, self.quantity, self.log)
        lo = max(float(self.lo), 1e-6) if self.log else float(self.lo)
        return Scale(self.quantity, lo, max(float(self.hi), lo * 1.001 + 1e-6), self.log)


def vertex_values(quantity: str, scene, solution) -> np.ndarray:
    """(V,) lux or cd/m² at the solution's vertices (:mod:`iat.measure.photometry`)."""
    from iat.measure import photometry as ph

    if quantity == "luminance":
        return ph.vertex_luminance(solution)
    emission = (
        scene.patch_emission if scene is not None and scene.n_patches == len(solution.patch_albedo) else None
    )
    return ph.vertex_illuminance(solution, emission)


class FalseColorView:
    """Draws the false-colour view on the window's moderngl ``ctx`` (made at the first draw)."""

    def __init__(self, ctx):
        from iat.render.gl import program
        from iat.render.renderer import Renderer

        self.ctx = ctx
        self.renderer = Renderer(ctx)  # no scene set: no detail textures scale the colours
        self._prog = program(ctx, "legend")
        self._quad = ctx.vertex_array(self._prog, [])
        self._tex = None
        self._label = None  # the probe's readout texture
        self._probe = None  # (Visibility of the drawn triangles, their corners, lux and cd/m² at them)
        self._key = None
        self._legend_key = None
        self._legend_size = (0, 0)

    def release(self) -> None:
        if self._probe is not None:
            self._probe[0].close()
        for o in (self._tex, self._label, self._quad, self._prog):
            if o is not None:
                try:
                    o.release()
                except Exception:  # the context may already be gone
                    log.debug("release failed", exc_info=True)
        self._tex = self._label = self._quad = self._prog = None
        self.renderer.release()

    def _update(self, state) -> None:
        from iat.render.false_color import quantity_solution, vertex_colors

        sol, fc = state.model.solution, state.view.false_color
        key = (id(sol), fc.key()[:5])
        if key == self._key:
            return
        values = vertex_values(fc.quantity, state.model.scene, sol)
        scale = fc.scale(values)
        self.renderer.set_solution(quantity_solution(sol, values, vertex_colors(values, scale)))
        fc.shown = scale
        if self._probe is None or self._probe[4] is not sol:
            self._probe_scene(state, sol)
        self._key = key

    def _probe_scene(self, state, sol) -> None:
        from iat.radiosity.visibility import Visibility

        if self._probe is not None:
            self._probe[0].close()
        drawn = sol.drawn_mesh()
        tri = np.asarray(drawn.triangles, dtype=np.int64).reshape(-1, 3)
        lux = vertex_values("illuminance", state.model.scene, sol)
        cd = vertex_values("luminance", state.model.scene, sol)
        both = drawn.radiance(np.stack([lux, cd, np.zeros(len(lux))], axis=1))
        self._probe = (
            Visibility(drawn.position[tri], threads=1),
            drawn.position[tri],
            both[tri],
            drawn.patch[tri[:, 0]],
            sol,
        )

    def probe_at(self, cam, rect, mouse) -> dict | None:
        """``{"lux", "cd_m2", "point", "patch"}`` of the surface under window pixel ``mouse`` in the
        view ``rect`` (values linear over the drawn triangle, as the colours), or None (nothing)."""
        from viewer.picking import mouse_ray

        x, y, w, h = rect
        if self._probe is None or not (x <= mouse[0] < x + w and y <= mouse[1] < y + h):
            return None
        vis, corners, vals = self._probe[:3]
        o, d = mouse_ray(cam, rect, mouse)
        tri, bary = vis.first_hits(o[None, :], d[None, :], np.array([1e7]))
        if tri[0] < 0:
            return None
        b = np.array([1.0 - bary[0, 0] - bary[0, 1], bary[0, 0], bary[0, 1]])
        v = b @ vals[tri[0]]
        point = (b @ corners[tri[0]]).tolist()
        return {
            "lux": float(v[0]),
            "cd_m2": float(v[1]),
            "point": point,
            "patch": int(self._probe[3][tri[0]]),
        }

    def _legend(self, scale, height: int) -> tuple[int, int]:
        from iat.render.false_color import legend_image

        key = (scale, height)
        if key != self._legend_key:
            img = np.flipud(legend_image(height, scale))  # GL rows from the bottom
            if self._tex is not None:
                self._tex.release()
            self._tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, np.ascontiguousarray(img).tobytes())
            self._legend_key, self._legend_size = key, (img.shape[1], img.shape[0])
        return self._legend_size

    def draw(self, state, cam, target, viewport) -> None:
        """The view in false colour into ``target`` (a framebuffer) at ``viewport`` (x, y, w, h)."""
        self._update(state)
        self.renderer.draw(cam, "mesh", viewport=viewport, exposure=1.0, tonemap=True, target=target)
        x, y, w, h = (int(v) for v in viewport)
        lh = min(h - 16, LEGEND_MAX_HEIGHT)
        if lh < 60:
            return
        lw, lh = self._legend(state.view.false_color.shown, lh)
        if lw + 16 > w:
            return
        import moderngl

        ctx = self.ctx
        target.use()
        ctx.viewport = (x + w - lw - 8, y + (h - lh) // 2, lw, lh)
        ctx.disable(moderngl.DEPTH_TEST)  # (the renderer leaves it off too)
        self._tex.use(0)
        self._prog["image"] = 0
        self._quad.render(mode=moderngl.TRIANGLE_STRIP, vertices=4)
        self._draw_probe(state, cam, viewport)
        ctx.viewport = (x, y, w, h)

    def _draw_probe(self, state, cam, viewport) -> None:
        """The readout under the mouse (``state.view.false_color.probed``), drawn beside it."""
        import cv2

        fc = state.view.false_color
        fc.probed = self.probe_at(cam, state.view.rect, fc.mouse()) if fc.probe else None
        if fc.probed is None:
            return
        lux = fc.probed["lux"]
        text = f"{'?' if not np.isfinite(lux) else f'{lux:.0f}'} lx  {fc.probed['cd_m2']:.0f} cd/m2"
        font, fs = cv2.FONT_HERSHEY_SIMPLEX, 0.5
        (tw, th), _ = cv2.getTextSize(text, font, fs, 1)
        img = np.full((th + 12, tw + 12, 3), 20, dtype=np.uint8)
        cv2.putText(img, text, (6, th + 5), font, fs, (240, 240, 240), 1, cv2.LINE_AA)
        if self._label is not None:
            self._label.release()
        self._label = self.ctx.texture(
            (img.shape[1], img.shape[0]), 3, np.ascontiguousarray(np.flipud(img)).tobytes()
        )
        sx, sy = state.view.framebuffer_scale
        rx, ry = (fc.mouse()[0] - state.view.rect[0]) * sx, (fc.mouse()[1] - state.view.rect[1]) * sy
        vx, vy, vw, vh = (int(v) for v in viewport)
        lx = int(min(vx + rx + 14, vx + vw - img.shape[1]))
        ly = int(max(vy + vh - ry - 14 - img.shape[0], vy))
        self.ctx.viewport = (lx, ly, img.shape[1], img.shape[0])
        self._label.use(0)
        self._quad.render(mode=5, vertices=4)  # GL_TRIANGLE_STRIP


def settings_panel(state) -> None:
    """The View panel's controls of the false-colour mode (no GL here)."""
    from imgui_bundle import imgui

    fc = state.view.false_color
    for i, (q, label) in enumerate(QUANTITIES.items()):
        if i:
            imgui.same_line()
        if imgui.radio_button(label, fc.quantity == q):
            fc.quantity = q
    _, fc.log = imgui.checkbox("Log scale", fc.log)
    imgui.same_line()
    _, fc.probe = imgui.checkbox("Probe", fc.probe)
    imgui.same_line()
    _, fc.auto = imgui.checkbox("Auto range", fc.auto)
    if not fc.auto:
        _, fc.lo = imgui.input_float("From", float(fc.lo))
        _, fc.hi = imgui.input_float("To", float(fc.hi))
    if fc.shown is not None:
        imgui.text_disabled(fc.shown.describe())
    imgui.text_disabled("daylight factor: iat render --false-color daylight-factor, iat analyse")
