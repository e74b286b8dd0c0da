"""Colour: luminance weights, the sRGB transfer curve, exposure and the tone map.

Everything inside IAT is linear RGB radiance; tone mapping happens only at the
output (PNG files here, the renderer's window path in ``shaders/color.glsl``,
which uses the same curve): multiply by the exposure, clamp to ``[0, 1]`` (no
Reinhard, no filmic), encode with the sRGB OETF, round to 8 bits.
"""

from __future__ import annotations

import numpy as np

#: Rec. 709 / sRGB luminance weights of linear RGB.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
#: lm/W: radiometric values to photometric ones, ``LUMINOUS_EFFICACY x LUMINANCE_WEIGHTS . rgb``
#: (RADIANCE's white efficacy; the one conversion, :mod:`iat.measure.photometry`)
LUMINOUS_EFFICACY = 179.0


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """The sRGB OETF on linear values already clamped to ``[0, 1]``.

    x : (...) float array -> (...) float64 in ``[0, 1]``
    """
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1.0 / 2.4) - 0.055)


def srgb_decode(y: np.ndarray) -> np.ndarray:
    """The inverse of :func:`srgb_encode`: sRGB-encoded values in ``[0, 1]`` -> linear.

    y : (...) float array -> (...) float64 in ``[0, 1]``
    """
    y = np.asarray(y, dtype=np.float64)
    return np.where(y <= 0.04045, y / 12.92, np.power((np.maximum(y, 0.04045) + 0.055) / 1.055, 2.4))


def auto_exposure(linear: np.ndarray) -> float:
    """Exposure that maps the 99th percentile of luminance to 0.8.

    linear : (h, w, 3) float linear radiance. Returns 1.0 for a black (or non-finite) image.
    """
    a = np.asarray(linear, dtype=np.float64)
    lum = a[..., :3] @ LUMINANCE_WEIGHTS if a.ndim >= 1 and a.shape[-1] >= 3 else a
    lum = lum[np.isfinite(lum)]
    if lum.size == 0:
        return 1.0
    p99 = float(np.percentile(lum, 99))
    if not np.isfinite(p99) or p99 <= 0.0:
        return 1.0
    return 0.8 / p99


def tonemap(linear: np.ndarray, exposure: float | None = 1.0) -> np.ndarray:
    """Linear radiance to display values.

    linear : (h, w, 3) float linear RGB radiance (NaN counts as 0, +inf as 1)
    exposure : multiplier applied first; None picks :func:`auto_exposure`
    Returns (h, w, 3) uint8 sRGB-encoded.
    """
    a = np.asarray(linear, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"tonemap expects an (h, w, 3) image, got shape {a.shape}")
    if exposure is None:
        exposure = auto_exposure(a)
    x = np.nan_to_num(a * float(exposure), nan=0.0, posinf=1.0, neginf=0.0)
    x = np.clip(x, 0.0, 1.0)
    return np.rint(srgb_encode(x) * 255.0).astype(np.uint8)
