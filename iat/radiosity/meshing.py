"""Meshing: the split test on the quad-trees (:func:`split_test`), probe points, the interpolation
a naive solver would use (for the bias it would cause), coarse receiver grids and the (P, V)
averaging matrix."""

from __future__ import annotations

import numpy as np
from scipy import sparse

from iat.errors import SolveError
from iat.geometry import quadtree as qt
from iat.radiosity.context import Context
from iat.radiosity.options import (
    ABS_FLOOR,
    BIG_LEVELS,
    BIG_TOLERANCE,
    GAIN_LIMIT,
    PENUMBRA_TOLERANCE,
    SPLIT_NOISE,
)
from iat.radiosity.patches import Patches
from iat.radiosity.progress import SolveCancelled
from iat.radiosity.sampling import luminance_of


# -- meshing helpers ------------------------------------------------------------
def probe_keys(forest: qt.Forest) -> tuple[np.ndarray, np.ndarray]:
    """(L, 5) int64 keys of the points that become corners when a leaf splits, and (L, 5) bool validity.

    Quads: centre and the four edge midpoints. Triangles: the three edge midpoints.
    """
    s = forest.leaf_size
    h = s // 2
    i = forest.leaf_i.astype(np.int64)
    j = forest.leaf_j.astype(np.int64)
    q = forest.leaf_is_quad
    down = ~q & forest.leaf_flip
    pi = np.stack([i + h, i + h, i + s, i + h, i], axis=1)
    pj = np.stack([j + h, j, j + h, j + s, j + h], axis=1)
    # up triangle (i,j),(i+s,j),(i,j+s): midpoints (i+h,j), (i+h,j+h), (i,j+h)
    # down triangle (i+s,j+s),(i,j+s),(i+s,j): midpoints (i+h,j+s), (i+h,j+h), (i+s,j+h)
    tri = ~q
    pi[tri, :3] = np.stack([i + h, i + h, np.where(down, i + s, i)], axis=1)[tri]
    pj[tri, :3] = np.stack([np.where(down, j + s, j), j + h, j + h], axis=1)[tri]
    pi[tri, 3:] = pi[tri, :1]
    pj[tri, 3:] = pj[tri, :1]
    valid = np.ones((forest.n_leaves, 5), dtype=bool)
    valid[tri, 3:] = False
    return qt.make_key(forest.leaf_patch[:, None], pi, pj, forest.n), valid


def probe_interp(forest: qt.Forest) -> np.ndarray:
    """(L, 5, 4) int64 corner slots whose mean interpolates each probe of :func:`probe_keys`."""
    q = forest.leaf_is_quad
    down = ~q & forest.leaf_flip
    out = np.empty((forest.n_leaves, 5, 4), dtype=np.int64)
    # quad corners 0:(0,0) 1:(s,0) 2:(s,s) 3:(0,s); probes centre, bottom, right, top, left
    out[q] = [[0, 1, 2, 3], [0, 1, 0, 1], [1, 2, 1, 2], [2, 3, 2, 3], [3, 0, 3, 0]]
    # up corners 0:(0,0) 1:(s,0) 2:(0,s); probes (h,0), (h,h), (0,h)
    up = ~q & ~forest.leaf_flip
    out[up] = [[0, 1, 0, 1], [1, 2, 1, 2], [0, 2, 0, 2], [0, 1, 0, 1], [0, 1, 0, 1]]
    # down corners 0:(s,s) 1:(0,s) 2:(s,0); probes (h,s), (h,h), (s,h)
    out[down] = [[0, 1, 0, 1], [1, 2, 1, 2], [0, 2, 0, 2], [0, 1, 0, 1], [0, 1, 0, 1]]
    return out


