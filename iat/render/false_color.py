"""False colour: a per-vertex quantity (lux, cd/m², daylight factor %) drawn through a colour scale,
with its legend drawn into the image.

:func:`quantity_solution` puts a quantity where a solution's radiance was (red: the value; green:
1 where it is known, 0.5 where it is not, e.g. a black surface's illuminance; glass left out), so
mesh mode draws it interpolated exactly as it draws radiance; :func:`false_color_image` renders that
on a renderer of its own (no detail textures, no sky, no glass), maps each pixel through the
:class:`Scale` and draws the legend. :func:`vertex_colors` gives per-vertex colours instead (the
viewer's view mode: a solution whose radiance is the colour, drawn with exposure 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from iat.color import srgb_decode

#: the colour map, display (sRGB) values from low to high: dark blue, blue, cyan, green, yellow,
#: orange, red, dark red (a "turbo"-like spectrum, as RADIANCE's falsecolor and DIALux use)
PALETTE = np.array(
    [
        [0.19, 0.07, 0.23],
        [0.27, 0.38, 0.87],
        [0.16, 0.68, 0.98],
        [0.10, 0.90, 0.72],
        [0.46, 0.99, 0.36],
        [0.84, 0.91, 0.21],
        [0.99, 0.64, 0.18],
        [0.89, 0.27, 0.05],
        [0.48, 0.02, 0.01],
    ]
)
#: display colour of surfaces whose value is unknown (a black surface's illuminance, glass)
UNKNOWN = np.array([0.5, 0.5, 0.5])
#: the quantities and their units
UNITS = {"illuminance": "lx", "luminance": "cd/m2", "daylight-factor": "%"}
QUANTITIES = tuple(UNITS)


@dataclass(frozen=True)
class Scale:
    """A colour scale: ``lo`` maps to the first colour and ``hi`` to the last, linearly or in
    log10 (``log``; then ``lo > 0``); values outside are clamped to the ends."""

    quantity: str
    lo: float
    hi: float
    log: bool = True

    def __post_init__(self):
        if self.quantity not in UNITS:
            raise ValueError(f"unknown quantity {self.quantity!r} (one of {', '.join(QUANTITIES)})")
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.hi > self.lo):
            raise ValueError(f"a scale's range must be finite with lo < hi, got {self.lo}, {self.hi}")
        if self.log and self.lo <= 0:
            raise ValueError(f"a log scale needs lo > 0, got {self.lo}")

    @property
    def unit(self) -> str:
        return UNITS[self.quantity]

    def position(self, values) -> np.ndarray:
        """(...) float64 in [0, 1] (NaN stays NaN)."""
        v = np.asarray(values, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.log:
                t = (np.log10(np.maximum(v, 1e-300)) - math.log10(self.lo)) / math.log10(self.hi / self.lo)
            else:
                t = (v - self.lo) / (self.hi - self.lo)
        return np.where(np.isnan(v), np.nan, np.clip(t, 0.0, 1.0))

    def ticks(self) -> list[float]:
        """Values to label: each power of ten (log; with 2 and 5 between when under three
        decades), or about six round steps (linear)."""
        if self.log:
            k0, k1 = math.floor(math.log10(self.lo) + 1e-9), math.ceil(math.log10(self.hi) - 1e-9)
            steps = (1, 2, 5) if k1 - k0 <= 3 else (1,)
            vals = [m * 10.0**k for k in range(k0, k1 + 1) for m in steps]
        else:
            step = nice_step((self.hi - self.lo) / 5)
            vals = list(np.arange(math.ceil(self.lo / step) * step, self.hi + step * 1e-6, step))
        return [float(v) for v in vals if self.lo * (1 - 1e-9) <= v <= self.hi * (1 + 1e-9)]

    def describe(self) -> str:
        """One line: ``illuminance, log scale 10 .. 10000 lx``."""
        kind = "log" if self.log else "linear"
        return f"{self.quantity}, {kind} scale {fmt(self.lo)} .. {fmt(self.hi)} {self.unit}"

    def to_dict(self) -> dict:
        return {"quantity": self.quantity, "lo": self.lo, "hi": self.hi, "log": self.log, "unit": self.unit}


def nice_step(x: float) -> float:
    """The round number (1, 2 or 5 x a power of ten) at or above ``x`` > 0."""
    k = math.floor(math.log10(x))
    for m in (1, 2, 5, 10):
        if m * 10.0**k >= x * (1 - 1e-9):
            return m * 10.0**k
    return 10.0 ** (k + 1)


def fmt(v: float) -> str:
    """A label: ``0``, ``0.5``, ``20``, ``1500``, ``10000``, ``2e+06``."""
    if v == 0:
        return "0"
    if abs(v) >= 1e6 or abs(v) < 1e-2:
        return f"{v:.0e}"
    if abs(v) >= 100:
        return f"{v:.0f}"
    return f"{v:.3g}"


def auto_scale(values, quantity: str, log: bool | None = None) -> Scale:
    """A scale for ``values``: the daylight factor linear from 0 to 10 % (the usual range; to a
    round number at or above twice the median when that is higher: vertices crowd where the light
    changes, so a window's bright reveal weighs more than the room in any upper percentile);
    illuminance and luminance in log10, from the power of ten at or above the 99th percentile down
    two to four decades (to the power of ten at or below the 1st percentile)."""
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if log is None:
        log = quantity != "daylight-factor"
    if log:
        pos = v[v > 0]
        p1, p99 = np.percentile(pos, [1, 99]) if len(pos) else (1.0, 100.0)
        hi = 10.0 ** math.ceil(math.log10(max(float(p99), 1e-6)))
        lo = 10.0 ** math.floor(math.log10(max(float(p1), 1e-6)))
        return Scale(quantity, min(max(lo, hi / 1e4), hi / 100), hi, True)
    if quantity == "daylight-factor":
        top = 2.0 * float(np.median(v)) if len(v) else 0.0
        hi = 10.0 if top <= 10.0 else math.ceil(top / nice_step(top / 5)) * nice_step(top / 5)
        return Scale(quantity, 0.0, float(hi), False)
    top = max(float(np.percentile(v, 99)) if len(v) else 1.0, 1e-6)
    return Scale(quantity, 0.0, math.ceil(top / nice_step(top / 5)) * nice_step(top / 5), False)


def colorize(values, scale: Scale) -> np.ndarray:
    """(..., 3) float64 display (sRGB) colours of ``values`` (...); NaN -> :data:`UNKNOWN`."""
    t = scale.position(values)
    x = np.nan_to_num(t, nan=0.0) * (len(PALETTE) - 1)
    i = np.clip(np.floor(x).astype(np.int64), 0, len(PALETTE) - 2)
    f = (x - i)[..., None]
    out = PALETTE[i] * (1 - f) + PALETTE[i + 1] * f
    return np.where(np.isnan(t)[..., None], UNKNOWN, out)


def vertex_colors(values, scale: Scale) -> np.ndarray:
    """(V, 3) float32 linear colours of per-vertex ``values``: drawn as radiance with exposure 1 and
    the sRGB tone map, each vertex shows its :func:`colorize` colour."""
    return srgb_decode(colorize(values, scale)).astype(np.float32)


def quantity_solution(solution, values, colors=None):
    """A copy of ``solution`` that mesh mode draws as the quantity: its radiance
    ``(value, 1, 0)`` at known vertices and ``(0, 0.5, 0)`` at unknown ones (or ``colors`` (V, 3)
    when given), its glass triangles left out and nothing transmissive."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if colors is None:
        known = np.isfinite(v)
        rad = np.stack([np.where(known, v, 0.0), np.where(known, 1.0, 0.5), np.zeros(len(v))], axis=1)
    else:
        rad = np.asarray(colors, dtype=np.float32).reshape(-1, 3)
    tri = np.asarray(solution.tri_vertices).reshape(-1, 3)
    tau = np.asarray(getattr(solution, "patch_transmission", np.zeros(0)), dtype=np.float64).reshape(-1)
    if len(tau) and (tau > 0).any() and len(tri):
        n = 1 << int(solution.max_depth)
        patch = np.asarray(solution.vert_key, dtype=np.int64)[tri[:, 0]] // ((n + 1) * (n + 1))
        tri = tri[tau[patch] <= 0]
    return replace(
        solution,
        vert_radiance=rad.astype(np.float32),
        tri_vertices=tri,
        patch_transmission=np.zeros(0, dtype=np.float32),
    )


def quantity_image(
    solution, values, camera, size: tuple[int, int], renderer=None
) -> tuple[np.ndarray, np.ndarray]:
    """(h, w) float64 the per-vertex ``values`` of ``solution`` as seen by ``camera`` (NaN where no
    surface is drawn or its value is unknown), and (h, w) bool where a surface is drawn.
    ``renderer``: a :class:`~iat.render.renderer.Renderer` with no scene set (else detail textures
    would scale the values); default one made here."""
    from iat.render.renderer import Renderer

    own = renderer is None
    r = Renderer() if own else renderer
    try:
        r.set_solution(quantity_solution(solution, values))
        img = r.render(camera, size=size, mode="mesh", exposure=1.0)
    finally:
        if own:
            r.release()
    g = img[..., 1]
    return np.where(g > 0.75, img[..., 0] / np.maximum(g, 1e-6), np.nan), g > 0.25


def false_color_image(
    solution,
    values,
    camera,
    size: tuple[int, int],
    scale: Scale | None = None,
    legend: bool = True,
    renderer=None,
) -> tuple[np.ndarray, Scale]:
    """(h, w, 3) uint8 sRGB image of the per-vertex ``values`` through ``scale`` (default
    :func:`auto_scale` of the values), unknown surfaces grey, background black, with the legend
    (:func:`draw_legend`); and the scale used. ``renderer`` as :func:`quantity_image`'s."""
    scale = auto_scale(values, "illuminance") if scale is None else scale
    q, drawn = quantity_image(solution, values, camera, size, renderer)
    rgb = np.where(drawn[..., None], colorize(q, scale), 0.0)
    img = np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8)
    if legend:
        img = draw_legend(img, scale)
    return img, scale


