"""GPU pixel formats of the atlas pages: bytes per texel, the host dtype of each format's GPU
form, the conversions to and from it, and the quantisation the stored formats apply.

Pages are linear radiance ``(..., 3)`` float32; their GPU form is ``(..., 4)``
(:data:`GPU_DTYPES`), written to GL as it is. rgba8 stores sRGB8 of ``radiance / page_scale``
(one scale for all pages: :func:`rgba8_page_scale`).
"""

from __future__ import annotations

import numpy as np

from iat.color import srgb_decode, srgb_encode
from iat.errors import OptionError

#: bytes per texel on the GPU for each pixel format
BYTES_PER_TEXEL = {"rgba16f": 8, "rgba8": 4, "rgb9e5": 4}
#: host dtype of each pixel format's GPU form: ``(..., 4)`` arrays the renderer writes as they are
#: (rgba8: sRGB8 codes of ``page / page_scale``, alpha 255; rgb9e5: the 9e5-rounded values as half
#: floats, which hold them exactly and which GL packs into GL_RGB9_E5; float formats: alpha 1)
GPU_DTYPES = {"rgba16f": np.float16, "rgba32f": np.float32, "rgba8": np.uint8, "rgb9e5": np.float16}
#: largest finite half float; brighter radiance is clamped to it, never turned into inf
HALF_MAX = 65504.0


def quantise_rgba8(x: np.ndarray, scale: float) -> np.ndarray:
    """Round-trip through sRGB8 of ``x / scale`` (clamped to [0, 1]); float32."""
    return (srgb_decode(_rgba8_codes(x, scale) / 255.0) * scale).astype(np.float32)


def to_gpu(
    x: np.ndarray, pixel_format: str, page_scale: float = 1.0, out: np.ndarray | None = None
) -> np.ndarray:
    """``(..., 3)`` linear values -> their GPU form ``(..., 4)`` of dtype ``GPU_DTYPES[pixel_format]``.

    rgba8: ``rint(sRGB(clip(x / page_scale, 0, 1)) x 255)`` (GL_SRGB8_ALPHA8 decodes it before
    filtering); rgb9e5: :func:`quantise_rgb9e5` then float16 (exact); rgba16f: clamped to
    +-:data:`HALF_MAX`; rgba32f: as is.
    out : an array of that shape and dtype to write into (returned), or None for a new one.
    """
    if pixel_format not in GPU_DTYPES:
        raise OptionError(f"unknown pixel format {pixel_format!r} (known: {', '.join(GPU_DTYPES)})")
    x = np.asarray(x)[..., :3]
    dt = GPU_DTYPES[pixel_format]
    if out is None:
        out = np.empty(x.shape[:-1] + (4,), dtype=dt)
    if pixel_format == "rgba8":
        out[..., 3] = 255
        out[..., :3] = _rgba8_codes(x, page_scale)
        return out
    out[..., 3] = 1.0
    if pixel_format == "rgb9e5":
        out[..., :3] = quantise_rgb9e5(x)
    elif pixel_format == "rgba16f":
        np.clip(x, -HALF_MAX, HALF_MAX, out=out[..., :3], casting="unsafe")
    else:
        out[..., :3] = x
    return out


def from_gpu(g: np.ndarray, pixel_format: str, page_scale: float = 1.0) -> np.ndarray:
    """Inverse of :func:`to_gpu`: ``(..., 4)`` GPU form -> ``(..., 3)`` float32 linear values
    (what the shader reads, times ``page_scale`` for rgba8)."""
    g = np.asarray(g)[..., :3]
    if pixel_format == "rgba8":
        return (srgb_decode(g.astype(np.float64) / 255.0) * page_scale).astype(np.float32)
    return g.astype(np.float32)


def _rgba8_codes(x: np.ndarray, scale: float) -> np.ndarray:
    return np.round(srgb_encode(np.clip(np.asarray(x, np.float64) / scale, 0.0, 1.0)) * 255.0).astype(
        np.uint8
    )


def quantise_rgb9e5(x: np.ndarray) -> np.ndarray:
    """Round-trip through GL_RGB9_E5 (EXT_texture_shared_exponent); float32."""
    n_bits, bias, emax = 9, 15, 31
    vmax = (2**n_bits - 1) / 2**n_bits * 2.0 ** (emax - bias)
    c = np.clip(np.asarray(x, np.float64), 0.0, vmax)
    m = np.maximum(c.max(axis=-1, keepdims=True), 2.0 ** (-bias - 1))
    e = np.maximum(-bias - 1, np.floor(np.log2(m))) + 1 + bias
    mm = np.floor(m / 2.0 ** (e - bias - n_bits) + 0.5)
    e = np.where(mm >= 2**n_bits, e + 1, e)
    step = 2.0 ** (e - bias - n_bits)
    return (np.floor(c / step + 0.5) * step).astype(np.float32)


def rgba8_page_scale(values: np.ndarray) -> float:
    """The rgba8 page scale of stored values ``(V, 3)`` (the largest; 1.0 when empty or not > 0)."""
    s = float(values.max()) if values.size else 1.0
    return s if s > 0 else 1.0
