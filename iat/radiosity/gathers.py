"""Gathers from a shooting patch (:class:`Gathers`): sample patterns, the shooters' kernel
geometry, receivers in front of a shooter, analytic form factors (cached per mesh), the
visibility-weighted gather kernels, and the culling of receiver patches a shooter's earlier rays
found fully occluded."""

from __future__ import annotations

import threading
import time
from typing import NamedTuple

import numpy as np

from iat.radiosity import kernels
from iat.radiosity.bundles import (
    ShooterArrays,
    ShotField,
    finish_rows,
    receiver_rows,
    sample_rays,
    traced_rows,
)
from iat.radiosity.culling import CullCounts, pack, unpack
from iat.radiosity.formfactor import point_polygon
from iat.radiosity.options import (
    F_DIRECTION,
    FF_FAR,
    GATHER_BLOCK,
    PATTERN_CACHE_POINTS,
    SHOOTER_COVERAGE,
    SPLIT_RECEIVERS,
    SolveOptions,
)
from iat.radiosity.patches import Patches, ReceiverGeometry, ranges_of
from iat.radiosity.sampling import GAUSS_QUAD, GAUSS_TRI, NO_IMPORTANCE, Shooter
from iat.radiosity.tasks import TaskPool, no_check
from iat.radiosity.visibility import Visibility

_MASK64 = (1 << 64) - 1


class _Shot(NamedTuple):
    """What every block of one :meth:`Gathers.gathers` call shares."""

    shooter: ShooterArrays
    pat: np.ndarray  # (S, 2) the sample pattern
    salt: np.uint64  # the rotations' hash salt
    correlated: bool
    field: ShotField
    sets: list  # per receiver set: (geo, idx (k,), f (k,))