def leaf_longest_edge(forest: qt.Forest, corners: np.ndarray) -> np.ndarray:
    """(L,) float64 longest world edge of each leaf."""
    c = qt.leaf_corner_lattice(forest)
    w = qt.lattice_to_world(
        corners,
        forest.patch_is_quad,
        np.repeat(forest.leaf_patch, 4),
        c[..., 0].ravel(),
        c[..., 1].ravel(),
        forest.n,
    ).reshape(-1, 4, 3)
    e = np.linalg.norm(np.roll(w, -1, axis=1) - w, axis=2)
    tri = ~forest.leaf_is_quad
    e[tri, 2] = np.linalg.norm(w[tri, 0] - w[tri, 2], axis=1)
    return e.max(axis=1)


def parent_interpolation(keys: np.ndarray, is_quad: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """For non-root vertex keys: (k, 4) keys of the parent-edge ends (or parent corners) and (k, 4) weights.

    A vertex first appears as the midpoint of an edge (or the centre of a quad) of
    the leaf whose split created it; its naive interpolated value is the mean of
    that edge's ends (or of the quad's four corners).
    """
    p, i, j = qt.decode_key(keys, n)
    low = (i | j) & -(i | j)  # largest power of two dividing both: the level's leaf size
    s2 = 2 * low
    a, b = i - i % s2, j - j % s2
    x, y = i % s2, j % s2
    quad = is_quad[p]
    ci = np.stack([a, a + s2, a, a + s2], axis=1)
    cj = np.stack([b, b, b + s2, b + s2], axis=1)
    w = np.full((len(keys), 4), 0.25)
    horiz = (x > 0) & (y == 0)
    vert = (x == 0) & (y > 0)
    diag = (x > 0) & (y > 0) & ~quad
    for mask, e0, e1 in (
        (horiz, (a, j), (a + s2, j)),
        (vert, (i, b), (i, b + s2)),
        (diag, (a + s2, b), (a, b + s2)),
    ):
        ci[mask, 0], cj[mask, 0] = e0[0][mask], e0[1][mask]
        ci[mask, 1], cj[mask, 1] = e1[0][mask], e1[1][mask]
        ci[mask, 2:], cj[mask, 2:] = ci[mask, :1], cj[mask, :1]
        w[mask] = (0.5, 0.5, 0.0, 0.0)
    return qt.make_key(p[:, None], ci, cj, n), w


def coarse_keys(is_quad: np.ndarray, level: int, n: int) -> np.ndarray:
    """(Vc,) sorted keys of every patch's lattice grid at ``level`` (triangles: i + j <= n)."""
    k, s = 1 << level, n >> level
    a, b = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    a, b = a.ravel(), b.ravel()
    p = np.arange(len(is_quad))
    keys = qt.make_key(p[:, None], a[None, :] * s, b[None, :] * s, n)
    tri = a + b <= k
    return np.sort(np.concatenate([keys[is_quad].ravel(), keys[~is_quad][:, tri].ravel()]))


def coarse_weights(keys: np.ndarray, coarse: np.ndarray, is_quad: np.ndarray, level: int, n: int):
    """(V, Vc) sparse CSR: values at ``keys`` interpolated (bilinear / barycentric) in the
    level-``level`` cells of their patches from values at the grid keys ``coarse``."""
    p, i, j = qt.decode_key(keys, n)
    k, s = 1 << level, n >> level
    a, b = np.minimum(i // s, k - 1), np.minimum(j // s, k - 1)
    fx, fy = (i - a * s) / s, (j - b * s) / s
    quad = is_quad[p]
    lower = fx + fy <= 1.0
    ci = np.stack([a, a + 1, a + 1, a], axis=1)
    cj = np.stack([b, b, b + 1, b + 1], axis=1)
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), fx * fy, (1 - fx) * fy], axis=1)
    tl, tu = ~quad & lower, ~quad & ~lower
    ci[tl], cj[tl] = np.stack([a, a + 1, a, a], 1)[tl], np.stack([b, b, b + 1, b + 1], 1)[tl]
    w[tl] = np.stack([1 - fx - fy, fx, fy, 0 * fx], 1)[tl]
    ci[tu], cj[tu] = np.stack([a + 1, a, a + 1, a + 1], 1)[tu], np.stack([b + 1, b + 1, b, b], 1)[tu]
    w[tu] = np.stack([fx + fy - 1, 1 - fx, 1 - fy, 0 * fx], 1)[tu]
    cols = qt.lookup(coarse, qt.make_key(p[:, None], ci * s, cj * s, n))
    ok = w > 0
    rows = np.repeat(np.arange(len(keys)), 4).reshape(-1, 4)
    return sparse.csr_matrix((w[ok], (rows[ok], cols[ok])), shape=(len(keys), len(coarse)))


