"""Re-solving a light change (:func:`resolve`): only the difference of the sources is shot, on the
mesh of the previous solution (radiosity is linear in the sources)."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from iat.color import LUMINANCE_WEIGHTS
from iat.errors import OptionError
from iat.progress import Progress
from iat.radiosity.checks import check_mesh, check_scene, validated_options
from iat.radiosity.direct import light_power
from iat.radiosity.options import RESOLVE_MAX_CHANGE, SolveOptions
from iat.radiosity.patches import emitter_shares, solver_albedo
from iat.radiosity.progress import SolveCancelled
from iat.radiosity.run import SolveRun
from iat.radiosity.solution import Solution
from iat.radiosity.solver import solve
from iat.radiosity.sources import daylit, light_from_record, light_record, light_signature
from iat.radiosity.state import Shoot
from iat.radiosity.visibility import Visibility


def resolve(
    previous: Solution, scene, options: SolveOptions | None = None, progress: Progress | None = None
) -> Solution:
    """Continue from ``previous`` after the lights or the emission of ``scene`` changed.

    The geometry and the albedos must be those ``previous`` was solved with (else
    :class:`iat.errors.OptionError`); the lights (point / spot) and the emission may differ.
    Radiosity is linear in the sources, so only the difference is solved, on the leaves and
    vertices of ``previous`` (the same ``vert_key``): the direct light of the sources that
    changed -- new minus old, at every vertex, exactly as a fresh solve computes it (lights
    present in both cancel and are not traced again) -- is added to the previous reflected
    radiance, and that difference field, which may be negative, is shot progressively (by
    the magnitude of its power) until its unshot power is below ``convergence`` times the
    smaller of the changed sources' power and the new emitted power: the difference is
    converged as a scene of its own, since its light sits where the sources changed and
    the uniform ambient term would spread it badly. The result matches
    ``solve(scene, mesh=previous)`` within the solver's noise and convergence, in a fraction
    of its time when a part of the light changed (``stats['mode'] == 'resolve'``).

    When the changed power exceeds the new emitted power (most of the light went away), the
    previous solution's noise would dominate the result: the scene is then solved afresh on
    the mesh (``stats['mode'] == 'mesh'``), as it is for a solution that lacks the record of
    its sources (``stats['sources']``), and for a scene lit, now or before, by the sun or a sky.

    options : None takes ``previous``'s options (``max_depth`` always comes from it).
    """
    check_scene(scene)
    check_mesh(previous, scene, "resolve")
    opts = SolveOptions.from_dict(previous.options) if options is None else options
    opts = replace(validated_options(opts), max_depth=int(previous.max_depth)).validate()
    if not np.allclose(previous.patch_albedo, solver_albedo(scene), rtol=1e-6, atol=1e-9):
        raise OptionError("resolve: the albedos changed since the previous solution; solve again")
    src = previous.stats.get("sources") if isinstance(previous.stats, dict) else None
    if not src or daylit(scene) or src.get("daylight"):  # (the sun and the sky: solved afresh on the mesh)
        return solve(scene, opts, progress, mesh=previous)
    change = SourceChange.between(src, scene)
    if change.power > RESOLVE_MAX_CHANGE * change.new_power:
        return solve(scene, opts, progress, mesh=previous)
    t_start = time.perf_counter()
    with Visibility.of_scene(scene) as vis:
        run = SolveRun(scene, opts, progress, vis, t_start)
        run.take_mesh(previous)
        geo = run.mesh.geo
        old_reflected = np.asarray(previous.vert_radiance, dtype=np.float64) - change.old_emission[geo.patch]
        t0 = time.perf_counter()
        try:
            run.progress.report(0.0, f"resolving: direct light of {change.count} changed sources")
            delta = change.reflected_direct(run.ctx, geo, run.check)
        except SolveCancelled:
            delta = np.zeros((len(run.keys), 3))
        offset = run.light_correction(lights=change.lights, signs=change.signs)
        run.set_direct(old_reflected + delta, offset, delta + offset, time.perf_counter() - t0)
        if not run.progress.cancelled:
            run.run_plan([Shoot(opts.convergence * min(run.power0, change.power), (0.2, 1.0))])
        return run.finish(
            mode="resolve",
            fallback_reflectance=previous.stats.get("reflectance"),
            extra={
                "changed_sources": change.count,
                "changed_power_fraction": float(change.power / change.new_power)
                if change.new_power > 0
                else 0.0,
            },
        )


@dataclass
class SourceChange:
    """What changed between the sources a solution recorded and a scene's: per patch the emission
    ``diff`` (P, 3) = new - ``old_emission`` on the ``changed`` patches, point / spot lights
    ``added`` and ``removed`` (equal ones cancel; a light whose intensity changed is added as the
    difference), the luminance ``power`` of the change (by magnitude) and the scene's
    ``new_power``, both in W."""

    emission: np.ndarray
    old_emission: np.ndarray
    diff: np.ndarray
    changed: np.ndarray
    added: list
    removed: list
    power: float
    new_power: float

    @classmethod
    def between(cls, src: dict, scene) -> SourceChange:
        emission, area = scene.patch_emission, scene.patch_area
        old_emission = np.zeros_like(emission)
        for row in src.get("emitters", []):
            old_emission[int(row[0])] = row[1:4]
        diff = emission - old_emission
        new_lights = [lt for lt in scene.lights if lt.kind in ("point", "spot")]
        added, removed = _light_difference(new_lights, [light_from_record(d) for d in src.get("lights", [])])
        power = float(np.pi * (np.abs(diff @ LUMINANCE_WEIGHTS) * area).sum())
        power += sum(light_power(lt) for lt in added + removed)
        new_power = float(np.pi * (emission @ LUMINANCE_WEIGHTS * area).sum())
        new_power += sum(light_power(lt) for lt in new_lights)
        changed = np.flatnonzero((diff != 0).any(axis=1))
        return cls(emission, old_emission, diff, changed, added, removed, power, float(new_power))

    @property
    def count(self) -> int:
        return int(len(self.changed) + len(self.added) + len(self.removed))

    @property
    def lights(self) -> list:
        return self.added + self.removed

    @property
    def signs(self) -> list[float]:
        return [1.0] * len(self.added) + [-1.0] * len(self.removed)

    def reflected_direct(self, ctx, geo, check) -> np.ndarray:
        """(n, 3) the reflected direct light of the change at ``geo``'s vertices: the old light
        of each changed source off and the new on, each sampled as a fresh solve samples it."""
        incoming = np.zeros((len(geo.key), 3))
        old_share = emitter_shares(self.old_emission, ctx.patches.area)
        for e in self.changed:
            was = ctx.light.emitter_side(old_share[e])
            now = ctx.light.emitter_side(ctx.patches.emitter_share[e])
            if was == now:
                incoming += ctx.light.emitter_gather(int(e), geo, now)[:, None] * self.diff[e]
            else:
                for side, e_rad in ((now, self.emission[e]), (was, -self.old_emission[e])):
                    if e_rad.any():
                        incoming += ctx.light.emitter_gather(int(e), geo, side)[:, None] * e_rad
            check()
        for lt, sign in zip(self.lights, self.signs, strict=True):
            incoming += sign * ctx.light.light_irradiance(lt, geo) / np.pi
            check()
        return ctx.patches.albedo[geo.patch] * incoming


def _light_difference(new_lights: list, removed: list) -> tuple[list, list]:
    """``(added, removed)``: the lights of ``new_lights`` not among the old ``removed`` (which loses
    the ones matched); a light equal but for its intensity is added as the difference."""
    added = []
    for lt in new_lights:
        sig = light_signature(lt)
        sigs = [light_signature(o) for o in removed]  # (lights hold arrays: match by index)
        i = next((k for k, o in enumerate(sigs) if o == sig), None)
        if i is None:
            i = next((k for k, o in enumerate(sigs) if o[:-1] == sig[:-1]), None)
            if i is None:
                added.append(lt)
                continue
            d = light_from_record(light_record(lt))
            d.radiant_intensity = d.radiant_intensity - removed[i].radiant_intensity
            added.append(d)
        del removed[i]
    return added, removed
