"""Compiled kernels of the ambient term's final gather (:mod:`iat.radiosity.remainder`): each vertex's
cosine-distributed rays, and what they read where they land (the patch's coarse lattice of unshot
light, a sheet's twin, the inside of a solid) with the patches they meet. The same conventions as
:mod:`iat.radiosity.kernels` (C-contiguous arrays, numpy's arithmetic in its order, results
independent of the thread count, the GIL released)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

import iat.radiosity.kernels  # noqa: F401 (sets numba's OpenMP wait policy before its threads start)


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def cosine_rays(dx, dy, t1, t2, normal, origin32, w, o, d):
    """Cosine-distributed rays of b vertices, S each, in vertex order (b S,): the disc points
    ``dx, dy`` (S,) lifted to the hemisphere (Malley) in each vertex's frame ``t1, t2, normal``
    (b, 3), as :func:`iat.radiosity.sampling.disk_to_hemisphere` does. Writes the directions to
    ``w`` (b S, 3) float64 and ``d`` (b S, 3) float32, and the vertex's ray origin ``origin32``
    (b, 3) float32 to ``o`` (b S, 3) float32 (as embreex takes them)."""
    b, S = t1.shape[0], dx.shape[0]
    for i in prange(b):
        for j in range(S):
            q = i * S + j
            x, y = dx[j], dy[j]
            z = math.sqrt(max(1.0 - x * x - y * y, 0.0))
            for c in range(3):
                v = x * t1[i, c] + y * t2[i, c] + z * normal[i, c]
                w[q, c] = v
                d[q, c] = np.float32(v)
                o[q, c] = origin32[i, c]


#: runs of vertices :func:`ambient_hits` spreads over the threads
AMBIENT_RUNS = 16


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def ambient_hits(tri, bary, dirs, tri_patch, tri_uv, normal, twin, twin_swap, means, flat, g, k, first,
                 back, rows, cols, counts):  # fmt: skip
    """The ambient term's rays of a block of vertices, ``k`` each, in vertex order (n * k,): where
    a ray meets a front face (opaque triangle ``tri`` >= 0, barycentric ``bary`` (n*k, 2), direction
    ``dirs`` (n*k, 3) against the normal (P, 3) of its patch ``tri_patch[tri]``), the unshot radiance
    there, read piecewise-linearly (as ``sampling.sample_lattice``) from ``flat`` ((P (g+1)^2, 3):
    each patch's g x g lattice) at the hit's lattice (u, v) (``tri_uv`` (T, 3, 2)); a ray that meets
    the back of a patch with a coincident ``twin`` (P,) (-1: none) facing it reads the twin there
    (at (v, u) where ``twin_swap`` (P,), else the twin's mean ``means`` (P, 3)). Adds each
    vertex's mean over its rays to ``first`` (n, 3) and the fraction of its rays that meet a back
    face (no twin: the inside of a solid, a vertex buried in it) to ``back`` (n,); writes per
    vertex the patches its rays met (``rows`` its index in the block, ``cols`` the patch) and the
    fraction of its rays on each (``counts``), and returns how many such pairs. The vertices are
    spread over the threads in runs (each vertex's sums in its rays' order: the thread count
    changes nothing), their pairs gathered after."""
    n = tri.shape[0] // k
    runs = min(n, AMBIENT_RUNS)
    found = np.empty(n * k, dtype=np.int64)  # vertex v's patches at v k ..., its rays on each
    tally = np.empty(n * k, dtype=np.int64)
    nf = np.zeros(n, dtype=np.int64)
    for r in prange(runs):
        owner = np.full(normal.shape[0], -1, dtype=np.int64)  # the last vertex whose rays met patch p ...
        slot = np.empty(normal.shape[0], dtype=np.int64)  # ... and where in its found / tally
        for v in range(r * n // runs, (r + 1) * n // runs):
            nf[v] = _vertex_hits(v, tri, bary, dirs, tri_patch, tri_uv, normal, twin, twin_swap, means, flat,
                                 g, k, first, back, owner, slot, found, tally)  # fmt: skip
    m = 0
    for v in range(n):
        for j in range(v * k, v * k + nf[v]):
            rows[m] = v
            cols[m] = found[j]
            counts[m] = tally[j] / k
            m += 1
    return m


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _vertex_hits(v, tri, bary, dirs, tri_patch, tri_uv, normal, twin, twin_swap, means, flat, g, k, first,
                 back, owner, slot, found, tally):  # fmt: skip
    """Vertex v's rays of :func:`ambient_hits`: its sums, and the patches they met with their rays
    on each at ``found[v k ...]``, ``tally[v k ...]``; returns how many patches."""
    nf = 0
    at = v * k
    for q in range(v * k, (v + 1) * k):
        t = tri[q]
        if t < 0:
            continue
        p = tri_patch[t]
        swap = False
        if dirs[q, 0] * normal[p, 0] + dirs[q, 1] * normal[p, 1] + dirs[q, 2] * normal[p, 2] >= 0.0:
            if twin[p] < 0:
                back[v] += 1.0 / k
                continue  # a back face
            swap = twin_swap[p]
            p = twin[p]  # the back of a sheet whose twin faces the ray: the twin's light
            if not swap:
                for c in range(3):
                    first[v, c] += means[p, c] / k
        if swap or tri_patch[t] == p:
            b1, b2 = bary[q, 0], bary[q, 1]
            b0 = 1.0 - b1 - b2
            u = min(max(b0 * tri_uv[t, 0, 0] + b1 * tri_uv[t, 1, 0] + b2 * tri_uv[t, 2, 0], 0.0), 1.0)
            w = min(max(b0 * tri_uv[t, 0, 1] + b1 * tri_uv[t, 1, 1] + b2 * tri_uv[t, 2, 1], 0.0), 1.0)
            if swap:
                u, w = w, u
            x, y = u * g, w * g
            a, b = min(int(x), g - 1), min(int(y), g - 1)
            fx, fy = x - a, y - b
            i00 = p * (g + 1) * (g + 1) + a * (g + 1) + b
            if fx + fy <= 1.0:
                wb, ib, w10, w01 = 1.0 - fx - fy, i00, fx, fy
            else:
                wb, ib, w10, w01 = fx + fy - 1.0, i00 + g + 2, 1.0 - fy, 1.0 - fx
            for c in range(3):
                val = flat[ib, c] * wb + flat[i00 + g + 1, c] * w10 + flat[i00 + 1, c] * w01
                first[v, c] += val / k
        if owner[p] != v:
            owner[p], slot[p] = v, nf
            found[at + nf] = p
            tally[at + nf] = 0
            nf += 1
        tally[at + slot[p]] += 1
    return nf