def averaging_matrix(
    forest: qt.Forest,
    keys: np.ndarray,
    corners: np.ndarray,
    area: np.ndarray,
    leaf_coverage: np.ndarray | None = None,
):
    """(P, V) scipy.sparse CSR: row p averages vertex values over patch p (area-weighted leaf means).

    leaf_coverage : (L,) the fraction of each leaf on its patch's surface
      (:meth:`~iat.radiosity.patches.Patches.leaf_coverage`), or None (all 1). A panel cell's
      leaves then weigh by their covered area and its row still sums to 1: weighed by their
      lattice area over the covered area ``area``, its row summed to the cell's lattice area over
      its covered area, and its light counted that much too bright wherever a patch's mean was read
      (what it shoots, the ambient term's later bounces)."""
    idx = qt.lookup(keys, qt.leaf_corner_keys(forest))
    la = qt.leaf_area(forest, corners)
    if leaf_coverage is not None:
        la = la * leaf_coverage
        P = len(area)
        partial = np.bincount(forest.leaf_patch, weights=leaf_coverage < 1.0, minlength=P) > 0
        area = np.where(partial, np.bincount(forest.leaf_patch, weights=la, minlength=P), area)
    wl = la / np.maximum(area[forest.leaf_patch], 1e-300)
    q = forest.leaf_is_quad
    wc = np.where(q, 0.25, 1.0 / 3.0)[:, None] * wl[:, None] * np.ones((1, 4))
    wc[~q, 3] = 0.0
    rows = np.repeat(forest.leaf_patch.astype(np.int64), 4)
    return sparse.csr_matrix((wc.ravel(), (rows, idx.ravel())), shape=(len(area), len(keys)))


class VertexCache:
    """Values (n, 3) at sorted vertex keys (n,) and the standard error of their luminance (n,),
    grown by :meth:`add`."""

    def __init__(self, keys=None, vals=None, noise=None):
        self.keys = np.zeros(0, dtype=np.int64) if keys is None else np.asarray(keys, dtype=np.int64)
        self.vals = np.zeros((0, 3)) if vals is None else np.asarray(vals, dtype=np.float64)
        self.noise = np.zeros(len(self.keys)) if noise is None else np.asarray(noise, dtype=np.float64)

    def find(self, keys: np.ndarray) -> np.ndarray:
        return qt.lookup(self.keys, keys)

    def get(self, keys: np.ndarray) -> np.ndarray:
        """(n, 3) values at ``keys``; 0 where unknown."""
        i = self.find(keys)
        out = np.zeros((len(keys), 3))
        out[i >= 0] = self.vals[i[i >= 0]]
        return out

    def noise_at(self, keys: np.ndarray) -> np.ndarray:
        """(n,) the standard error at ``keys``; 0 where unknown."""
        i = self.find(keys)
        out = np.zeros(len(keys))
        out[i >= 0] = self.noise[i[i >= 0]]
        return out

    def add(self, keys: np.ndarray, vals: np.ndarray, noise: np.ndarray) -> None:
        k = np.concatenate([self.keys, keys])
        order = np.argsort(k, kind="stable")
        self.keys = k[order]
        self.vals = np.concatenate([self.vals, vals])[order]
        self.noise = np.concatenate([self.noise, noise])[order]


