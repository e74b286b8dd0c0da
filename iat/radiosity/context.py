"""Per-solve constant data and the gather kernels (:class:`Context`): receiver geometry, form
factors, visibility-weighted gathers from a shooting patch, direct light of emitters and point /
spot lights (with the element-integrated correction of :mod:`.pointlight`)."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass

import numpy as np

from iat.color import LUMINANCE_WEIGHTS
from iat.geometry import quadtree as qt
from iat.geometry.clip import clamp_into, coverage_grid
from iat.radiosity.formfactor import point_polygon
from iat.radiosity.kernels import block_inputs, gather_finish, gather_rays, one_thread, patch_form_factors
from iat.radiosity.options import (
    CULL_RAYS,
    DIRECT_SAMPLE_FACTOR,
    F_DIRECTION,
    FF_CACHE_ENTRIES,
    FF_EPS,
    FF_FAR,
    GATHER_BLOCK,
    MAX_ELEMENT_FRACTION,
    MIN_ELEMENT_FRACTION,
    PATTERN_CACHE_POINTS,
    RAY_EPS,
    RAY_EPS_PATCH,
    SHOOTER_COVERAGE,
    SKY_SAMPLES,
    SPLIT_RECEIVERS,
    SUN_SAMPLES,
    SolveOptions,
)
from iat.radiosity.pointlight import lumped_light
from iat.radiosity.sampling import (
    GAUSS_QUAD,
    GAUSS_TRI,
    Shooter,
    disk_to_hemisphere,
    hash_uniform,
    luminance_of,
    pattern_side,
    rotated_disk,
)
from iat.radiosity.sky import sky_radiance
from iat.radiosity.visibility import Visibility


class SolveCancelled(Exception):
    """Internal: the progress callback asked to stop."""


_MASK64 = (1 << 64) - 1
_TASKS: dict[int, ThreadPoolExecutor] = {}
_TASKS_LOCK = threading.Lock()
_IN_TASK = threading.local()


def _task_pool(n: int) -> ThreadPoolExecutor:
    """The process's pool of ``n`` gather threads (made once per ``n``, shared by all solves)."""
    with _TASKS_LOCK:
        if n not in _TASKS:
            _TASKS[n] = ThreadPoolExecutor(n, thread_name_prefix="iat-gather")
        return _TASKS[n]


def _no_check() -> None:
    pass


@dataclass
class ReceiverGeometry:
    """Receiver geometry of a set of vertices (all (n, ...) arrays)."""

    key: np.ndarray  # (n,) int64 vertex keys
    patch: np.ndarray  # (n,) int64
    pos: np.ndarray  # (n, 3) world position on the patch
    normal: np.ndarray  # (n, 3)
    ff: np.ndarray  # (n, 3) form-factor point, nudged into its own patch
    origin: np.ndarray  # (n, 3) ray origin, off the surface
    start: np.ndarray | None = None  # (P + 1,) first index of each patch when keys are sorted
    cache: dict | None = None  # per-shooter form factors (the mesh's geometry only)
    _origin32: np.ndarray | None = None

    def origin32(self) -> np.ndarray:
        """(n, 3) float32 ray origins (made once)."""
        if self._origin32 is None:
            self._origin32 = np.ascontiguousarray(self.origin, dtype=np.float32)
        return self._origin32

    def take(self, idx) -> ReceiverGeometry:
        return ReceiverGeometry(
            self.key[idx], self.patch[idx], self.pos[idx], self.normal[idx], self.ff[idx], self.origin[idx]
        )


