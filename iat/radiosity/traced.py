"""Gathers that trace their own rays (issue 41): a shot's sample set-up, Embree traversal and sum in
one ``nogil`` numba call, the rays never materialised as arrays; and the sun's and the sky's
directions of a block of vertices made and traced in one call (:func:`sky_escape`,
:func:`sun_escape`).

:func:`gather_traced` is :func:`~iat.radiosity.kernels.block_inputs`, then
:func:`~iat.radiosity.kernels.gather_rays`, :meth:`~iat.radiosity.visibility.Visibility.visible` and
:func:`~iat.radiosity.kernels.gather_finish` row by row: the same samples (:func:`.row_weights`), the
same float32 rays (:func:`.kernels.sample_ray`), traced by the same Embree calls
(:func:`.embree.visible8`), summed in the same order (:func:`.kernels.field_terms`,
:func:`.kernels.finish_row`), so its rows are those of the three-step path to the bit
(``tests/test_embree_c.py``). Rows are spread over the calling thread's numba threads in tasks of
``ROWS`` (``prange``); each row is one task's, in a fixed order, so the thread count changes nothing.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit, prange

from iat.radiosity.embree import PACKET, fetch_add, packet_record, set_lane, take_tasks, visible8, workers
from iat.radiosity.kernels import (
    concentric_unit,
    field_terms,
    finish_row,
    row_inputs,
    row_weights,
    sample_ray,
    wrap_unit,
)

#: receivers per parallel task (one set of scratch arrays each)
ROWS = 32
#: (vertex, direction) pairs per parallel task of :func:`sky_pair_rays`
PAIRS = 256


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def gather_traced(occ, isect, scene, glass, glass_tau,
                  ii, key, salt, correlated, ff, normal, patch, tangent, f, f_direction, origin32,
                  pat, geom, uvc, poly_n, poly_o, tol, is_quad, para, linear_uv, area, mask, has_mask, imp,
                  t32, half_eps, has_field, flat, nl, field_mean, clamp_lo, clamp_hi):  # fmt: skip
    """What the receivers ``ii`` (b,) of a receiver set gather from one shooter, their rays traced here.

    occ, isect, scene, glass, glass_tau : :meth:`Visibility.embree_args`; ii ... origin32 as
    :func:`.kernels.block_inputs` takes them (f (b,): the rows' form factors); pat ... half_eps the
    pattern and the shooter as :func:`.kernels.gather_rays`; has_field ... clamp_hi the field as
    :func:`.kernels.gather_finish`. Returns ``out`` (b, 3) (gather_finish's), ``seen`` (b,) what of
    each row's rays got through (summed), ``rays`` (b,) int64 each row's rays, and how many rays were
    traced against the glass besides.
    """
    b, S = ii.shape[0], pat.shape[0]
    n_s = float(S)
    out = np.zeros((b, 3))
    seen = np.zeros(b)
    rays = np.zeros(b, dtype=np.int64)
    tasks = (b + ROWS - 1) // ROWS
    through = np.zeros(tasks, dtype=np.int64)
    nw, nxt = workers()
    for _ in prange(nw):
        take_tasks(nxt, tasks, _gather_task, _gather_scratch, (S,),
                   (b, S, n_s, occ, isect, scene, glass, glass_tau, ii, key, salt, correlated, ff, normal,
                    patch, tangent, f, f_direction, origin32, pat, geom, uvc, poly_n, poly_o, tol, is_quad,
                    para, linear_uv, area, mask, has_mask, imp, t32, half_eps, has_field, flat, nl,
                    field_mean, clamp_lo, clamp_hi, out, seen, rays, through))  # fmt: skip
    return out, seen, rays, through.sum()


@njit(cache=True, nogil=True)
def _gather_scratch(S):
    """A worker's scratch of :func:`_gather_task` for a pattern of S samples."""
    rot, x, nr = np.empty((ROWS, 4)), np.empty((ROWS, 3)), np.empty((ROWS, 3))
    t1, t2 = np.empty((ROWS, 3)), np.empty((ROWS, 3))
    o32 = np.empty((ROWS, 3), dtype=np.float32)
    sw, su, sv = np.empty(2 * S), np.empty(2 * S), np.empty(2 * S)
    return rot, x, nr, t1, t2, o32, sw, su, sv, packet_record()


@njit(cache=True, nogil=True, error_model="numpy")
def _gather_task(task, scratch, b, S, n_s, occ, isect, scene, glass, glass_tau, ii, key, salt, correlated,
                 ff, normal, patch, tangent, f, f_direction, origin32, pat, geom, uvc, poly_n, poly_o, tol,
                 is_quad, para, linear_uv, area, mask, has_mask, imp, t32, half_eps, has_field, flat, nl,
                 field_mean, clamp_lo, clamp_hi, out, seen, rays, through):  # fmt: skip
    """Rows ``task * ROWS ...`` of :func:`gather_traced` (scratch: :func:`_gather_scratch`'s; the
    rest: its arguments and outputs)."""
    rot, x, nr, t1, t2, o32, sw, su, sv, pk = scratch
    lane_vis = pk[3]
    lo = task * ROWS
    m = min(b, lo + ROWS) - lo
    for j in range(m):  # block_inputs' rows
        r = ii[lo + j]
        k = 0 if correlated else key[r]
        row_inputs(j, r, patch[r], k, salt, ff, normal, tangent, origin32, rot, x, nr, t1, t2, o32)
    for j in range(m):
        i = lo + j
        cnt, wsum = row_weights(j, pat, rot, x, nr, t1, t2, f[i] >= f_direction, n_s, geom, uvc, poly_n,
                                 poly_o, tol, is_quad, para, linear_uv, area, mask, has_mask, imp, sw, su,
                                 sv, 0)  # fmt: skip
        ox, oy, oz = o32[j, 0], o32[j, 1], o32[j, 2]
        wvis = 0.0
        sv_sum = 0.0
        res0 = res1 = res2 = 0.0
        for q0 in range(0, cnt, PACKET):  # a packet of neighbouring samples, then their sums in order
            n = min(PACKET, cnt - q0)
            for lane in range(n):
                dx, dy, dz, tfar = sample_ray(su[q0 + lane], sv[q0 + lane], t32, para, o32[j], half_eps)
                set_lane(pk, lane, ox, oy, oz, dx, dy, dz, tfar)
            through[task] += visible8(occ, isect, scene, glass, glass_tau, pk, n)
            for lane in range(n):
                q, vis = q0 + lane, lane_vis[lane]
                wr = sw[q] * vis  # as gather_finish sums them
                wvis += wr
                sv_sum += vis
                if has_field:
                    v0, v1, v2 = field_terms(flat, nl, su[q], sv[q], wr)
                    res0 += v0
                    res1 += v1
                    res2 += v2
        rays[i] = cnt
        seen[i] = sv_sum
        finish_row(out, i, f[i], wsum, wvis, res0, res1, res2, x[j], has_field, flat, nl, geom, uvc,
                   linear_uv, is_quad, para, field_mean, clamp_lo, clamp_hi)  # fmt: skip


# -- the sun's and the sky's rays ----------------------------------------------------------------
@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def sky_rays(occ, isect, scene, glass, glass_tau, pat, rot, t1, t2, normal, origin32, tfar, min_y, w, free):
    """The sky's directions of b vertices and what of each gets out: pattern pat (S, 2) rotated by
    rot (b, 2) per vertex, mapped to the disc and lifted to the hemisphere of the frame t1, t2,
    normal (b, 3) (``sampling.rotated_disk`` then ``sampling.disk_to_hemisphere``, the same
    arithmetic) into ``w`` (b, S, 3) float64; traced from origin32 (b, 3) float32 as far as tfar
    (float32) into ``free`` (b, S) (:func:`.embree.visible8`); a direction whose y is below min_y
    (float32: 0 for a sky whose ground is black) is not traced and gets 0. Returns the rays traced
    against the glass besides."""
    return _escape(_sky_direction, (t1, t2, normal, w), occ, isect, scene, glass, glass_tau, pat, rot,
                   origin32, tfar, min_y, free)  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy")
def _sky_direction(i, j, dx, dy, t1, t2, normal, w):
    """Direction j of vertex i of :func:`sky_rays` (float32) from its disc point dx, dy, kept in w."""
    return _lift(dx, dy, t1, t2, normal, i, w[i, j])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _lift(dx, dy, t1, t2, normal, i, out):
    """Disc point dx, dy lifted to the hemisphere of vertex i's frame t1, t2, normal (b, 3): into
    ``out`` (3,) float64 (``sampling.disk_to_hemisphere``'s arithmetic), and returned as float32."""
    dz = math.sqrt(max(1.0 - dx * dx - dy * dy, 0.0))
    for c in range(3):
        out[c] = dx * t1[i, c] + dy * t2[i, c] + dz * normal[i, c]
    return np.float32(out[0]), np.float32(out[1]), np.float32(out[2])


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def sun_rays(occ, isect, scene, glass, glass_tau, pat, rot, to_sun, half, t1, t2, origin32, tfar, free):
    """What of each of S directions to the sun's disc gets out, from b vertices: pattern pat (S, 2)
    rotated by rot (b, 2) per vertex and mapped to the disc, ``to_sun + half (dx t1 + dy t2)``
    normalised (to_sun, t1, t2 (3,): the disc's frame; the arithmetic of
    ``DirectLight.sun_irradiance``), traced from origin32 (b, 3) float32 as far as tfar into
    ``free`` (b, S). Returns the rays traced against the glass besides."""
    return _escape(_sun_direction, (to_sun, half, t1, t2), occ, isect, scene, glass, glass_tau, pat, rot,
                   origin32, tfar, np.float32(-np.inf), free)  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy")
def _sun_direction(i, j, dx, dy, to_sun, half, t1, t2):
    """Direction j of vertex i of :func:`sun_rays` (float32) from its disc point dx, dy."""
    d0 = to_sun[0] + half * (dx * t1[0] + dy * t2[0])
    d1 = to_sun[1] + half * (dx * t1[1] + dy * t2[1])
    d2 = to_sun[2] + half * (dx * t1[2] + dy * t2[2])
    n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)  # np.linalg.norm's sum, in its order
    return np.float32(d0 / n), np.float32(d1 / n), np.float32(d2 / n)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _escape(direction, dir_args, occ, isect, scene, glass, glass_tau, pat, rot, origin32, tfar, min_y, free):
    """:func:`sky_rays` and :func:`sun_rays`: direction j of vertex i is ``direction(i, j, dx, dy,
    *dir_args)`` (float32) from the rotated pattern's disc point dx, dy, traced if its y is at least
    min_y (else 0). The workers take vertices
    from the shared counter as :func:`.embree.take_tasks` does, but run the row here: inlined into
    the kernel, direction stays a global function (passed on to a task as a value, it would keep
    the kernel from numba's cache), and the ``prange`` is the kernel's."""
    b = rot.shape[0]
    through = np.zeros(b, dtype=np.int64)
    nw, nxt = workers()
    for _ in prange(nw):
        i = fetch_add(nxt, 0, 1)
        if i < b:
            pk, lanes = packet_record(), np.empty(PACKET, dtype=np.int64)
        while i < b:
            ox, oy, oz = origin32[i, 0], origin32[i, 1], origin32[i, 2]
            n = 0
            for j in range(pat.shape[0]):
                dx, dy = concentric_unit(wrap_unit(pat[j, 0], rot[i, 0]), wrap_unit(pat[j, 1], rot[i, 1]))
                wx, wy, wz = direction(i, j, dx, dy, *dir_args)
                if wy < min_y:
                    free[i, j] = 0.0
                    continue
                set_lane(pk, n, ox, oy, oz, wx, wy, wz, tfar)
                lanes[n] = j
                n += 1
                if n == PACKET:
                    through[i] += _flush(occ, isect, scene, glass, glass_tau, pk, n, lanes, free[i])
                    n = 0
            if n:
                through[i] += _flush(occ, isect, scene, glass, glass_tau, pk, n, lanes, free[i])
            i = fetch_add(nxt, 0, 1)
    return through.sum()


@njit(cache=True, nogil=True, inline="always")
def _flush(occ, isect, scene, glass, glass_tau, pk, n, lanes, free):
    """Trace the packet pk's n lanes (:func:`.embree.visible8`) and put what of each gets through at
    ``free[lanes[lane]]``; returns the rays traced against the glass."""
    through = visible8(occ, isect, scene, glass, glass_tau, pk, n)
    for lane in range(n):
        free[lanes[lane]] = pk[3][lane]
    return through


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def sky_pair_rays(occ, isect, scene, glass, glass_tau, pat, rot, t1, t2, normal, origin32, tfar, min_y,
                  vi, pj, w, free):  # fmt: skip
    """:func:`sky_rays` for m (vertex, direction) pairs: direction ``pj[m]`` of pattern pat (S, 2)
    at vertex ``vi[m]`` of rot, t1, t2, normal, origin32 (b, ...), into ``w`` (m, 3) and ``free``
    (m,), by the same arithmetic, in tasks of ``PAIRS``. Returns the rays traced against the glass
    besides."""
    tasks = (vi.shape[0] + PAIRS - 1) // PAIRS
    through = np.zeros(tasks, dtype=np.int64)
    nw, nxt = workers()
    for _ in prange(nw):
        take_tasks(nxt, tasks, _pair_task, _pair_scratch, (),
                   (occ, isect, scene, glass, glass_tau, pat, rot, t1, t2, normal, origin32, tfar, min_y,
                    vi, pj, w, free, through))  # fmt: skip
    return through.sum()


@njit(cache=True, nogil=True, error_model="numpy")
def _pair_task(t, scratch, occ, isect, scene, glass, glass_tau, pat, rot, t1, t2, normal, origin32, tfar,
               min_y, vi, pj, w, free, through):  # fmt: skip
    """Task t of :func:`sky_pair_rays`: its pairs ``t * PAIRS ...``, in packets."""
    pk, lanes = scratch
    n = 0
    end = min((t + 1) * PAIRS, vi.shape[0])
    for m in range(t * PAIRS, end):
        i, j = vi[m], pj[m]
        dx, dy = concentric_unit(wrap_unit(pat[j, 0], rot[i, 0]), wrap_unit(pat[j, 1], rot[i, 1]))
        wx, wy, wz = _lift(dx, dy, t1, t2, normal, i, w[m])
        if wy < min_y:
            free[m] = 0.0
        else:
            set_lane(pk, n, origin32[i, 0], origin32[i, 1], origin32[i, 2], wx, wy, wz, tfar)
            lanes[n] = m
            n += 1
        if n == PACKET or (n and m == end - 1):
            through[t] += _flush(occ, isect, scene, glass, glass_tau, pk, n, lanes, free)
            n = 0


@njit(cache=True, nogil=True)
def _pair_scratch():
    """A worker's scratch of :func:`_pair_task`: a packet and its lanes' pairs."""
    return packet_record(), np.empty(PACKET, dtype=np.int64)


def sky_pair_escape(vis, pat, rot, t1, t2, normal, origin32, tfar: float, dark_ground: bool, vi, pj):
    """With the C API, :func:`sky_pair_rays` of the pairs ``vi, pj`` (m,) on the ray threads, counted
    in ``vis``: ``(w (m, 3), free (m,))``; None with embreex."""
    args = vis.embree_args()
    if args is None:
        return None
    m = len(vi)
    w, free = np.empty((m, 3)), np.empty(m)
    t0 = time.perf_counter()
    min_y = np.float32(0.0 if dark_ground else -np.inf)
    with vis.kernel_threads():
        through = sky_pair_rays(*args, pat, rot, _c(t1), _c(t2), _c(normal), np.ascontiguousarray(origin32),
                                np.float32(tfar), min_y, np.ascontiguousarray(vi, dtype=np.int64),
                                np.ascontiguousarray(pj, dtype=np.int64), w, free)  # fmt: skip
    traced = int(np.count_nonzero(w[:, 1] >= 0)) if dark_ground else m
    vis.count(traced + int(through), time.perf_counter() - t0)
    return w, free


def sky_escape(vis, pat, rot, t1, t2, normal, origin32, tfar: float, dark_ground: bool = False):
    """With the C API (:meth:`Visibility.embree_args`), :func:`sky_rays` of a block of k vertices on
    the ray threads, counted in ``vis``: ``(w (k, S, 3), free (k, S))``; None with embreex. With
    ``dark_ground`` the directions below the horizon are not traced (``free`` 0: they bring nothing)."""
    args = vis.embree_args()
    if args is None:
        return None
    k, S = len(rot), len(pat)
    w, free = np.empty((k, S, 3)), np.empty((k, S))
    t0 = time.perf_counter()
    min_y = np.float32(0.0 if dark_ground else -np.inf)
    with vis.kernel_threads():
        through = sky_rays(*args, pat, rot, _c(t1), _c(t2), _c(normal), np.ascontiguousarray(origin32),
                           np.float32(tfar), min_y, w, free)  # fmt: skip
    traced = k * S - int(np.count_nonzero(w[..., 1] < 0)) if dark_ground else k * S
    vis.count(traced + int(through), time.perf_counter() - t0)
    return w, free


def sun_escape(vis, pat, rot, to_sun, half: float, t1, t2, origin32, tfar: float):
    """With the C API, :func:`sun_rays` of a block of k vertices on the ray threads, counted in
    ``vis``: ``free`` (k, S); None with embreex."""
    args = vis.embree_args()
    if args is None:
        return None
    k, S = len(rot), len(pat)
    free = np.empty((k, S))
    t0 = time.perf_counter()
    with vis.kernel_threads():
        through = sun_rays(*args, pat, rot, _c(to_sun), float(half), _c(t1), _c(t2),
                           np.ascontiguousarray(origin32), np.float32(tfar), free)  # fmt: skip
    vis.count(k * S + int(through), time.perf_counter() - t0)
    return free


def _c(a):
    return np.ascontiguousarray(a, dtype=np.float64)