def split_test(ctx: Context, forest: qt.Forest, cache: VertexCache, evaluate, report, label: str, span):
    """Split elements until nothing deviates by more than the tolerance (see the module docstring).

    cache : reflected radiance (n, 3) at vertex keys, extended with ``evaluate(new_keys)``, which
    returns it with the standard error of its luminance (n,). A probe splits its element where it
    deviates from the interpolation by more than the tolerance plus ``SPLIT_NOISE`` times the
    deviation's standard error (the sky's noise is not light to resolve).
    Returns (forest, passes, cancelled); on cancel the last forest whose vertices are all
    evaluated (or the given one) is returned.
    """
    opts, D, pt = ctx.opts, ctx.opts.max_depth, ctx.patches
    emission_y = luminance_of(pt.emission)
    good, passes = forest, 0
    try:
        while True:
            keys = qt.vertex_keys(forest)
            cand = (forest.leaf_level < D) & pt.leaf_has_surface(forest)
            if pt.min_size > 0 and cand.any():
                cand[cand] = leaf_longest_edge(forest.take(cand), pt.corners) / 2 >= pt.min_size
            sub = forest.take(cand)
            big = None
            if pt.max_size > 0 and sub.n_leaves:
                big = leaf_longest_edge(sub, pt.corners) > pt.max_size
                big &= sub.leaf_level < D - BIG_LEVELS
            pk, pvalid = probe_keys(sub)
            need = qt.sorted_unique(np.concatenate([keys, pk[pvalid]]))
            new = need[cache.find(need) < 0]
            report(
                span[0] + (span[1] - span[0]) * passes / (D + 1),
                f"{label}: pass {passes + 1}, {forest.n_leaves} elements, {len(new)} new points",
            )
            vals, noise = evaluate(new)
            if not np.isfinite(vals).all():  # never refine on a blown-up value
                raise SolveError(
                    f"{label}: non-finite radiance at {int((~np.isfinite(vals)).any(axis=1).sum())} points"
                )
            cache.add(new, vals, noise)
            good, passes = forest, passes + 1
            if not cand.any():
                break
            # split test on luminance of the outgoing radiance (emission + reflected)
            refl_y = luminance_of(cache.vals)
            # (the mean is capped by the most the scene can reflect on average: a point light touching a
            # wall puts I / d^2 on one vertex, which would lift the floor above all other light)
            mean_y = min(
                area_mean(forest, keys, cache.find(keys), refl_y, pt), ctx.light.max_mean_reflected()
            )
            eps_abs = max(ABS_FLOOR * mean_y, 1e-30)
            y = refl_y + emission_y[qt.decode_key(cache.keys, pt.n)[0]]
            at = np.concatenate([qt.leaf_corner_keys(sub), pk], axis=1)  # (L, 9) corners, then probes
            idx = cache.find(at)
            vy = y[idx]
            vm = np.concatenate([np.ones((sub.n_leaves, 4), dtype=bool), pvalid], axis=1)
            mean = (vy * vm).sum(axis=1) / vm.sum(axis=1)
            if opts.criterion == "uniform":
                score = np.full(sub.n_leaves, np.inf)
            elif opts.criterion == "variation":
                hi = np.where(vm, vy, -np.inf).max(axis=1)
                lo = np.where(vm, vy, np.inf).min(axis=1)
                score = hi - lo
            else:
                slots = probe_interp(sub)
                weights = (slots[..., None] == np.arange(4)).mean(axis=2)  # (L, 5, 4) of each corner
                interp = np.einsum("lpc,lc->lp", weights, vy[:, :4])
                var = cache.noise[idx] ** 2
                sd = np.sqrt(var[:, 4:] + np.einsum("lpc,lc->lp", weights**2, var[:, :4]))
                dev = np.abs(vy[:, 4:] - interp) - SPLIT_NOISE * sd
                score = np.where(pvalid, np.maximum(dev, 0.0), 0.0).max(axis=1)
            tol = np.full(sub.n_leaves, opts.tolerance)
            if len(ctx.light.penumbra):  # an emitter's penumbra: its real structure, finer
                tol[((qt.lookup(ctx.light.penumbra, at) >= 0) & vm).any(axis=1)] *= PENUMBRA_TOLERANCE
            if big is not None:  # an element larger than max_size must interpolate more closely
                tol[big] *= BIG_TOLERANCE
            split = score > tol * (mean + eps_abs)
            if not split.any():
                break
            mask = np.zeros(forest.n_leaves, dtype=bool)
            mask[cand] = split
            forest = qt.balance(qt.split(forest, mask))
    except SolveCancelled:
        return good, passes, True
    return forest, passes, False


