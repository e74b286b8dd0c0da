"""The background re-solve after light edits (:class:`Relighter`).

After an edit that changed only lights or emission, :func:`iat.radiosity.resolve`
continues from the last converged solution (shooting only the difference) on the same
mesh; the work is re-run with increasing effort (a coarse convergence first, then the
final one), each result published as it arrives so the view improves step by step. A
newer edit cancels the work in progress.

By daylight (a sun or a sky, before or after the edit) the coarse steps would cost nearly what the
final one does (each gathers the sky anew), so the first step is a *preview* instead: the new light
on the mesh on screen with :meth:`~iat.radiosity.SolveOptions.preview`'s options (the direct sun
and sky with fewer rays, the strongest patches shot, the other bounces from the ambient term), then
the final step (afresh when the sun moved, else on the mesh). The open house by a new sun: the
preview in 2.3 s, the new solve in 26 s (docs/benchmarks.md, "A first sunlit image").
"""

from __future__ import annotations

import dataclasses
import logging
import time
import traceback
from dataclasses import dataclass
from typing import Any

from iat.errors import IATError
from iat.lighting.edits import lights_only_changed
from iat.worker import LatestWorker

log = logging.getLogger(__name__)


@dataclass
class RelightResult:
    """One published step of a :class:`Relighter`.

    solution, scene : the solution and the scene it lights (None and "error" on failure)
    step, steps : this step (1-based) of the effort schedule; ``final`` when step == steps
    version : the edit it answers (``submit``'s version)
    seconds : time of this step; total_seconds : since the edit was taken up
    mode : "resolve" (continued from the previous solution), "mesh", "solve" or "preview" (a
      daylight edit's first look on the mesh on screen)
    """

    solution: Any
    scene: Any
    step: int
    steps: int
    version: int
    seconds: float = 0.0
    total_seconds: float = 0.0
    mode: str = "resolve"
    error: str | None = None

    @property
    def final(self) -> bool:
        return self.step == self.steps and self.error is None


class Relighter(LatestWorker):
    """Re-solves on a worker thread as lights change; the UI polls the newest improvement.

    solution, scene : the converged solution on screen and the scene it was solved for
    options : the solve options (default: the solution's own)
    schedule : coarser steps solved before the final one, as multiples of the final
      convergence (capped at 0.5); each step starts again from the last converged solution
      with more effort and is published as it arrives (the first after a fraction of the
      final time). The default (8, 2.5) with convergence 0.05 runs 0.4, 0.125, then 0.05. By
      daylight a preview replaces them (see the module's docstring).

    ``submit(scene)`` asks for the lights of ``scene`` (cancels the step in progress, except a
    first, coarse step, which finishes so that a continuous drag still shows progress);
    ``submit(scene, remesh=True)`` solves afresh (new adaptive mesh) instead. ``poll()``
    returns the newest result not yet returned.
    """

    def __init__(self, solution, scene, options=None, schedule=(8.0, 2.5), name: str = "iat-relight"):
        from iat.radiosity import SolveOptions

        self.base = solution
        self.base_scene = scene
        if options is None:
            try:
                options = SolveOptions.from_dict(solution.options)
            except Exception:  # an old or hand-made solution
                options = SolveOptions(max_depth=int(solution.max_depth))
        self.options = options
        self.schedule = tuple(float(c) for c in schedule)
        self._version = 0
        self._hold = False  # the step under way finishes even when a newer edit arrives
        super().__init__(name)

    @property
    def steps_done(self) -> int:
        """Steps published so far."""
        return self.published

    # -- UI side ---------------------------------------------------------------------------------
    def submit(self, scene, version: int | None = None, remesh: bool = False) -> None:
        with self._cv:
            self._version = self._version + 1 if version is None else int(version)
            self._request((scene, self._version, bool(remesh)))

    # -- worker ----------------------------------------------------------------------------------
    def report(self, fraction: float, message: str) -> bool:
        """Each progress report of the step under way (fraction 0..1 of the step, on the worker
        thread); False stops the step. Override it to watch or cancel (the viewer's
        ``ProgressRelighter``); this one lets every step go on."""
        return True

    def _progress(self, fraction, message) -> bool:
        if not self.report(fraction, message):
            return False
        # the first (coarse) step always finishes, so a light dragged without pause still
        # shows a new solution every step's time; later steps give way to a newer edit
        if self._hold:
            with self._cv:
                return not self._stop
        return not self._superseded()

    def _work(self, request) -> None:
        from iat.radiosity import resolve, solve
        from iat.radiosity.sources import daylit

        scene, version, remesh = request
        t_job = time.perf_counter()
        self._hold = False
        progress = self._progress
        try:
            final_conv = float(self.options.convergence)
            fresh = remesh or not lights_only_changed(self.base_scene, scene)
            if daylit(scene) or daylit(self.base_scene):
                plan = [("preview", final_conv), ("solve" if fresh else "resolve", final_conv)]
            elif fresh:
                plan = [("solve", final_conv)]
            else:
                coarse = sorted({min(0.5, final_conv * m) for m in self.schedule}, reverse=True)
                plan = [("resolve", c) for c in coarse if c > final_conv] + [("resolve", final_conv)]
            for k, (how, conv) in enumerate(plan, 1):
                self._hold = k == 1 and len(plan) > 1
                if k > 1 and self._superseded():
                    break
                opts = dataclasses.replace(self.options, convergence=conv)
                t0 = time.perf_counter()
                if how == "preview":
                    sol = preview(scene, self.base, self.options, progress)
                    if sol is None:  # other patches: no preview
                        continue
                elif how == "solve":
                    sol = solve(scene, opts, progress)
                else:
                    try:
                        sol = resolve(self.base, scene, opts, progress)
                    except IATError:
                        raise
                    except Exception:  # a solver bug: solve afresh on the mesh, slower but right
                        log.warning("resolve failed, solving on the mesh instead", exc_info=True)
                        sol = solve(scene, opts, progress, mesh=self.base)
                if sol.stats.get("cancelled"):
                    break
                now = time.perf_counter()
                r = RelightResult(
                    sol,
                    scene,
                    k,
                    len(plan),
                    version,
                    now - t0,
                    now - t_job,
                    str(sol.stats.get("mode", how)),
                )
                if k == len(plan):
                    self.base, self.base_scene = sol, scene
                self._publish(r)
        except Exception as e:  # reported to the UI; the last good solution stays
            log.debug("relight failed:\n%s", traceback.format_exc())
            msg = str(e) if isinstance(e, IATError) else f"{type(e).__name__}: {e}"
            self._publish(RelightResult(None, scene, 0, 0, version, error=msg))


def preview(scene, previous, options, progress=None):
    """The light of ``scene`` on ``previous``'s mesh at ``options.preview()`` (a first look), or None
    when ``previous`` was solved on other patches than ``scene``'s."""
    from iat.radiosity import solve
    from iat.radiosity.checks import check_mesh

    try:
        check_mesh(previous, scene, "preview")
    except IATError:
        return None
    sol = solve(scene, options.preview(), progress, mesh=previous)
    sol.stats["mode"] = "preview"
    return sol
