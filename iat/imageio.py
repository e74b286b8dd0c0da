"""Images out: tone map + sRGB 8-bit PNG, float32 ``.npy``, both written atomically.

Everything inside IAT is linear RGB radiance; tone mapping happens only here
(and in the renderer's window path, which uses the same curve): multiply by the
exposure, clamp to ``[0, 1]`` (no Reinhard, no filmic), encode with the sRGB
OETF, round to 8 bits.
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

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


#: A temporary file of an atomic write left behind by a killed writer is removed by the next
#: successful write of the same target once it is older than this (seconds): a younger one may
#: belong to another process writing the same file right now.
STALE_TEMPORARY_S = 3600.0


def temporary_pattern(path: str | os.PathLike) -> re.Pattern:
    """The names of the temporary files :func:`atomic_write` makes for ``path``: ``.<name>.<random>.tmp``
    in the same directory (``<random>``: letters, digits and ``_``, no dot)."""
    return re.compile(rf"\.{re.escape(Path(path).name)}\.[A-Za-z0-9_]+\.tmp")


def remove_stale_temporaries(path: str | os.PathLike, older_than_s: float = STALE_TEMPORARY_S) -> list[Path]:
    """Delete the temporaries of earlier writes of ``path`` (killed writers' debris) older than
    ``older_than_s`` seconds; returns those removed. Errors (a file already gone, no permission) are
    ignored: this is housekeeping after a write that already succeeded."""
    path = Path(path)
    pattern = temporary_pattern(path)
    now = time.time()
    removed = []
    try:
        siblings = list(os.scandir(path.parent))
    except OSError:
        return removed
    for entry in siblings:
        if not pattern.fullmatch(entry.name):
            continue
        try:
            if (
                entry.is_file(follow_symlinks=False)
                and now - entry.stat(follow_symlinks=False).st_mtime > older_than_s
            ):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
        except OSError:
            pass
    return removed


def atomic_write(
    path: str | os.PathLike, write: Callable[[BinaryIO], None], *, make_parents: bool = True
) -> Path:
    """Write through ``write(fileobj)`` into a temporary file next to ``path``, then rename over it.

    The one atomic writer of IAT's outputs (PNG and ``.npy`` images, GLB files, solutions): the
    temporary is ``.<name>.<random>.tmp`` in the target's directory (:func:`temporary_pattern`); it is
    flushed and fsynced, made ``0o644`` and renamed over ``path`` with ``os.replace``. If ``write``
    (or anything before the rename) raises, the temporary is removed, any old file at ``path`` is
    left untouched, and the exception propagates. After a successful write, temporaries of ``path``
    left by killed writers and older than :data:`STALE_TEMPORARY_S` are removed.
    make_parents : create missing parent directories first.
    """
    path = Path(path)
    if make_parents:
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
    remove_stale_temporaries(path)
    return path


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
