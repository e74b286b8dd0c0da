"""The per-scene arrays a solve reads and never writes (:class:`Patches`), the receiver geometry
of a set of vertex keys (:class:`ReceiverGeometry`) and the form-factor cache a mesh's geometry
carries (:class:`FormFactorCache`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from iat.geometry import quadtree as qt
from iat.geometry.clip import clamp_into, coverage_grid
from iat.geometry.sides import twin_index
from iat.radiosity.culling import pack
from iat.radiosity.options import (
    FF_CACHE_ENTRIES,
    FF_EPS,
    MAX_ELEMENT_FRACTION,
    MIN_ELEMENT_FRACTION,
    RAY_EPS,
    RAY_EPS_PATCH,
    SolveOptions,
)
from iat.radiosity.sampling import luminance_of


class FormFactorCache:
    """Per shooter, the analytic form factors it has to the receivers of one geometry (a mesh's
    vertices or a coarse grid): ``entries[s] = [idx (k,) int64, f (k,) float32, done (ceil(P /
    8),) uint8]`` (the receivers found so far, and the patches already searched as
    :func:`~iat.radiosity.culling.pack`'s bits). A patch shoots several times on the same mesh;
    when the entries (``done`` counted as its bytes / 12) exceed ``FF_CACHE_ENTRIES`` the oldest
    shooters go first."""

    def __init__(self):
        self.entries: dict[int, list[np.ndarray]] = {}
        self.size = 0

    def entry(self, s: int, n_patches: int) -> list[np.ndarray]:
        """The entry of shooter s, made empty when it has none."""
        e = self.entries.get(s)
        if e is None:
            e = self.entries[s] = [
                np.zeros(0, dtype=np.int64),
                np.zeros(0, dtype=np.float32),
                pack(np.zeros(n_patches, dtype=bool)),
            ]
            self.size += len(e[2]) // 12
        return e

    def grew(self, s: int, n: int) -> None:
        """Count n more entries of shooter s, dropping the oldest other shooters above the limit."""
        self.size += n
        while self.size > FF_CACHE_ENTRIES and len(self.entries) > 1:
            old = self.entries.pop(next(k for k in self.entries if k != s))
            self.size -= len(old[0]) + len(old[2]) // 12


@dataclass
class ReceiverGeometry:
    """Receiver geometry of a set of vertices (all (n, ...) arrays)."""

    key: np.ndarray  # (n,) int64 vertex keys
    patch: np.ndarray  # (n,) int64
    pos: np.ndarray  # (n, 3) world position on the patch
    normal: np.ndarray  # (n, 3)
    ff: np.ndarray  # (n, 3) form-factor point, nudged into its own patch
    origin: np.ndarray  # (n, 3) ray origin, off the surface
    start: np.ndarray | None = None  # (P + 1,) first index of each patch when keys are sorted
    cache: FormFactorCache | None = None  # per-shooter form factors (a mesh's or grid's geometry)
    _origin32: np.ndarray | None = None

    def origin32(self) -> np.ndarray:
        """(n, 3) float32 ray origins (made once)."""
        if self._origin32 is None:
            self._origin32 = np.ascontiguousarray(self.origin, dtype=np.float32)
        return self._origin32

    def take(self, idx) -> ReceiverGeometry:
        return ReceiverGeometry(
            self.key[idx], self.patch[idx], self.pos[idx], self.normal[idx], self.ff[idx], self.origin[idx]
        )


def ranges_of(start: np.ndarray, patches: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(start[p], start[p + 1])`` over ``patches`` (sorted)."""
    a, b = start[patches], start[patches + 1]
    n = b - a
    keep = n > 0
    a, n = a[keep], n[keep]
    if len(n) == 0:
        return np.zeros(0, dtype=np.int64)
    off = np.repeat(a - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    return np.arange(int(n.sum()), dtype=np.int64) + off


def emitter_shares(emission: np.ndarray, area: np.ndarray) -> np.ndarray:
    """(P,) each patch's share of the emitted power (luminance of ``emission`` (P, 3) x ``area``
    (P,)); 0 on patches that emit nothing, and all 0 when nothing does."""
    power = np.abs(luminance_of(emission)) * area
    total = float(power.sum())
    return power / total if total > 0 else np.zeros(len(area))


def solver_albedo(scene) -> np.ndarray:
    """(P, 3) the albedo the solver uses: the scene's, clamped to [0, 1] (albedo 1 is kept: an
    albedo-1 closed room never converges, and the solve stops at ``max_shots`` saying how much
    light is left unshot; > 1 would create energy at every bounce); 0 on glass (transmissive
    patches pass light on and neither reflect nor store it)."""
    alb = np.clip(scene.patch_albedo, 0.0, 1.0)
    return np.where(scene.patch_transmission[:, None] > 0, 0.0, alb)  # glass passes light, keeps none


@dataclass(frozen=True)
class Patches:
    """The root patches of a scene as the solver reads them (P patches; lengths in world units).

    Made once per solve by :meth:`of_scene`; no stage writes them. ``coverage`` keeps the panel
    cells' coverage grids it has made (a cache, not state)."""

    corners: np.ndarray  # (P, 4, 3) corners (a triangle's fourth repeats, unused)
    is_quad: np.ndarray  # (P,) bool
    normal: np.ndarray  # (P, 3) unit normals (the side that receives)
    area: np.ndarray  # (P,) surface area (a panel cell's covered part)
    lattice_area: np.ndarray  # (P,) area of the whole lattice (a panel cell's rectangle)
    clip_uv: np.ndarray  # (C, 3, 2) panel cells' clip triangles in lattice (u, v)
    clip_start: np.ndarray  # (P + 1,) each patch's first clip triangle
    clipped: np.ndarray  # (P,) bool: a panel cell
    clip_world: np.ndarray  # (C, 3, 3) the clip triangles in world space
    albedo: np.ndarray  # (P, 3) :func:`solver_albedo`
    emission: np.ndarray  # (P, 3) emitted radiance, W / (m^2 sr)
    n_corners: np.ndarray  # (P,) 4 or 3
    centre: np.ndarray  # (P, 3)
    radius: np.ndarray  # (P,) largest corner distance from the centre
    tangent: np.ndarray  # (P, 2, 3) a tangent frame per patch
    valid_corner: np.ndarray  # (P, 4) bool: the corner exists
    emitters: np.ndarray  # (E,) patches that emit
    emitter_share: np.ndarray  # (P,) :func:`emitter_shares`
    scale: float  # the scene's diagonal
    eps_ray: float  # ray offset at the scene's scale
    eps_patch: np.ndarray  # (P,) ray offset per patch
    eps_ff: float  # form-factor point offset into its patch
    min_size: float  # smallest element edge (``min_element_size`` or a fraction of the scene)
    max_size: float  # element edge above which the split test is stricter
    n: int  # lattice cells a side at ``max_depth``
    twin: np.ndarray  # (P,) int64 the coincident patch facing the other way (a sheet's back), -1: none
    twin_swap: np.ndarray  # (P,) bool: the twin's lattice (u, v) is this patch's (v, u)
    family: np.ndarray | None  # (P,) int64 the root a shadow cut made it from (shoots with its kin), or None
    _coverage: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def of_scene(cls, scene, opts: SolveOptions) -> Patches:
        corners, is_quad, normal = scene.corner_positions, scene.patch_is_quad, scene.patch_normal
        area = scene.patch_area
        clip_uv = scene.clip_uv
        tri_world = scene.world_triangles()
        emission = scene.patch_emission
        P = len(area)
        n_corners = np.where(is_quad, 4, 3)
        centre = np.where(is_quad[:, None], corners.mean(axis=1), corners[:, :3].mean(axis=1))
        radius = np.linalg.norm(corners - centre[:, None, :], axis=2).max(axis=1)
        lo, hi = scene.bounds if P else (np.zeros(3), np.zeros(3))
        scale = max(float(np.linalg.norm(hi - lo)), 1e-12)
        eps_ray = RAY_EPS * scale
        # per patch: no more than a fiftieth of the patch's radius (a 1 cm object in a 100 m scene
        # keeps its shadow), no less than 32 float32 steps at the scene's extent (embree's precision)
        extent = float(np.abs(np.stack([lo, hi])).max()) if P else 1.0
        floor = 32.0 * float(np.spacing(np.float32(max(extent, 1e-30))))
        mes = opts.min_element_size
        # a tangent frame per patch (for cosine-distributed directions)
        helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(normal, helper)
        t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-300)
        twin, twin_swap = twin_index(corners, is_quad)
        return cls(
            corners=corners,
            is_quad=is_quad,
            normal=normal,
            area=area,
            lattice_area=scene.lattice_area,
            clip_uv=clip_uv,
            clip_start=scene.clip_start,
            clipped=scene.patch_clipped,
            clip_world=tri_world[len(tri_world) - len(clip_uv) :],
            albedo=solver_albedo(scene),
            emission=emission,
            n_corners=n_corners,
            centre=centre,
            radius=radius,
            tangent=np.stack([t1, np.cross(normal, t1)], axis=1),
            valid_corner=np.arange(4)[None, :] < n_corners[:, None],
            emitters=np.flatnonzero((emission > 0).any(axis=1)),
            emitter_share=emitter_shares(emission, area),
            scale=scale,
            eps_ray=eps_ray,
            eps_patch=np.clip(RAY_EPS_PATCH * radius, min(floor, eps_ray), eps_ray),
            eps_ff=FF_EPS * scale,
            min_size=MIN_ELEMENT_FRACTION * math.sqrt(float(area.sum())) if mes is None else float(mes),
            max_size=MAX_ELEMENT_FRACTION * math.sqrt(float(area.sum())),
            n=1 << opts.max_depth,
            twin=twin,
            twin_swap=twin_swap,
            family=scene.patch_family,
        )

    @property
    def n_patches(self) -> int:
        return len(self.area)

    def polygon(self, s: int) -> np.ndarray:
        """(k, 3) the corners of patch s (k = 4 or 3)."""
        return self.corners[s, : self.n_corners[s]]

    def geometry(self, keys: np.ndarray, cached: bool = False) -> ReceiverGeometry:
        """The :class:`ReceiverGeometry` of vertex keys (n,) int64; ``cached``: with a
        :class:`FormFactorCache` (a mesh's vertices or a coarse grid, which shooters reach
        several times)."""
        keys = np.asarray(keys, dtype=np.int64)
        p, i, j = qt.decode_key(keys, self.n)
        if self.clipped.any() and self.clipped[p].any():
            pos = qt.patch_point(self.corners, self.is_quad, p, *self.clamped_uv(p, i / self.n, j / self.n))
        else:
            pos = qt.lattice_to_world(self.corners, self.is_quad, p, i, j, self.n)
        nrm = self.normal[p]
        t = self.centre[p] - pos
        t -= np.einsum("nc,nc->n", t, nrm)[:, None] * nrm
        tl = np.linalg.norm(t, axis=1)
        that = t / np.maximum(tl, 1e-300)[:, None]
        ff = pos + np.minimum(self.eps_ff, 0.5 * tl)[:, None] * that
        eps = self.eps_patch[p][:, None]
        origin = pos + eps * nrm + np.minimum(eps, 0.5 * tl[:, None]) * that
        start = None
        if len(keys) == 0 or np.all(keys[1:] > keys[:-1]):
            start = np.searchsorted(keys, qt.make_key(np.arange(self.n_patches + 1), 0, 0, self.n))
        return ReceiverGeometry(keys, p, pos, nrm, ff, origin, start, FormFactorCache() if cached else None)

    def clamped_uv(self, p: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice (u, v) of points on patches ``p`` moved into their clip triangles (points of a
        panel cell outside its surface take the nearest surface point, 2 ray offsets inside)."""
        u, v = np.asarray(u, dtype=np.float64).copy(), np.asarray(v, dtype=np.float64).copy()
        sel = np.flatnonzero(self.clipped[p])
        if len(sel) == 0:
            return u, v
        side = np.linalg.norm(self.corners[p[sel], 1] - self.corners[p[sel], 0], axis=1)
        margin = 2.0 * self.eps_patch[p[sel]] / np.maximum(side, 1e-300)
        out = clamp_into(np.stack([u[sel], v[sel]], axis=1), p[sel], self.clip_uv, self.clip_start, margin)
        u[sel], v[sel] = out[:, 0], out[:, 1]
        return u, v

    def coverage(self, p: int, res: int) -> np.ndarray:
        """(res, res) bool surface coverage of clipped patch p at cell centres (``grid[v, u]``)."""
        key = (int(p), int(res))
        if key not in self._coverage:
            a, b = self.clip_start[p], self.clip_start[p + 1]
            self._coverage[key] = coverage_grid(self.clip_uv[a:b], res)
        return self._coverage[key]

    def leaf_has_surface(self, forest: qt.Forest) -> np.ndarray:
        """(L,) bool: False for leaves of panel cells that cover none of the cell's surface (at
        the finest lattice's cell centres): they are not split."""
        return self.leaf_coverage(forest) > 0

    def leaf_coverage(self, forest: qt.Forest) -> np.ndarray:
        """(L,) float64 the fraction of each leaf's lattice cells whose centres lie on its patch's
        surface: 1 on patches that are not panel cells."""
        out = np.ones(forest.n_leaves)
        lp = np.asarray(forest.leaf_patch, dtype=np.int64)
        leaves = np.flatnonzero(self.clipped[lp])  # the panel cells' leaves
        if len(leaves) == 0:
            return out
        sat, row = self.coverage_tables()
        r = row[lp[leaves]]
        size = self.n >> np.asarray(forest.leaf_level[leaves], dtype=np.int64)
        i0 = np.asarray(forest.leaf_i[leaves], dtype=np.int64)
        j0 = np.asarray(forest.leaf_j[leaves], dtype=np.int64)
        i1, j1 = i0 + size, j0 + size

        def at(j, i):
            return sat[r, j, i].astype(np.int64)

        out[leaves] = (at(j1, i1) - at(j0, i1) - at(j1, i0) + at(j0, i0)) / (size * size)
        return out

    def coverage_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``(sat, row)``: the summed-area tables of the panel cells' coverage on the finest lattice
        (:meth:`coverage` at ``n``), (C, n+1, n+1) unsigned ints, ``sat[r, j, i]`` the cells (a, b)
        with a < i, b < j on the surface of the cell in row r; row (P,) int64 each clipped patch's
        row (-1 elsewhere). Made once (n = 64: 8.3 kB a panel cell)."""
        if "sat" not in self._coverage:
            cells = np.flatnonzero(self.clipped)
            row = np.full(self.n_patches, -1, dtype=np.int64)
            row[cells] = np.arange(len(cells))
            sat = np.zeros((len(cells), self.n + 1, self.n + 1), dtype=np.min_scalar_type(self.n * self.n))
            for r, p in enumerate(cells):
                a, b = self.clip_start[p], self.clip_start[p + 1]
                sat[r, 1:, 1:] = coverage_grid(self.clip_uv[a:b], self.n).cumsum(axis=0).cumsum(axis=1)
            self._coverage["sat"] = sat, row
        return self._coverage["sat"]
