"""The viewer's re-bakes: one worker thread that bakes the newest requested policy.

:class:`BakeWorker` re-bakes the latest requested :class:`~iat.bake.policy.BakePolicy` on one
worker thread (pure numpy); the UI thread picks the result (a :class:`BakeResult`) up with
:meth:`BakeWorker.poll` and uploads it. Requests made while a bake runs are coalesced: only
the newest is baked next. A request may also bring a new source (:class:`BakeSource`: a
re-solved solution after a light moved, or a solution set for the day cycle). While no
request waits it pre-warms: it bakes the sliders' neighbours of the policy just baked
(:func:`neighbour_policies`), one per idle turn, so that the next step finds the Baker's
caches warm; a request made meanwhile is served first.

The Scale slider moves on the ladder ``2**(k/4)`` (:func:`snap_scale`), so every scale it can
reach is one the worker pre-warms (:func:`scale_neighbours`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.errors import Cancelled
from iat.worker import LatestWorker
from viewer.jobs import error_text

log = logging.getLogger(__name__)


@dataclass
class BakeResult:
    """What a bake request came to: ``baked`` (a Baked, or a BakedSet for a solution set) or
    ``error`` (one line), how long it took, and the source generation it baked."""

    policy: BakePolicy
    baked: Any = None
    error: str | None = None
    seconds: float = 0.0
    source: int = 0


@dataclass
class BakeSource:
    """What a :class:`BakeWorker` bakes from: one solution, or a solution set (``solutions``),
    with the scene (detail textures). The Baker is built on the worker thread."""

    solution: Any
    scene: Any = None
    solutions: Any = None  # a SolutionSet: bake_set instead of bake

    def baker(self) -> Baker:
        return Baker(self.solution, self.scene)


SCALE_MIN, SCALE_MAX = 0.125, 2.0  # the Scale slider's range (viewer/panels.py)
SCALE_STEPS_PER_OCTAVE = 4  # the pre-warmed scales: 2**(k/4), the budget's ladder (iat.bake)


def snap_scale(scale: float) -> float:
    """``scale`` rounded to the ladder ``2**(k/4)`` inside the slider's range: the Scale slider's
    values, so every value it can reach is one the bake worker pre-warms (and 1, 1/2, 1/4, 1/8 are
    on it: the scales at which harmonised seams are exactly 0)."""
    n = SCALE_STEPS_PER_OCTAVE
    v = float(2.0 ** (round(n * float(np.log2(float(scale)))) / n))
    return min(max(v, SCALE_MIN), SCALE_MAX)


def scale_neighbours(scale: float) -> list[float]:
    """The scales next to ``scale`` on the ladder ``2**(k/4)`` within the slider's range: the
    ladder values on either side (its neighbours when ``scale`` is on the ladder itself), smaller
    first. Values are ``2.0 ** (k / 4)`` exactly, as the benchmark's and the budget's ladder."""
    n = SCALE_STEPS_PER_OCTAVE
    x = n * float(np.log2(float(scale))) if scale > 0 else float("-inf")
    if not np.isfinite(x):
        return []
    k = round(x)
    if abs(x - k) < 1e-9:  # on the ladder
        ks = (k - 1, k + 1)
    else:
        ks = (int(np.floor(x)), int(np.ceil(x)))
    lo, hi = SCALE_MIN * (1 - 1e-9), SCALE_MAX * (1 + 1e-9)
    return [float(2.0 ** (j / n)) for j in ks if lo <= 2.0 ** (j / n) <= hi]


def neighbour_policies(policy: BakePolicy, deepest: int, previous: BakePolicy | None = None) -> list:
    """What a slider can reach from ``policy`` in one step: threshold +-1 (within 0 .. deepest + 1)
    and the neighbouring scales (:func:`scale_neighbours`), everything else unchanged; the slider
    that moved last from ``previous`` first, in the direction it moved. Empty for a budget
    policy (the baker chooses threshold and scale then)."""
    if policy.budget_mb is not None:
        return []
    t, sc = int(policy.threshold), float(policy.scale)
    ts = [u for u in (t + 1, t - 1) if 0 <= u <= deepest + 1]
    ss = scale_neighbours(sc)
    if previous is not None and previous.threshold > t:
        ts.reverse()  # moving down: the lower threshold first
    if previous is not None and previous.scale < sc:
        ss.reverse()  # moving up: the larger scale first
    first_scale = previous is not None and previous.scale != sc and previous.threshold == t
    tpols = [dataclasses.replace(policy, threshold=u) for u in ts]
    spols = [dataclasses.replace(policy, scale=v) for v in ss]
    return spols + tpols if first_scale else tpols + spols


class BakeWorker(LatestWorker):
    """Bakes on one worker thread; :meth:`submit` never blocks, :meth:`poll` returns the newest result.

    baker : the :class:`~iat.bake.baker.Baker` (used by this thread only: a Baker is not thread-safe)
    prewarm : while idle, bake the neighbours of the last policy baked (:func:`neighbour_policies`),
      one per idle turn, to warm the Baker's caches (their results are dropped, nothing is
      published or uploaded). A request made meanwhile is taken as soon as the neighbour's bake
      reaches its next stage (the bake is cancelled there; caches stay valid) and the remaining
      neighbours are dropped for the new policy's. Bounded: the immediate neighbours only, and
      none for a day-cycle set, a budget policy, a request that brought a new source (a re-solve
      after a light edit streams those; the next slider step pre-warms again) or a failed bake.
      Needs a real Baker (``baker.solution``); a stand-in without one is never pre-warmed.
    warm_from : the policy already baked (the viewer's first bake, made by :class:`OpenJob`): its
      neighbours are pre-warmed as soon as the thread starts, unless a request comes first.

    Counters: ``prewarmed`` (neighbour bakes finished), ``prewarm_cancelled`` (stopped for a
    request), ``prewarm_log`` (the last 256: ``(policy, seconds, finished)``).
    """

    def __init__(
        self,
        baker: Baker,
        name: str = "iat-bake",
        prewarm: bool = True,
        warm_from: BakePolicy | None = None,
    ):
        self.baker = baker
        self.solutions = None  # the set baked with bake_set, or None
        self.source = 0  # generation of the source baked from (0: the one given here)
        self._pending_source: tuple[int, BakeSource] | None = None
        self.prewarm = bool(prewarm)
        self.prewarmed = 0
        self.prewarm_cancelled = 0
        self.prewarm_log: list[tuple[BakePolicy, float, bool]] = []
        self._warm_queue: list[BakePolicy] = []  # neighbours still to bake (under the lock)
        self._seed = warm_from  # planned by the thread on its first idle turn
        self._warming = False  # a neighbour bake is running (read under the lock)
        self._last_policy: BakePolicy | None = None
        self._deepest: tuple[Any, int] | None = None
        super().__init__(name)

    @property
    def bakes(self) -> int:
        """Bakes finished so far (failed ones included)."""
        return self.published

    def submit(
        self, policy: BakePolicy, source: BakeSource | None = None, generation: int | None = None
    ) -> None:
        """Ask for a bake of ``policy``; replaces a request not started yet. ``source`` switches
        to another solution (or set) first; its ``generation`` comes back in the result."""
        with self._cv:
            if source is not None:
                gen = self.source + 1 if generation is None else int(generation)
                self._pending_source = (gen, source)
            self._request(policy)

    @property
    def warming(self) -> bool:
        """Pre-warming: a neighbour bake runs or more are queued (not counted as :attr:`busy`)."""
        with self._cv:
            return self._warming or (self.prewarm and (bool(self._warm_queue) or self._seed is not None))

    def wait_warm(self, timeout: float = 60.0) -> bool:
        """Block until idle and done pre-warming (tests and the benchmark); True when so."""
        end = time.monotonic() + timeout
        with self._cv:
            while (
                self._running
                or self._pending is not None
                or self._warming
                or (self.prewarm and (self._warm_queue or self._seed is not None))
            ):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(min(left, 0.05))
        return True

    def _take(self) -> tuple[BakePolicy, tuple[int, BakeSource] | None]:
        source, self._pending_source = self._pending_source, None
        self._warm_queue, self._seed = [], None  # the new policy gets its own neighbours
        return super()._take(), source

    def _deepest_tree(self) -> int | None:
        """Deepest patch tree of the baker's solution (cached per baker), None without one."""
        sol = getattr(self.baker, "solution", None)
        if sol is None or not hasattr(sol, "patch_depth"):
            return None
        if self._deepest is None or self._deepest[0] is not self.baker:
            depth = np.asarray(sol.patch_depth())
            self._deepest = (self.baker, int(depth.max()) if depth.size else 0)
        return self._deepest[1]

    def _plan_prewarm(self, policy: BakePolicy, previous: BakePolicy | None) -> None:
        deepest = self._deepest_tree() if self.prewarm and self.solutions is None else None
        queue = [] if deepest is None else neighbour_policies(policy, deepest, previous)
        with self._cv:
            if self._pending is None:  # a newer request replaces them anyway
                self._warm_queue = queue

    def _work(self, request) -> None:
        policy, source = request
        t0 = time.perf_counter()
        previous, self._last_policy = self._last_policy, None
        try:
            if source is not None:
                gen, src = source
                self.baker, self.solutions, self.source = src.baker(), src.solutions, gen
            if self.solutions is not None:
                r = BakeResult(policy, baked=self.baker.bake_set(self.solutions, policy))
            else:
                r = BakeResult(policy, baked=self.baker.bake(policy))
        except Exception as e:  # shown in the window; the viewer keeps the last good bake
            log.debug("bake failed", exc_info=True)
            r = BakeResult(policy, error=error_text(e))
        r.seconds = time.perf_counter() - t0
        r.source = self.source
        if r.error is None:
            self._last_policy = policy
            # a slider step; not a new source (a re-solve streams those: its neighbours would
            # compete with the re-solve for the CPU, and be stale at its next result)
            if source is None:
                self._plan_prewarm(policy, previous)
        self._publish(r)

    def _idle(self) -> bool:
        """Bake the next queued neighbour (its result only warms the Baker's caches)."""
        with self._cv:
            if not self.prewarm or self._pending is not None or self._stop:
                return False
            seed, self._seed = self._seed, None
            if seed is None and not self._warm_queue:
                return False
            self._warming = True
        policy, finished, t0 = None, False, time.perf_counter()
        try:
            if seed is not None:
                self._last_policy = seed
                self._plan_prewarm(seed, None)
            with self._cv:
                if not self._warm_queue or self._pending is not None or self._stop:
                    return True
                policy = self._warm_queue.pop(0)
            t0 = time.perf_counter()
            self.baker.bake(policy, progress=lambda _f, _m: not self._superseded())
            finished = True
        except Cancelled:
            pass
        except Exception:  # a neighbour that cannot be baked is no error: the slider may never go there
            log.debug("pre-warm bake of %s failed", policy, exc_info=True)
        finally:
            dt = time.perf_counter() - t0
            with self._cv:
                self._warming = False
                if policy is not None:
                    if finished:
                        self.prewarmed += 1
                    elif self._pending is not None:
                        self.prewarm_cancelled += 1
                    self.prewarm_log.append((policy, dt, finished))
                    del self.prewarm_log[:-256]
                self._cv.notify_all()
        return True
