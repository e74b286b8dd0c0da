"""Images out: tone map + sRGB 8-bit PNG, float32 ``.npy``, both written atomically.

Everything inside IAT is linear RGB radiance; tone mapping happens only here
(and in the renderer's window path, which uses the same curve): multiply by the
exposure, clamp to ``[0, 1]`` (no Reinhard, no filmic), encode with the sRGB
OETF, round to 8 bits.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

#: Rec. 709 / sRGB luminance weights of linear RGB.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """The sRGB OETF on linear values already clamped to ``[0, 1]``.

    x : (...) float array -> (...) float64 in ``[0, 1]``
    """
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1.0 / 2.4) - 0.055)


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


def _atomic_write(path: str | os.PathLike, write: Callable[[object], None]) -> Path:
    """Write through ``write(fileobj)`` into a temp file next to ``path``, then rename over it.

    Parent directories are created. If ``write`` raises, the temp file is removed,
    any old file at ``path`` is left untouched, and the exception propagates.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def save_png(path: str | os.PathLike, linear: np.ndarray, exposure: float | None = 1.0) -> Path:
    """Tone map ``linear`` ((h, w, 3) float radiance) and write an 8-bit sRGB PNG atomically.

    exposure : multiplier before the clamp; None picks :func:`auto_exposure`.
    Returns the path written.
    """
    from PIL import Image

    img = Image.fromarray(tonemap(linear, exposure))
    return _atomic_write(path, lambda f: img.save(f, format="PNG"))


def save_npy(path: str | os.PathLike, linear: np.ndarray) -> Path:
    """Write ``linear`` as a float32 ``.npy`` (no tone map) atomically; returns the path."""
    a = np.ascontiguousarray(np.asarray(linear, dtype=np.float32))
    return _atomic_write(path, lambda f: np.save(f, a, allow_pickle=False))


def load_png(path: str | os.PathLike) -> np.ndarray:
    """Read a PNG back as (h, w, 3) uint8 (for tests and comparisons)."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))
