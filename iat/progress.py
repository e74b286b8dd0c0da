"""Progress: the callback type every long stage takes, and its terminal bar.

A stage calls ``progress(fraction, message)`` with ``fraction`` in [0, 1]; a return of False
asks it to stop (it raises :class:`~iat.errors.Cancelled`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable

#: ``progress(fraction, message) -> bool | None``; False cancels.
Progress = Callable[[float, str], "bool | None"]


class ProgressBar:
    """A ``progress(fraction, message) -> bool`` callback drawn as a tqdm bar with ETA on stderr."""

    def __init__(self, desc: str, enabled: bool = True, close_when_done: bool = False):
        self.enabled = bool(enabled) and sys.stderr.isatty()
        self.desc = desc
        self.close_when_done = close_when_done  # a stage followed by another: clear the bar at 1.0
        self._bar = None

    def __call__(self, fraction: float, message: str = "") -> bool:
        if not self.enabled:
            return True
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(total=1000, desc=self.desc, unit="‰", leave=False, file=sys.stderr)
        self._bar.n = int(1000 * min(max(fraction, 0.0), 1.0))
        self._bar.set_postfix_str(message[:40], refresh=False)
        self._bar.refresh()
        if self.close_when_done and fraction >= 1.0:
            self.close()
        return True

    def close(self):
        if self._bar is not None:
            self._bar.close()
            self._bar = None
