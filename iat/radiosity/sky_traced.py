"""The sky's whole estimate at a block of vertices in one kernel (issue 41).

:meth:`.direct.DirectLight.sky_irradiance` estimates a vertex's sky from its rotated stratified
directions, and a noisy vertex again with the grid twice as fine, tracing its new directions only
where the light can change (:mod:`.sky_passes`). :func:`sky_vertices` does all of it for one vertex
at a time: make and trace the directions (packets of 8, :func:`.embree.visible8`), look the sky up
(:func:`.sky.seen_light`), sum, test the noise, settle the strata and trace the new directions.
No (k, S, 3) array of directions, light or free fractions is made; a worker's scratch holds one
vertex's grids.

Its arithmetic is numpy's path's (``DirectLight``'s, kept for embreex): the same directions
(:func:`sky_direction`, which that path calls too: :func:`sky_directions`), the same light, the
sums added in the same order (``einsum`` and ``bincount`` add in index order), so the two give the
same bits (``tests/test_embree_c.py``); the noise test's luminances are summed here in a loop and
by numpy with a matrix product, which may differ in the last bit, and decide only whether a vertex
is estimated again.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit, prange

from iat.radiosity.embree import PACKET, packet_record, set_lane, take_tasks, workers
from iat.radiosity.kernels import wrap_unit
from iat.radiosity.sampling import LUMINANCE_WEIGHTS
from iat.radiosity.sky import seen_light
from iat.radiosity.sky_passes import SkyLevel
from iat.radiosity.traced import flush_packet

#: what a later estimate (4 x the directions, one a stratum) leaves of the standard error of the one
#: before: a stratified estimate of light cut by edges (a window's outline) errs as N^(-3/4), not
#: N^(-1/2). The window-lit room's back wall, 8 seeds: the seeds' spread fell 2.8x (0.030 -> 0.011), and
#: the quarters' error, times this, is 1.2x that spread at either estimate (tests/test_sky.py)
REFINED_ERROR = 2.0**-1.5


def pack_levels(levels: list[SkyLevel]) -> tuple[np.ndarray, ...]:
    """The later estimates' levels (:func:`.sky_passes.sky_levels`) end to end, as
    :func:`sky_vertices` takes them: ``points`` (P, 2), ``parent``, ``cell`` (P,) and ``old_cell``
    (P / 3,) int64; level e's rows follow those of the levels before it."""
    fields = ("points", "parent", "cell", "old_cell")
    cat = [np.concatenate([getattr(lv, f) for lv in levels]) if levels else np.zeros(0) for f in fields]
    points = np.ascontiguousarray(cat[0], dtype=np.float64).reshape(-1, 2)
    return points, *(np.ascontiguousarray(c, dtype=np.int64) for c in cat[1:])


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def sky_vertices(occ, isect, scene, glass, glass_tau, pat, side, points, parent, cell, old_cell,
                 rot, t1, t2, normal, origin32, tfar, min_y, kind, table, up, ground,
                 other, noise, radius, passes, out, counts, err):  # fmt: skip
    """The sky's irradiance at b vertices, every estimate, their rays traced here.

    occ ... glass_tau : :meth:`Visibility.embree_args`. pat (side², 2): the first estimate's pattern,
    row-major on a side x side grid; points ... old_cell: the later estimates' (:func:`pack_levels`).
    rot (b, 2), t1, t2, normal (b, 3): each vertex's rotation and frame; origin32 (b, 3) float32,
    tfar float32; a direction whose y is below min_y (float32) is not traced and brings 0. kind,
    table, up, ground: the sky (:meth:`.sky.SkyTable.kernel_args`). other (b,): the luminance
    irradiance of each vertex's other sources (W/m²); noise, radius, passes: ``SKY_NOISE``,
    ``SKY_SETTLED``, ``SKY_PASSES``. Writes ``out`` (b, 3) W/m², ``counts`` (b, passes, 3) int64:
    per estimate whether the vertex had it, the rays traced and the directions that took their
    stratum's value, and ``err`` (b,): the standard error of the last estimate's luminance (W/m²;
    :func:`_std_error` of the last grid tested, times ``REFINED_ERROR`` for each estimate after
    it). Returns the rays traced against the glass besides."""
    b = rot.shape[0]
    grid = pat.shape[0] << (2 * (passes - 1))  # the finest grid's strata
    through = np.zeros(b, dtype=np.int64)
    nw, nxt = workers()
    for _ in prange(nw):
        take_tasks(nxt, b, _vertex, _vertex_scratch, (grid,),
                   (occ, isect, scene, glass, glass_tau, pat, side, points, parent, cell, old_cell,
                    rot, t1, t2, normal, origin32, tfar, min_y, kind, table, up, ground,
                    other, noise, radius, passes, out, counts, err, through))  # fmt: skip
    return through.sum()