def measure_interpolation_bias(
    keys: np.ndarray, old_keys: np.ndarray, cache: VertexCache, patches: Patches
) -> tuple[float, int]:
    """Mean relative error (sum |interpolated - exact| / sum exact, luminance of reflected radiance)
    that parent interpolation would have given the vertices of ``keys`` not in ``old_keys``."""
    late = keys[qt.lookup(old_keys, keys) < 0]
    if len(late) == 0:
        return 0.0, 0
    pkeys, pw = parent_interpolation(late, patches.is_quad, patches.n)
    pi = cache.find(pkeys)
    ok = (pi >= 0).all(axis=1) & (cache.find(late) >= 0)
    if not ok.any():
        return 0.0, 0
    y = luminance_of(cache.vals)
    interp = (y[pi[ok]] * pw[ok]).sum(axis=1)
    exact = y[cache.find(late[ok])]
    tot = exact.sum()
    return (float(np.abs(interp - exact).sum() / tot) if tot > 0 else 0.0), int(ok.sum())


def area_mean(
    forest: qt.Forest, keys: np.ndarray, kidx: np.ndarray, y: np.ndarray, patches: Patches
) -> float:
    """Area-weighted mean over the scene of per-vertex values ``y[kidx]`` (leaf-corner means)."""
    if forest.n_leaves == 0:
        return 0.0
    yv = y[kidx]
    corner = qt.lookup(keys, qt.leaf_corner_keys(forest))
    q = forest.leaf_is_quad
    vals = yv[corner]
    leaf_mean = np.where(q, vals.mean(axis=1), vals[:, :3].mean(axis=1))
    la = qt.leaf_area(forest, patches.corners)
    return float((leaf_mean * la).sum() / max(la.sum(), 1e-300))


def probe_shot_gain(forest: qt.Forest, cache: VertexCache, patches: Patches) -> np.ndarray:
    """(P,) ratio of each patch's reflected power integrated with the probes (a quadratic rule per
    leaf: 3 x 3 Simpson on quads, the edge midpoints on triangles) to the power of its piecewise
    linear interpolant (the corner means), from the luminance values in ``cache``; leaves without
    all their probes evaluated (the last level, below the minimum size) count as linear. Within
    ``GAIN_LIMIT``; 1 for a patch with no reflected light."""
    P = len(patches.area)
    if forest.n_leaves == 0 or len(cache.keys) == 0:
        return np.ones(P)
    y = luminance_of(cache.vals)
    ci = cache.find(qt.leaf_corner_keys(forest))
    pk, pvalid = probe_keys(forest)
    pi = cache.find(pk)
    q = forest.leaf_is_quad
    cvalid = np.ones(ci.shape, dtype=bool)
    cvalid[~q, 3] = False
    have = ((ci >= 0) | ~cvalid).all(axis=1) & ((pi >= 0) | ~pvalid).all(axis=1)
    yc = np.where(ci >= 0, y[np.maximum(ci, 0)], 0.0)
    yp = np.where(pi >= 0, y[np.maximum(pi, 0)], 0.0)
    lin = np.where(q, yc.sum(axis=1) / 4.0, yc[:, :3].sum(axis=1) / 3.0)
    quad = np.where(
        q, (yc.sum(axis=1) + 4.0 * yp[:, 1:5].sum(axis=1) + 16.0 * yp[:, 0]) / 36.0, yp[:, :3].mean(axis=1)
    )
    quad = np.where(have, quad, lin)
    la = qt.leaf_area(forest, patches.corners)
    num = np.bincount(forest.leaf_patch, weights=la * quad, minlength=P)
    den = np.bincount(forest.leaf_patch, weights=la * lin, minlength=P)
    gain = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
    return np.clip(gain, 1.0 / (1.0 + GAIN_LIMIT), 1.0 + GAIN_LIMIT)
