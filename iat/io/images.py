"""Images out: tone-mapped sRGB 8-bit PNG (:func:`iat.color.tonemap`) and float32 ``.npy``,
both written atomically (:func:`iat.fsutil.atomic_write`); PNG in; model textures decoded to
linear RGB (:func:`decode_texture`)."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from iat.color import srgb_decode, tonemap
from iat.errors import LoadError
from iat.fsutil import atomic_write
from iat.io.messages import one_line


def save_png(path: str | os.PathLike, linear: np.ndarray, exposure: float | None = 1.0) -> Path:
    """Tone map ``linear`` ((h, w, 3) float radiance) and write an 8-bit sRGB PNG atomically.

    exposure : multiplier before the clamp; None picks :func:`auto_exposure`.
    Returns the path written.
    """
    from PIL import Image

    img = Image.fromarray(tonemap(linear, exposure))
    return atomic_write(path, lambda f: img.save(f, format="PNG"))


def save_npy(path: str | os.PathLike, linear: np.ndarray) -> Path:
    """Write ``linear`` as a float32 ``.npy`` (no tone map) atomically; returns the path."""
    a = np.ascontiguousarray(np.asarray(linear, dtype=np.float32))
    return atomic_write(path, lambda f: np.save(f, a, allow_pickle=False))


def load_png(path: str | os.PathLike) -> np.ndarray:
    """Read a PNG back as (h, w, 3) uint8 (for tests and comparisons)."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def decode_texture(data, path: Path, what: str) -> np.ndarray:
    """Encoded image bytes or a PIL image -> (h, w, 3) float32 linear RGB (sRGB decoded).

    8-bit images are read as ``code / 255``, 16-bit grey ones as ``code / 65535``.
    Raises :class:`iat.errors.LoadError` naming ``path`` and the texture ``what``.
    """
    from PIL import Image

    try:
        img = data if isinstance(data, Image.Image) else Image.open(io.BytesIO(data))
        img.load()
        if img.mode in ("I;16", "I;16B", "I;16L", "I"):
            a = np.asarray(img, dtype=np.float32) / 65535.0
            a = np.repeat(a[..., None], 3, axis=2)
        else:
            a = np.asarray(img.convert("RGB"), dtype=np.float32) / 255.0
    except Exception as e:  # noqa: BLE001 - any decoder failure is a bad file
        raise LoadError(f"cannot decode texture {what} ({one_line(e)})", path) from e
    if a.ndim != 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise LoadError(f"cannot decode texture {what} (empty image)", path)
    return np.ascontiguousarray(srgb_decode(np.clip(a, 0.0, 1.0)).astype(np.float32))
