"""Model faults tinted in the 3D view (issue 36): the patches that carry a fault the loader found
(:func:`iat.geometry.faults.patch_faults`) drawn over the surfaces in each kind's colour.

:class:`FaultTint` is an overlay of a :class:`~iat.render.renderer.Renderer`: appended to its
``overlays``, it is drawn after the mode (preview, mesh, IAT, split; not the difference) and before
the sky and glass, into the same framebuffer and depth buffer (``shaders/faults.glsl``). The pixel
of a tinted patch becomes ``(1 - alpha) x what was drawn + alpha x colour``: in a float target
(:meth:`Renderer.render`) the colour is linear and the drawn radiance is exposure x radiance; in a
display target (tone mapped) both are sRGB-encoded. A patch with a back-to-back twin is tinted on its
front only (as the renderer draws it); the others on both sides.

:func:`render_faults` is ``iat render --faults``: the view exposed as ``iat render`` exposes it,
then tinted, with a legend of the kinds shown and their patch counts.
"""

from __future__ import annotations

import numpy as np

from iat.geometry.faults import COLORS, FAULTS, LABELS, fault_counts, patch_faults
from iat.geometry.sides import twin_patches
from iat.render import gl
from iat.render.buffers import upload_buffer
from iat.render.gl import Registry

#: the tint's share of a tinted pixel
ALPHA = 0.6
#: every kind
ALL = (1 << len(FAULTS)) - 1


class FaultTint:
    """The faulty patches of one scene, tinted (GL objects on ``ctx``; :meth:`release` frees them).

    shown : bits of the kinds tinted (:data:`ALL`); alpha : the tint's share (:data:`ALPHA`);
    enabled : False draws nothing. Set them between frames (they are uniforms).
    """

    def __init__(self, ctx):
        self.ctx = ctx
        self._reg = Registry()
        self.program = self._reg.add(gl.program(ctx, "faults"))
        self._vbo = self._vao = None
        self._twins = self._count = 0  # triangles: the first ``_twins`` have a twin (culled from behind)
        self.shown, self.alpha, self.enabled = ALL, ALPHA, True
        self.bits = np.zeros(0, dtype=np.uint8)

    def set_scene(self, scene, bits: np.ndarray | None = None) -> np.ndarray:
        """Upload the faulty patches of ``scene``; ``bits`` (P,) uint8 of :func:`patch_faults`
        (found when None). Returns the bits."""
        bits = patch_faults(scene) if bits is None else np.asarray(bits, dtype=np.uint8)
        tp = scene.world_triangle_patch()
        sel = bits[tp] > 0
        twin = twin_patches(scene.corner_positions, scene.patch_is_quad)[tp]
        order = np.concatenate([np.flatnonzero(sel & twin), np.flatnonzero(sel & ~twin)])
        tri = scene.world_triangles()[order]
        data = np.empty((len(order), 3, 4), dtype=np.float32)
        data[..., :3] = tri
        data[..., 3] = bits[tp[order]][:, None]
        self._vbo = upload_buffer(self.ctx, self._reg, self._vbo, data)
        if self._vao is None:
            self._vao = self._reg.add(
                self.ctx.vertex_array(self.program, [(self._vbo, "3f 1f", "in_position", "in_bits")])
            )
        self._twins, self._count = int((sel & twin).sum()), len(order)
        self.bits = bits
        return bits

    def draw(self, clip: bytes, tonemap: bool) -> None:
        """Tint the faulty patches in the bound framebuffer (``clip``: clip_from_world, column-major
        float32; ``tonemap``: a display target). Leaves blending, culling and the polygon offset off."""
        if not (self.enabled and self.shown and self._count):
            return
        import moderngl

        ctx, p = self.ctx, self.program
        p["clip_from_world"].write(clip)
        p["shown"].value, p["alpha"].value, p["tonemap"].value = (
            int(self.shown),
            float(self.alpha),
            bool(tonemap),
        )
        p["colors"].write(np.array([COLORS[k] for k in FAULTS], dtype=np.float32).tobytes())
        # two passes over the same triangles: the nearest tint fragment of each pixel writes its depth
        # (the colour kept: blend ZERO, ONE), then only it blends (depth equal): a pixel two faulty
        # patches cover (along a crease) is tinted once
        ctx.enable(moderngl.BLEND)
        ctx.polygon_offset = (-1.0, -1.0)
        n = 3 * self._twins
        try:
            for depth_func, blend in (
                ("<=", (moderngl.ZERO, moderngl.ONE)),
                ("==", moderngl.DEFAULT_BLENDING),
            ):
                ctx.depth_func, ctx.blend_func = depth_func, blend
                ctx.enable(moderngl.CULL_FACE)  # a patch with a twin: its front only
                self._vao.render(moderngl.TRIANGLES, vertices=n)
                ctx.disable(moderngl.CULL_FACE)
                self._vao.render(moderngl.TRIANGLES, vertices=3 * self._count - n, first=n)
        finally:
            ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            ctx.depth_func, ctx.polygon_offset = "<", (0.0, 0.0)

    def release(self) -> None:
        self._reg.release_all()
        self._vbo = self._vao = None
        self._count = self._twins = 0


