"""Per-patch quad-trees on an integer lattice, as flat numpy arrays.

Every patch has a lattice of ``n + 1`` points per side, ``n = 2**max_depth``;
lattice point ``(i, j)`` sits at ``(u, v) = (i / n, j / n)`` of the patch
(bilinear for quads, barycentric for triangles with ``i + j <= n``). A leaf is
``(patch, level, i, j, flip)`` with size ``s = n >> level`` lattice units:

- quad leaf: corners ``(i, j), (i+s, j), (i+s, j+s), (i, j+s)`` (counter-clockwise
  in ``(u, v)``, the winding of the patch);
- triangle leaf, ``flip=False`` ("up"): ``(i, j), (i+s, j), (i, j+s)``;
  ``flip=True`` ("down"): ``(i+s, j+s), (i, j+s), (i+s, j)``; both counter-clockwise.

Vertices are keyed ``(patch * (n+1) + i) * (n+1) + j`` (int64) and kept sorted,
so every lookup is a ``np.searchsorted``. See ``docs/architecture.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

#: corner offsets in units of the leaf size, (4, 2); quads use all four
QUAD_CORNERS = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
#: "up" and "down" triangle corner offsets, (3, 2) each
UP_CORNERS = np.array([[0, 0], [1, 0], [0, 1]])
DOWN_CORNERS = np.array([[1, 1], [0, 1], [1, 0]])


@dataclass
class Forest:
    """All patches' quad-trees.

    max_depth : deepest level allowed; the lattice has ``2**max_depth + 1`` points per side
    patch_is_quad : (P,) bool
    leaf_patch : (L,) int32; leaf_level : (L,) int8; leaf_i, leaf_j : (L,) int32; leaf_flip : (L,) bool
    """

    max_depth: int
    patch_is_quad: np.ndarray
    leaf_patch: np.ndarray
    leaf_level: np.ndarray
    leaf_i: np.ndarray
    leaf_j: np.ndarray
    leaf_flip: np.ndarray

    @property
    def n(self) -> int:
        """Lattice intervals per patch side, ``2**max_depth``."""
        return 1 << self.max_depth

    @property
    def n_leaves(self) -> int:
        return len(self.leaf_patch)

    @property
    def n_patches(self) -> int:
        return len(self.patch_is_quad)

    @property
    def leaf_size(self) -> np.ndarray:
        """(L,) int64 leaf side in lattice units."""
        return np.int64(self.n) >> self.leaf_level.astype(np.int64)

    @property
    def leaf_is_quad(self) -> np.ndarray:
        """(L,) bool."""
        return self.patch_is_quad[self.leaf_patch]

    def patch_depth(self) -> np.ndarray:
        """(P,) int8: deepest leaf level of each patch (0 for an unsplit root)."""
        d = np.zeros(self.n_patches, dtype=np.int8)
        np.maximum.at(d, self.leaf_patch, self.leaf_level)
        return d

    def take(self, mask: np.ndarray) -> Forest:
        """A forest with only the leaves where ``mask`` (L,) is True (or those of a numpy index)."""
        return Forest(
            self.max_depth,
            self.patch_is_quad,
            self.leaf_patch[mask],
            self.leaf_level[mask],
            self.leaf_i[mask],
            self.leaf_j[mask],
            self.leaf_flip[mask],
        )


def roots(patch_is_quad: np.ndarray, max_depth: int) -> Forest:
    """One level-0 leaf per patch."""
    p = len(patch_is_quad)
    z = np.zeros(p, dtype=np.int32)
    return Forest(
        int(max_depth),
        np.asarray(patch_is_quad, dtype=bool),
        np.arange(p, dtype=np.int32),
        np.zeros(p, dtype=np.int8),
        z,
        z.copy(),
        np.zeros(p, dtype=bool),
    )


def make_key(patch, i, j, n: int) -> np.ndarray:
    """int64 vertex keys of lattice points; arrays broadcast."""
    m = np.int64(n + 1)
    return (np.asarray(patch, dtype=np.int64) * m + np.asarray(i, dtype=np.int64)) * m + np.asarray(
        j, dtype=np.int64
    )


def decode_key(key: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(patch, i, j) int64 arrays of vertex keys."""
    m = np.int64(n + 1)
    key = np.asarray(key, dtype=np.int64)
    return key // (m * m), (key // m) % m, key % m