@njit(cache=True, nogil=True)
def _vertex_scratch(grid):
    """A worker's scratch of :func:`_vertex` for grids of up to ``grid`` strata: a grid's free
    fractions and light, the next grid's, the new directions' (and every traced direction's
    float64 unit vector), the settled strata and their rows, a packet and its lanes."""
    return (np.empty(grid), np.empty((grid, 3)), np.empty(grid), np.empty((grid, 3)),
            np.empty(grid), np.empty((grid, 3)), np.empty((grid, 3)), np.empty(grid, dtype=np.int64),
            np.empty(grid, dtype=np.bool_), np.empty(grid, dtype=np.bool_),
            packet_record(), np.empty(PACKET, dtype=np.int64))  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy")
def _vertex(i, sc, occ, isect, scene, glass, glass_tau, pat, side, points, parent, cell, old_cell,
            rot, t1, t2, normal, origin32, tfar, min_y, kind, table, up, ground,
            other, noise, radius, passes, out, counts, err, through):  # fmt: skip
    """Vertex i of :func:`sky_vertices`."""
    fr, lt, nf, nl, fo, lo, wd, sel, settled, row, pk, lanes = sc
    ray = (occ, isect, scene, glass, glass_tau, pk, lanes, rot, t1, t2, normal, origin32, tfar, min_y, wd)
    S = pat.shape[0]
    for j in range(S):
        sel[j] = j
    n_ray, n_glass = _trace(i, pat, 0, sel, S, fr, ray)
    seen_light(kind, table, up, ground, wd, fr, S, lt)
    t = np.zeros(3)
    t[0], t[1], t[2] = _sum3(fr, lt, S, settled, False)
    counts[i, 0, 0], counts[i, 0, 1] = 1, n_ray
    g, count, at = side, S, 0
    for est in range(passes):
        for c in range(3):
            out[i, c] = np.pi * t[c] / count
        if est + 1 == passes and est > 0:
            break
        err[i] = sigma = _std_error(fr, lt, g, count)
        if est + 1 == passes or not _noisy(i, sigma, out, other, noise):
            break
        gg, m = g * g, 3 * g * g
        _settle(fr, g, rot, i, radius, row, settled)
        s3 = _sum3(fr, lt, gg, settled, True)  # a settled stratum's 3 new directions bring its light
        n_sel = 0
        for p in range(m):
            if not settled[parent[at + p]]:
                sel[n_sel] = p
                n_sel += 1
        r, gl = _trace(i, points, at, sel, n_sel, fo, ray)
        n_glass += gl
        seen_light(kind, table, up, ground, wd, fo, n_sel, lo)
        s1 = _sum3(fo, lo, n_sel, settled, False)
        for c in range(3):
            t[c] += 3.0 * s3[c]
            t[c] += s1[c]
        counts[i, est + 1, 0], counts[i, est + 1, 1], counts[i, est + 1, 2] = 1, r, m - n_sel
        count *= 4
        err[i] = REFINED_ERROR * sigma
        if est + 2 < passes:  # the finer grid: the old directions and the new ones
            o3 = at // 3
            for j in range(gg):
                nf[old_cell[o3 + j]] = fr[j]
                for c in range(3):
                    nl[old_cell[o3 + j], c] = lt[j, c]
            q = 0
            for p in range(m):
                k, a = cell[at + p], parent[at + p]
                if q < n_sel and sel[q] == p:
                    nf[k] = fo[q]
                    for c in range(3):
                        nl[k, c] = lo[q, c]
                    q += 1
                else:
                    nf[k] = fr[a]
                    for c in range(3):
                        nl[k, c] = lt[a, c]
            fr, nf, lt, nl = nf, fr, nl, lt
        at += m
        g *= 2
    through[i] = n_glass


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _trace(i, pts, at, sel, n_sel, fo, ray):
    """Trace the directions ``pts[at + sel[q]]`` (q < n_sel; before vertex i's rotation) from vertex
    i, in packets: what of each gets through into ``fo[q]`` (0 below min_y, not traced), its unit
    vector into ``wd[q]`` (only where some gets through). Returns (rays traced, rays traced against
    the glass besides). Under a level ceiling (a frame whose tangents have y 0, its normal down) a
    direction off the disc's rim (square point within 1e-9 of its edge) has y below 0: it is
    dropped with ``min_y`` 0 before it is made."""
    occ, isect, scene, glass, glass_tau, pk, lanes, rot, t1, t2, normal, origin32, tfar, min_y, wd = ray
    ox, oy, oz = origin32[i, 0], origin32[i, 1], origin32[i, 2]
    down = min_y == 0.0 and t1[i, 1] == 0.0 and t2[i, 1] == 0.0 and normal[i, 1] < 0.0
    n = traced = extra = 0
    for q in range(n_sel):
        j = at + sel[q]
        if down:
            a, b = 2.0 * wrap_unit(pts[j, 0], rot[i, 0]) - 1.0, 2.0 * wrap_unit(pts[j, 1], rot[i, 1]) - 1.0
            if max(abs(a), abs(b)) < 1.0 - 1e-9:
                fo[q] = 0.0
                continue
        wx, wy, wz = sky_direction(pts[j, 0], pts[j, 1], rot, t1, t2, normal, i, wd, q)
        if wy < min_y:
            fo[q] = 0.0
            continue
        set_lane(pk, n, ox, oy, oz, wx, wy, wz, tfar)
        lanes[n] = q
        n += 1
        traced += 1
        if n == PACKET:
            extra += flush_packet(occ, isect, scene, glass, glass_tau, pk, n, lanes, fo)
            n = 0
    if n:
        extra += flush_packet(occ, isect, scene, glass, glass_tau, pk, n, lanes, fo)
    return traced, extra


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def sky_direction(pu, pv, rot, t1, t2, normal, i, out, q):
    """The sky direction of pattern point (pu, pv) at vertex i: rotated by ``rot[i]`` (b, 2) on the
    unit square, mapped to the disc (:func:`concentric`) and lifted to the hemisphere of the frame
    t1, t2, normal (b, 3) (Malley: cosine-distributed); into ``out[q]`` (3,) float64, and returned
    as float32 (the ray's)."""
    dx, dy = concentric(wrap_unit(pu, rot[i, 0]), wrap_unit(pv, rot[i, 1]))
    dz = math.sqrt(max(1.0 - dx * dx - dy * dy, 0.0))
    for c in range(3):
        out[q, c] = dx * t1[i, c] + dy * t2[i, c] + dz * normal[i, c]
    return np.float32(out[q, 0]), np.float32(out[q, 1]), np.float32(out[q, 2])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def concentric(u, v):
    """Shirley-Chiu's concentric map of (u, v) in the unit square onto the unit disc, as
    :func:`.kernels.concentric_unit`, its sine and cosine by polynomials (Taylor, degree 13 and 16
    on [-pi/4, pi/4]: within 3e-14 of ``math``'s; half the time)."""
    a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
    if abs(a) > abs(b):
        s, c = _sin_cos(_PI_4 * b / a)
        return a * c, a * s
    if b == 0.0:
        return 0.0, 0.0
    s, c = _sin_cos(_PI_4 * a / b)  # the angle is pi/2 minus this one
    return b * s, b * c


