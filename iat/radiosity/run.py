"""One solve's state and stages (:class:`SolveRun`): meshing by direct light (A), progressive
shooting (B), refinement on the total radiance (C) and the ambient term (D), as
:mod:`iat.radiosity.solver` describes them; :func:`iat.radiosity.solver.solve` and
:func:`iat.radiosity.resolving.resolve` drive it."""

from __future__ import annotations

import math
import time

import numpy as np

from iat.errors import SolveError
from iat.geometry import quadtree as qt
from iat.radiosity.context import Context
from iat.radiosity.kernels import add_at_rows, rows_product, shot_power
from iat.radiosity.meshing import (
    VertexCache,
    coarse_weights,
    measure_interpolation_bias,
    probe_shot_gain,
    split_test,
)
from iat.radiosity.openness import kept_fraction
from iat.radiosity.options import (
    ABS_FLOOR,
    COARSE_EPS,
    COARSE_SIZE,
    ENERGY_SLACK,
    FF_SUM_LIMIT,
    IMPORTANCE_MIX,
    IMPORTANCE_PEAK_LIMIT,
    IMPORTANCE_SIDE,
    MAX_REFLECTANCE,
    PEAK_RATIO,
    REFINE_SAMPLE_FACTOR,
    SHOT_FULL_SHARE,
    SHOT_GROUP,
    SHOT_GROUP_RATIO,
    SHOT_SAMPLE_FACTOR,
    SolveOptions,
)
from iat.radiosity.patches import ranges_of
from iat.radiosity.progress import SolveCancelled, SolveProgress
from iat.radiosity.remainder import ambient_term
from iat.radiosity.sampling import field_importance, luminance_of, pattern_side, peak_factor
from iat.radiosity.solution import Solution
from iat.radiosity.sources import sources_record
from iat.radiosity.state import CoarseGrid, Mesh, Radiance, Refine, Shoot
from iat.radiosity.visibility import Visibility