def leaf_corner_lattice(forest: Forest) -> np.ndarray:
    """(L, 4, 2) int64 lattice corners, counter-clockwise; triangles repeat corner 2 in slot 3."""
    out = np.empty((forest.n_leaves, 4, 2), dtype=np.int64)
    _leaf_corner_lattice(
        np.ascontiguousarray(forest.leaf_i, dtype=np.int64),
        np.ascontiguousarray(forest.leaf_j, dtype=np.int64),
        np.ascontiguousarray(forest.leaf_size, dtype=np.int64),
        np.ascontiguousarray(forest.leaf_is_quad, dtype=np.bool_),
        np.ascontiguousarray(forest.leaf_flip, dtype=np.bool_),
        _CORNER_OFFSETS,
        out,
    )
    return out


#: the corner offsets of a quad, an "up" and a "down" triangle (corner 2 repeated in slot 3)
_CORNER_OFFSETS = np.stack(
    [QUAD_CORNERS, np.vstack([UP_CORNERS, UP_CORNERS[2:]]), np.vstack([DOWN_CORNERS, DOWN_CORNERS[2:]])]
).astype(np.int64)


@njit(cache=True, nogil=True)
def _leaf_corner_lattice(i, j, size, is_quad, flip, offsets, out):
    for k in range(i.shape[0]):
        kind = 0 if is_quad[k] else (2 if flip[k] else 1)
        for c in range(4):
            out[k, c, 0] = i[k] + offsets[kind, c, 0] * size[k]
            out[k, c, 1] = j[k] + offsets[kind, c, 1] * size[k]


def leaf_corner_keys(forest: Forest) -> np.ndarray:
    """(L, 4) int64 corner keys; triangles repeat corner 2 in slot 3."""
    c = leaf_corner_lattice(forest)
    return make_key(forest.leaf_patch[:, None], c[..., 0], c[..., 1], forest.n)


def sorted_unique(keys: np.ndarray) -> np.ndarray:
    """(K,) sorted unique values of ``keys`` (any shape): ``np.unique`` without its overhead.

    ``np.sort`` + a mask of the first of each run. numpy 2.4's ``np.unique`` (hash-based, then
    sorted) takes 0.5-0.9 s on 1 M random int64 keys where this takes 0.05-0.07 s (9-12x), and
    0.09-0.15 s against 0.06-0.07 s on the leaf-corner keys of a 256 000-leaf forest
    (docs/stability.md, G1).
    """
    return _first_of_runs(np.sort(np.asarray(keys).ravel()))


def _first_of_runs(k: np.ndarray) -> np.ndarray:
    """The first of each run of equal values of sorted k."""
    return k[np.r_[True, k[1:] != k[:-1]]] if len(k) else k


def vertex_keys(forest: Forest) -> np.ndarray:
    """(V,) int64 sorted unique keys of every leaf corner."""
    return sorted_unique(leaf_corner_keys(forest))