_PI_4 = math.pi / 4


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _sin_cos(t):
    """sin t and cos t for |t| <= pi/4, their Taylor series to t^13 and t^16."""
    x = t * t
    s = 1 / 362880 + x * (-1 / 39916800 + x / 6227020800)
    s = 1.0 + x * (-1 / 6 + x * (1 / 120 + x * (-1 / 5040 + x * s)))
    c = 1 / 40320 + x * (-1 / 3628800 + x * (1 / 479001600 - x / 87178291200))
    c = 1.0 + x * (-1 / 2 + x * (1 / 24 + x * (-1 / 720 + x * c)))
    return t * s, c


@njit(cache=True, nogil=True, error_model="numpy")
def sky_directions(pts, rot, t1, t2, normal, vi, pj, out):
    """:func:`sky_direction` of pattern point ``pj[m]`` (pts (S, 2)) at vertex ``vi[m]`` into
    ``out`` (m, 3) float64: the directions numpy's path (``DirectLight``, for embreex) traces."""
    for m in range(vi.shape[0]):
        sky_direction(pts[pj[m], 0], pts[pj[m], 1], rot, t1, t2, normal, vi[m], out, m)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _sum3(f, lo, n, settled, masked):
    """The sum over q < n of ``f[q] lo[q]`` (3,), in index order (``einsum``'s and ``bincount``'s);
    with ``masked`` only where ``settled[q]``."""
    a = b = c = 0.0
    for q in range(n):
        x = f[q] if not masked or settled[q] else 0.0
        a += x * lo[q, 0]
        b += x * lo[q, 1]
        c += x * lo[q, 2]
    return a, b, c


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _std_error(fr, lt, g, count):
    """The standard error (luminance, W/m²) of an estimate from its g x g grid (``fr``, ``lt``) of
    ``count`` directions, as its four interleaved quarters tell it (:func:`.sky_passes.quarter_sums`;
    on the window-lit room's back wall 1.2x the spread between seeds)."""
    w0, w1, w2 = LUMINANCE_WEIGHTS[0], LUMINANCE_WEIGHTS[1], LUMINANCE_WEIGHTS[2]
    q = np.zeros(4)
    for a in range(g):
        for b in range(g):
            j = a * g + b
            q[(a & 1) * 2 + (b & 1)] += fr[j] * (lt[j, 0] * w0 + lt[j, 1] * w1 + lt[j, 2] * w2)
    for k in range(4):
        q[k] = np.pi * q[k] / (count / 4)
    mean = (q[0] + q[1] + q[2] + q[3]) / 4.0
    var = ((q[0] - mean) ** 2 + (q[1] - mean) ** 2 + (q[2] - mean) ** 2 + (q[3] - mean) ** 2) / 3.0
    return math.sqrt(var / 4.0)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _noisy(i, sigma, out, other, noise):
    """Whether vertex i's estimate ``out[i]`` with standard error ``sigma`` is above ``noise`` of its
    direct light (this estimate's luminance plus ``other[i]``)."""
    e = out[i, 0] * LUMINANCE_WEIGHTS[0] + out[i, 1] * LUMINANCE_WEIGHTS[1] + out[i, 2] * LUMINANCE_WEIGHTS[2]
    return sigma > noise * max(e + other[i], 1e-300)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _settle(v, g, rot, i, radius, row, settled):
    """:func:`.sky_passes.settled_strata` of vertex i's g x g grid ``v`` into ``settled`` (g²,):
    every stratum within ``radius`` on the torus shares its value, and its row and column are not
    the ones the rotation's wrap cuts; none for a negative ``radius``. ``row`` (g²,): scratch."""
    if radius < 0:
        settled[: g * g] = False
        return
    for a in range(g):
        for b in range(g):
            x, ok = v[a * g + b], True
            for d in range(1, radius + 1):
                if v[a * g + _wrap(b + d, g)] != x or v[a * g + _wrap(b - d, g)] != x:
                    ok = False
                    break
            row[a * g + b] = ok
    cut_a = math.floor(g * (1.0 - rot[i, 0]))
    cut_b = math.floor(g * (1.0 - rot[i, 1]))
    for a in range(g):
        for b in range(g):
            j = a * g + b
            ok = row[j] and a != cut_a and b != cut_b
            for d in range(1, radius + 1):
                if not ok:
                    break
                for e in (_wrap(a + d, g), _wrap(a - d, g)):
                    if not row[e * g + b] or v[e * g + b] != v[j]:
                        ok = False
            settled[j] = ok