class SolveRun:
    """The state of one solve, one owner for each piece: ``ctx`` (:class:`Context`, what does
    not change), ``progress`` (:class:`SolveProgress`), ``mesh`` (:class:`Mesh`, replaced when
    stage C refines), ``coarse`` (the :class:`CoarseGrid` receivers and what they received),
    ``rad`` (:class:`Radiance` at the mesh's vertices), the shot counters and the stats."""

    def __init__(self, scene, opts: SolveOptions, progress, vis: Visibility, t_start: float):
        self.scene, self.opts, self.vis, self.t_start = scene, opts, vis, t_start
        self.progress = SolveProgress(progress)
        self.ctx = ctx = Context(scene, opts, vis)
        self.P = ctx.patches.n_patches
        self.m_side = pattern_side(opts.samples)
        self.stats: dict = {
            "interpolation_bias": 0.0,
            "interpolation_bias_vertices": 0,
            "interpolation_bias_total": 0.0,
            "interpolation_bias_total_vertices": 0,
            "mesh_passes": 0,
            "refine_passes": 0,
        }
        self.timings = {"meshing_s": 0.0, "shooting_s": 0.0, "refining_s": 0.0}
        self.shots = 0
        self.shot_index = np.ones(self.P, dtype=np.int64)  # jitter index per patch; 0 was the direct pass
        self.shot_power = np.zeros(self.P)  # luminance power each patch has shot so far
        self.shot_log: list[tuple[np.ndarray, np.ndarray]] = []  # (shot, received-and-reflected) power
        self.power0 = ctx.light.emitted_power()
        # what convergence and sample shares are measured against: the power the scene received
        # from its sources in the direct pass (the emitted power until then; in an open scene
        # most of that escapes, and the rest would look converged before any bounce)
        self.power_ref = self.power0
        # (P,) the share of each patch's light that stays in the scene (iat.radiosity.openness), and
        # the received power so weighted: what a shot's share of the light is measured against
        self.kept = kept_fraction(ctx.patches, vis, opts.seed)
        self.power_kept = self.power0
        self.u_start = 1e-300  # the unshot power when the plan began (progress is on a log scale)
        self.mesh: Mesh | None = None
        self.coarse: list[CoarseGrid] | None = None  # made at the first mesh (they depend on none)
        self.levels: dict[int, np.ndarray] = {}  # per shooter: receiver level of each patch (-1: vertices)
        self.direct_cache = VertexCache()  # reflected direct radiance at every point evaluated
        self.rad = Radiance.zeros(0, self.P)

    def check(self) -> None:
        """The progress poll the stages call inside long loops."""
        self.progress.check()

    # -- the mesh -----------------------------------------------------------------
    def set_mesh(self, forest: qt.Forest, keys: np.ndarray) -> None:
        if self.coarse is None:
            self.coarse = CoarseGrid.levels(self.ctx.patches, self.opts.max_depth)
        self.mesh = Mesh.build(self.ctx.patches, forest, keys, self.coarse)

    @property
    def forest(self) -> qt.Forest:
        return self.mesh.forest

    @property
    def keys(self) -> np.ndarray:
        return self.mesh.keys

    def set_direct(
        self, reflected: np.ndarray, offset: np.ndarray, unshot: np.ndarray, seconds: float
    ) -> None:
        """Start shooting from this direct light (V, 3) each, found in ``seconds`` (a re-solve's
        difference of the sources: :func:`iat.radiosity.resolving.resolve`)."""
        self.rad = Radiance(reflected, unshot, offset, self.rad.gain)
        self.timings["meshing_s"] = seconds

    def direct_with_noise(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) the reflected direct radiance at vertex keys (n,), and (n,) its standard error
        (:meth:`.direct.DirectLight.direct`)."""
        noise = np.zeros(len(keys))
        return self.ctx.light.direct(keys, self.check, noise=noise), noise

    def mesh_by_direct_light(self) -> None:
        """Stage A."""
        ctx, pg = self.ctx, self.progress
        t0 = time.perf_counter()
        roots = qt.roots(ctx.patches.is_quad, self.opts.max_depth)
        forest, passes, _ = split_test(
            ctx,
            roots,
            self.direct_cache,
            self.direct_with_noise,
            pg.report,
            "meshing",
            (0.0, 0.2),
        )
        keys = qt.vertex_keys(forest)
        bias, bias_n = measure_interpolation_bias(keys, qt.vertex_keys(roots), self.direct_cache, ctx.patches)
        self.stats.update(
            mesh_passes=int(passes), interpolation_bias=bias, interpolation_bias_vertices=bias_n
        )
        pg.step(f"meshing: {forest.n_leaves} elements, vertex table")
        self.set_mesh(forest, keys)
        reflected = self.direct_cache.get(keys)  # 0 where a cancel left a vertex unevaluated
        pg.step("meshing: light the elements receive")
        offset = self.light_correction()
        pg.step("meshing: power each patch shoots")
        self.rad = Radiance(reflected, reflected + offset, offset, self.shot_gain(self.direct_cache, offset))
        self.power_ref, self.power_kept = self.received_power(), self.received_power(self.kept)
        self.timings["meshing_s"] = time.perf_counter() - t0

    def take_mesh(self, sol: Solution) -> None:
        """The leaves and vertices of ``sol``, unchanged."""
        forest = qt.Forest(
            sol.max_depth,
            np.asarray(sol.patch_is_quad, dtype=bool),
            np.asarray(sol.leaf_patch, dtype=np.int32),
            np.asarray(sol.leaf_level, dtype=np.int8),
            np.asarray(sol.leaf_i, dtype=np.int32),
            np.asarray(sol.leaf_j, dtype=np.int32),
            np.asarray(sol.leaf_flip, dtype=bool),
        )
        self.set_mesh(forest, np.asarray(sol.vert_key, dtype=np.int64))
        self.rad = Radiance.zeros(len(self.keys), self.P)

    def direct_on_mesh(self) -> None:
        """Direct light at every vertex of the given mesh (no subdivision)."""
        t0 = time.perf_counter()
        self.progress.report(0.0, f"direct light on the given mesh: {len(self.keys)} vertices")
        try:
            reflected = self.ctx.light.direct(self.keys, self.check, self.mesh.geo)
        except SolveCancelled:
            reflected = np.zeros((len(self.keys), 3))
        offset = self.light_correction()
        self.rad = Radiance(reflected, reflected + offset, offset, self.rad.gain)
        self.power_ref, self.power_kept = self.received_power(), self.received_power(self.kept)
        self.timings["meshing_s"] = time.perf_counter() - t0

    def received_power(self, weight: np.ndarray | None = None) -> float:
        """Luminance power the surfaces received in the direct pass: their reflected direct light
        (with the point lights' element correction) over their albedo; surfaces of albedo 0 reflect
        nothing and do not count. In a closed scene this is the emitted power. ``weight`` (P,): each
        patch's share counted (``kept``: what stays in the scene)."""
        if not len(self.keys):
            return 0.0
        rho = self.ctx.patches.albedo
        mean = self.mesh.M @ np.abs(self.rad.reflected + self.rad.offset)
        incident = np.where(rho > 1e-6, mean / np.maximum(rho, 1e-6), 0.0)
        area = self.ctx.patches.area if weight is None else self.ctx.patches.area * weight
        return float(np.pi * (luminance_of(incident) * area).sum())

    def light_correction(self, forest=None, keys=None, geo=None, lights=None, signs=None) -> np.ndarray:
        """(V, 3) :meth:`DirectLight.light_correction` on the current mesh (or the given one): added
        to the exact reflected direct radiance, it gives the unshot radiance whose power is what the
        elements received from the point / spot lights. Zero when cancelled."""
        forest = self.forest if forest is None else forest
        keys = self.keys if keys is None else keys
        geo = self.mesh.geo if geo is None else geo
        if self.progress.cancelled:
            return np.zeros((len(keys), 3))
        try:
            return self.ctx.light.light_correction(forest, keys, geo, lights, signs)
        except SolveCancelled:
            return np.zeros((len(keys), 3))

    def shot_gain(self, cache: VertexCache, offset: np.ndarray) -> np.ndarray:
        """(P,) :func:`probe_shot_gain` of the current mesh from the values in ``cache``: the power of each
        patch's light integrated with its probes over that of its linear interpolant, which its
        shots multiply (an element that stays coarse under concave light interpolates below it).
        1 on patches lit by point or spot lights (whose ``offset`` (V, 3) already shoots the light
        the elements hold) and when the solve was cancelled; at most 1 / the patch's largest albedo."""
        if self.progress.cancelled:
            return np.ones(self.P)
        gain = probe_shot_gain(self.forest, cache, self.ctx.patches)
        # what a patch shoots never exceeds what it received: rho x gain <= 1 (near-white patches
        # facing each other would otherwise grow their light at every bounce)
        gain = np.minimum(gain, 1.0 / np.maximum(self.ctx.patches.albedo.max(axis=1), 1e-300))
        if len(offset) and np.any(offset):
            lit = np.zeros(self.P, dtype=bool)
            lit[qt.decode_key(self.keys, self.ctx.patches.n)[0][np.any(offset != 0, axis=1)]] = True
            gain[lit] = 1.0
        return gain

    # -- shooting -----------------------------------------------------------------
    def patch_power(self, unshot: np.ndarray, m_abs: np.ndarray | None = None) -> np.ndarray:
        """(P,) luminance power of each patch's unshot field (by magnitude: it may be signed);
        ``m_abs`` (P, 3): ``M @ |unshot|`` when the caller keeps it (then ``unshot`` is not read)."""
        if m_abs is None:
            m_abs = self.mesh.M @ np.abs(unshot)
        return np.pi * luminance_of(m_abs) * self.ctx.patches.area

    def shoot(self, step: Shoot) -> None:
        """Shoot until the unshot power is below ``step.target`` or max_shots, a :meth:`shot_group`
        at a time."""
        ctx, mesh, opts, rad = self.ctx, self.mesh, self.opts, self.rad
        if self.power_ref <= 0 or len(self.keys) == 0:
            return
        t0 = time.perf_counter()
        span, target, u_start = step.span, step.target, self.u_start
        span_log = math.log(u_start / target) if u_start > target > 0 else 1.0  # progress on a log scale
        # M @ |unshot| (P, 3) (what :meth:`patch_power` weighs), kept up to date by the shots' rows
        m_abs = mesh.M @ np.abs(rad.unshot)
        # (V,) what a unit of reflected radiance at a vertex is in power: pi M^T area
        vertex_power = np.pi * (mesh.M.T @ ctx.patches.area)
        try:
            while self.shots < opts.max_shots:
                power = self.patch_power(rad.unshot, m_abs)
                total = float(power.sum())
                if total <= target:
                    break
                self.check_energy(total, "unshot")
                done = min(1.0, max(0.0, math.log(u_start / max(total, 1e-300)) / span_log))
                self.progress.set(
                    span[0] + (span[1] - span[0]) * done,
                    f"shooting: {self.shots} shots, unshot {total / self.power_ref:.3g} of received",
                )
                self.check()
                group = self.shot_group(power, opts.max_shots - self.shots)
                jobs = [(s, float(power[s])) for s in group]  # each shot's field is taken in its task
                shots = list(ctx.pool.traced_map(lambda job: self.shot_gather(*job), jobs, self.check))
                for s in group:  # (the light one shooter of the group sends another stays unshot there)
                    rad.unshot[mesh.start[s] : mesh.start[s + 1]] = 0.0
                for s, shot in zip(group, shots, strict=True):
                    self.apply_shot(s, float(power[s]), shot, m_abs, vertex_power)
        finally:
            self.timings["shooting_s"] += time.perf_counter() - t0

    def apply_shot(
        self, s: int, power: float, shot: tuple, m_abs: np.ndarray, vertex_power: np.ndarray
    ) -> None:
        """Add what one :meth:`shot_gather` from s (of luminance ``power``) returned: to the coarse
        grids, the vertices' reflected and unshot radiance, and the rows of ``m_abs`` ((P, 3),
        ``M @ |unshot|``) that changed; log what it shot and what the vertices it reached
        reflect (``vertex_power`` (V,): the power of a unit of reflected radiance at each)."""
        mesh, rad, P = self.mesh, self.rad, self.ctx.patches
        rows, dv, acc, field_mean = shot
        got, reflected = shot_power(rows, dv, mesh.rho, vertex_power)
        scale = self.shot_scale(s, got, field_mean)
        if scale is not None:
            dv, reflected = dv * scale, reflected * scale
        for k, ci, got_k in acc:
            add_at_rows(self.coarse[k].acc, ci, got_k)
        self.shot_index[s] += 1
        self.shot_power[s] += power
        self.shots += 1
        add_at_rows(rad.reflected, rows, dv)
        add_at_rows(rad.unshot, rows, dv)
        # the rows of M @ |unshot| that changed: the patches it reached, and s
        reached = np.zeros(self.P, dtype=bool)
        reached[mesh.geo.patch[rows]] = True
        reached[s] = True
        touched = np.flatnonzero(reached)
        m_abs[touched] = rows_product(mesh.M.indptr, mesh.M.indices, mesh.M.data, rad.unshot, touched, True)
        self.shot_log.append((np.pi * P.area[s] * field_mean, reflected))

    def shot_scale(self, s: int, got: np.ndarray, field_mean: np.ndarray) -> np.ndarray | None:
        """(3,) the factor, per channel, that scales a shot from s back to the power it sent when
        its receivers would get more than ``FF_SUM_LIMIT`` times that (its sampled form factors sum
        above 1: a blow-up, not quadrature noise); None when none would. ``got`` (3,): the power
        they received (:func:`~iat.radiosity.kernels.shot_power`); ``field_mean`` (3,): the mean
        radiance s shot."""
        sent = np.pi * self.ctx.patches.area[s] * np.abs(field_mean)
        over = got > FF_SUM_LIMIT * sent
        if not over.any():
            return None
        self.stats["renormalised_shots"] = self.stats.get("renormalised_shots", 0) + 1
        return np.where(over, sent / np.where(over, got, 1.0), 1.0)

    def reflected_bound(self) -> float:
        """Luminance power (W) the surfaces can reflect over all bounces at most: ``rho / (1 -
        rho)`` of the power they received from the sources, rho the largest albedo (any channel);
        inf when rho >= 1 (an albedo-1 room never converges: ``max_shots`` stops it)."""
        rho = float(self.ctx.patches.albedo.max()) if self.P else 0.0
        return math.inf if rho >= 1.0 else max(self.power_ref, self.power0) * rho / (1.0 - rho)

    def check_energy(self, power: float, what: str) -> None:
        """Raise :class:`SolveError` when ``power`` (luminance W, the ``what`` light) is not finite
        or exceeds ``ENERGY_SLACK`` times :meth:`reflected_bound`: a solve that blew up stops with
        one line instead of writing a wrong solution."""
        bound = ENERGY_SLACK * self.reflected_bound()
        if not math.isfinite(power) or power > bound:
            raise SolveError(
                f"the solve diverged after {self.shots} shots: {what} power {power:.3g} W exceeds the "
                f"{bound:.3g} W the albedos allow (coincident faces or a near-white material?); "
                "see docs/stability.md"
            )

    def samples_by_power(
        self, m_hi: int, power: float, field: np.ndarray, s: int
    ) -> tuple[int, np.ndarray | None]:
        """How a gather samples the ``field`` ((N+1, N+1, 3) lattice radiance) of shooter s, of
        luminance ``power``: ``(m, importance)``, its samples per side and the tables its area
        samples are drawn by (None: uniformly). m is ``m_hi`` x sqrt(power / (``SHOT_FULL_SHARE`` x
        the received power that stays in the scene, ``power_kept``)), 1 to ``m_hi`` (a faint shot's
        noise matters less). One pattern serves all of a shot's receivers, so a shot from one point
        throws its light from there to the whole scene: measured against all the received power,
        which an open scene's sunlit outside dominates, a room's own shots were faint, made from one
        point, and their errors added up with more shots instead of averaging (the window-lit room
        at convergence 0.0005: 12-15 % error, bias +9 / -4 / +9 % by seed). A concentrated field (a
        sunlit patch on a floor: :func:`peak_factor` above 1) has its points drawn by its light
        (:func:`field_importance`), so that they land in its bright part, and m times
        :func:`peak_factor` up to ``IMPORTANCE_PEAK_LIMIT``."""
        share = power / max(SHOT_FULL_SHARE * self.power_kept, 1e-300)
        m = max(1, min(m_hi, round(m_hi * math.sqrt(share))))
        peak = peak_factor(field, PEAK_RATIO, math.inf)
        if peak <= 1.0:
            return round(m), None
        imp = field_importance(field, bool(self.ctx.patches.is_quad[s]), IMPORTANCE_SIDE, IMPORTANCE_MIX)
        return round(m * min(peak, IMPORTANCE_PEAK_LIMIT)), imp

    def shot_group(self, power: np.ndarray, left: int) -> list[int]:
        """The patches that shoot next, at once (their gathers share the threads, and each one's
        Python runs while the other's kernels and rays do): the one with the most unshot power
        (P,), then up to ``SHOT_GROUP - 1`` more with at least ``SHOT_GROUP_RATIO`` of its power;
        at most ``left``. Pieces a shadow cut made of one root (``Patches.family``) rank by their
        sum and shoot as one group: cut in pieces, a floor's sun patch would rank below the
        building's sunlit outside, stay unshot and light its room only through the ambient term."""
        family = self.ctx.patches.family
        if family is not None:  # the pieces a shadow cut made of a root shoot together, as it would
            kin = np.bincount(family, weights=power)
            members = np.flatnonzero((family == int(np.argmax(kin))) & (power > 0))
            if len(members) > 1:
                return [int(s) for s in members[np.lexsort((members, -power[members]))][:left]]
        first = int(np.argmax(power))
        k = min(SHOT_GROUP, left, len(power))
        if k <= 1:
            return [first]
        top = np.argpartition(-power, k - 1)[:k] if k < len(power) else np.arange(len(power))
        top = top[np.lexsort((top, -power[top]))]  # by power, then index (as argmax on ties)
        rest = [int(s) for s in top if s != first][: k - 1]
        return [first, *(s for s in rest if power[s] >= SHOT_GROUP_RATIO * power[first])]

    def receiver_levels(self, s: int, field_mean: np.ndarray) -> np.ndarray:
        """(P,) int8 receiver level of each patch for the shots of s: -1 at every vertex, k on
        the coarse grid of level k (``COARSE_EPS``). Decided at the first shot of s, from the
        largest form factor of a patch's corners to s, the shot's radiance and the patch's
        radiance then, and kept for its later (fainter) shots, so that every shot of s reaches a
        patch at the same level (what :meth:`refine_total` relies on)."""
        if s in self.levels:
            return self.levels[s]
        ctx, mesh = self.ctx, self.mesh
        lvl = np.full(self.P, -1, dtype=np.int8)
        if self.coarse:
            dist = np.linalg.norm(ctx.patches.centre - ctx.patches.centre[s], axis=1) - ctx.patches.radius[s]
            size = ctx.patches.radius / np.maximum(dist, 1e-300)
            size[dist <= 0] = np.inf
            # form factors only to the corners of patches small and far enough for some level
            may = (size < max(COARSE_SIZE)) & mesh.finer_any
            cgeo = self.coarse[0].geo  # the patches' corners
            idx, f = ctx.gathers.form_factors(s, cgeo, patches=may)
            fmax = np.zeros(self.P)
            np.maximum.at(fmax, cgeo.patch[idx], f)
            y = mesh.M @ luminance_of(self.rad.reflected) + luminance_of(ctx.patches.emission)
            floor = ABS_FLOOR * float((y * ctx.patches.area).sum() / max(ctx.patches.area.sum(), 1e-300))
            lum_mean = float(luminance_of(np.abs(field_mean)))
            rel = fmax * lum_mean * luminance_of(ctx.patches.albedo) / (y + max(floor, 1e-30))
            for level in range(len(self.coarse) - 1, -1, -1):  # the coarsest that is fine enough
                sel = (rel < COARSE_EPS[level]) & (size < COARSE_SIZE[level])
                sel &= mesh.finer[level]
                lvl[sel] = level
        self.levels[s] = lvl
        return lvl

    def shot_gather(self, s: int, power: float) -> tuple[np.ndarray, np.ndarray, list, np.ndarray]:
        """The reflected radiance one shot from s (of luminance ``power``) adds, ``(rows, dv, acc,
        field_mean)``: the vertices it reaches (k,) (distinct) and what each gets (k, 3) (nothing
        at the others): gathered at the vertices of the patches it lights noticeably,
        interpolated from coarse grids on the others; ``acc`` lists per coarse level ``(level,
        points, values)`` what its grid points received, which the caller adds to the grids'
        ``acc``; ``field_mean`` (3,) the mean radiance it shot. A shot reads no state that another
        shot of its group writes (the caller applies them once all have returned)."""
        ctx, mesh = self.ctx, self.mesh
        avg = mesh.M
        field = mesh.lattice.grid(s, self.rad.unshot) * self.rad.gain[s]
        field_mean = rows_product(avg.indptr, avg.indices, avg.data, self.rad.unshot, np.array([s]), False)[0]
        field_mean = field_mean * self.rad.gain[s]
        m, imp = self.samples_by_power(SHOT_SAMPLE_FACTOR * self.m_side, power, field, s)
        shot = int(self.shot_index[s])
        lvl = self.receiver_levels(s, field_mean)
        # the vertices of the patches it lights noticeably, and a coarse grid per level of the others
        levels = [k for k in range(len(self.coarse or [])) if (lvl == k).any()]
        parts = [(mesh.geo, lvl < 0)] + [(self.coarse[k].geo, lvl == k) for k in levels]
        (idx, g), *got = ctx.gathers.gathers(
            s, parts, m, shot, field, field_mean, correlated=False, cull=True, importance=imp
        )
        rows, dv, acc = [idx], [mesh.rho[idx] * g], []
        for k, (ci, g) in zip(levels, got, strict=True):
            c, w = self.coarse[k], mesh.coarse_w[k]
            got_c = c.rho[ci] * g
            acc.append((k, ci, got_c))
            gc = np.zeros_like(c.acc)  # dense: the interpolation weights index grid points
            gc[ci] = got_c
            # the vertices of the patches at this level whose grid received take what it received
            # (a vertex interpolates its own patch's grid)
            got_any = np.zeros(self.P, dtype=bool)
            got_any[c.geo.patch[ci]] = True
            rows.append(ranges_of(mesh.start, np.flatnonzero(got_any & (lvl == k))))
            dv.append(rows_product(w.indptr, w.indices, w.data, gc, rows[-1], False))
        return np.concatenate(rows), np.concatenate(dv), acc, field_mean

    def refine_total(self, step: Refine) -> None:
        """Stage C: refine on the total radiance. New vertices get their direct light and a
        gather of everything each patch has shot so far (exact: shots are linear, so one
        gather of their sum equals replaying them all), never an interpolated value
        (:class:`TotalLight`). Their unshot radiance is what they received minus what their
        patch already shot from there (:meth:`Radiance.remap`), so energy the coarser mesh could
        not hold is shot again, not lost."""
        ctx = self.ctx
        t0 = time.perf_counter()
        old_keys = self.keys
        total = TotalLight(self)
        forest, passes, _ = split_test(
            ctx, self.forest, total.cache, total.evaluate, self.progress.report, step.label, step.span
        )
        self.stats["refine_passes"] += passes
        keys = qt.vertex_keys(forest)
        self.timings["refining_s"] += time.perf_counter() - t0
        if len(keys) == len(old_keys):
            self.rad.gain = self.shot_gain(total.cache, self.rad.offset)
            return
        self.add_refine_bias(*measure_interpolation_bias(keys, old_keys, total.cache, ctx.patches))
        # new vertices shoot the element-integrated light of the point lights, not its vertex peak
        light_corr = (
            self.light_correction(forest, keys, ctx.patches.geometry(keys))
            if ctx.light.lights
            else np.zeros((len(keys), 3))
        )
        old_idx = qt.lookup(old_keys, keys)
        self.rad = self.rad.remap(
            keys, old_idx, total.cache.get(keys), light_corr, total.grids, ctx.patches.n
        )
        self.set_mesh(forest, keys)
        self.rad.gain = self.shot_gain(total.cache, self.rad.offset)

    def add_refine_bias(self, bias: float, n: int) -> None:
        """Fold one refinement's interpolation bias over its n late vertices into the stats (a
        vertex-weighted mean over the refinement stages)."""
        n_old = self.stats["interpolation_bias_total_vertices"]
        if n:
            mean = self.stats["interpolation_bias_total"]
            self.stats["interpolation_bias_total"] = (mean * n_old + bias * n) / (n_old + n)
        self.stats["interpolation_bias_total_vertices"] = n_old + n

    def run_plan(self, plan: list[Shoot | Refine]) -> None:
        self.u_start = max(float(self.patch_power(self.rad.unshot).sum()), 1e-300)
        try:
            for step in plan:
                if self.progress.cancelled:
                    break
                if isinstance(step, Shoot):
                    self.shoot(step)
                elif self.opts.refine_indirect and self.shots:
                    self.refine_total(step)
        except SolveCancelled:
            pass

    # -- the result ---------------------------------------------------------------
    def reflected_fraction(self, fallback=None) -> np.ndarray:
        """(3,) the fraction r of a shot's power the scene reflects back, over the last half of the
        shots (``fallback`` when there were none, or 0): a statistic of the solve."""
        log = self.shot_log[len(self.shot_log) // 2 :]
        if log:
            sp = np.sum([np.abs(a) for a, _ in log], axis=0)
            rp = np.sum([np.abs(b) for _, b in log], axis=0)
            r = np.where(sp > 0, rp / np.where(sp > 0, sp, 1.0), 0.0)
        elif fallback is not None and len(fallback) == 3:
            r = np.asarray(fallback, dtype=np.float64)
        else:
            r = np.zeros(3)
        return np.clip(r, 0.0, MAX_REFLECTANCE)

    def finish(self, mode="solve", fallback_reflectance=None, extra=None) -> Solution:
        ctx, opts = self.ctx, self.opts
        forest, keys = self.forest, self.keys
        unshot_power = self.patch_power(self.rad.unshot)
        vpatch = qt.decode_key(keys, ctx.patches.n)[0]
        reflected = self.rad.reflected
        amb = np.zeros((len(keys), 3))
        if opts.ambient and opts.max_shots > 0 and len(keys) and not self.progress.cancelled:
            try:
                amb = ambient_term(
                    ctx,
                    self.mesh,
                    self.vis,
                    self.scene,
                    self.rad.unshot,
                    self.rad.gain,
                    opts.ambient_rays,
                    self.check,
                )
            except SolveCancelled:
                amb = np.zeros((len(keys), 3))
            reflected = reflected + amb
        radiance = ctx.patches.emission[vpatch] + reflected
        if not np.isfinite(radiance).all():
            self.check_energy(math.inf, "reflected")
        # (with the point lights' element correction: a vertex next to a light holds its 1/d^2 peak)
        held = self.mesh.M @ np.abs(reflected + self.rad.offset)
        self.check_energy(float(np.pi * (ctx.patches.area * luminance_of(held)).sum()), "reflected")
        radiance = np.maximum(radiance, 0.0)
        unshot_fraction = float(unshot_power.sum() / self.power_ref) if self.power_ref > 0 else 0.0
        self.progress.finish(f"done: {self.shots} shots, {len(keys)} vertices")
        elapsed = time.perf_counter() - self.t_start
        vis = self.vis
        sol = Solution.from_forest(
            forest,
            ctx.patches.corners,
            self.scene.patch_material,
            ctx.patches.albedo,
            keys,
            radiance,
            options=opts.to_dict(),
            model_path=str(getattr(self.scene, "path", "") or ""),
            clip_uv=self.scene.clip_uv,
            clip_patch=self.scene.clip_patch,
            patch_transmission=self.scene.patch_transmission.astype(np.float32),
        )
        area_tot = float(ctx.patches.area.sum())
        sol.stats = {
            "elements": int(forest.n_leaves),
            "vertices": int(len(keys)),
            "triangles": int(len(sol.drawn_mesh().triangles)),
            "shots": int(self.shots),
            "rays": int(vis.rays),
            "rays_per_s": float(vis.rays / vis.seconds) if vis.seconds > 0 else 0.0,
            "sky_counts": ctx.light.sky_counts.tolist(),
            "time_s": float(elapsed),
            **{k: float(v) for k, v in self.timings.items()},
            "unshot_fraction": unshot_fraction,
            **self.stats,
            "max_depth_reached": int(forest.leaf_level.max()) if forest.n_leaves else 0,
            "min_element_size": float(ctx.patches.min_size),
            "emitted_power": float(self.power0),
            "received_power": float(self.power_ref),
            "ambient_luminance_fraction": float(
                np.pi * (ctx.patches.area * luminance_of(self.mesh.M @ amb)).sum() / self.power_ref
            )
            if self.power_ref > 0 and area_tot > 0
            else 0.0,
            "reflectance": [float(x) for x in self.reflected_fraction(fallback_reflectance)],
            "culled_pairs": float(ctx.gathers.culled_fraction()),
            "mode": mode,
            "sources": sources_record(ctx),
            "shadow_cuts": [[list(k) for k in group] for group in self.scene.shadow_cuts],
            "load": loader_choices(self.scene),
            "cancelled": bool(self.progress.cancelled),
            "options": opts.to_dict(),
            **(extra or {}),
        }
        return sol


def loader_choices(scene) -> dict:
    """The loader's ``sides`` and ``cut`` choices that made ``scene`` (``load_scene(**...)`` loads its
    model the same again; empty for a scene built in memory)."""
    found = {"sides": getattr(scene.sides, "mode", None), "cut": getattr(scene.pierce, "mode", None)}
    return {k: v for k, v in found.items() if v is not None}


class TotalLight:
    """Stage C's evaluation of new points (:meth:`evaluate`): their direct light, what the coarse
    grids of their patch received (interpolated, as at the old vertices) and one gather of what
    each source has shot so far (its shot field times its gain, ``grids``). One sample pattern per
    source for all new vertices, with ``REFINE_SAMPLE_FACTOR`` x the samples a side its shots had
    (its error is a coherent offset of them all, which the shots' per-vertex patterns average
    out). ``cache`` holds the total reflected radiance of every point evaluated."""

    def __init__(self, run: SolveRun):
        self.run = run
        rad, mesh = run.rad, run.mesh
        shot_field = rad.shot()
        self.sources = [int(p) for p in np.flatnonzero(run.shot_index > 1)]
        self.grids = {p: mesh.lattice.grid(p, shot_field) * rad.gain[p] for p in self.sources}
        self.means = (mesh.M @ shot_field) * rad.gain[:, None]
        self.cache = VertexCache(mesh.keys, rad.reflected.copy(), run.direct_cache.noise_at(mesh.keys))
        m_ref = REFINE_SAMPLE_FACTOR * run.m_side
        self.m_src = {  # per source: its samples a side and importance tables
            p: run.samples_by_power(m_ref, run.shot_power[p], self.grids[p], p) for p in self.sources
        }
        self.n_pass = run.stats["refine_passes"]

    def evaluate(self, new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) the total reflected radiance at the new vertex keys (n,), and (n,) the standard
        error of its direct light (the shots' gathers are correlated between vertices: smooth)."""
        run, ctx = self.run, self.run.ctx
        out, noise = run.direct_cache.get(new), run.direct_cache.noise_at(new)
        missing = run.direct_cache.find(new) < 0
        if missing.any():
            out[missing], noise[missing] = run.direct_with_noise(new[missing])
        if not len(new):
            return out, noise
        geo = ctx.patches.geometry(new)
        rho = ctx.patches.albedo[geo.patch]
        on = np.zeros(run.P, dtype=bool)
        on[geo.patch] = True
        for level, c in enumerate(run.coarse or []):
            out += coarse_weights(new, c.keys, ctx.patches.is_quad, level, ctx.patches.n) @ c.acc
        calls = []  # the sources that can reach these vertices (most reach none of a few)
        for p in self.sources:
            fine = run.levels[p] < 0 if p in run.levels else None
            if (ctx.gathers.receiver_patches(p, True, fine) & on).any():
                calls.append((geo, p, fine))
        for g in ctx.pool.traced_map(self.gather, calls, run.check):
            out += rho * g
        return out, noise

    def gather(self, call: tuple) -> np.ndarray:
        """(n, 3) what source p shot, gathered at ``geo`` (on its ``fine`` patches, None: all)."""
        geo, p, fine = call
        jitter = int(self.run.shot_index[p]) + 1_000_000 * (1 + self.n_pass)
        return self.run.ctx.gathers.gather(
            p,
            geo,
            self.m_src[p][0],
            jitter,
            self.grids[p],
            self.means[p],
            correlated=True,
            cull=True,
            patches=fine,
            importance=self.m_src[p][1],
        )
