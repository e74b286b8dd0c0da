"""Gathers that trace their own rays (issue 41): a shot's sample set-up, Embree traversal and sum in
one ``nogil`` numba call, the rays never materialised as arrays; and the sun's directions of a block
of vertices made and traced in one call (:func:`sun_escape`; the sky's: :mod:`.sky_traced`).

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


# -- the sun's rays ------------------------------------------------------------------------------
@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def sun_rays(occ, isect, scene, glass, glass_tau, pat, rot, to_sun, half, t1, t2, origin32, tfar, free):
    """What of each of S directions to the sun's disc gets out, from b vertices: pattern pat (S, 2)
    rotated by rot (b, 2) per vertex and mapped to the disc, ``to_sun + half (dx t1 + dy t2)``
    normalised (to_sun, t1, t2 (3,): the disc's frame; the arithmetic of
    ``DirectLight.sun_irradiance``), traced from origin32 (b, 3) float32 as far as tfar into
    ``free`` (b, S). Returns the rays traced against the glass besides. The workers take vertices
    from the shared counter as :func:`.embree.take_tasks` does."""
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
                wx, wy, wz = _sun_direction(dx, dy, to_sun, half, t1, t2)
                set_lane(pk, n, ox, oy, oz, wx, wy, wz, tfar)
                lanes[n] = j
                n += 1
                if n == PACKET:
                    through[i] += flush_packet(occ, isect, scene, glass, glass_tau, pk, n, lanes, free[i])
                    n = 0
            if n:
                through[i] += flush_packet(occ, isect, scene, glass, glass_tau, pk, n, lanes, free[i])
            i = fetch_add(nxt, 0, 1)
    return through.sum()


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _sun_direction(dx, dy, to_sun, half, t1, t2):
    """A direction of :func:`sun_rays` (float32) from its disc point dx, dy."""
    d0 = to_sun[0] + half * (dx * t1[0] + dy * t2[0])
    d1 = to_sun[1] + half * (dx * t1[1] + dy * t2[1])
    d2 = to_sun[2] + half * (dx * t1[2] + dy * t2[2])
    n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)  # np.linalg.norm's sum, in its order
    return np.float32(d0 / n), np.float32(d1 / n), np.float32(d2 / n)


@njit(cache=True, nogil=True, inline="always")
def flush_packet(occ, isect, scene, glass, glass_tau, pk, n, lanes, free):
    """Trace the packet pk's n lanes (:func:`.embree.visible8`) and put what of each gets through at
    ``free[lanes[lane]]``; returns the rays traced against the glass."""
    through = visible8(occ, isect, scene, glass, glass_tau, pk, n)
    for lane in range(n):
        free[lanes[lane]] = pk[3][lane]
    return through


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
