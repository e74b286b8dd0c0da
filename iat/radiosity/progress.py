"""A solve's progress and cancel (:class:`SolveProgress`): one object that every stage reports to
and polls, and that says whether the user cancelled."""

from __future__ import annotations

import time


class SolveCancelled(Exception):
    """Internal: the progress callback asked to stop."""


class SolveProgress:
    """Reports ``(fraction, message)`` to the user's ``progress(fraction, message) -> bool``
    callback (None: silent); a False return cancels: :meth:`report` raises
    :class:`SolveCancelled` and :attr:`cancelled` stays True, so the stages after it finish with
    what was evaluated."""

    def __init__(self, callback=None):
        self.callback = callback
        self.cancelled = False
        self.fraction = 0.0
        self.message = ""
        self._last = 0.0  # perf_counter of the last poll that reached the callback

    def report(self, fraction: float, message: str) -> None:
        self.fraction, self.message = fraction, message
        if self.callback is not None and self.callback(float(min(max(fraction, 0.0), 1.0)), message) is False:
            self.cancelled = True
            raise SolveCancelled

    def step(self, message: str) -> None:
        """Report a new stage at the current fraction (so a big model is never silent for long);
        nothing once cancelled (the solve is finishing with what it has)."""
        if not self.cancelled:
            try:
                self.report(self.fraction, message)
            except SolveCancelled:
                pass  # the stages below see ``cancelled`` and keep what was evaluated

    def check(self) -> None:
        """Cheap poll inside long loops: reaches the callback at most 20 times a second."""
        now = time.perf_counter()
        if self.callback is not None and now - self._last > 0.05:
            self._last = now
            self.report(self.fraction, self.message)

    def set(self, fraction: float, message: str) -> None:
        """Where the solve is, for the next :meth:`check` (reports nothing now)."""
        self.fraction, self.message = fraction, message

    def finish(self, message: str) -> None:
        """The last report (fraction 1), unless cancelled; a cancel now changes nothing."""
        if not self.cancelled:
            try:
                self.report(1.0, message)
            except SolveCancelled:
                pass
