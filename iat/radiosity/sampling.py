"""Sampling kernels of the solver: hashed jitter, the concentric disc map, Gauss rules, the geometry of
a shooting patch (:class:`Shooter`) and radiance fields on a patch lattice (:class:`Lattice`)."""

from __future__ import annotations

import math

import numpy as np

from iat.color import LUMINANCE_WEIGHTS
from iat.geometry import quadtree as qt


def hash_uniform(keys: np.ndarray, salt: int, k: int = 2) -> np.ndarray:
    """(n, k) float64 in [0, 1): k splitmix64 hashes of (key, salt)."""
    z = np.asarray(keys, dtype=np.int64).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    z ^= np.uint64(salt & 0xFFFFFFFFFFFFFFFF)
    out = []
    for _ in range(k):
        z = z + np.uint64(0x9E3779B97F4A7C15)
        x = z.copy()
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x = x ^ (x >> np.uint64(31))
        out.append((x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53)))
    return np.stack(out, axis=1)


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


def rotated_disk(pattern: np.ndarray, ru: np.ndarray, rv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`concentric_disk` of a stratified pattern (S, 2) in [0, 1)^2 shifted by ``ru``, ``rv``
    (k, 1) per row (Cranley-Patterson rotation, modulo 1): (k, S) disc points each."""
    return concentric_disk((pattern[None, :, 0] + ru) % 1.0, (pattern[None, :, 1] + rv) % 1.0)


def _cross2(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]


class Shooter:
    """Geometry of one patch as a shooter: kernel terms, inside test, inverse parametrisation,
    area Jacobian.

    Quads: ``p(u, v) = c0 + u e1 + v e2 + u v e3`` (bilinear); triangles: ``c0 + u e1 + v e2``.
    ``area`` is the lattice's whole area (a panel cell's rectangle) and ``mask`` a panel cell's
    surface coverage (samples off it count for nothing).
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

    def kernel(self, u: np.ndarray, v: np.ndarray, d0: np.ndarray, nr: np.ndarray) -> np.ndarray:
        """(b, S) ``cos_r cos_s / (pi r^2)`` at points p(u, v) (u, v: (b or 1, S)) seen from
        receivers with normals nr (b, 3) at ``origin - d0`` (d0: (b, 3))."""
        g, bn = self.gram, self.bn
        d0n = np.einsum("bc,bc->b", d0, nr)[:, None]
        dd = np.einsum("bc,bc->b", d0, d0)[:, None]
        de = d0 @ self.basis.T  # (b, 3): d0 . e1, d0 . e2, d0 . e3
        en = nr @ self.basis.T  # (b, 3)
        h = (d0 @ self.normal)[:, None]
        dn = d0n + u * en[:, :1] + v * en[:, 1:2]  # d . nr, d = p - x
        ds = h + u * bn[0] + v * bn[1]  # d . n_s (< 0 in front)
        r2 = (
            dd
            + 2 * u * de[:, :1]
            + 2 * v * de[:, 1:2]
            + u * u * g[0, 0]
            + v * v * g[1, 1]
            + 2 * u * v * g[0, 1]
        )
        if not self.parallelogram:
            uv = u * v
            dn = dn + uv * en[:, 2:3]
            ds = ds + uv * bn[2]
            r2 = r2 + 2 * uv * de[:, 2:3] + uv * uv * g[2, 2] + 2 * uv * (u * g[0, 2] + v * g[1, 2])
        return np.maximum(dn, 0.0) * np.maximum(-ds, 0.0) / (np.pi * np.maximum(r2 * r2, 1e-300))

    def on_surface(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(...) bool: lattice (u, v) is on a panel cell's surface (its mask)."""
        r = self.mask.shape[0]
        a = np.clip((np.asarray(u) * r).astype(np.int64), 0, r - 1)
        b = np.clip((np.asarray(v) * r).astype(np.int64), 0, r - 1)
        return self.mask[b, a]

    def inside(self, pts: np.ndarray) -> np.ndarray:
        """(...) bool: points (..., 3) on the plane inside the convex polygon."""
        ok = np.ones(pts.shape[:-1], dtype=bool)
        for o, en in zip(self.edge_o, self.edge_n, strict=True):
            ok &= (pts - o) @ en <= self.tol * np.linalg.norm(en)
        return ok

    def inside_uv(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(...) bool: parallelogram / triangle parameters inside the patch."""
        t = 1e-9
        ok = (u >= -t) & (v >= -t)
        return ok & (u + v <= 1 + t) if not self.is_quad else ok & (u <= 1 + t) & (v <= 1 + t)

    def clip_uv(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, v = np.clip(u, 0.0, 1.0), np.clip(v, 0.0, 1.0)
        if not self.is_quad:
            tot = np.maximum(u + v, 1.0)
            u, v = u / tot, v / tot
        return u, v

    def foot_uv(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice parameters of the feet of points x (b, 3) on the patch plane (clipped)."""
        if self.parallelogram:
            rel = x - self.origin
            return self.clip_uv(rel @ self.a1, rel @ self.a2)
        foot = x - ((x - self.origin) @ self.normal)[:, None] * self.normal
        return self.uv(foot)

    def uv(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice parameters (u, v) of points (..., 3) on the patch plane (clipped to the patch)."""
        h = (pts - self.origin) @ self.frame.T  # (..., 2)
        e, f, g = self.frame @ self.e1, self.frame @ self.e2, self.frame @ self.e3
        if not self.is_quad or np.abs(g).max() <= 1e-12 * max(np.abs(e).max(), np.abs(f).max()):
            det = _cross2(e, f)
            u, v = _cross2(h, f) / det, _cross2(e, h) / det
        else:  # inverse bilinear: k2 v^2 + k1 v + k0 = 0
            k2 = _cross2(g, f)
            k1 = _cross2(e, f) + _cross2(h, g)
            k0 = _cross2(h, e)
            if abs(k2) < 1e-14:
                v = -k0 / np.where(k1 == 0, 1e-300, k1)
            else:
                disc = np.sqrt(np.clip(k1 * k1 - 4 * k0 * k2, 0.0, None))
                v1, v2 = (-k1 - disc) / (2 * k2), (-k1 + disc) / (2 * k2)
                v = np.where((v1 >= -1e-9) & (v1 <= 1 + 1e-9), v1, v2)
            den = e + v[..., None] * g
            u = np.einsum("...c,...c->...", h - v[..., None] * f, den) / np.maximum(
                np.einsum("...c,...c->...", den, den), 1e-300
            )
        return self.clip_uv(u, v)

    def point(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(..., 3) points at lattice parameters (u, v)."""
        u, v = np.asarray(u)[..., None], np.asarray(v)[..., None]
        p = self.origin + u * self.e1 + v * self.e2
        return p if self.parallelogram else p + (u * v) * self.e3

    def target(self, pts: np.ndarray) -> np.ndarray:
        """(..., 3) ray targets for points on the patch: ``eps`` off its front, and pulled
        towards its centre by at most ``eps`` (so a target at a corner is not inside a
        neighbouring wall)."""
        return pts + self.eps * self.normal + self.shrink * (self.centre - pts)

    def target_uv(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(k, 3) :meth:`target` of the points at lattice parameters u, v (k,)."""
        k = 1.0 - self.shrink
        base = k * self.origin + self.eps * self.normal + self.shrink * self.centre
        out = base + np.outer(u, k * self.e1) + np.outer(v, k * self.e2)
        return out if self.parallelogram else out + np.outer(u * v, k * self.e3)

    def target_uv32(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(k, 3) float32 :meth:`target_uv` (the ray targets as embreex takes them)."""
        if not hasattr(self, "_t32"):
            k = 1.0 - self.shrink
            base = k * self.origin + self.eps * self.normal + self.shrink * self.centre
            self._t32 = tuple(
                np.asarray(x, dtype=np.float32) for x in (base, k * self.e1, k * self.e2, k * self.e3)
            )
        base, e1, e2, e3 = self._t32
        u32, v32 = u.astype(np.float32)[:, None], v.astype(np.float32)[:, None]
        out = u32 * e1
        out += v32 * e2
        out += base
        if not self.parallelogram:
            out += (u32 * v32) * e3
        return out

    def jacobian(self, u: np.ndarray, v: np.ndarray) -> np.ndarray | float:
        """Area per unit (u, v) of the area samples at lattice parameters (u, v)."""
        if self.parallelogram:  # constant; the square -> triangle warp is area-uniform too
            return self.area
        c = self.cgram
        j2 = (
            c[0, 0]
            + u * u * c[1, 1]
            + v * v * c[2, 2]
            + 2 * u * c[0, 1]
            + 2 * v * c[0, 2]
            + 2 * u * v * c[1, 2]
        )
        return np.maximum(np.sqrt(np.maximum(j2, 0.0)), 1e-300)


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


def weighted_lattice_sums(
    flat_t: np.ndarray, n: int, u: np.ndarray, v: np.ndarray, w: np.ndarray, rows: np.ndarray, n_rows: int
) -> np.ndarray:
    """(n_rows, 3) sums over samples grouped by ``rows`` of ``w`` x the lattice field at (u, v):
    ``bincount(rows, w * sample_lattice(flat, n, u, v)[:, c])`` per channel, from the
    transposed field ``flat_t`` (3, (N+1)**2), with 1-D gathers and no (k, 3) temporaries."""
    x, y = u * n, v * n
    a = np.minimum(x.astype(np.int64), n - 1)
    b = np.minimum(y.astype(np.int64), n - 1)
    fx, fy = x - a, y - b
    i00 = a * (n + 1) + b
    sxy = fx + fy
    lower = sxy <= 1.0
    w_base = np.abs(1.0 - sxy) * w
    i_base = np.where(lower, i00, i00 + n + 2)
    w10 = np.where(lower, fx, 1.0 - fy) * w
    w01 = np.where(lower, fy, 1.0 - fx) * w
    i10, i01 = i00 + n + 1, i00 + 1
    out = np.empty((n_rows, 3))
    for c in range(3):
        fc = flat_t[c]
        val = fc.take(i_base) * w_base
        val += fc.take(i10) * w10
        val += fc.take(i01) * w01
        out[:, c] = np.bincount(rows, weights=val, minlength=n_rows)
    return out


class Lattice:
    """Per-patch radiance on the full lattice from vertex values (the shooters' radiance fields)."""

    def __init__(self, forest: qt.Forest, keys: np.ndarray):
        self.forest = forest
        self.n = forest.n
        self.corner = qt.lookup(keys, qt.leaf_corner_keys(forest))  # (L, 4)
        self.order = np.argsort(forest.leaf_patch, kind="stable")
        self.starts = np.searchsorted(forest.leaf_patch[self.order], np.arange(forest.n_patches + 1))
        self._offsets: dict[int, tuple] = {}

    def _level(self, level: int):
        if level not in self._offsets:
            s = self.n >> level
            a, b = np.meshgrid(np.arange(s + 1), np.arange(s + 1), indexing="ij")
            a, b = a.ravel(), b.ravel()
            x, y = a / s, b / s
            wq = np.stack([(1 - x) * (1 - y), x * (1 - y), x * y, (1 - x) * y], axis=1)
            up = np.flatnonzero(a + b <= s)
            down = np.flatnonzero(a + b >= s)
            wu = np.stack([1 - x - y, x, y, 0 * x], axis=1)[up]  # corners (0,0), (1,0), (0,1)
            wd = np.stack([x + y - 1, 1 - x, 1 - y, 0 * x], axis=1)[down]  # (1,1), (0,1), (1,0)
            self._offsets[level] = (a, b, wq, up, wu, down, wd)
        return self._offsets[level]

    def grid(self, p: int, values: np.ndarray) -> np.ndarray:
        """(N+1, N+1, 3) values of patch p on its lattice, interpolated in its leaves from ``values``."""
        n, fo = self.n, self.forest
        g = np.zeros((n + 1, n + 1, 3))
        leaves = self.order[self.starts[p] : self.starts[p + 1]]
        lvl = fo.leaf_level[leaves]
        for level in np.unique(lvl):
            sel = leaves[lvl == level]
            a, b, wq, up, wu, down, wd = self._level(int(level))
            vals = values[self.corner[sel]]  # (l, 4, 3)
            i0, j0 = fo.leaf_i[sel][:, None], fo.leaf_j[sel][:, None]
            if fo.patch_is_quad[p]:
                g[i0 + a, j0 + b] = np.einsum("gk,lkc->lgc", wq, vals)
                continue
            flip = fo.leaf_flip[sel]
            for mask, pts, w in ((~flip, up, wu), (flip, down, wd)):
                if mask.any():
                    g[i0[mask] + a[pts], j0[mask] + b[pts]] = np.einsum("gk,lkc->lgc", w, vals[mask])
        return g


def pattern_side(samples: int) -> int:
    return max(1, math.ceil(math.sqrt(samples) - 1e-9))


def luminance_of(x: np.ndarray) -> np.ndarray:
    return np.asarray(x) @ LUMINANCE_WEIGHTS