@njit(cache=True, nogil=True, inline="always")
def _wrap(x, g):
    """``x % g`` for x in [-g, 2g), without a division."""
    return x + g if x < 0 else (x - g if x >= g else x)


def sky_estimate(vis, light, pat, side: int, levels: tuple, passes: int, rot, frame, origin32, tfar: float,
                 dark_ground: bool, other, noise: float, radius: int):  # fmt: skip
    """With the C API and a sky :func:`.sky.seen_light` looks up (``light``:
    :meth:`.sky.SkyTable.kernel_args`, None for an image), :func:`sky_vertices` of a block of k
    vertices on the ray threads, counted in ``vis``: ``(out (k, 3) W/m², counts (passes, 3) int64:
    per estimate the vertices, the rays traced and the directions that took their stratum's
    value, err (k,): each estimate's standard error, luminance W/m²)``; None otherwise.
    ``levels``: :func:`pack_levels` of ``passes - 1`` levels; frame: (t1, t2, normal) (k, 3) each;
    with ``dark_ground`` the directions below the horizon are not traced."""
    args = vis.embree_args()
    if args is None or light is None:
        return None
    k = len(rot)
    out, counts, err = np.empty((k, 3)), np.zeros((k, passes, 3), dtype=np.int64), np.zeros(k)
    min_y = np.float32(0.0 if dark_ground else -np.inf)
    t0 = time.perf_counter()
    with vis.kernel_threads():
        through = sky_vertices(*args, pat, int(side), *levels, rot, *(_c(f) for f in frame),
                               np.ascontiguousarray(origin32), np.float32(tfar), min_y, *light, _c(other),
                               float(noise), int(radius), passes, out, counts, err)  # fmt: skip
    c = counts.sum(axis=0)
    vis.count(int(c[:, 1].sum()) + int(through), time.perf_counter() - t0)
    return out, c, err


def _c(a):
    return np.ascontiguousarray(a, dtype=np.float64)
