"""The viewer's background re-solve after light edits: :class:`~iat.lighting.relight.Relighter` with
its progress kept for the Lighting panel (fraction, step, an ETA from the measured rate) and a
Cancel.

A re-solve after a light edit takes seconds to minutes (37-109 s on the house on 2 shared cores);
the panel shows a bar, the step under way (the Relighter solves coarse steps first, or by daylight
a preview on the mesh on screen) and the time left, estimated from the rate measured in this step
so far: ``elapsed * (1 - f) / f`` once a few percent are done (None before: no guess from
nothing). Cancel stops the step at its next progress report; the view keeps the lighting it shows
(the last step solved, or from before the edit), and says so.
"""

from __future__ import annotations

import threading
import time

from iat.lighting.relight import Relighter

#: progress below which no ETA is given (too little measured)
ETA_MIN_FRACTION = 0.03


def options_in_force(state):
    """The :class:`~iat.radiosity.SolveOptions` of the open model's solves: its re-solve's (the
    solution on screen may be a preview, solved at lighter ones), else its solution's, else the
    Model panel's."""
    from iat.radiosity import SolveOptions

    if state.lighting.relighter is not None:
        return state.lighting.relighter.options
    try:
        return SolveOptions.from_dict(state.model.solution.options)
    except Exception:
        return state.model.solve_options


def result_line(res) -> str:
    """The status line of a published :class:`~iat.lighting.relight.RelightResult`."""
    if res.mode == "preview" and not res.final:
        return f"preview of the new light in {res.total_seconds:.2f} s; solving in full"
    return f"lighting re-solved in {res.total_seconds:.2f} s ({res.mode}, {res.steps} steps)"


class ProgressRelighter(Relighter):
    """A :class:`Relighter` whose progress the UI reads: ``fraction`` (0..1 of the step under way),
    ``message``, ``step`` (1, 2, ... within an edit's plan), :attr:`eta` (seconds, or None), and
    :meth:`cancel` (the edit under way is dropped; ``cancelled`` stays True until the next
    :meth:`submit`)."""

    def __init__(self, solution, scene, **kw):
        self.fraction = 0.0
        self.message = ""
        self.step = 0
        self.step_started: float | None = None
        self.edit_started: float | None = None
        self.cancelled = False
        self._cancel_event = threading.Event()
        super().__init__(solution, scene, **kw)

    def submit(self, scene, version: int | None = None, remesh: bool = False) -> None:
        self._cancel_event.clear()
        self.cancelled = False
        self.fraction, self.message, self.step = 0.0, "starting", 0
        self.step_started, self.edit_started = None, time.perf_counter()
        super().submit(scene, version, remesh)

    def cancel(self) -> None:
        """Stop the re-solve under way at its next progress report."""
        self._cancel_event.set()
        self.cancelled = True

    @property
    def eta(self) -> float | None:
        """Seconds left in the step under way, from its measured rate (None until measurable)."""
        f, t0 = self.fraction, self.step_started
        if t0 is None or f < ETA_MIN_FRACTION:
            return None
        spent = time.perf_counter() - t0
        return spent * (1.0 - f) / f

    # -- worker side ---------------------------------------------------------------------------
    def report(self, fraction, message) -> bool:
        f = float(min(max(fraction, 0.0), 1.0))
        now = time.perf_counter()
        if self.step_started is None or f < self.fraction - 0.2:  # a new step starts from 0
            self.step += 1
            self.step_started = now
        self.fraction, self.message = f, str(message)
        return not self._cancel_event.is_set()
