"""A solve's changing state, typed: the mesh it solves on (:class:`Mesh`, with its
:class:`CoarseGrid` receivers), the radiance at its vertices (:class:`Radiance`) and the steps of
its plan (:class:`Shoot`, :class:`Refine`). :class:`iat.radiosity.run.SolveRun` owns one of each."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from iat.geometry import quadtree as qt
from iat.radiosity.meshing import averaging_matrix, coarse_keys, coarse_weights
from iat.radiosity.options import COARSE_EPS
from iat.radiosity.patches import Patches, ReceiverGeometry
from iat.radiosity.sampling import Lattice


@dataclass
class CoarseGrid:
    """The coarse receiver grid of one level (``COARSE_EPS``): every patch's corners (level 0) or
    3 x 3 points, on which far, faint shots are received instead of at every vertex (G points)."""

    keys: np.ndarray  # (G,) int64 lattice keys, sorted
    geo: ReceiverGeometry  # their geometry, with a form-factor cache
    npts: np.ndarray  # (P,) points per patch
    rho: np.ndarray  # (G, 3) albedo
    acc: np.ndarray  # (G, 3) reflected radiance received so far (the shots add to it)

    @classmethod
    def levels(cls, patches: Patches, max_depth: int) -> list[CoarseGrid]:
        """The grids of every level that a lattice of ``max_depth`` has (they depend on no mesh)."""
        out = []
        for level in range(min(len(COARSE_EPS), max_depth)):
            ck = coarse_keys(patches.is_quad, level, patches.n)
            geo = patches.geometry(ck, cached=True)
            out.append(cls(ck, geo, np.diff(geo.start), patches.albedo[geo.patch], np.zeros((len(ck), 3))))
        return out


@dataclass(frozen=True)
class Mesh:
    """The mesh a solve shoots on (V vertices, P patches): made by :meth:`build` from a forest and
    its vertex keys, and replaced as a whole when stage C refines."""

    forest: qt.Forest
    keys: np.ndarray  # (V,) int64 vertex keys, sorted
    M: sparse.csr_matrix  # (P, V) area-averaging matrix
    lattice: Lattice  # per patch, its vertices' values on its lattice
    start: np.ndarray  # (P + 1,) each patch's first vertex
    geo: ReceiverGeometry  # the vertices' geometry, with a form-factor cache
    rho: np.ndarray  # (V, 3) the vertices' albedo
    coarse_w: list  # per coarse level: (V, G) interpolation from its grid's points
    finer: list  # per coarse level: (P,) bool, patches with more vertices than its grid
    finer_any: np.ndarray  # (P,) bool: finer at some level

    @classmethod
    def build(cls, patches: Patches, forest: qt.Forest, keys: np.ndarray, coarse: list[CoarseGrid]) -> Mesh:
        n, P = patches.n, patches.n_patches
        start = np.searchsorted(keys, qt.make_key(np.arange(P + 1), 0, 0, n))
        nverts = np.diff(start)
        finer = [nverts > c.npts for c in coarse]
        return cls(
            forest=forest,
            keys=keys,
            M=averaging_matrix(
                forest,
                keys,
                patches.corners,
                patches.area,
                patches.leaf_coverage(forest) if patches.clipped.any() else None,
            ),
            lattice=Lattice(forest, keys),
            start=start,
            geo=patches.geometry(keys, cached=True),
            rho=patches.albedo[qt.decode_key(keys, n)[0]],
            coarse_w=[coarse_weights(keys, c.keys, patches.is_quad, lv, n) for lv, c in enumerate(coarse)],
            finer=finer,
            finer_any=np.logical_or.reduce(finer) if coarse else np.zeros(P, bool),
        )


@dataclass
class Radiance:
    """The radiance at a mesh's V vertices (W / (m^2 sr), (V, 3)) and each of its P patches' gain.

    ``reflected``: what they reflect so far; ``unshot``: what their patch has yet to shoot;
    ``offset``: what a patch shoots beyond its exact vertex values (the element-integrated light of
    the point lights, :meth:`iat.radiosity.direct.DirectLight.light_correction`), so that what it
    has shot so far is :meth:`shot`; ``gain`` (P,): what a patch shoots is its unshot field times
    this (:func:`iat.radiosity.meshing.probe_shot_gain`)."""

    reflected: np.ndarray
    unshot: np.ndarray
    offset: np.ndarray
    gain: np.ndarray

    @classmethod
    def zeros(cls, n_vertices: int, n_patches: int) -> Radiance:
        z = np.zeros((n_vertices, 3))
        return cls(z, z.copy(), z.copy(), np.ones(n_patches))

    def shot(self) -> np.ndarray:
        """(V, 3) what each vertex's patch has shot from there so far."""
        return self.reflected + self.offset - self.unshot

    def remap(
        self,
        keys: np.ndarray,
        old_idx: np.ndarray,
        reflected: np.ndarray,
        light_corr: np.ndarray,
        grids: dict,
        n: int,
    ) -> Radiance:
        """The radiance on a refined mesh of vertex keys (V',), where ``old_idx`` (V',) is each
        vertex's index in this mesh (-1: new). Old vertices keep their unshot radiance and
        offset; every vertex takes ``reflected`` (V', 3), what it received, and a new one's unshot
        radiance is that plus its point lights' correction ``light_corr`` (V', 3) minus what its
        patch already shot from there (``grids[p]``, (n+1, n+1, 3) per patch that shot), so light
        a coarse element could not hold is shot again, not lost. The gain is kept."""
        old = old_idx >= 0
        unshot = np.zeros((len(keys), 3))
        unshot[old] = self.unshot[old_idx[old]]
        p_new, i_new, j_new = qt.decode_key(keys, n)
        for p in np.unique(p_new[~old]):
            sel = np.flatnonzero(~old & (p_new == p))
            shot_here = grids[int(p)][i_new[sel], j_new[sel]] if int(p) in grids else 0.0
            unshot[sel] = np.maximum(reflected[sel] + light_corr[sel] - shot_here, 0.0)
        offset = np.zeros((len(keys), 3))
        offset[old] = self.offset[old_idx[old]]
        offset[~old] = light_corr[~old]
        return Radiance(reflected, unshot, offset, self.gain)


@dataclass(frozen=True)
class Shoot:
    """Shoot until the unshot power is below ``target`` (luminance W), reporting progress over
    ``span`` (fractions of the solve)."""

    target: float
    span: tuple[float, float]


@dataclass(frozen=True)
class Refine:
    """Stage C: refine on the total radiance, reporting as ``label`` over ``span``."""

    label: str
    span: tuple[float, float]