def lookup(keys: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Indices of ``query`` in sorted ``keys``; -1 where absent. Shapes follow ``query``. A binary
    search per query, spread over the threads."""
    query = np.asarray(query, dtype=np.int64)
    out = np.empty(query.shape, dtype=np.int64)
    _lookup(
        np.ascontiguousarray(keys, dtype=np.int64), np.ascontiguousarray(query).reshape(-1), out.reshape(-1)
    )
    return out


@njit(cache=True, parallel=True, nogil=True)
def _lookup(keys, query, out):
    n = keys.shape[0]
    for i in prange(query.shape[0]):
        x = query[i]
        lo, hi = 0, n
        while lo < hi:
            mid = (lo + hi) >> 1
            if keys[mid] < x:
                lo = mid + 1
            else:
                hi = mid
        out[i] = lo if lo < n and keys[lo] == x else -1


def split(forest: Forest, mask: np.ndarray) -> Forest:
    """Replace the leaves where ``mask`` (L,) is True by their four children.

    Leaves already at ``max_depth`` are left as they are.
    """
    mask = np.asarray(mask, dtype=bool) & (forest.leaf_level < forest.max_depth)
    if not mask.any():
        return forest
    keep = forest.take(~mask)
    par = forest.take(mask)
    h = (par.leaf_size // 2).astype(np.int32)
    i, j, q, f = par.leaf_i, par.leaf_j, par.leaf_is_quad, par.leaf_flip
    # child anchors (4, k) and flips (4, k)
    ci = np.stack([i, i + h, i, i + h])
    cj = np.stack([j, j, j + h, j + h])
    cf = np.zeros((4, len(i)), dtype=bool)
    up = ~q & ~f
    down = ~q & f
    # up triangle: up (i,j), up (i+h,j), up (i,j+h), down (i,j)
    ci[3, up], cj[3, up], cf[3, up] = i[up], j[up], True
    # down triangle: down (i+h,j), down (i,j+h), down (i+h,j+h), up (i+h,j+h)
    ci[0, down], cj[0, down] = i[down] + h[down], j[down]
    ci[1, down], cj[1, down] = i[down], j[down] + h[down]
    ci[2, down], cj[2, down] = i[down] + h[down], j[down] + h[down]
    ci[3, down], cj[3, down] = i[down] + h[down], j[down] + h[down]
    cf[:3, down] = True
    cf[3, down] = False
    return Forest(
        forest.max_depth,
        forest.patch_is_quad,
        np.concatenate([keep.leaf_patch, np.tile(par.leaf_patch, 4)]),
        np.concatenate([keep.leaf_level, np.tile(par.leaf_level + 1, 4).astype(np.int8)]),
        np.concatenate([keep.leaf_i, ci.reshape(-1)]).astype(np.int32),
        np.concatenate([keep.leaf_j, cj.reshape(-1)]).astype(np.int32),
        np.concatenate([keep.leaf_flip, cf.reshape(-1)]),
    )


def _edge_points(forest: Forest, fractions: tuple[int, ...], denom: int) -> np.ndarray:
    """(L, 4, len(fractions)) int64 keys of points at ``f / denom`` along each leaf edge.

    Edges run corner k -> corner k+1; triangles' slot-3 edge is degenerate
    (corner 2 -> corner 2 repeated) and is replaced by edge 2 -> 0.
    """
    fr = np.asarray(fractions, dtype=np.int64)
    out = np.empty((forest.n_leaves, 4, len(fr)), dtype=np.int64)
    _edge_keys(
        leaf_corner_lattice(forest),
        np.ascontiguousarray(forest.leaf_is_quad, dtype=np.bool_),
        np.ascontiguousarray(forest.leaf_patch, dtype=np.int64),
        fr,
        denom,
        forest.n,
        out,
    )
    return out


@njit(cache=True, nogil=True)
def _edge_keys(c, is_quad, patch, fr, denom, n, out):
    """:func:`_edge_points` compiled (integer arithmetic: floor division as numpy's)."""
    m = n + 1
    for k in range(c.shape[0]):
        for e in range(4):
            a = e if is_quad[k] or e < 3 else 2  # triangles: 0-1, 1-2, 2-0, and 2-0 again in slot 3
            b = (e + 1) % 4 if is_quad[k] else (e + 1 if e < 2 else 0)
            for f in range(fr.shape[0]):
                pi = c[k, a, 0] + ((c[k, b, 0] - c[k, a, 0]) * fr[f]) // denom
                pj = c[k, a, 1] + ((c[k, b, 1] - c[k, a, 1]) * fr[f]) // denom
                out[k, e, f] = (patch[k] * m + pi) * m + pj


def balance(forest: Forest) -> Forest:
    """Split leaves until every leaf's edge neighbours are at most one level finer (2:1): a leaf of
    size 4 or more is split when a vertex lies at a quarter of one of its edges. After a round, a
    leaf it left is tested only against the round's new vertices (it was not split for the others)."""
    keys = vertex_keys(forest)
    fresh, kept = keys, forest.n_leaves  # the vertices to test the first ``kept`` leaves against
    while True:
        big = forest.leaf_size >= 4
        if not big.any():
            return forest
        bad = np.zeros(forest.n_leaves, dtype=bool)
        for sel, against in ((np.flatnonzero(big[:kept]), fresh), (kept + np.flatnonzero(big[kept:]), keys)):
            if len(sel):
                bad[sel] = (lookup(against, _edge_points(forest.take(sel), (1, 3), 4)) >= 0).any(axis=(1, 2))
        if not bad.any():
            return forest
        before = forest.n_leaves
        forest = split(forest, bad)
        # a split leaf's corners are its children's: the new vertices are the children's corners
        # (:func:`split` puts the 4 children of each of the k split leaves last)
        children = 4 * (forest.n_leaves - before) // 3
        kept = forest.n_leaves - children
        fresh = sorted_unique(leaf_corner_keys(forest.take(slice(kept, None))))
        keys = merge_keys(keys, fresh)


def merge_keys(keys: np.ndarray, more: np.ndarray) -> np.ndarray:
    """(K,) sorted unique union of sorted unique ``keys`` and ``more`` (any shape and order): the
    two sorted runs merged by numpy's stable sort (timsort: linear in their length), not sorted anew."""
    return _first_of_runs(np.sort(np.concatenate([keys, np.sort(np.ravel(more))]), kind="stable"))


def hanging_midpoints(forest: Forest, keys: np.ndarray) -> np.ndarray:
    """(L, 4) int64 vertex indices of hanging midpoints on each edge, -1 where none.

    Edge k runs from corner k to corner k+1 (triangles: 0-1, 1-2, 2-0; slot 3 is -1).
    """
    out = np.full((forest.n_leaves, 4), -1, dtype=np.int64)
    sel = forest.leaf_size >= 2
    if sel.any():
        mid = _edge_points(forest.take(sel), (1,), 2)[..., 0]
        out[sel] = lookup(keys, mid)
    out[~forest.leaf_is_quad, 3] = -1
    return out


def triangulate(forest: Forest, keys: np.ndarray) -> np.ndarray:
    """(T, 3) int32 anchored triangles, indices into ``keys``, counter-clockwise.

    A leaf with no hanging vertex gives two triangles (quad) or one (triangle);
    one with hanging midpoints is fanned from its first hanging midpoint over its
    boundary polygon, so neighbours share every edge point: no cracks.
    """
    corner = lookup(keys, leaf_corner_keys(forest))  # (L, 4)
    mid = hanging_midpoints(forest, keys)  # (L, 4)
    n_leaf = forest.n_leaves
    poly = np.full((n_leaf, 8), -1, dtype=np.int64)
    poly[:, 0::2] = corner
    poly[:, 1::2] = mid
    tri = ~forest.leaf_is_quad
    poly[tri, 6] = -1  # triangles have three corners
    present = poly >= 0
    # compact each row: present entries first, in order
    order = np.argsort(~present, axis=1, kind="stable")
    poly = np.take_along_axis(poly, order, axis=1)
    is_mid = np.take_along_axis(np.tile(np.arange(8) % 2 == 1, (n_leaf, 1)), order, axis=1)
    k = present.sum(axis=1)
    has_mid = (is_mid & (np.arange(8)[None, :] < k[:, None])).any(axis=1)
    start = np.where(has_mid, np.argmax(is_mid & (np.arange(8)[None, :] < k[:, None]), axis=1), 0)
    rows = np.arange(n_leaf)
    out = []
    for t in range(1, 7):
        ok = t <= k - 2
        if not ok.any():
            break
        r, s, kk = rows[ok], start[ok], k[ok]
        out.append(np.stack([poly[r, s], poly[r, (s + t) % kk], poly[r, (s + t + 1) % kk]], axis=1))
    return np.concatenate(out).astype(np.int32) if out else np.zeros((0, 3), dtype=np.int32)


def bilinear(c: np.ndarray, u, v) -> np.ndarray:
    """(k, d) the bilinear blend of corner values c (k, 4, d) at parameters u, v (k,): the
    quad parametrisation of :mod:`iat.io.scene`, for positions, detail uvs or anything else."""
    u = np.asarray(u, dtype=np.float64)[:, None]
    v = np.asarray(v, dtype=np.float64)[:, None]
    return (1 - u) * (1 - v) * c[:, 0] + u * (1 - v) * c[:, 1] + u * v * c[:, 2] + (1 - u) * v * c[:, 3]


def patch_point(patch_corners: np.ndarray, patch_is_quad: np.ndarray, patch, u, v) -> np.ndarray:
    """(k, 3) float64 world points at parameters (u, v) (k,) of patches ``patch`` (k,): bilinear on
    quads (as :func:`bilinear`), barycentric on triangles."""
    patch = np.ascontiguousarray(patch, dtype=np.int64)
    out = np.empty((len(patch), 3))
    _patch_point(
        np.ascontiguousarray(patch_corners, dtype=np.float64),
        np.ascontiguousarray(patch_is_quad, dtype=np.bool_),
        patch,
        np.ascontiguousarray(u, dtype=np.float64).reshape(-1),
        np.ascontiguousarray(v, dtype=np.float64).reshape(-1),
        out,
    )
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _patch_point(corners, is_quad, patch, u, v, out):
    """:func:`patch_point` compiled (a mesh's every leaf corner, each refinement pass): the numpy
    expressions' arithmetic in their order, so the same bits."""
    for k in range(patch.shape[0]):
        p, a, b = patch[k], u[k], v[k]
        c = corners[p]
        if is_quad[p]:
            w0, w1, w2, w3 = (1 - a) * (1 - b), a * (1 - b), a * b, (1 - a) * b
            for x in range(3):
                out[k, x] = w0 * c[0, x] + w1 * c[1, x] + w2 * c[2, x] + w3 * c[3, x]
        else:
            for x in range(3):
                out[k, x] = c[0, x] + a * (c[1, x] - c[0, x]) + b * (c[2, x] - c[0, x])


def lattice_to_world(patch_corners: np.ndarray, patch_is_quad: np.ndarray, patch, i, j, n: int) -> np.ndarray:
    """(k, 3) float64 world positions of lattice points.

    patch_corners : (P, 4, 3) float64; patch_is_quad : (P,) bool; patch, i, j : (k,) ints
    """
    u = np.asarray(i, dtype=np.float64) / n
    v = np.asarray(j, dtype=np.float64) / n
    return patch_point(patch_corners, patch_is_quad, patch, u, v)


def keys_to_world(
    patch_corners: np.ndarray, patch_is_quad: np.ndarray, keys: np.ndarray, n: int
) -> np.ndarray:
    """(V, 3) float64 world positions of vertex keys."""
    p, i, j = decode_key(keys, n)
    return lattice_to_world(patch_corners, patch_is_quad, p, i, j, n)


def leaf_area(forest: Forest, patch_corners: np.ndarray) -> np.ndarray:
    """(L,) float64 world area of each leaf."""
    c = leaf_corner_lattice(forest)
    w = lattice_to_world(
        patch_corners,
        forest.patch_is_quad,
        np.repeat(forest.leaf_patch, 4),
        c[..., 0].reshape(-1),
        c[..., 1].reshape(-1),
        forest.n,
    ).reshape(-1, 4, 3)
    a = 0.5 * np.linalg.norm(np.cross(w[:, 1] - w[:, 0], w[:, 2] - w[:, 0]), axis=1)
    a += 0.5 * np.linalg.norm(np.cross(w[:, 2] - w[:, 0], w[:, 3] - w[:, 0]), axis=1)  # 0 for triangles
    return a
