"""Images out: tone-mapped sRGB 8-bit PNG (:func:`iat.color.tonemap`) and float32 ``.npy``,
both written atomically (:func:`iat.fsutil.atomic_write`); PNG in."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from iat.color import tonemap
from iat.fsutil import atomic_write


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
