"""Sampling kernels of the solver: hashed jitter, the concentric disc map, Gauss rules, the geometry of
a shooting patch (:class:`Shooter`) and radiance fields on a patch lattice (:class:`Lattice`)."""

from __future__ import annotations

import math

import numpy as np

from iat.color import LUMINANCE_WEIGHTS
from iat.geometry import quadtree as qt
from iat.radiosity.bundles import ShooterArrays
from iat.radiosity.kernels import hash_keys
from iat.radiosity.lattice_kernels import leaf_fields, tent_means

#: a coarse grid point is the tent-weighted mean of this many fine points per cell side
COARSE_SUB = 4
#: patches whose fine fields are read at once
COARSE_CHUNK = 256


def hash_uniform(keys: np.ndarray, salt: int, k: int = 2) -> np.ndarray:
    """(n, k) float64 in [0, 1): k splitmix64 hashes of (key, salt) (:func:`.kernels.hash_keys`)."""
    keys = np.ascontiguousarray(keys, dtype=np.int64).reshape(-1)
    return hash_keys(keys, np.uint64(int(salt) & 0xFFFFFFFFFFFFFFFF), int(k))


def concentric_disk(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shirley-Chiu concentric map of the unit square onto the unit disc."""
    a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    phi = np.where(first, (np.pi / 4) * b / safe_a, np.pi / 2 - (np.pi / 4) * a / safe_b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


_G2 = 0.5 + np.array([-0.5, 0.5]) / math.sqrt(3.0)
#: ((u, v) (1, G) each, weights (G,)) of the Gauss rules in lattice parameters: 2 x 2 on the
#: unit square (weights x Jacobian), Dunavant's degree-4 rule on triangles (weights x area:
#: the triangles' Jacobian is their area)
GAUSS_QUAD = (
    (np.repeat(_G2, 2)[None, :], np.tile(_G2, 2)[None, :]),
    np.full(4, 0.25),
)
_DA, _DB = 0.445948490915965, 0.091576213509771
GAUSS_TRI = (
    (
        np.array([[_DA, 1 - 2 * _DA, _DA, _DB, 1 - 2 * _DB, _DB]]),
        np.array([[_DA, _DA, 1 - 2 * _DA, _DB, _DB, 1 - 2 * _DB]]),
    ),
    np.array([0.223381589678011] * 3 + [0.109951743655322] * 3),
)


def disk_to_hemisphere(dx, dy, t1, t2, normal) -> np.ndarray:
    """(k, S, 3) directions: disc points ``dx, dy`` ((k, S), or (1, S) shared by all) lifted to the
    hemisphere (Malley: cosine-distributed for uniform disc points) in the frames ``t1, t2, normal``
    (k, 3) each."""
    dz = np.sqrt(np.maximum(1.0 - dx * dx - dy * dy, 0.0))
    return dx[..., None] * t1[:, None] + dy[..., None] * t2[:, None] + dz[..., None] * normal[:, None]


def rotated_disk(pattern: np.ndarray, ru: np.ndarray, rv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`concentric_disk` of a stratified pattern (S, 2) in [0, 1)^2 shifted by ``ru``, ``rv``
    (k, 1) per row (Cranley-Patterson rotation, modulo 1): (k, S) disc points each."""
    return concentric_disk((pattern[None, :, 0] + ru) % 1.0, (pattern[None, :, 1] + rv) % 1.0)


class Shooter:
    """Geometry of one patch as a shooter, in the form the gather kernels take it
    (:meth:`kernel_args`, :mod:`iat.radiosity.kernels`).

    Quads: ``p(u, v) = c0 + u e1 + v e2 + u v e3`` (bilinear); triangles: ``c0 + u e1 + v e2``.
    ``area`` is the lattice's whole area (a panel cell's rectangle) and ``mask`` a panel cell's
    surface coverage (samples off it count for nothing). Ray targets are ``eps`` off its front
    and pulled towards its centre by at most ``eps`` (a target at a corner is not inside a
    neighbouring wall).
    """

    def __init__(
        self,
        corners: np.ndarray,
        is_quad: bool,
        normal: np.ndarray,
        area: float,
        eps: float,
        mask: np.ndarray | None = None,
    ):
        self.is_quad = is_quad
        self.mask = mask  # (r, r) bool surface of a panel cell (mask[v, u]), None: all of it
        self.normal = normal
        self.area = area
        c = corners if is_quad else corners[:3]
        self.origin = c[0]
        self.poly = c
        self.e1 = corners[1] - corners[0]
        self.e2 = (corners[3] if is_quad else corners[2]) - corners[0]
        self.e3 = corners[0] - corners[1] + corners[2] - corners[3] if is_quad else np.zeros(3)
        scale = max(np.linalg.norm(self.e1), np.linalg.norm(self.e2))
        self.parallelogram = not is_quad or np.linalg.norm(self.e3) <= 1e-12 * scale
        self.centre = c.mean(axis=0)
        self.eps = eps
        self.shrink = eps / max(float(np.linalg.norm(c - self.centre, axis=1).max()), 1e-300)
        t1 = self.e1 / max(np.linalg.norm(self.e1), 1e-300)
        self.frame = np.stack([t1, np.cross(normal, t1)])  # (2, 3) in-plane axes
        self.edge_n = np.cross(np.roll(c, -1, axis=0) - c, normal)  # (k, 3) outward edge normals
        self.edge_o = c
        self.tol = 1e-9 * max(float(np.abs(c - c.mean(axis=0)).max()), 1e-300)
        # dual basis of (e1, e2) in the plane: (y - origin) . a1 = u for parallelograms
        cn = float(np.cross(self.e1, self.e2) @ normal)
        cn = cn if abs(cn) > 1e-300 else 1e-300
        self.a1 = np.cross(self.e2, normal) / cn
        self.a2 = np.cross(normal, self.e1) / cn
        # Gram terms of the parametrisation, for kernels from per-receiver scalars
        self.basis = np.stack([self.e1, self.e2, self.e3])  # (3, 3)
        self.gram = self.basis @ self.basis.T
        self.bn = self.basis @ normal
        cr = np.stack([np.cross(self.e1, self.e2), np.cross(self.e1, self.e3), np.cross(self.e3, self.e2)])
        self.cgram = cr @ cr.T
        e, f, g = self.frame @ self.e1, self.frame @ self.e2, self.frame @ self.e3
        linear = not is_quad or np.abs(g).max() <= 1e-12 * max(np.abs(e).max(), np.abs(f).max())
        k = 1.0 - self.shrink
        base = k * self.origin + eps * normal + self.shrink * self.centre
        rows = [self.origin, normal, self.e1, self.e2, self.e3, self.a1, self.a2, *self.frame]
        self._kargs = ShooterArrays(
            geom=np.vstack([*rows, self.gram, self.cgram, self.bn]).astype(np.float64),
            uvc=np.ascontiguousarray(np.stack([e, f, g]), dtype=np.float64),
            poly_n=np.ascontiguousarray(self.edge_n, dtype=np.float64),
            poly_o=np.ascontiguousarray(self.edge_o, dtype=np.float64),
            tol=float(self.tol),
            is_quad=bool(is_quad),
            para=bool(self.parallelogram),
            linear_uv=bool(linear),
            area=float(area),
            mask=np.zeros((1, 1), dtype=bool) if mask is None else np.ascontiguousarray(mask, dtype=bool),
            has_mask=mask is not None,
            t32=np.stack([base, k * self.e1, k * self.e2, k * self.e3]).astype(np.float32),
            half_eps=np.float32(0.5 * eps),
        )

    def kernel_args(self) -> ShooterArrays:
        """The shooter as :mod:`iat.radiosity.kernels` takes it (``k = 1 - shrink`` in ``t32``:
        the targets of points p(u, v))."""
        return self._kargs


def sample_lattice(flat: np.ndarray, n: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(k, 3) piecewise-linear interpolation at lattice parameters u, v (k,) of a lattice
    grid given flat, ((N+1)**2, 3).

    Each lattice cell is split along its anti-diagonal, so triangle patches (points with
    ``u + v <= 1``) only ever read lattice points inside the triangle.
    """
    x, y = u * n, v * n
    a = np.minimum(x.astype(np.int64), n - 1)
    b = np.minimum(y.astype(np.int64), n - 1)
    fx, fy = x - a, y - b
    i00 = a * (n + 1) + b
    lower = fx + fy <= 1.0
    # lower: g00 (1-fx-fy) + g10 fx + g01 fy ; upper: g11 (fx+fy-1) + g01 (1-fx) + g10 (1-fy)
    w_base = np.where(lower, 1.0 - fx - fy, fx + fy - 1.0)
    i_base = np.where(lower, i00, i00 + n + 2)
    w10 = np.where(lower, fx, 1.0 - fy)
    w01 = np.where(lower, fy, 1.0 - fx)
    return flat[i_base] * w_base[:, None] + flat[i00 + n + 1] * w10[:, None] + flat[i00 + 1] * w01[:, None]


class Lattice:
    """Per-patch radiance on the full lattice from vertex values (the shooters' radiance fields)."""

    def __init__(self, forest: qt.Forest, keys: np.ndarray):
        self.forest = forest
        self.n = forest.n
        self.corner = qt.lookup(keys, qt.leaf_corner_keys(forest))  # (L, 4)
        self.order = np.lexsort((forest.leaf_level, forest.leaf_patch))  # by patch, coarse leaves first
        self.starts = np.searchsorted(forest.leaf_patch[self.order], np.arange(forest.n_patches + 1))

    def grid(self, p: int, values: np.ndarray) -> np.ndarray:
        """(N+1, N+1, 3) values of patch p on its lattice, interpolated in its leaves from ``values``."""
        return self._fields(self.order[self.starts[p] : self.starts[p + 1]], 1, p, 1, values)[0]

    def coarse_grids(self, values: np.ndarray, g: int) -> np.ndarray:
        """(P, g+1, g+1, 3) every patch's field on the ``g`` x ``g`` lattice (``g`` a power of 2, at
        most N), each point the tent-weighted mean of the field around it (read ``COARSE_SUB`` times
        finer per side): the coarse grid's piecewise-linear field keeps the fine one's integral, so a
        sun patch smaller than a coarse cell keeps its power wherever it falls.
        values : (V, 3) at the lattice's vertex keys."""
        g = min(int(g), self.n)
        r = min(COARSE_SUB, self.n // g)  # fine points per coarse cell, per side
        fine = g * r
        tent = (r - np.abs(np.arange(1 - r, r))) / r  # (2r - 1,)
        ij = np.arange(fine + 1)
        edge = np.where((ij == 0) | (ij == fine), 0.5, 1.0)
        quad = edge[:, None] * edge[None, :]  # the fine points' shares of the patch (trapezoid rule)
        tri = np.where(ij[:, None] + ij[None, :] <= fine, quad, 0.0)  # a triangle's lattice points
        out = np.empty((self.forest.n_patches, g + 1, g + 1, 3))
        for a in range(0, self.forest.n_patches, COARSE_CHUNK):
            b = min(a + COARSE_CHUNK, self.forest.n_patches)
            leaves = self.order[self.starts[a] : self.starts[b]]
            f = self._fields(leaves, b - a, a, self.n // fine, values)
            tent_means(out[a:b], f, self.forest.patch_is_quad[a:b], quad, tri, tent, r)
        return out

    def _fields(self, leaves: np.ndarray, count: int, first: int, step: int, values: np.ndarray):
        """(count, N/step + 1, N/step + 1, 3) the fields of patches ``first`` on from ``leaves``."""
        fo, side = self.forest, self.n // step + 1
        out = np.zeros((count, side, side, 3))
        leaf_fields(
            out, first, step, leaves, fo.leaf_patch, fo.leaf_level, fo.leaf_i, fo.leaf_j, fo.leaf_flip,
            fo.patch_is_quad, self.corner, np.ascontiguousarray(values, dtype=np.float64),
        )  # fmt: skip
        return out


def finer_strata(strata: np.ndarray, pattern: np.ndarray, side: int) -> np.ndarray:
    """(S, 2) int64 strata of a side x side grid's points ``pattern`` (S, 2) in [0, 1)^2, lying in
    the strata ``strata`` (S, 2), on the grid of 2 side: each point's quarter of its stratum."""
    return 2 * strata + (pattern * side - strata >= 0.5)


def nested_pattern(
    pattern: np.ndarray, strata: np.ndarray, side: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The 3 S points that make a pattern of one point a stratum on the grid of 2 side, with the
    S points ``pattern`` (S, 2) of a side x side grid (one in each of its strata ``strata``
    (S, 2)): one jittered point in each quarter of a stratum its old point is not in.
    Returns ((3 S, 2) points, (3 S, 2) their strata on the finer grid)."""
    quarters = np.array([[0, 0], [0, 1], [1, 0], [1, 1]])
    sub = 2 * strata[:, None, :] + quarters[None]  # (S, 4, 2)
    free = np.any(sub != finer_strata(strata, pattern, side)[:, None, :], axis=2)
    new = sub[free]
    return (new + rng.random(new.shape)) / (2 * side), new


def pattern_side(samples: int) -> int:
    return max(1, math.ceil(math.sqrt(samples) - 1e-9))


def luminance_of(x: np.ndarray) -> np.ndarray:
    return np.asarray(x) @ LUMINANCE_WEIGHTS


#: no importance: the gather kernels' placeholder for :func:`field_importance`'s tables
NO_IMPORTANCE = np.zeros((1, 2))


def field_importance(field: np.ndarray, is_quad: bool, side: int, mix: float) -> np.ndarray:
    """The tables by which a gather draws its area samples by a shooter's light
    (:func:`iat.radiosity.kernels.importance_warp`), ``(2 G + 1, G + 1)`` float64, G = min(side, N):
    row 0 the cumulative density over the G columns of the unit square (``a``), rows ``1 + i`` the
    cumulative density over the G cells of column i (``b``), rows ``1 + G + i`` (first G entries) the
    density of column i's cells relative to uniform (mean 1). The density is ``mix`` uniform and
    ``1 - mix`` by the field's luminance (absolute) on each cell, read at 2 x 2 points of it, where
    the square maps to the shooter as the pattern does (onto a triangle by the square-root warp).
    field : the shooter's lattice radiance (N+1, N+1, 3)."""
    n = field.shape[0] - 1
    g = max(1, min(side, n))
    k = 2 * g
    c = (np.arange(k) + 0.5) / k
    a, b = (x.ravel() for x in np.meshgrid(c, c, indexing="ij"))
    if not is_quad:
        sq = np.sqrt(a)
        a, b = sq * (1.0 - b), sq * b
    flat = np.asarray(field, dtype=np.float64).reshape(-1, 3)
    lum = np.abs(luminance_of(sample_lattice(flat, n, a, b))).reshape(g, 2, g, 2).sum(axis=(1, 3))
    total = float(lum.sum())
    p = np.full((g, g), 1.0 / (g * g))
    if total > 0:
        p = mix * p + (1.0 - mix) * lum / total
    out = np.zeros((2 * g + 1, g + 1))
    col = p.sum(axis=1)
    out[0, 1:] = np.cumsum(col) / col.sum()
    out[1 : g + 1, 1:] = np.cumsum(p, axis=1) / col[:, None]
    out[0, g] = 1.0
    out[1 : g + 1, g] = 1.0
    out[g + 1 :, :g] = p * (g * g)
    return out


def peak_factor(grid: np.ndarray, ratio: float, limit: float) -> float:
    """How much more finely per side a shooter's field must be sampled than a smooth one:
    ``sqrt(peak / mean / ratio)`` of its luminance, between 1 and ``limit`` (a sun patch on a floor
    is a small bright part: the stratified points must land in it, or the shot's light is off by
    as much; fields within ``ratio`` of their mean are sampled as before).
    grid : a patch's lattice field, (..., 3) radiance."""
    lum = np.abs(luminance_of(np.asarray(grid, dtype=np.float64).reshape(-1, 3)))
    mean = float(lum.mean()) if lum.size else 0.0
    if mean <= 0:
        return 1.0
    return float(min(max(np.sqrt(lum.max() / mean / ratio), 1.0), limit))
