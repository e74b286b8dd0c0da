"""Compiled kernels of the solver's hot loops (numba ``njit``, cached on disk): the point-to-polygon
form factor, the sample weights of a gather (area and direction samples, balance heuristic) with
the shadow rays they need, and the gather's visible fraction and field integral after tracing.

Every kernel takes plain C-contiguous arrays (float64 unless stated; lengths in world units,
radiance in W / (m^2 sr)) and keeps the arithmetic of the numpy code it replaced, in the same
order (no fastmath), so its results agree with it to rounding. Loops over receivers run in
parallel (``prange``); each output row is written by one thread in a fixed order, so results do
not depend on the number of threads (a solve is bit-for-bit the same on a 1-thread worker).
They release the GIL (a solve on a background thread leaves the viewer's thread running). The
first call compiles them (tens of seconds; numba caches the result next to this file).

A shooter's geometry travels as ``geom`` (16, 3) float64, rows: 0 origin ``c0``, 1 unit normal,
2-4 ``e1, e2, e3`` of ``p(u, v) = c0 + u e1 + v e2 + u v e3``, 5-6 the dual basis ``a1, a2``
(``(y - c0) . a1 = u`` on a parallelogram), 7-8 the in-plane frame, 9-11 the Gram matrix of
``(e1, e2, e3)``, 12-14 that of ``(e1 x e2, e1 x e3, e3 x e2)``, 15 ``(e1, e2, e3) . normal``;
and ``uvc`` (3, 2): ``e1, e2, e3`` in the in-plane frame (the inverse bilinear map).
(:meth:`iat.radiosity.sampling.Shooter.kernel_args` makes them.)
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

# numba's OpenMP workers wait passively between parallel loops: spinning, they would take the
# cores from embree's threads between two kernels (and from other processes on a shared machine)
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

from numba import get_num_threads, njit, prange, set_num_threads  # noqa: E402

from iat.radiosity import blas  # noqa: E402, F401 (numpy's OpenBLAS on one thread)

_PI = math.pi
_BELOW_ONE = 1.0 - 2.0**-53  # the largest float64 below 1
#: receivers per parallel task of the form-factor kernels (one set of scratch arrays each)
_CHUNK = 256


@contextmanager
def one_thread() -> Iterator[None]:
    """The kernels this thread calls inside run on it alone (numba's thread count is the
    calling thread's): for callers that run several kernels at once on their own threads."""
    before = get_num_threads()
    set_num_threads(1)
    try:
        yield
    finally:
        set_num_threads(before)


# -- form factors -------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _contour_term(ax, ay, az, bx, by, bz, nx, ny, nz):
    """One edge a -> b of Lambert's contour sum: gamma n . (a x b) / |a x b| (0 for a null edge)."""
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    cn = math.sqrt(cx * cx + cy * cy + cz * cz)
    if not cn > 1e-300:
        return 0.0
    gamma = math.atan2(cn, ax * bx + ay * by + az * bz)
    return gamma * (cx * nx + cy * ny + cz * nz) / cn


@njit(cache=True, error_model="numpy")
def _point_polygon_one(x, nrm, poly, r, d, pts):
    """Form factor from one receiver (x (3,), unit normal nrm (3,)) to the convex polygon poly
    (k, 3), clipped to the receiver's front half-space; r (k, 3), d (k,), pts (2k, 3) scratch."""
    k = poly.shape[0]
    size = 0.0
    for i in range(k):
        for c in range(3):
            r[i, c] = poly[i, c] - x[c]
            size = max(size, abs(r[i, c]))
    front = False
    full = True
    for i in range(k):
        di = r[i, 0] * nrm[0] + r[i, 1] * nrm[1] + r[i, 2] * nrm[2]
        if abs(di) <= 1e-12 * size:
            di = 0.0
        d[i] = di
        front |= di > 0.0
        full &= di >= 0.0
    if not front:  # a polygon lying in (or behind) the tangent plane subtends nothing
        return 0.0
    m = 0
    if full:
        for i in range(k):
            for c in range(3):
                pts[i, c] = r[i, c]
        m = k
    else:  # Sutherland-Hodgman on the tangent plane: v_i if inside, the crossing where the side changes
        for i in range(k):
            j = (i + 1) % k
            inside, in_next = d[i] >= 0.0, d[j] >= 0.0
            if inside:
                for c in range(3):
                    pts[m, c] = r[i, c]
                m += 1
            if inside != in_next:
                t = d[i] / (d[i] - d[j])
                for c in range(3):
                    pts[m, c] = r[i, c] + t * (r[j, c] - r[i, c])
                m += 1
        if m < 3:
            return 0.0
    s = 0.0
    for i in range(m):
        j = i + 1 if i + 1 < m else 0
        s += _contour_term(
            pts[i, 0], pts[i, 1], pts[i, 2], pts[j, 0], pts[j, 1], pts[j, 2], nrm[0], nrm[1], nrm[2]
        )
    return min(max(abs(s) / (2.0 * _PI), 0.0), 1.0)


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def point_polygon(x, nrm, poly):
    """(n,) form factors from receivers at x (n, 3) with unit normals nrm (n, 3) to the convex
    planar polygon poly (k, 3) (either winding), in [0, 1]: Lambert's contour integral over the
    part of the polygon in front of each receiver's tangent plane."""
    n, k = x.shape[0], poly.shape[0]
    out = np.empty(n)
    for c in prange((n + _CHUNK - 1) // _CHUNK):  # scratch per chunk of receivers
        r, d, pts = np.empty((k, 3)), np.empty(k), np.empty((2 * k, 3))
        for i in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
            out[i] = _point_polygon_one(x[i], nrm[i], poly, r, d, pts)
    return out


@njit(cache=True, error_model="numpy")
def _kernel(u, v, d0n, dd, de0, de1, de2, en0, en1, en2, h, geom, para):
    """``cos_r cos_s / (pi r^2)`` at p(u, v) from one receiver, from its scalars against the
    shooter: ``d0 = c0 - x``: d0n = d0 . nr, dd = d0 . d0, de_k = d0 . e_k, en_k = nr . e_k,
    h = d0 . normal (the order of operations of the numpy code it replaced)."""
    dn = d0n + u * en0 + v * en1
    ds = h + u * geom[15, 0] + v * geom[15, 1]
    r2 = dd + 2 * u * de0 + 2 * v * de1 + u * u * geom[9, 0] + v * v * geom[10, 1] + 2 * u * v * geom[9, 1]
    if not para:
        uv = u * v
        dn = dn + uv * en2
        ds = ds + uv * geom[15, 2]
        r2 = r2 + 2 * uv * de2 + uv * uv * geom[11, 2] + 2 * uv * (u * geom[9, 2] + v * geom[10, 2])
    return max(dn, 0.0) * max(-ds, 0.0) / (_PI * max(r2 * r2, 1e-300))


@njit(cache=True, error_model="numpy")
def _jacobian(u, v, geom, para, area):
    """Area per unit (u, v) at lattice parameters (u, v)."""
    if para:
        return area
    j2 = (
        geom[12, 0]
        + u * u * geom[13, 1]
        + v * v * geom[14, 2]
        + 2 * u * geom[12, 1]
        + 2 * v * geom[12, 2]
        + 2 * u * v * geom[13, 2]
    )
    return max(math.sqrt(max(j2, 0.0)), 1e-300)


@njit(cache=True, error_model="numpy")
def _receiver_scalars(x, nr, geom):
    """(d0n, dd, de0, de1, de2, en0, en1, en2, h) of a receiver at x with normal nr."""
    d0x, d0y, d0z = geom[0, 0] - x[0], geom[0, 1] - x[1], geom[0, 2] - x[2]
    d0n = d0x * nr[0] + d0y * nr[1] + d0z * nr[2]
    dd = d0x * d0x + d0y * d0y + d0z * d0z
    de0 = d0x * geom[2, 0] + d0y * geom[2, 1] + d0z * geom[2, 2]
    de1 = d0x * geom[3, 0] + d0y * geom[3, 1] + d0z * geom[3, 2]
    de2 = d0x * geom[4, 0] + d0y * geom[4, 1] + d0z * geom[4, 2]
    en0 = nr[0] * geom[2, 0] + nr[1] * geom[2, 1] + nr[2] * geom[2, 2]
    en1 = nr[0] * geom[3, 0] + nr[1] * geom[3, 1] + nr[2] * geom[3, 2]
    en2 = nr[0] * geom[4, 0] + nr[1] * geom[4, 1] + nr[2] * geom[4, 2]
    h = d0x * geom[1, 0] + d0y * geom[1, 1] + d0z * geom[1, 2]
    return d0n, dd, de0, de1, de2, en0, en1, en2, h


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def patch_form_factors(x, nr, poly, centre, far, geom, para, area, gu, gv, gw):
    """(n,) form factors to a shooter (the convex polygon poly (k, 3), centre (3,), geometry geom)
    from receivers x (n, 3) with unit normals nr (n, 3): for a receiver farther than ``far`` from
    the centre that sees all of poly in front of it, a Gauss rule over the shooter (nodes gu, gv
    (G,) in lattice parameters, weights gw (G,) summing to 1 over its lattice); else the analytic
    contour integral (:func:`point_polygon`)."""
    n, k = x.shape[0], poly.shape[0]
    out = np.empty(n)
    for c in prange((n + _CHUNK - 1) // _CHUNK):  # scratch per chunk of receivers
        r, d, pts = np.empty((k, 3)), np.empty(k), np.empty((2 * k, 3))
        for i in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
            out[i] = _patch_form_factor(
                x[i], nr[i], poly, centre, far, geom, para, area, gu, gv, gw, r, d, pts
            )
    return out


@njit(cache=True, error_model="numpy")
def _patch_form_factor(x, nr, poly, centre, far, geom, para, area, gu, gv, gw, r, d, pts):
    """One receiver of :func:`patch_form_factors` (r, d, pts: scratch)."""
    k, g = poly.shape[0], gu.shape[0]
    xn = x[0] * nr[0] + x[1] * nr[1] + x[2] * nr[2]
    ahead = True
    for j in range(k):
        ahead &= poly[j, 0] * nr[0] + poly[j, 1] * nr[1] + poly[j, 2] * nr[2] - xn > 0
    dx, dy, dz = x[0] - centre[0], x[1] - centre[1], x[2] - centre[2]
    if ahead and math.sqrt(dx * dx + dy * dy + dz * dz) > far:
        d0n, dd, de0, de1, de2, en0, en1, en2, h = _receiver_scalars(x, nr, geom)
        s = 0.0
        for j in range(g):
            kk = _kernel(gu[j], gv[j], d0n, dd, de0, de1, de2, en0, en1, en2, h, geom, para)
            s += kk * _jacobian(gu[j], gv[j], geom, para, area) * gw[j]
        return s
    return _point_polygon_one(x, nr, poly, r, d, pts)


# -- the samples of a gather ------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _clip_uv(u, v, is_quad):
    u = min(max(u, 0.0), 1.0)
    v = min(max(v, 0.0), 1.0)
    if not is_quad:
        tot = max(u + v, 1.0)
        u, v = u / tot, v / tot
    return u, v


@njit(cache=True, error_model="numpy")
def _on_surface(u, v, mask):
    r = mask.shape[0]
    a = min(max(np.int64(u * r), 0), r - 1)
    b = min(max(np.int64(v * r), 0), r - 1)
    return mask[b, a]


@njit(cache=True, error_model="numpy")
def _inverse_bilinear(px, py, pz, geom, uvc, linear_uv, is_quad):
    """Lattice parameters (clipped) of a point on the shooter's plane."""
    rx, ry, rz = px - geom[0, 0], py - geom[0, 1], pz - geom[0, 2]
    h0 = rx * geom[7, 0] + ry * geom[7, 1] + rz * geom[7, 2]
    h1 = rx * geom[8, 0] + ry * geom[8, 1] + rz * geom[8, 2]
    e0, e1 = uvc[0, 0], uvc[0, 1]
    f0, f1 = uvc[1, 0], uvc[1, 1]
    g0, g1 = uvc[2, 0], uvc[2, 1]
    if linear_uv:
        det = e0 * f1 - e1 * f0
        u = (h0 * f1 - h1 * f0) / det
        v = (e0 * h1 - e1 * h0) / det
    else:
        k2 = g0 * f1 - g1 * f0
        k1 = (e0 * f1 - e1 * f0) + (h0 * g1 - h1 * g0)
        k0 = h0 * e1 - h1 * e0
        if abs(k2) < 1e-14:
            v = -k0 / (1e-300 if k1 == 0 else k1)
        else:
            disc = math.sqrt(max(k1 * k1 - 4 * k0 * k2, 0.0))
            v1, v2 = (-k1 - disc) / (2 * k2), (-k1 + disc) / (2 * k2)
            v = v1 if (v1 >= -1e-9) & (v1 <= 1 + 1e-9) else v2
        d0, d1 = e0 + v * g0, e1 + v * g1
        u = ((h0 - v * f0) * d0 + (h1 - v * f1) * d1) / max(d0 * d0 + d1 * d1, 1e-300)
    return _clip_uv(u, v, is_quad)


@njit(cache=True, error_model="numpy")
def concentric_unit(u, v):
    """Shirley-Chiu concentric map of (u, v) in the unit square onto the unit disc."""
    a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
    if abs(a) > abs(b):
        r = a
        phi = (_PI / 4) * b / (1.0 if a == 0 else a)
    else:
        r = b
        phi = _PI / 2 - (_PI / 4) * a / (1.0 if b == 0 else b)
    if a == 0 and b == 0:
        phi = 0.0
    return r * math.cos(phi), r * math.sin(phi)


@njit(cache=True, error_model="numpy")
def wrap_unit(p, r):
    """``(p + r) % 1.0`` for p, r in [0, 1) (exact: p + r - 1 is, for a sum in [1, 2))."""
    t = p + r
    return t - 1.0 if t >= 1.0 else t


@njit(cache=True, error_model="numpy")
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, error_model="numpy", inline="always")
def _cell(row, x, g):
    """The cell i < g of the cumulative row (g + 1,) with ``row[i] <= x < row[i + 1]`` (binary search)."""
    lo, hi = 0, g - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if row[mid] <= x:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(cache=True, error_model="numpy")
def importance_warp(a, b, imp):
    """(s, t, r): the point (a, b) of the unit square drawn by the importance tables ``imp``
    (:func:`iat.radiosity.sampling.field_importance`: the inverse of its cumulative densities,
    column then cell) and the density r there relative to uniform."""
    g = (imp.shape[0] - 1) // 2
    i = _cell(imp[0], a, g)
    c0, c1 = imp[0, i], imp[0, i + 1]
    s = (i + (a - c0) / (c1 - c0)) / g
    j = _cell(imp[1 + i], b, g)
    d0, d1 = imp[1 + i, j], imp[1 + i, j + 1]
    t = (j + (b - d0) / (d1 - d0)) / g
    return min(s, _BELOW_ONE), min(t, _BELOW_ONE), imp[1 + g + i, j]


@njit(cache=True, error_model="numpy")
def importance_density(u, v, is_quad, imp):
    """The density relative to uniform of the importance tables ``imp`` at the shooter's lattice
    parameters (u, v) (on a triangle, the square's point the square-root warp takes there)."""
    g = (imp.shape[0] - 1) // 2
    if not is_quad:
        sq = u + v
        u, v = sq * sq, v / sq if sq > 0 else 0.0
    i = min(max(np.int64(u * g), 0), g - 1)
    j = min(max(np.int64(v * g), 0), g - 1)
    return imp[1 + g + i, j]


@njit(cache=True, error_model="numpy")
def row_weights(i, pat, rot, x, nr, t1, t2, near, n_s, geom, uvc, poly_n, poly_o, tol,
                 is_quad, para, linear_uv, area, mask, has_mask, imp, sw, su, sv, base):  # fmt: skip
    """The samples of weight > 0 of receiver row i (its S area samples, then its S cosine-direction
    samples when ``near``): their MIS weights sw and lattice parameters su, sv, written from
    ``base`` on; returns their count and the sum of their weights. With importance tables ``imp``
    (more than one row: :func:`iat.radiosity.sampling.field_importance`) the area samples are drawn
    by them, and both kinds weighted by that density."""
    drawn = imp.shape[0] > 1
    S = pat.shape[0]
    xi, ni = x[i], nr[i]
    d0n, dd, de0, de1, de2, en0, en1, en2, h = _receiver_scalars(xi, ni, geom)
    q, wsum = base, 0.0
    for j in range(S):  # area samples: the stratified pattern shifted by the row's rotation
        ua = wrap_unit(pat[j, 0], rot[i, 0])
        va = wrap_unit(pat[j, 1], rot[i, 1])
        r = 1.0
        if drawn:
            ua, va, r = importance_warp(ua, va, imp)
        if not is_quad:  # area-uniform square -> triangle warp
            sq = math.sqrt(ua)
            ua, va = sq * (1 - va), sq * va
        ka = _kernel(ua, va, d0n, dd, de0, de1, de2, en0, en1, en2, h, geom, para)
        ja = _jacobian(ua, va, geom, para, area)
        if has_mask and not _on_surface(ua, va, mask):
            ka = 0.0
        wa = ka / (n_s * r / ja + (n_s * ka if near else 0.0) + 1e-300)
        if wa > 0:
            sw[q], su[q], sv[q] = wa, ua, va
            wsum += wa
            q += 1
    if not near:
        return q - base, wsum
    # direction samples: cosine-distributed about the receiver's normal, kept where they hit
    t1n, t2n, nn = _dot3(t1[i], geom[1]), _dot3(t2[i], geom[1]), _dot3(ni, geom[1])
    t1a, t2a, na = _dot3(t1[i], geom[5]), _dot3(t2[i], geom[5]), _dot3(ni, geom[5])
    t1b, t2b, nb = _dot3(t1[i], geom[6]), _dot3(t2[i], geom[6]), _dot3(ni, geom[6])
    rx, ry, rz = xi[0] - geom[0, 0], xi[1] - geom[0, 1], xi[2] - geom[0, 2]
    hx = rx * geom[1, 0] + ry * geom[1, 1] + rz * geom[1, 2]  # height over the shooter's plane
    xa = rx * geom[5, 0] + ry * geom[5, 1] + rz * geom[5, 2]
    xb = rx * geom[6, 0] + ry * geom[6, 1] + rz * geom[6, 2]
    k = poly_n.shape[0]
    for j in range(S):
        dx, dy = concentric_unit(wrap_unit(pat[j, 0], rot[i, 2]), wrap_unit(pat[j, 1], rot[i, 3]))
        dz = math.sqrt(max(1.0 - dx * dx - dy * dy, 0.0))
        den = dx * t1n + dy * t2n + dz * nn  # < 0: towards the front of the shooter
        ok = den < -1e-12
        t = hx / -den if ok else 0.0
        if para:
            ud = xa + t * (dx * t1a + dy * t2a + dz * na)
            vd = xb + t * (dx * t1b + dy * t2b + dz * nb)
            tt = 1e-9
            hit = ok and t > 0 and ud >= -tt and vd >= -tt
            hit = hit and ((ud <= 1 + tt and vd <= 1 + tt) if is_quad else ud + vd <= 1 + tt)
            ud, vd = _clip_uv(ud, vd, is_quad)
            if has_mask and hit:
                hit = _on_surface(ud, vd, mask)
            jd = area
        else:
            wx = dx * t1[i, 0] + dy * t2[i, 0] + dz * ni[0]
            wy = dx * t1[i, 1] + dy * t2[i, 1] + dz * ni[1]
            wz = dx * t1[i, 2] + dy * t2[i, 2] + dz * ni[2]
            yx, yy, yz = xi[0] + t * wx, xi[1] + t * wy, xi[2] + t * wz
            hit = ok and t > 0
            for e in range(k):  # inside the convex polygon: behind every edge's outward normal
                en = poly_n[e]
                s = (yx - poly_o[e, 0]) * en[0] + (yy - poly_o[e, 1]) * en[1] + (yz - poly_o[e, 2]) * en[2]
                hit = hit and s <= tol * math.sqrt(en[0] * en[0] + en[1] * en[1] + en[2] * en[2])
            ud, vd = _inverse_bilinear(yx, yy, yz, geom, uvc, linear_uv, is_quad)
            jd = _jacobian(ud, vd, geom, para, area)
        wd = 0.0
        if hit:
            kd = dz * -den / (_PI * max(t * t, 1e-300))
            r = importance_density(ud, vd, is_quad, imp) if drawn else 1.0
            wd = kd / (n_s * r / jd + n_s * kd + 1e-300)
        if wd > 0:
            sw[q], su[q], sv[q] = wd, ud, vd
            wsum += wd
            q += 1
    return q - base, wsum


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def gather_rays(pat, rot, x, nr, t1, t2, near, origin32, geom, uvc, poly_n, poly_o, tol, is_quad,
                para, linear_uv, area, mask, has_mask, imp, t32, half_eps, buf, ro, rd, rt):  # fmt: skip
    """The samples of a block of b receivers of a gather from one shooter, and their shadow rays.

    pat (S, 2) stratified pattern in [0, 1)^2; rot (b, 4) per-row rotations (area, direction);
    x, nr (b, 3) receiver points and unit normals; t1, t2 (b, 3) their tangents; near (b,) bool
    (direction samples too); origin32 (b, 3) float32 ray origins; geom, uvc the shooter (module
    docstring); poly_n, poly_o (k, 3) its edges' outward normals and points; tol the inside
    test's slack; is_quad, para (a parallelogram), linear_uv (the (u, v) inverse is linear);
    area its lattice area; mask (r, r) bool coverage of a panel cell (used when has_mask); imp
    the importance tables the area samples are drawn by (:func:`row_weights`); t32 (4, 3) float32
    ``base, e1, e2, e3`` of the ray targets (:meth:`Shooter.kernel_args`); half_eps float32, taken
    off the targets' distance. buf (6, n) float64, ro, rd (n, 3) and rt
    (n,) float32, n >= 2 b S: scratch and outputs, reused between calls (fresh memory would
    cost a page fault per 4 KiB).

    Returns ``off`` (b + 1,) int64 (row i's samples are ``off[i]:off[i+1]``), ``wsum`` (b,) the
    rows' weight sums, and per sample of weight > 0 (row-major), views of the first k rows of
    buf, ro, rd, rt: ``w, u, v`` (k,) float64 and the rays ``o, d`` (k, 3) float32 (unit
    directions), ``tfar`` (k,) float32.
    """
    b, S = x.shape[0], pat.shape[0]
    n_s = float(S)
    sw, su, sv = buf[0], buf[1], buf[2]
    cnt = np.zeros(b, dtype=np.int64)
    wsum = np.zeros(b)
    for i in prange(b):
        cnt[i], wsum[i] = row_weights(i, pat, rot, x, nr, t1, t2, near[i], n_s, geom, uvc, poly_n,
                                       poly_o, tol, is_quad, para, linear_uv, area, mask, has_mask,
                                       imp, sw, su, sv, i * 2 * S)  # fmt: skip
    off = np.zeros(b + 1, dtype=np.int64)
    for i in range(b):
        off[i + 1] = off[i] + cnt[i]
    k = off[b]
    ws, us, vs = buf[3, :k], buf[4, :k], buf[5, :k]
    for i in prange(b):
        p = i * 2 * S
        for q in range(off[i], off[i + 1]):
            ws[q], us[q], vs[q] = sw[p], su[p], sv[p]
            for c in range(3):
                ro[q, c] = origin32[i, c]
            rd[q, 0], rd[q, 1], rd[q, 2], rt[q] = sample_ray(su[p], sv[p], t32, para, origin32[i], half_eps)
            p += 1
    return off, wsum, ws, us, vs, ro[:k], rd[:k], rt[:k]


@njit(cache=True, error_model="numpy")
def _target(u32, v32, t32, para, c):
    """Coordinate c of the float32 ray target ``base + u e1 + v e2 (+ u v e3)`` of ``t32``."""
    tc = u32 * t32[1, c]
    tc += v32 * t32[2, c]
    tc += t32[0, c]
    if not para:
        tc += (u32 * v32) * t32[3, c]
    return tc


@njit(cache=True, error_model="numpy")
def sample_ray(u, v, t32, para, o32, half_eps):
    """The shadow ray of the sample at lattice parameters (u, v) from the float32 origin o32 (3,): its
    unit direction and its length less ``half_eps`` (float32 ``dx, dy, dz, tfar``) to the sample's
    target on the shooter (:func:`gather_rays`)."""
    u32, v32 = np.float32(u), np.float32(v)
    zero = np.float32(0.0)
    dx = _target(u32, v32, t32, para, 0) - o32[0]
    dy = _target(u32, v32, t32, para, 1) - o32[1]
    dz = _target(u32, v32, t32, para, 2) - o32[2]
    r2 = zero
    r2 += dx * dx
    r2 += dy * dy
    r2 += dz * dz
    r = np.float32(math.sqrt(r2))
    rr = max(r, np.float32(1e-30))
    return dx / rr, dy / rr, dz / rr, max(r - half_eps, zero)


@njit(cache=True, nogil=True, error_model="numpy")
def rows_product(indptr, indices, data, x, rows, absolute):
    """(k, 3) the rows ``rows`` (k,) of ``A @ x`` (or ``A @ |x|`` when ``absolute``) for the CSR
    matrix A (indptr, indices, data) and x (m, 3): the same sums in the same order as scipy's
    product, so a shot can update the rows it touched and match the whole product bit for bit."""
    out = np.zeros((rows.shape[0], 3))
    for i in range(rows.shape[0]):
        r = rows[i]
        t0 = t1 = t2 = 0.0
        for q in range(indptr[r], indptr[r + 1]):
            j, a = indices[q], data[q]
            if absolute:
                t0 += a * abs(x[j, 0])
                t1 += a * abs(x[j, 1])
                t2 += a * abs(x[j, 2])
            else:
                t0 += a * x[j, 0]
                t1 += a * x[j, 1]
                t2 += a * x[j, 2]
        out[i, 0] = t0
        out[i, 1] = t1
        out[i, 2] = t2
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def add_at_rows(out, rows, vals):
    """``out[rows[i]] += vals[i]`` for distinct rows (k,), out (n, 3), vals (k, 3): a shot's update
    in time proportional to the rows it reached (numpy's fancy-indexed add is ~10x slower a row)."""
    for i in range(rows.shape[0]):
        r = rows[i]
        out[r, 0] += vals[i, 0]
        out[r, 1] += vals[i, 1]
        out[r, 2] += vals[i, 2]


@njit(cache=True, nogil=True, error_model="numpy")
def shot_power(rows, dv, rho, vertex_power):
    """A shot's power at the vertices ``rows`` (k,) it reached: ``(got, reflected)``, each (3,) a
    channel's sum over them of ``vertex_power`` (V,) times ``|dv| / rho`` (the radiance they
    received before their albedo ``rho`` (V, 3); 0 where rho is 0) and times ``dv`` (k, 3), the
    radiance they reflect. One pass over the rows (numpy's took six temporaries of (k, 3))."""
    got = np.zeros(3)
    reflected = np.zeros(3)
    for i in range(rows.shape[0]):
        r = rows[i]
        w = vertex_power[r]
        for c in range(3):
            d = dv[i, c]
            reflected[c] += w * d
            if rho[r, c] > 0:
                got[c] += w * abs(d) / rho[r, c]
    return got, reflected


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@njit(cache=True, error_model="numpy")
def hash_row(key, salt, out, i):
    """``out[i, :]``: ``out.shape[1]`` splitmix64 hashes of (key, salt) as uniform numbers in [0, 1)."""
    z = np.uint64(key) * _GOLDEN
    z ^= salt
    for j in range(out.shape[1]):
        z = z + _GOLDEN
        x = (z ^ (z >> np.uint64(30))) * _MIX1
        x = (x ^ (x >> np.uint64(27))) * _MIX2
        x = x ^ (x >> np.uint64(31))
        out[i, j] = np.float64(x >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True, nogil=True, error_model="numpy")
def hash_keys(keys, salt, k):
    """(n, k) float64 in [0, 1): k splitmix64 hashes of each of keys (n,) int64 with salt (uint64)."""
    out = np.empty((keys.shape[0], k))
    for i in range(keys.shape[0]):
        hash_row(keys[i], salt, out, i)
    return out


@njit(cache=True, error_model="numpy", inline="always")
def row_inputs(j, r, p, key, salt, ff, normal, tangent, origin32, rot, x, nr, t1, t2, o32):
    """Row ``j`` of a gather's per-receiver inputs for receiver ``r`` of patch ``p``: its pattern
    rotation (:func:`hash_row` of ``key`` with ``salt``), point, normal, its patch's tangents and its
    float32 origin (the arrays as :func:`block_inputs` returns them)."""
    hash_row(key, salt, rot, j)
    for c in range(3):
        x[j, c] = ff[r, c]
        nr[j, c] = normal[r, c]
        t1[j, c] = tangent[p, 0, c]
        t2[j, c] = tangent[p, 1, c]
        o32[j, c] = origin32[r, c]


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def block_inputs(ii, key, salt, correlated, ff, normal, patch, tangent, f, f_direction, origin32):
    """The per-receiver inputs of :func:`gather_rays` for the rows ``ii`` (b,) of a receiver set:
    ``rot`` (b, 4) the rows' pattern rotations (:func:`hash_keys` of their keys (n,) int64 with
    ``salt`` uint64; of key 0 for every row when ``correlated``),
    their points ``x`` and normals ``nr`` (b, 3) (rows of ff, normal (n, 3)), the tangents
    ``t1, t2`` (b, 3) of their patches (patch (n,), tangent (P, 2, 3)), ``near`` (b,) bool
    (form factor f (b,) at least f_direction), ``o32`` (b, 3) float32 (rows of origin32) and
    ``rp`` (b,) their patches."""
    b = ii.shape[0]
    rot = np.empty((b, 4))
    x, nr = np.empty((b, 3)), np.empty((b, 3))
    t1, t2 = np.empty((b, 3)), np.empty((b, 3))
    o32 = np.empty((b, 3), dtype=np.float32)
    near = np.empty(b, dtype=np.bool_)
    rp = np.empty(b, dtype=np.int64)
    for i in prange(b):
        r = ii[i]
        p = patch[r]
        rp[i] = p
        k = 0 if correlated else key[r]
        row_inputs(i, r, p, k, salt, ff, normal, tangent, origin32, rot, x, nr, t1, t2, o32)
        near[i] = f[i] >= f_direction
    return rot, x, nr, t1, t2, near, o32, rp


@njit(cache=True, error_model="numpy")
def _sample_lattice(flat, n, u, v, c):
    """Channel c of the piecewise-linear lattice field flat ((N+1)**2, 3) at (u, v)
    (:func:`iat.radiosity.sampling.sample_lattice`)."""
    xx, yy = u * n, v * n
    a = min(np.int64(xx), n - 1)
    b = min(np.int64(yy), n - 1)
    fx, fy = xx - a, yy - b
    i00 = a * (n + 1) + b
    if fx + fy <= 1.0:
        return flat[i00, c] * (1.0 - fx - fy) + flat[i00 + n + 1, c] * fx + flat[i00 + 1, c] * fy
    up = flat[i00 + n + 2, c] * (fx + fy - 1.0) + flat[i00 + n + 1, c] * (1.0 - fy)
    return up + flat[i00 + 1, c] * (1.0 - fx)


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def gather_finish(off, ws, vis, us, vs, fb, wsum, has_field, flat, nl, x, geom, uvc, linear_uv,
                  is_quad, para, field_mean, clamp_lo, clamp_hi):  # fmt: skip
    """What a block of b receivers gathers once its rays are traced.

    off, ws, us, vs, wsum as :func:`gather_rays` returned them, vis (k,) float64 what each ray
    lets through, fb (b,) the analytic form factors. Returns ``out`` (b, 3): with no field
    (``has_field`` False) column 0 is ``F x`` the visible fraction; with a field (flat
    ((nl+1)**2, 3) the shooter's radiance on its lattice of nl cells a side, field_mean (3,)
    its area mean) the radiance-weighted form factor, with the control variate at each
    receiver's foot x (b, 3) on the shooter, clamped to >= 0 / <= 0 where ``clamp_lo`` /
    ``clamp_hi``; and ``seen`` (b,) the rays of each row that got through (summed ``vis``).
    """
    b = fb.shape[0]
    out = np.zeros((b, 3))
    seen = np.zeros(b)
    for i in prange(b):
        wvis = 0.0
        sv = 0.0
        res0 = res1 = res2 = 0.0
        for q in range(off[i], off[i + 1]):
            wr = ws[q] * vis[q]  # MIS estimate of the visible kernel integral, per sample
            wvis += wr
            sv += vis[q]
            if has_field:
                v0, v1, v2 = field_terms(flat, nl, us[q], vs[q], wr)
                res0 += v0
                res1 += v1
                res2 += v2
        seen[i] = sv
        finish_row(out, i, fb[i], wsum[i], wvis, res0, res1, res2, x[i], has_field, flat, nl, geom, uvc,
                   linear_uv, is_quad, para, field_mean, clamp_lo, clamp_hi)  # fmt: skip
    return out, seen


@njit(cache=True, error_model="numpy")
def field_terms(flat, nl, u, v, wr):
    """The field flat ((nl+1)**2, 3) at lattice parameters (u, v), weighted by wr: three channels."""
    xx, yy = u * nl, v * nl
    a = min(np.int64(xx), nl - 1)
    bb = min(np.int64(yy), nl - 1)
    fx, fy = xx - a, yy - bb
    i00 = a * (nl + 1) + bb
    sxy = fx + fy
    lower = sxy <= 1.0
    w_base = abs(1.0 - sxy) * wr
    i_base = i00 if lower else i00 + nl + 2
    w10 = (fx if lower else 1.0 - fy) * wr
    w01 = (fy if lower else 1.0 - fx) * wr
    i10, i01 = i00 + nl + 1, i00 + 1
    v0 = flat[i_base, 0] * w_base
    v0 += flat[i10, 0] * w10
    v0 += flat[i01, 0] * w01
    v1 = flat[i_base, 1] * w_base
    v1 += flat[i10, 1] * w10
    v1 += flat[i01, 1] * w01
    v2 = flat[i_base, 2] * w_base
    v2 += flat[i10, 2] * w10
    v2 += flat[i01, 2] * w01
    return v0, v1, v2


@njit(cache=True, error_model="numpy")
def finish_row(out, i, fbi, wsi, wvis, res0, res1, res2, xi, has_field, flat, nl, geom, uvc, linear_uv,
               is_quad, para, field_mean, clamp_lo, clamp_hi):  # fmt: skip
    """Row i of :func:`gather_finish`'s ``out`` from the row's sums over its samples: ``wvis`` (the
    visible weights), ``res0..2`` (:func:`field_terms`); fbi its form factor, wsi its weight sum,
    xi (3,) its point."""
    frac = wvis / (wsi if wsi > 0 else 1.0)
    fv = fbi * frac  # analytic F x visible fraction
    if not has_field:
        out[i, 0] = fv
        return
    # control variate: the field at the receiver's foot on the shooter for near receivers,
    # the shooter's mean for far ones
    if para:
        rx, ry, rz = xi[0] - geom[0, 0], xi[1] - geom[0, 1], xi[2] - geom[0, 2]
        fu, fw = _clip_uv(
            rx * geom[5, 0] + ry * geom[5, 1] + rz * geom[5, 2],
            rx * geom[6, 0] + ry * geom[6, 1] + rz * geom[6, 2],
            is_quad,
        )
    else:
        hh = (xi[0] - geom[0, 0]) * geom[1, 0] + (xi[1] - geom[0, 1]) * geom[1, 1]
        hh += (xi[2] - geom[0, 2]) * geom[1, 2]
        fu, fw = _inverse_bilinear(
            xi[0] - hh * geom[1, 0], xi[1] - hh * geom[1, 1], xi[2] - hh * geom[1, 2],
            geom, uvc, linear_uv, is_quad,
        )  # fmt: skip
    w_near = min(1.0, 2.0 * fbi)
    for c in range(3):
        cv = w_near * _sample_lattice(flat, nl, fu, fw, c) + (1.0 - w_near) * field_mean[c]
        res = (res0 if c == 0 else res1 if c == 1 else res2) - cv * wvis
        val = fv * cv + res
        if clamp_lo:
            val = max(val, 0.0)
        if clamp_hi:
            val = min(val, 0.0)
        out[i, c] = val
