"""Compiled kernels of the lattice fields (:class:`iat.radiosity.sampling.Lattice`): patches' fields
interpolated from their leaves' corners (:func:`leaf_fields`), and read down to a coarser lattice by
tent-weighted means (:func:`tent_means`). numba ``njit``, cached on disk, in the manner of
:mod:`iat.radiosity.kernels` (whose import sets numba's thread layer up first)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from iat.radiosity import kernels  # noqa: F401 (OMP_WAIT_POLICY and numpy's BLAS threads, before numba runs)


@njit(cache=True, nogil=True, error_model="numpy")
def leaf_fields(out, first, step, leaves, patch, level, li, lj, flip, is_quad, corner, values):
    """Patches' fields on their lattice, every ``step``-th point a side: ``out`` (Q, N/step + 1,
    N/step + 1, 3) (N the lattice's side), row ``patch[leaf] - first`` for a leaf's patch. Per leaf in
    ``leaves`` (in order, so that a finer leaf listed later writes the points it shares with a
    coarser one), its points interpolated from its corners' ``values`` (V, 3) (``corner`` (L, 4)
    their rows): bilinear on a quad patch (``is_quad`` (P,)), linear on the leaf's half of its
    square on a triangle (``flip``: the half with the far corner). patch, level, li, lj (L,): each
    leaf's patch, level and lattice position."""
    n = (out.shape[1] - 1) * step
    for t in range(leaves.shape[0]):
        q = leaves[t]
        s = n >> level[q]
        c0, c1, c2, c3 = corner[q, 0], corner[q, 1], corner[q, 2], corner[q, 3]
        row = patch[q] - first
        quad = is_quad[patch[q]]
        for a in range((step - li[q] % step) % step, s + 1, step):
            x = a / s
            for b in range((step - lj[q] % step) % step, s + 1, step):
                y = b / s
                if quad:
                    w0, w1, w2, w3 = (1 - x) * (1 - y), x * (1 - y), x * y, (1 - x) * y
                elif not flip[q]:
                    if a + b > s:
                        continue
                    w0, w1, w2, w3 = 1 - x - y, x, y, 0 * x
                else:
                    if a + b < s:
                        continue
                    w0, w1, w2, w3 = x + y - 1, 1 - x, 1 - y, 0 * x
                i, j = (li[q] + a) // step, (lj[q] + b) // step
                for k in range(3):
                    out[row, i, j, k] = (
                        w0 * values[c0, k] + w1 * values[c1, k] + w2 * values[c2, k] + w3 * values[c3, k]
                    )


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def tent_means(out, f, is_quad, quad, tri, tent, r):
    """Per patch, its fine field ``f`` (Q, M, M, 3) read down to ``out`` (Q, G, G, 3), every r-th
    point (M = (G - 1) r + 1): the mean of the field around it weighted by ``tent`` (2 r - 1,) along
    each axis (the window cut at the edges) and by the fine points' shares of the patch, ``quad`` or
    ``tri`` (M, M) as ``is_quad`` (Q,) says."""
    m, g, h = f.shape[1], out.shape[1], tent.shape[0] // 2
    for q in prange(f.shape[0]):
        w = quad if is_quad[q] else tri
        rows = np.zeros((g, m, 4))  # along the first axis: 3 weighted channels and the weight
        for i in range(g):
            for a in range(tent.shape[0]):
                x = i * r + a - h
                if 0 <= x < m:
                    for y in range(m):
                        wt = tent[a] * w[x, y]
                        for k in range(3):
                            rows[i, y, k] += wt * f[q, x, y, k]
                        rows[i, y, 3] += wt
        for i in range(g):
            for j in range(g):
                s0 = s1 = s2 = s3 = 0.0
                for b in range(tent.shape[0]):
                    y = j * r + b - h
                    if 0 <= y < m:
                        s0 += tent[b] * rows[i, y, 0]
                        s1 += tent[b] * rows[i, y, 1]
                        s2 += tent[b] * rows[i, y, 2]
                        s3 += tent[b] * rows[i, y, 3]
                s3 = max(s3, 1e-300)
                out[q, i, j, 0], out[q, i, j, 1], out[q, i, j, 2] = s0 / s3, s1 / s3, s2 / s3
