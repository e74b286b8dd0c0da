"""Time left for a background job, from the rate its progress is measured to advance.

The Stats panel (opening a model: the load, then the solve) and the Lighting panel (solving the
day cycle's states) show a bar and the time left. :class:`RateEta` is fed the job's fraction each
time a panel is drawn and answers ``(1 - f) / rate``, the rate measured over the last
``window_s`` seconds of the stage under way (a solve's stages do not advance the fraction
evenly: the recent rate follows the stage that runs now, where the average since the start
would carry the earlier stages' pace). No answer before the stage has run ``min_s`` seconds and
advanced ``min_fraction`` (no guess from nothing); a fraction that falls starts a new stage (the
load done, the solve begins at 0), as :class:`viewer.relight.ProgressRelighter` starts a step.
"""

from __future__ import annotations

import time
from collections import deque


class RateEta:
    """Seconds left from measured progress: :meth:`update` ``(fraction)`` -> seconds or None."""

    def __init__(self, window_s: float = 15.0, min_s: float = 1.0, min_fraction: float = 0.02):
        self.window_s, self.min_s, self.min_fraction = float(window_s), float(min_s), float(min_fraction)
        self._samples: deque[tuple[float, float]] = deque()
        self._stage_start: tuple[float, float] | None = None

    def update(self, fraction: float, now: float | None = None) -> float | None:
        now = time.perf_counter() if now is None else float(now)
        f = float(min(max(fraction, 0.0), 1.0))
        s = self._samples
        if s and f < s[-1][1] - 1e-9:  # a new stage
            s.clear()
            self._stage_start = None
        if self._stage_start is None:
            self._stage_start = (now, f)
        s.append((now, f))
        while len(s) > 2 and now - s[1][0] >= self.window_s:  # keep one sample older than the window
            s.popleft()
        t0, f0 = self._stage_start
        if now - t0 < self.min_s or f - f0 < self.min_fraction or f >= 1.0:
            return None
        ta, fa = s[0]
        if now - ta < self.min_s or f <= fa:  # nothing advanced in the window: the stage's own rate
            ta, fa = t0, f0
        rate = (f - fa) / max(now - ta, 1e-9)
        return (1.0 - f) / rate if rate > 0 else None


class JobEta:
    """One :class:`RateEta` per job shown (a new job starts afresh)."""

    def __init__(self):
        self._job = None
        self._eta = RateEta()

    def update(self, job, fraction: float) -> float | None:
        if job is not self._job:
            self._job, self._eta = job, RateEta()
        return self._eta.update(fraction)
