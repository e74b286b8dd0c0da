"""Atomic writes: the one writer of IAT's outputs, and the cleanup of killed writers' temporaries."""

from __future__ import annotations

import os
import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

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