def ranges_of(start: np.ndarray, patches: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(start[p], start[p + 1])`` over ``patches`` (sorted)."""
    a, b = start[patches], start[patches + 1]
    n = b - a
    keep = n > 0
    a, n = a[keep], n[keep]
    if len(n) == 0:
        return np.zeros(0, dtype=np.int64)
    off = np.repeat(a - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    return np.arange(int(n.sum()), dtype=np.int64) + off


def emitter_shares(emission: np.ndarray, area: np.ndarray) -> np.ndarray:
    """(P,) each patch's share of the emitted power (luminance of ``emission`` (P, 3) x ``area``
    (P,)); 0 on patches that emit nothing, and all 0 when nothing does."""
    power = np.abs(luminance_of(emission)) * area
    total = float(power.sum())
    return power / total if total > 0 else np.zeros(len(area))


class Context:
    """Per-solve constant data and the shared gather kernels."""

    def __init__(self, scene, opts: SolveOptions, vis: Visibility):
        self.opts = opts
        self.corners = scene.corner_positions
        self.is_quad = scene.patch_is_quad
        self.normal = scene.patch_normal
        self.area = scene.patch_area
        self.lattice_area = scene.lattice_area
        # panel cells: clip triangles (lattice uv) per patch, their world triangles, coverage grids
        self.clip_uv, self.clip_start = scene.clip_uv, scene.clip_start
        self.clipped = scene.patch_clipped
        tri_world = scene.world_triangles()
        self.clip_world = tri_world[len(tri_world) - len(self.clip_uv) :]
        self._coverage: dict[tuple[int, int], np.ndarray] = {}
        self.albedo = solver_albedo(scene)
        self.emission = scene.patch_emission
        self.n_patches = len(self.area)
        self.n_corners = np.where(self.is_quad, 4, 3)
        self.centre = np.where(
            self.is_quad[:, None], self.corners.mean(axis=1), self.corners[:, :3].mean(axis=1)
        )
        self.radius = np.linalg.norm(self.corners - self.centre[:, None, :], axis=2).max(axis=1)
        lo, hi = scene.bounds if self.n_patches else (np.zeros(3), np.zeros(3))
        self.scale = max(float(np.linalg.norm(hi - lo)), 1e-12)
        self.eps_ray = RAY_EPS * self.scale
        # per patch: no more than a fiftieth of the patch's radius (a 1 cm object in a 100 m scene
        # keeps its shadow), no less than 32 float32 steps at the scene's extent (embree's precision)
        extent = float(np.abs(np.stack([lo, hi])).max()) if self.n_patches else 1.0
        floor = 32.0 * float(np.spacing(np.float32(max(extent, 1e-30))))
        self.eps_patch = np.clip(RAY_EPS_PATCH * self.radius, min(floor, self.eps_ray), self.eps_ray)
        self.eps_ff = FF_EPS * self.scale
        mes = opts.min_element_size
        self.min_size = (
            MIN_ELEMENT_FRACTION * math.sqrt(float(self.area.sum())) if mes is None else float(mes)
        )
        self.max_size = MAX_ELEMENT_FRACTION * math.sqrt(float(self.area.sum()))
        self.n = 1 << opts.max_depth
        self.vis = vis
        self.lights = [lt for lt in scene.lights if lt.kind in ("point", "spot")]
        self.suns = [lt for lt in scene.lights if lt.kind == "directional" and np.any(lt.radiant_intensity)]
        self.sky = getattr(scene, "sky", None)
        self.emitters = np.flatnonzero((self.emission > 0).any(axis=1))
        self.emitter_share = emitter_shares(self.emission, self.area)  # (P,) for the direct pass's samples
        # a tangent frame per patch (for cosine-distributed directions)
        helper = np.where(np.abs(self.normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(self.normal, helper)
        t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-300)
        self.tangent = np.stack([t1, np.cross(self.normal, t1)], axis=1)  # (P, 2, 3)
        # receiver corners' heights (P, 4) over their own patch centre, for the plane tests
        self._valid_corner = np.arange(4)[None, :] < self.n_corners[:, None]
        self._shooters: dict[int, Shooter] = {}
        self._patterns: dict[tuple[int, int, int], np.ndarray] = {}
        self._pattern_points = 0  # (u, v) pairs in _patterns
        self._buffers = threading.local()  # per thread: the gathers' scratch (:meth:`_scratch`)
        self._lock = threading.Lock()  # form-factor caches and cull counts, shared by gather threads
        self._cand: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        # per shooter: rays traced to each receiver patch and how many were unoccluded
        self._vis_rays: dict[int, np.ndarray] = {}
        self._vis_seen: dict[int, np.ndarray] = {}

    # -- geometry -------------------------------------------------------------
    def polygon(self, s: int) -> np.ndarray:
        return self.corners[s, : self.n_corners[s]]

    def geometry(self, keys: np.ndarray) -> ReceiverGeometry:
        keys = np.asarray(keys, dtype=np.int64)
        p, i, j = qt.decode_key(keys, self.n)
        if self.clipped.any() and self.clipped[p].any():
            pos = qt.patch_point(self.corners, self.is_quad, p, *self.clamped_uv(p, i / self.n, j / self.n))
        else:
            pos = qt.lattice_to_world(self.corners, self.is_quad, p, i, j, self.n)
        nrm = self.normal[p]
        t = self.centre[p] - pos
        t -= np.einsum("nc,nc->n", t, nrm)[:, None] * nrm
        tl = np.linalg.norm(t, axis=1)
        that = t / np.maximum(tl, 1e-300)[:, None]
        ff = pos + np.minimum(self.eps_ff, 0.5 * tl)[:, None] * that
        eps = self.eps_patch[p][:, None]
        origin = pos + eps * nrm + np.minimum(eps, 0.5 * tl[:, None]) * that
        start = None
        if len(keys) == 0 or np.all(keys[1:] > keys[:-1]):
            start = np.searchsorted(keys, qt.make_key(np.arange(self.n_patches + 1), 0, 0, self.n))
        return ReceiverGeometry(keys, p, pos, nrm, ff, origin, start)

    def clamped_uv(self, p: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice (u, v) of points on patches ``p`` moved into their clip triangles (points of a
        panel cell outside its surface take the nearest surface point, 2 ray offsets inside)."""
        u, v = np.asarray(u, dtype=np.float64).copy(), np.asarray(v, dtype=np.float64).copy()
        sel = np.flatnonzero(self.clipped[p])
        if len(sel) == 0:
            return u, v
        side = np.linalg.norm(self.corners[p[sel], 1] - self.corners[p[sel], 0], axis=1)
        margin = 2.0 * self.eps_patch[p[sel]] / np.maximum(side, 1e-300)
        out = clamp_into(np.stack([u[sel], v[sel]], axis=1), p[sel], self.clip_uv, self.clip_start, margin)
        u[sel], v[sel] = out[:, 0], out[:, 1]
        return u, v

    def coverage(self, p: int, res: int) -> np.ndarray:
        """(res, res) bool surface coverage of clipped patch p at cell centres (``grid[v, u]``)."""
        key = (int(p), int(res))
        if key not in self._coverage:
            a, b = self.clip_start[p], self.clip_start[p + 1]
            self._coverage[key] = coverage_grid(self.clip_uv[a:b], res)
        return self._coverage[key]

    def leaf_has_surface(self, forest: qt.Forest) -> np.ndarray:
        """(L,) bool: False for leaves of panel cells that cover none of the cell's surface (at
        the finest lattice's cell centres): they are not split."""
        out = np.ones(forest.n_leaves, dtype=bool)
        lp = np.asarray(forest.leaf_patch, dtype=np.int64)
        for p in np.unique(lp[self.clipped[lp]]):
            sat = np.zeros((self.n + 1, self.n + 1))
            sat[1:, 1:] = self.coverage(p, self.n).cumsum(axis=0).cumsum(axis=1)
            sel = np.flatnonzero(lp == p)
            size = self.n >> np.asarray(forest.leaf_level[sel], dtype=np.int64)
            i0 = np.asarray(forest.leaf_i[sel], dtype=np.int64)
            j0 = np.asarray(forest.leaf_j[sel], dtype=np.int64)
            i1, j1 = i0 + size, j0 + size
            out[sel] = (sat[j1, i1] - sat[j0, i1] - sat[j1, i0] + sat[j0, i0]) > 0
        return out

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
                self.corners[s],
                bool(self.is_quad[s]),
                self.normal[s],
                float(self.lattice_area[s]),
                float(self.eps_patch[s]),
                self.coverage(s, SHOOTER_COVERAGE) if self.clipped[s] else None,
            )
        return self._shooters[s]

    # -- kernels --------------------------------------------------------------
    def imap(self, fn: Callable, items: Iterable, check: Callable[[], None]) -> Iterator:
        """``fn(item)`` for each item, in order, up to :attr:`Visibility.threads` at once: a gather
        spends most of its time in kernels and rays that release the GIL, so two of them keep
        both cores busy where one leaves a core idle during its Python. Results do not depend on
        the thread count. ``check()`` is polled while waiting; when it raises, the tasks not
        started are dropped, the running ones finish, and the exception propagates. With one
        item or one thread, or inside a task, it runs in the calling thread (whose kernels and
        rays may then use every thread)."""
        threads = self.vis.threads
        items = list(items)
        in_task = getattr(_IN_TASK, "active", False)
        if threads <= 1 or len(items) <= 1 or in_task:
            for item in items:
                yield fn(item)
                if not in_task:  # (progress is reported from the solve's thread only)
                    check()
            return
        pool, pending, queued = _task_pool(threads), [], items[::-1]
        try:
            while pending or queued:
                while queued and len(pending) < 2 * threads:
                    pending.append(pool.submit(self._task, fn, queued.pop()))
                while not wait(pending[:1], timeout=0.05).done:
                    check()
                yield pending.pop(0).result()
        finally:
            for f in pending:
                f.cancel()
            wait(pending)

    def _task(self, fn: Callable, item):
        """``fn(item)`` on a gather thread: its kernels and rays run on this thread alone (the
        other tasks have the other cores), and it runs any :meth:`imap` of its own in order."""
        _IN_TASK.active = True
        try:
            with one_thread(), self.vis.on_this_thread():
                return fn(item)
        finally:
            _IN_TASK.active = False

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
        if s not in self._cand:
            poly = self.polygon(s)
            # some corner of s strictly in front of the receiver's plane
            h = np.einsum("pkc,pc->pk", poly[None, :, :] - self.centre[:, None, :], self.normal)
            sees = (h > 1e-9 * self.scale).any(axis=1)
            sees[s] = False
            # receiver corners in front of the plane of s
            hr = np.einsum("pkc,c->pk", self.corners - self.centre[s], self.normal[s])
            ahead = hr > 0.1 * self.eps_ff + 1e-9 * self.scale
            any_ahead = (ahead & self._valid_corner).any(axis=1)
            all_ahead = (ahead | ~self._valid_corner).all(axis=1)
            self._cand[s] = (sees & all_ahead, sees & any_ahead & ~all_ahead)
        return self._cand[s]

    def allowed(self, s: int, cull: bool, patches: np.ndarray | None) -> np.ndarray | None:
        """(P,) bool receiver patches allowed for s (``patches``, less the ones earlier gathers
        of s found fully occluded when ``cull``), or None for all."""
        ok = None if patches is None else np.asarray(patches, dtype=bool)
        if cull and s in self._vis_rays:
            hidden = (self._vis_rays[s] >= CULL_RAYS) & (self._vis_seen[s] == 0)
            ok = ~hidden if ok is None else ok & ~hidden
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
        front = (geo.ff[idx_part] - self.centre[s]) @ self.normal[s] > 0.1 * self.eps_ff
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
            entry = None if cache is None else cache.get(s)
            if cache is not None and entry is None:
                entry = cache[s] = [
                    np.zeros(0, dtype=np.int64),
                    np.zeros(0, dtype=np.float32),
                    np.zeros(self.n_patches, dtype=bool),
                ]
        need = ok if entry is None else (~entry[2] if ok is None else ok & ~entry[2])
        if entry is None or need.any():
            idx = self.receivers(s, geo, need)
            f = self._form_factors(s, geo.ff[idx], geo.normal[idx])
            keep = f > 1e-12
            idx, f = idx[keep], f[keep]
            if entry is None:
                return idx, f
            entry[0] = np.concatenate([entry[0], idx])
            entry[1] = np.concatenate([entry[1], f.astype(np.float32)])
            entry[2] |= True if need is None else need
            with self._lock:
                size = cache.get("_size", 0) + len(idx)
                while size > FF_CACHE_ENTRIES and len(cache) > 2:
                    old = next(k for k in cache if k not in ("_size", s))
                    size -= len(cache.pop(old)[0])
                cache["_size"] = size
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
        if self.clipped[s]:  # a panel cell: the sum over its clip triangles
            for tri in self.clip_world[self.clip_start[s] : self.clip_start[s + 1]]:
                f += point_polygon(x, nr, tri)
            return f
        sh = self.shooter(s)
        ka = sh.kernel_args()
        (gu, gv), gw = GAUSS_QUAD if sh.is_quad else GAUSS_TRI
        return patch_form_factors(
            np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(nr, dtype=np.float64),
            np.ascontiguousarray(self.polygon(s)), self.centre[s], FF_FAR * float(self.radius[s]),
            ka["geom"], ka["para"], ka["area"], gu.ravel(), gv.ravel(), gw,
        )  # fmt: skip

    def culled_fraction(self) -> float:
        """Fraction of (shooter, candidate receiver patch) pairs found fully occluded."""
        tot = hid = 0
        for s, rays in self._vis_rays.items():
            full, part = self.candidates(s)
            tot += int((full | part).sum())
            hid += int(((rays >= CULL_RAYS) & (self._vis_seen[s] == 0) & (full | part)).sum())
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
        idx, val = self.gathers(
            s, [(geo, patches)], m, shot, field, field_mean, correlated=correlated, cull=cull
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
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """:meth:`gather` from s to several receiver sets at once: ``parts`` is a list of ``(geo,
        patches)`` on disjoint patches (a shot's mesh vertices and its coarse grids), and their
        blocks of receivers run together on the threads. Per part ``(idx, val)``: the indices into
        ``geo`` of its receivers (k,) (distinct) and their values (k,) or (k, 3), the rows of what one
        :meth:`gather` per part in order returns that can be nonzero (so that a shot costs its
        receivers, not the mesh); each part's culling sees only its own patches."""
        ka = self.shooter(s).kernel_args()
        pat = self.pattern(s, m, shot)
        salt = np.uint64(((int(self.opts.seed) * 1_000_003 + int(s)) * 1_000_003 + int(shot)) & _MASK64)
        has_field = field is not None
        flat = np.zeros((1, 3)) if field is None else field.astype(np.float64).reshape(-1, 3)
        nl = 0 if field is None else field.shape[0] - 1
        mean = np.zeros(3) if field_mean is None else np.ascontiguousarray(field_mean, dtype=np.float64)
        # a field of one sign gives results of that sign
        clamp_lo = has_field and float(flat.min()) >= 0
        clamp_hi = has_field and float(flat.max()) <= 0
        sets = [(geo, *self.form_factors(s, geo, cull, patches)) for geo, patches in parts]

        def block(job: tuple[int, slice]):
            """One block of receivers: (its rows' values, rays and rays seen per receiver patch)."""
            geo, idx, f = sets[job[0]]
            sl = job[1]
            fb = np.ascontiguousarray(f[sl], dtype=np.float64)
            # per row: its rotation (one for all when correlated), point, normal, tangents, whether
            # it takes direction samples too, ray origin, patch
            rot, x, nr, t1, t2, near, o32, rp = block_inputs(
                idx[sl], geo.key, salt, correlated, geo.ff, geo.normal, geo.patch, self.tangent, fb,
                F_DIRECTION, geo.origin32(),
            )  # fmt: skip
            # the samples' weights and rays (float32, as embreex takes them: origins and targets
            # are off the surfaces by at least 32 float32 steps, so the rounding never crosses one)
            off, wsum, w, u, v, o, d, tfar = gather_rays(
                pat, rot, x, nr, t1, t2, near, o32, ka["geom"], ka["uvc"], ka["poly_n"], ka["poly_o"],
                ka["tol"], ka["is_quad"], ka["para"], ka["linear_uv"], ka["area"], ka["mask"],
                ka["has_mask"], ka["t32"], ka["half_eps"], *self._scratch(2 * len(fb) * len(pat)),
            )  # fmt: skip
            if len(w) == 0:
                return None
            vis = self.vis.visible(o, d, tfar)
            val, seen = gather_finish(
                off, w, vis, u, v, fb, wsum, has_field, flat, nl, x, ka["geom"], ka["uvc"],
                ka["linear_uv"], ka["is_quad"], ka["para"], mean, clamp_lo, clamp_hi,
            )  # fmt: skip
            rays = np.bincount(rp, weights=np.diff(off), minlength=self.n_patches)
            return (
                val if has_field else val[:, 0],
                rays,
                np.bincount(rp, weights=seen, minlength=self.n_patches),
            )

        # blocks of at most GATHER_BLOCK receivers; a large set in as many as there are threads
        jobs = []
        for k, (_, idx, _) in enumerate(sets):
            size = GATHER_BLOCK
            if len(idx) >= SPLIT_RECEIVERS:
                size = min(size, -(-len(idx) // self.vis.threads))
            jobs += [(k, slice(a, a + size)) for a in range(0, len(idx), size)]
        outs = [np.zeros(len(idx) if field is None else (len(idx), 3)) for _, idx, _ in sets]
        rays_p = [np.zeros(self.n_patches) for _ in sets]
        seen_p = [np.zeros(self.n_patches) for _ in sets]
        for (k, sl), res in zip(jobs, self.imap(block, jobs, _no_check), strict=True):
            if res is not None:
                outs[k][sl] = res[0]
                rays_p[k] += res[1]
                seen_p[k] += res[2]
        with self._lock:
            for k, (_, idx, _) in enumerate(sets):
                if len(idx) == 0:
                    continue
                if s in self._vis_rays:
                    self._vis_rays[s] += rays_p[k]
                    self._vis_seen[s] += seen_p[k]
                else:
                    self._vis_rays[s], self._vis_seen[s] = rays_p[k], seen_p[k]
        return [(idx, out) for (_, idx, _), out in zip(sets, outs, strict=True)]

    def light_kernel(self, light, geo: ReceiverGeometry) -> tuple[np.ndarray, np.ndarray]:
        """(n,) ``cos * att * vis / r^2`` at the vertices of ``geo`` for a point or spot light (the
        irradiance per unit intensity, with visibility), and (n,) ``max(cos, 0) / r^2`` (no cone, no
        visibility): what :func:`.pointlight.lumped_light` weighs an element's solid angle with."""
        d = light.position[None, :] - geo.pos
        r = np.linalg.norm(d, axis=1)
        u = d / np.maximum(r, 1e-300)[:, None]
        cos = np.einsum("nc,nc->n", u, geo.normal)
        att = np.ones(len(r))
        if light.kind == "spot":
            di = light.direction / max(np.linalg.norm(light.direction), 1e-300)
            cd = -(u @ di)
            co, ci = math.cos(light.outer_cone), math.cos(light.inner_cone)
            scale = 1.0 / max(1e-3, ci - co)
            att = np.clip((cd - co) * scale, 0.0, 1.0) ** 2
        near = r > 1e-12 * self.scale
        free = np.where((cos > 0) & near, cos / np.maximum(r * r, 1e-300), 0.0)
        ok = np.flatnonzero((cos > 0) & (att > 0) & near)
        k = np.zeros(len(r))
        if len(ok) == 0:
            return k, free
        do = light.position[None, :] - geo.origin[ok]
        ro = np.linalg.norm(do, axis=1)
        vis = self.vis.visible(
            geo.origin[ok], do / ro[:, None], np.maximum(ro - 0.5 * self.eps_patch[geo.patch[ok]], 0.0)
        )
        k[ok] = cos[ok] * att[ok] / (r[ok] * r[ok]) * vis
        return k, free

    def light_irradiance(self, light, geo: ReceiverGeometry) -> np.ndarray:
        """(n, 3) irradiance from a point or spot light, with visibility (exact at each vertex)."""
        return self.light_kernel(light, geo)[0][:, None] * light.radiant_intensity[None, :]

    def light_correction(
        self, forest: qt.Forest, keys: np.ndarray, geo: ReceiverGeometry, lights=None, signs=None
    ) -> np.ndarray:
        """(V, 3) what to add to the reflected direct radiance of the vertices ``keys`` of
        ``forest`` to get the radiance their patches must *shoot* for the point / spot lights
        (``lights``, default all, each times its sign in ``signs``): ``rho / pi`` times the
        element-integrated irradiance (:func:`.pointlight.lumped_light`: each element receives
        ``I x`` its solid angle from the light x its visible fraction, finite even when the light
        touches it) minus the exact vertex irradiance (whose 1/d^2 peak next to a light, spread
        over whole elements, would re-emit far more power than the wall received: defect D3)."""
        lights = self.lights if lights is None else lights
        signs = [1.0] * len(lights) if signs is None else signs
        out = np.zeros((len(keys), 3))
        if not lights or forest.n_leaves == 0:
            return out
        corner_idx = qt.lookup(keys, qt.leaf_corner_keys(forest))
        leaf_world = qt.lattice_to_world(
            self.corners,
            forest.patch_is_quad,
            np.repeat(forest.leaf_patch, 4),
            *(c.ravel() for c in np.moveaxis(qt.leaf_corner_lattice(forest), 2, 0)),
            forest.n,
        ).reshape(-1, 4, 3)
        la = qt.leaf_area(forest, self.corners)
        for light, sign in zip(lights, signs, strict=True):
            k, free = self.light_kernel(light, geo)
            lumped = lumped_light(
                light.position,
                leaf_world,
                self.normal[forest.leaf_patch],
                forest.leaf_is_quad,
                corner_idx,
                la,
                k,
                free,
                len(keys),
            )
            out += sign * (lumped - k)[:, None] * light.radiant_intensity[None, :]
        return self.albedo[geo.patch] * out / np.pi

    def emitter_side(self, share: float) -> int:
        """Samples per side of the direct pass's gathers from an emitter with ``share`` of the emitted
        power: ``DIRECT_SAMPLE_FACTOR`` x the per-side samples times ``sqrt(share)`` (samples by
        power, as the shots'), at least the per-side samples."""
        side = pattern_side(self.opts.samples)
        return max(side, round(DIRECT_SAMPLE_FACTOR * side * math.sqrt(share)))

    def emitter_gather(self, e: int, geo: ReceiverGeometry, side: int) -> np.ndarray:
        """(n,) ``F * vis`` from emissive patch e, as the direct pass computes it (per-vertex
        rotated patterns, shot 0), ``side`` samples per side (:meth:`emitter_side`)."""
        return self.gather(int(e), geo, side)

    def direct(
        self, keys: np.ndarray, check: Callable[[], None], geo: ReceiverGeometry | None = None
    ) -> np.ndarray:
        """(n, 3) reflected direct radiance (emission excluded) at vertex keys."""
        out = np.zeros((len(keys), 3))
        if len(keys) == 0:
            return out
        geo = self.geometry(keys) if geo is None else geo
        incoming = np.zeros((len(keys), 3))  # radiance-weighted: rho * incoming = reflected
        for e in self.emitters:
            side = self.emitter_side(self.emitter_share[e])
            incoming += self.emitter_gather(e, geo, side)[:, None] * self.emission[e]
            check()
        for light in self.lights:
            incoming += self.light_irradiance(light, geo) / np.pi
            check()
        for sun in self.suns:
            incoming += self.sun_irradiance(sun, geo, check) / np.pi
        if self.sky is not None:
            incoming += self.sky_irradiance(geo, check) / np.pi
        return self.albedo[geo.patch] * incoming

    def _escape(self, geo: ReceiverGeometry, idx: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(k, S) float: what of the rays from vertices ``idx`` (k,) along ``dirs`` (k, S, 3) leaves
        the scene (1 free, 0 blocked, a glass's transmittance through it)."""
        k, S = dirs.shape[:2]
        o = np.repeat(geo.origin32()[idx], S, axis=0)
        free = self.vis.visible(o, dirs.reshape(-1, 3), np.full(k * S, 4.0 * self.scale, dtype=np.float32))
        return free.reshape(k, S)

    def sun_irradiance(self, sun, geo: ReceiverGeometry, check: Callable[[], None]) -> np.ndarray:
        """(n, 3) irradiance from a directional light (the sun): ``E cos`` times the fraction of
        its disc (``angular_diameter``) each vertex sees, from ``SUN_SAMPLES`` directions
        stratified on the disc and rotated per vertex (soft shadow edges, exact where it is
        fully seen or hidden)."""
        to_sun = -np.asarray(sun.direction, dtype=np.float64)
        to_sun /= max(float(np.linalg.norm(to_sun)), 1e-300)
        out = np.zeros((len(geo.key), 3))
        cos = geo.normal @ to_sun
        lit = np.flatnonzero(cos > 0)
        if len(lit) == 0:
            return out
        helper = np.array([1.0, 0.0, 0.0]) if abs(to_sun[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t1 = np.cross(to_sun, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(to_sun, t1)
        m = pattern_side(SUN_SAMPLES)
        pat = self.pattern(self.n_patches, m, 1)
        half = math.tan(0.5 * max(float(sun.angular_diameter), 0.0))

        def block(idx: np.ndarray) -> np.ndarray:  # the fraction of the disc each vertex sees
            rot = hash_uniform(geo.key[idx], int(self.opts.seed) * 7919 + 17, 2)
            dx, dy = rotated_disk(pat, rot[:, :1], rot[:, 1:2])
            d = to_sun + half * (dx[..., None] * t1 + dy[..., None] * t2)
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            return self._escape(geo, idx, d).mean(axis=1)

        blocks = [lit[a : a + GATHER_BLOCK // 4] for a in range(0, len(lit), GATHER_BLOCK // 4)]
        for idx, frac in zip(blocks, self.imap(block, blocks, check), strict=True):
            out[idx] = (cos[idx] * frac)[:, None] * sun.radiant_intensity[None, :]
        return out

    def sky_irradiance(self, geo: ReceiverGeometry, check: Callable[[], None]) -> np.ndarray:
        """(n, 3) irradiance from the sky through whatever of each vertex's hemisphere is open:
        ``pi`` times the mean sky radiance over ``SKY_SAMPLES`` cosine-distributed directions
        (stratified, rotated per vertex) that leave the scene."""
        out = np.zeros((len(geo.key), 3))
        m = pattern_side(SKY_SAMPLES)
        pat = self.pattern(self.n_patches, m, 2)
        size = max(1, GATHER_BLOCK * 16 // (m * m))

        def block(idx: np.ndarray) -> np.ndarray:  # the irradiance at these vertices
            rot = hash_uniform(geo.key[idx], int(self.opts.seed) * 7919 + 29, 2)
            dx, dy = rotated_disk(pat, rot[:, :1], rot[:, 1:2])
            t1, t2 = self.tangent[geo.patch[idx], 0], self.tangent[geo.patch[idx], 1]
            w = disk_to_hemisphere(dx, dy, t1, t2, geo.normal[idx])
            free = self._escape(geo, idx, w)
            L = sky_radiance(self.sky, w.reshape(-1, 3)).reshape(len(idx), m * m, 3)
            return np.pi * np.einsum("ks,ksc->kc", free, L) / (m * m)

        blocks = [np.arange(a, min(a + size, len(geo.key))) for a in range(0, len(geo.key), size)]
        for idx, e in zip(blocks, self.imap(block, blocks, check), strict=True):
            out[idx] = e
        return out

    def max_mean_reflected(self) -> float:
        """Upper bound of the scene's area-mean reflected luminance radiance: all the emitted power
        received and reflected with the largest albedo, over the scene's area (inf for no area)."""
        a = float(self.area.sum())
        if a <= 0 or not len(self.albedo):
            return math.inf
        return float(luminance_of(self.albedo).max()) * self.emitted_power() / (np.pi * a)

    def emitted_power(self) -> float:
        """Luminance power emitted by emissive patches and lights (W, luminance-weighted); for the
        sun and the sky, what would reach the surfaces if nothing shadowed them (an upper bound)."""
        p = float(np.pi * (self.emission @ LUMINANCE_WEIGHTS * self.area).sum())
        for lt in self.lights:
            p += light_power(lt)
        for sun in self.suns:
            cos = np.maximum(self.normal @ -np.asarray(sun.direction, dtype=np.float64), 0.0)
            p += abs(float(sun.radiant_intensity @ LUMINANCE_WEIGHTS)) * float((cos * self.area).sum())
        if self.sky is not None:  # the brightest of 1024 directions over the whole area
            k = np.arange(1024) + 0.5
            z = 1.0 - 2.0 * k / 1024
            phi = np.pi * (1.0 + 5.0**0.5) * k
            r = np.sqrt(1.0 - z * z)
            dirs = np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1)
            peak = float((sky_radiance(self.sky, dirs) @ LUMINANCE_WEIGHTS).max())
            p += np.pi * max(peak, 0.0) * float(self.area.sum())
        return p


def light_power(lt) -> float:
    """Luminance power of a light (by magnitude: a difference of two lights may be negative)."""
    solid = 4 * np.pi if lt.kind == "point" else 2 * np.pi * (1 - math.cos(lt.outer_cone))
    return abs(float(lt.radiant_intensity @ LUMINANCE_WEIGHTS)) * solid


def solver_albedo(scene) -> np.ndarray:
    """(P, 3) the albedo the solver uses: the scene's, clamped to [0, 1] (albedo 1 is kept: an
    albedo-1 closed room never converges, and the solve stops at ``max_shots`` saying how much
    light is left unshot; > 1 would create energy at every bounce); 0 on glass (transmissive
    patches pass light on and neither reflect nor store it)."""
    alb = np.clip(scene.patch_albedo, 0.0, 1.0)
    return np.where(scene.patch_transmission[:, None] > 0, 0.0, alb)  # glass passes light, keeps none
