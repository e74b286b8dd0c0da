"""One-line descriptions of the exceptions that third-party readers (pygltflib, trimesh, PIL)
raise, for the cause of a :class:`iat.errors.LoadError`."""

from __future__ import annotations


def one_line(e: BaseException, limit: int = 200) -> str:
    """``"TypeName: message"`` with whitespace collapsed, cut to ``limit`` characters."""
    msg = " ".join(str(e).split())
    if len(msg) > limit:
        msg = msg[: limit - 3] + "..."
    return f"{type(e).__name__}: {msg}" if msg else type(e).__name__