class Gathers:
    """The gathers of one solve. Owns the caches they share across shots (patterns, shooters,
    per-thread scratch, the patches in front of each shooter as bits) and ``culling``
    (:class:`~iat.radiosity.culling.CullCounts`: per shooter, the rays traced to each receiver
    patch it reached and how many got through). Thread-safe:
    shots run two at a time (:class:`~iat.radiosity.tasks.TaskPool`)."""

    def __init__(self, patches: Patches, opts: SolveOptions, vis: Visibility, pool: TaskPool):
        self.patches, self.opts, self.vis, self.pool = patches, opts, vis, pool
        self._shooters: dict[int, Shooter] = {}
        self._patterns: dict[tuple[int, int, int], np.ndarray] = {}
        self._pattern_points = 0  # (u, v) pairs in _patterns
        self._buffers = threading.local()  # per thread: the gathers' scratch (:meth:`_scratch`)
        self._lock = threading.Lock()  # form-factor caches and cull counts, shared by gather threads
        self._cand: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # packed (:meth:`candidates`)
        self.culling = CullCounts()

    def pattern(self, s: int, m: int, shot: int) -> np.ndarray:
        """(m*m, 2) stratified jittered (u, v) in [0, 1)^2 for patch s (fixed per seed, patch, shot)."""
        key = (int(s), int(m), int(shot))
        pat = self._patterns.get(key)
        if pat is None:  # stage C's passes gather from every source with the same pattern
            rng = np.random.default_rng([self.opts.seed, int(s), int(shot), int(m)])
            a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
            pat = np.stack([(a.ravel() + rng.random(m * m)) / m, (b.ravel() + rng.random(m * m)) / m], axis=1)
            with self._lock:
                if self._pattern_points + m * m > PATTERN_CACHE_POINTS:
                    self._patterns.clear()
                    self._pattern_points = 0
                self._patterns[key] = pat
                self._pattern_points += m * m
        return pat

    def shooter(self, s: int) -> Shooter:
        if s not in self._shooters:
            self._shooters[s] = Shooter(
                self.patches.corners[s],
                bool(self.patches.is_quad[s]),
                self.patches.normal[s],
                float(self.patches.lattice_area[s]),
                float(self.patches.eps_patch[s]),
                self.patches.coverage(s, SHOOTER_COVERAGE) if self.patches.clipped[s] else None,
            )
        return self._shooters[s]

    def _scratch(self, n: int) -> tuple[np.ndarray, ...]:
        """The calling thread's buffers for n samples (:func:`.kernels.gather_rays`), kept between calls."""
        buf = getattr(self._buffers, "arrays", None)
        if buf is None or buf[0].shape[1] < n:
            n = max(n, 2 * GATHER_BLOCK * 64)
            buf = self._buffers.arrays = (
                np.empty((6, n)),
                np.empty((n, 3), dtype=np.float32),
                np.empty((n, 3), dtype=np.float32),
                np.empty(n, dtype=np.float32),
            )
        return buf

    def candidates(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(P,) bool ``full, part``: receiver patches that can see the front of patch s, entirely
        in front of its plane (``full``) or straddling it (``part``: test per vertex)."""
        P = self.patches.n_patches
        if s not in self._cand:
            poly = self.patches.polygon(s)
            # some corner of s strictly in front of the receiver's plane
            h = np.einsum(
                "pkc,pc->pk", poly[None, :, :] - self.patches.centre[:, None, :], self.patches.normal
            )
            sees = (h > 1e-9 * self.patches.scale).any(axis=1)
            sees[s] = False
            # receiver corners in front of the plane of s
            hr = np.einsum("pkc,c->pk", self.patches.corners - self.patches.centre[s], self.patches.normal[s])
            ahead = hr > 0.1 * self.patches.eps_ff + 1e-9 * self.patches.scale
            any_ahead = (ahead & self.patches.valid_corner).any(axis=1)
            all_ahead = (ahead | ~self.patches.valid_corner).all(axis=1)
            self._cand[s] = (pack(sees & all_ahead), pack(sees & any_ahead & ~all_ahead))
        full, part = self._cand[s]
        return unpack(full, P), unpack(part, P)

    def allowed(self, s: int, cull: bool, patches: np.ndarray | None) -> np.ndarray | None:
        """(P,) bool receiver patches allowed for s (``patches``, less the ones earlier gathers
        of s found fully occluded when ``cull``), or None for all."""
        ok = None if patches is None else np.asarray(patches, dtype=bool)
        if cull and s in self.culling:
            with self._lock:
                hidden = self.culling.hidden(s)
            ok = np.ones(self.patches.n_patches, dtype=bool) if ok is None else ok.copy()
            ok[hidden] = False
        return ok

    def receiver_patches(self, s: int, cull: bool = False, patches: np.ndarray | None = None) -> np.ndarray:
        """(P,) bool patches whose vertices a :meth:`gather` from s with these ``cull`` and
        ``patches`` may reach (in front of s and allowed): a gather to vertices on none of them
        returns zeros."""
        full, part = self.candidates(s)
        ok = self.allowed(s, cull, patches)
        return (full | part) if ok is None else (full | part) & ok

    def receivers(self, s: int, geo: ReceiverGeometry, allowed: np.ndarray | None = None) -> np.ndarray:
        """Sorted indices into ``geo`` of vertices that can receive from patch s (front side,
        other patch, on an ``allowed`` patch)."""
        full, part = self.candidates(s)
        if allowed is not None:
            full, part = full & allowed, part & allowed
        if geo.start is not None:
            idx_full = ranges_of(geo.start, np.flatnonzero(full))
            idx_part = ranges_of(geo.start, np.flatnonzero(part))
        else:
            idx_full = np.flatnonzero(full[geo.patch])
            idx_part = np.flatnonzero(part[geo.patch])
        front = (geo.ff[idx_part] - self.patches.centre[s]) @ self.patches.normal[
            s
        ] > 0.1 * self.patches.eps_ff
        return np.sort(np.concatenate([idx_full, idx_part[front]]), kind="stable")  # two sorted runs: merged

    def form_factors(
        self, s: int, geo: ReceiverGeometry, cull: bool = False, patches: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Receivers of s in ``geo`` with a form factor > 0 (indices) and their analytic form
        factors, on the allowed patches (see :meth:`allowed`). With ``geo.cache`` (a mesh's
        geometry) they are kept per shooter and receiver patch, since a patch shoots several
        times on the same mesh; the oldest shooters go first when the cache is full."""
        ok = self.allowed(s, cull, patches)
        cache = geo.cache
        with self._lock:  # gathers of other shooters may share the cache (:meth:`imap`)
            entry = None if cache is None else cache.entry(s, self.patches.n_patches)
        done = None if entry is None else unpack(entry[2], self.patches.n_patches)
        need = ok if entry is None else (~done if ok is None else ok & ~done)
        if entry is None or need.any():
            idx = self.receivers(s, geo, need)
            f = self._form_factors(s, geo.ff[idx], geo.normal[idx])
            keep = f > 1e-12
            idx, f = idx[keep], f[keep]
            if entry is None:
                return idx, f
            entry[0] = np.concatenate([entry[0], idx])
            entry[1] = np.concatenate([entry[1], f.astype(np.float32)])
            entry[2] = pack(done | need)
            with self._lock:
                cache.grew(s, len(idx))
        idx, f = entry[0], entry[1]
        if ok is not None:
            sel = ok[geo.patch[idx]]
            idx, f = idx[sel], f[sel]
        return idx, f

    def _form_factors(self, s: int, x: np.ndarray, nr: np.ndarray) -> np.ndarray:
        """(n,) point-to-polygon form factors from points x with normals nr to patch s: the
        analytic contour integral, or for receivers farther than ``FF_FAR`` shooter radii that
        see all of it, a Gauss rule over the shooter (2 x 2 points on quads, Dunavant's 6 on
        triangles; within 0.5 % of the analytic value there, 0.06 % on average)."""
        f = np.zeros(len(x))
        if len(x) == 0:
            return f
        if self.patches.clipped[s]:  # a panel cell: the sum over its clip triangles
            for tri in self.patches.clip_world[self.patches.clip_start[s] : self.patches.clip_start[s + 1]]:
                f += point_polygon(x, nr, tri)
            return f
        sh = self.shooter(s)
        ka = sh.kernel_args()
        (gu, gv), gw = GAUSS_QUAD if sh.is_quad else GAUSS_TRI
        pt = self.patches
        return kernels.patch_form_factors(
            np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(nr, dtype=np.float64),
            np.ascontiguousarray(pt.polygon(s)), pt.centre[s], FF_FAR * float(pt.radius[s]),
            ka.geom, ka.para, ka.area, gu.ravel(), gv.ravel(), gw,
        )  # fmt: skip

    def culled_fraction(self) -> float:
        """Fraction of (shooter, candidate receiver patch) pairs found fully occluded."""
        tot = hid = 0
        for s in self.culling.rows:
            full, part = self.candidates(s)
            tot += int((full | part).sum())
            hid += int((full | part)[self.culling.hidden(s)].sum())
        return hid / tot if tot else 0.0

    def gather(
        self,
        s: int,
        geo: ReceiverGeometry,
        m: int,
        shot: int = 0,
        field: np.ndarray | None = None,
        field_mean: np.ndarray | None = None,
        *,
        correlated: bool = False,
        cull: bool = False,
        patches: np.ndarray | None = None,
        importance: np.ndarray | None = None,
    ) -> np.ndarray:
        """Form factor x visible fraction from every vertex of ``geo`` to patch s.

        m : the sample patterns are m x m; shot : index of this patch's shot (0 for the
        direct pass), which fixes the jitter (a vertex re-evaluated later gets the same value).
        field : None for a uniform shooter, returning (n,) ``F * vis``; or the shooter's
        radiance on its lattice, (N+1, N+1, 3), with its area mean ``field_mean`` (3,),
        returning (n, 3) the radiance-weighted form factor: a shooter need not be uniform.
        correlated : one sample pattern for all receivers (errors vary smoothly over the
        receivers: no speckle), instead of the pattern rotated per receiver (errors
        independent per receiver: penumbrae become noise instead of banding).
        cull : skip receiver patches that earlier gathers from s found fully occluded.
        patches : (P,) bool, receive only on these patches (None: all).
        importance : the tables the area samples are drawn by, by the field's light
        (:func:`~iat.radiosity.sampling.field_importance`; None: uniformly on the shooter).

        ``F`` is the analytic form factor and ``vis`` the ratio of two estimates of the
        kernel integral (with and without visibility) from the same samples, so it is
        exact for an unoccluded shooter. A field is split into a constant ``c`` (a control
        variate: the field at the receiver's foot on the shooter for near receivers, the
        shooter's mean for far ones), weighted by ``F * vis``, and the rest, whose kernel
        integral is estimated directly (not as a ratio: a ratio of correlated estimates
        loses energy when the field is bright where the kernel is large). Near receivers
        (``F >= F_DIRECTION``) combine two strategies with the balance heuristic: m x m
        stratified points on the shooter's area (good when the shooter is far and small)
        and m x m cosine-distributed directions from the receiver that hit the shooter
        (good when it is near and large: the kernel is then too peaked for area samples);
        far receivers use the area samples alone. All kernel terms are computed from
        per-receiver scalars (no (n, samples, 3) arrays).
        """
        parts = [(geo, patches)]
        idx, val = self.gathers(
            s, parts, m, shot, field, field_mean, correlated=correlated, cull=cull, importance=importance
        )[0]
        out = np.zeros((len(geo.key), *val.shape[1:]))
        out[idx] = val
        return out

    def gathers(
        self,
        s: int,
        parts: list[tuple[ReceiverGeometry, np.ndarray | None]],
        m: int,
        shot: int = 0,
        field: np.ndarray | None = None,
        field_mean: np.ndarray | None = None,
        *,
        correlated: bool = False,
        cull: bool = False,
        with_ff: bool = False,
        importance: np.ndarray | None = None,
    ) -> list[tuple]:
        """:meth:`gather` from s to several receiver sets at once: ``parts`` is a list of ``(geo,
        patches)`` on disjoint patches (a shot's mesh vertices and its coarse grids), and their
        blocks of receivers run together on the threads. Per part ``(idx, val)``: the indices into
        ``geo`` of its receivers (k,) (distinct) and their values (k,) or (k, 3), the rows of what one
        :meth:`gather` per part in order returns that can be nonzero (so that a shot costs its
        receivers, not the mesh); each part's culling sees only its own patches. ``with_ff``: per part
        ``(idx, val, f)``, with the receivers' analytic form factors (k,). ``importance``: as
        :meth:`gather`."""
        pat = self.pattern(s, m, shot)
        salt = np.uint64(((int(self.opts.seed) * 1_000_003 + int(s)) * 1_000_003 + int(shot)) & _MASK64)
        has_field = field is not None
        flat = np.zeros((1, 3)) if field is None else field.astype(np.float64).reshape(-1, 3)
        fld = ShotField(
            flat,
            0 if field is None else field.shape[0] - 1,
            np.zeros(3) if field_mean is None else np.ascontiguousarray(field_mean, dtype=np.float64),
            has_field,
            has_field and float(flat.min()) >= 0,  # a field of one sign gives results of that sign
            has_field and float(flat.max()) <= 0,
            NO_IMPORTANCE if importance is None else np.ascontiguousarray(importance, dtype=np.float64),
        )
        sets = [(geo, *self.form_factors(s, geo, cull, patches)) for geo, patches in parts]
        shot_job = _Shot(self.shooter(s).kernel_args(), pat, salt, correlated, fld, sets)

        embree_args = self.vis.embree_args()
        if embree_args is not None:  # each set in one kernel that traces its own rays
            done = [self._traced(shot_job, k, embree_args) for k in range(len(sets))]
            outs, counts = [d[0] for d in done], [d[1:] for d in done]
        else:
            outs, counts = self._blocks(shot_job, field is not None)
        with self._lock:
            for c in counts:
                self.culling.add(s, *c)
        if with_ff:
            return [(idx, out, f) for (_, idx, f), out in zip(sets, outs, strict=True)]
        return [(idx, out) for (_, idx, _), out in zip(sets, outs, strict=True)]

    def gather_unoccluded(self, s: int, geo: ReceiverGeometry, m: int) -> tuple[np.ndarray, np.ndarray]:
        """(n,) ``F * vis`` from a uniform shooter s to the vertices of ``geo``, as :meth:`gather`
        (per-vertex patterns, shot 0, m x m samples), and (n,) their analytic ``F``: what each would
        get unoccluded (their ratio is its visible fraction)."""
        idx, val, f = self.gathers(s, [(geo, None)], m, with_ff=True)[0]
        out, ff = np.zeros(len(geo.key)), np.zeros(len(geo.key))
        out[idx], ff[idx] = val, f
        return out, ff

    def _traced(self, shot: _Shot, k: int, embree_args: tuple):
        """Set k of a gather in one :func:`~iat.radiosity.traced.gather_traced` call on the ray
        threads: its rows' values, and per row its patch, rays traced and rays seen (k,)."""
        geo, idx, f = shot.sets[k]
        if len(idx) == 0:
            e = np.zeros(0)
            return np.zeros(0 if not shot.field.has_field else (0, 3)), e.astype(np.int64), e, e
        t0 = time.perf_counter()
        with self.vis.kernel_threads():
            out, seen, rays, through = traced_rows(
                embree_args, idx, geo.key, shot.salt, shot.correlated, geo.ff, geo.normal, geo.patch,
                self.patches.tangent, np.ascontiguousarray(f, dtype=np.float64), F_DIRECTION, geo.origin32(),
                shot.pat, shot.shooter, shot.field,
            )  # fmt: skip
        self.vis.count(int(rays.sum()) + int(through), time.perf_counter() - t0)
        return out if shot.field.has_field else out[:, 0], geo.patch[idx], rays, seen

    def _blocks(self, shot: _Shot, has_field: bool) -> tuple[list, list, list]:
        """A gather's sets in blocks of at most ``GATHER_BLOCK`` receivers (a large set in as many
        as there are threads) on the gather threads, each traced with :meth:`Visibility.visible`
        (embreex's path): per set its rows' values, and per block its rows' patches, rays traced and
        rays seen (the counts :class:`CullCounts` takes)."""
        jobs = []
        for k, (_, idx, _) in enumerate(shot.sets):
            size = GATHER_BLOCK
            if len(idx) >= SPLIT_RECEIVERS:
                size = min(size, -(-len(idx) // self.vis.threads))
            jobs += [(k, slice(a, a + size)) for a in range(0, len(idx), size)]
        outs = [np.zeros(len(idx) if not has_field else (len(idx), 3)) for _, idx, _ in shot.sets]
        counts = []
        results = self.pool.imap(lambda job: self._block(shot, job), jobs, no_check)
        for (k, sl), res in zip(jobs, results, strict=True):
            if res is not None:
                outs[k][sl] = res[0]
                counts.append(res[1:])
        return outs, counts

    def _block(self, shot: _Shot, job: tuple[int, slice]):
        """One block of receivers of a gather, ``job = (set, rows)``: its rows' values, and the
        patches, rays traced and rays seen (b,); None when no sample has weight."""
        geo, idx, f = shot.sets[job[0]]
        sl = job[1]
        fb = np.ascontiguousarray(f[sl], dtype=np.float64)
        # per row: its rotation (one for all when correlated), point, normal, tangents, whether
        # it takes direction samples too, ray origin, patch
        rows = receiver_rows(
            idx[sl], geo.key, shot.salt, shot.correlated, geo.ff, geo.normal, geo.patch, self.patches.tangent,
            fb, F_DIRECTION, geo.origin32(),
        )  # fmt: skip
        # the samples' weights and rays (float32, as embreex takes them: origins and targets
        # are off the surfaces by at least 32 float32 steps, so the rounding never crosses one)
        scratch = self._scratch(2 * len(fb) * len(shot.pat))
        smp = sample_rays(shot.pat, rows, shot.shooter, shot.field.imp, scratch)
        if len(smp.w) == 0:
            return None
        vis = self.vis.visible(smp.o, smp.d, smp.tfar)
        val, seen = finish_rows(smp, vis, fb, rows, shot.shooter, shot.field)
        return val if shot.field.has_field else val[:, 0], rows.patch, np.diff(smp.off), seen