def legend_image(height: int, scale: Scale) -> np.ndarray:
    """(height, pw, 3) uint8 the scale's legend panel: a colour bar (low at the bottom) on a dark
    ground, tick labels, the unit above and ``log``/``linear`` below; its width fits the labels."""
    import cv2

    fs = max(0.3, min(0.5, height / 900))
    font, th = cv2.FONT_HERSHEY_SIMPLEX, max(1, int(round(fs * 2)))
    labels = [fmt(v) for v in scale.ticks()] or [fmt(scale.hi)]
    label_w = max(cv2.getTextSize(t, font, fs, th)[0][0] for t in [*labels, scale.unit, "linear"])
    text_h = cv2.getTextSize("lx", font, fs, th)[0][1]
    bar_w = max(8, height // 30)
    out = np.full((height, bar_w + label_w + 18, 3), 20, dtype=np.uint8)
    top, bottom = 2 * text_h + 12, height - 2 * text_h - 12
    ys = np.arange(top, bottom)
    t = 1.0 - (ys - top) / max(bottom - top - 1, 1)
    lo, hi = (math.log10(scale.lo), math.log10(scale.hi)) if scale.log else (scale.lo, scale.hi)
    vals = 10.0 ** (lo + t * (hi - lo)) if scale.log else lo + t * (hi - lo)
    out[top:bottom, 4 : 4 + bar_w] = np.round(colorize(vals, scale) * 255).astype(np.uint8)[:, None, :]
    white = (230, 230, 230)
    for v in scale.ticks():
        y = int(round(bottom - 1 - float(scale.position(v)) * (bottom - top - 1)))
        cv2.line(out, (4 + bar_w, y), (8 + bar_w, y), white, 1)
        cv2.putText(out, fmt(v), (10 + bar_w, y + text_h // 2), font, fs, white, th, cv2.LINE_AA)
    cv2.putText(out, scale.unit, (4, top - text_h // 2 - 4), font, fs, white, th, cv2.LINE_AA)
    kind = "log" if scale.log else "linear"
    cv2.putText(out, kind, (4, bottom + text_h + 8), font, fs, white, th, cv2.LINE_AA)
    return out


def draw_legend(img: np.ndarray, scale: Scale) -> np.ndarray:
    """``img`` (h, w, 3) uint8 with :func:`legend_image` at its right edge (4 pixels in)."""
    out = np.ascontiguousarray(img.copy())
    h, w = out.shape[:2]
    panel = legend_image(h - 4, scale)[:, : max(w - 4, 1)]
    out[2 : h - 2, w - 2 - panel.shape[1] : w - 2] = panel
    return out