def legend_rows(bits: np.ndarray, shown: int = ALL) -> list[tuple[str, tuple, int]]:
    """``[(label, colour, patches)]`` of the kinds ``shown`` lets through, in :data:`FAULTS` order:
    :data:`LABELS`, :data:`COLORS` (linear RGB) and the patches carrying the kind."""
    carried = fault_counts(bits)
    return [(LABELS[k], COLORS[k], carried[k]) for i, k in enumerate(FAULTS) if shown >> i & 1]


def draw_legend(img: np.ndarray, rows: list[tuple[str, tuple, int]]) -> np.ndarray:
    """``img`` (h, w, 3) float32 linear (saved with exposure 1) with the legend at its top left: a
    swatch and ``label: N patches`` a row on a dark ground, written as the linear values that encode
    to its sRGB pixels."""
    import cv2

    from iat.color import srgb_decode, srgb_encode

    h, w = img.shape[:2]
    fs = max(0.3, min(0.5, h / 900))
    font, th = cv2.FONT_HERSHEY_SIMPLEX, 1
    lines = [f"{label}: {n} patches" for label, _, n in rows] or ["no fault shown"]
    tw, tx = (
        max(cv2.getTextSize(t, font, fs, th)[0][0] for t in lines),
        cv2.getTextSize("lx", font, fs, th)[0][1],
    )
    step = tx + 10
    panel = np.full((min(step * len(lines) + 8, h), min(tw + step + 12, w), 3), 20, dtype=np.uint8)
    for k, text in enumerate(lines):
        y = 4 + k * step
        if k < len(rows):
            swatch = np.round(srgb_encode(np.asarray(rows[k][1], dtype=np.float64)) * 255)
            panel[y + 2 : y + step - 2, 4 : 4 + step - 4] = swatch.astype(np.uint8)
        cv2.putText(panel, text, (step + 6, y + tx + 4), font, fs, (230, 230, 230), th, cv2.LINE_AA)
    out = np.array(img, dtype=np.float32, copy=True)
    ph, pw = panel.shape[:2]
    out[:ph, :pw] = srgb_decode(panel.astype(np.float64) / 255.0)
    return out


def render_faults(renderer, scene, camera, size, mode: str, shown: int = ALL, exposure: float | None = None):
    """``(image (h, w, 3) float32, bits (P,) uint8)``: what ``renderer`` holds (scene, solution or
    bake) drawn in ``mode``, exposed by ``exposure`` (None: what :func:`iat.color.auto_exposure` picks
    for the untinted view), the faulty patches tinted over it (save it with exposure 1). The tint
    is taken off the renderer after."""
    from iat.color import auto_exposure

    if exposure is None:
        exposure = auto_exposure(renderer.render(camera, size=size, mode=mode))
    tint = FaultTint(renderer.ctx)
    try:
        bits = tint.set_scene(scene)
        tint.shown = int(shown)
        renderer.overlays.append(tint)
        try:
            img = renderer.render(camera, size=size, mode=mode, exposure=exposure)
        finally:
            renderer.overlays.remove(tint)
    finally:
        tint.release()
    return img, bits
