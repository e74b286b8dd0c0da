"""One exception family for IAT.

Every error a user can cause (a bad file, a bad option) is an :class:`IATError`
whose message names the file (when there is one) and the cause, in one line.
The CLI prints ``str(err)`` and exits 2; the viewer shows it and keeps running.
"""

from __future__ import annotations

from pathlib import Path


class IATError(Exception):
    """Base of every error IAT raises on purpose.

    Parameters
    ----------
    cause
      What went wrong, one line, no trailing period.
    path
      The file concerned, if any; it is named first in the message.
    """

    def __init__(self, cause: str, path: str | Path | None = None):
        self.cause = cause
        self.path = None if path is None else str(path)
        super().__init__(f"{self.path}: {cause}" if self.path else cause)


class LoadError(IATError):
    """A model file cannot be read or holds nothing usable."""


class SolutionFileError(IATError):
    """A solution ``.npz`` is damaged, of another version, or not a solution."""


class OptionError(IATError):
    """An option is out of range or inconsistent (threshold < 0, scale <= 0, ...)."""


class BakeError(IATError):
    """Baking failed (for instance a texture that cannot fit any atlas page)."""


class RenderError(IATError):
    """The renderer could not create a context or draw."""


class SolveError(IATError):
    """A solve broke a physical bound (its light grew past what the albedos allow) and stopped."""


class Cancelled(IATError):
    """A long operation was cancelled through its progress callback."""


class IATWarning(UserWarning):
    """Something IAT repaired on the way in (an albedo above 1 clamped, ...).

    Issued with :func:`warnings.warn`; the message names the file (when there is
    one) and what was changed, in one line. The CLI prints it as ``warning: ...``.
    """
