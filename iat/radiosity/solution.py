"""The radiosity solution: per-patch quad-trees and radiance at every mesh vertex.

Saved as a versioned ``.npz`` without pickles (``format = "iat-solution"``,
``version = SOLUTION_VERSION``). See ``docs/architecture.md`` for the fields.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iat.errors import SolutionFileError
from iat.fsutil import atomic_write
from iat.geometry import quadtree as qt
from iat.geometry.clip import clip_mesh

SOLUTION_FORMAT = "iat-solution"
SOLUTION_VERSION = 1

_ARRAYS = {
    "patch_corners": np.float64,
    "patch_is_quad": np.bool_,
    "patch_material": np.int64,
    "patch_albedo": np.float64,
    "leaf_patch": np.int32,
    "leaf_level": np.int8,
    "leaf_i": np.int32,
    "leaf_j": np.int32,
    "leaf_flip": np.bool_,
    "vert_key": np.int64,
    "vert_radiance": np.float32,
    "tri_vertices": np.int32,
}
#: arrays a file may lack (solutions of scenes without panel cells)
_OPTIONAL = {
    "clip_uv": (np.float64, (0, 3, 2)),
    "clip_patch": (np.int64, (0,)),
    "patch_transmission": (np.float32, (0,)),
}


@dataclass
class DrawnMesh:
    """The mesh as drawn: the vertex table's vertices, then the pieces of panel cells' triangles
    cut to their clip triangles (each a weighted sum of three table vertices).

    position : (V', 3) float64; patch : (V',) int64; triangles : (T', 3) int64 into the V' rows
    source : (V' - V, 3) int64 table vertices and weight : (V' - V, 3) float32 of the extra rows
    """

    position: np.ndarray
    patch: np.ndarray
    triangles: np.ndarray
    source: np.ndarray
    weight: np.ndarray

    def radiance(self, vert_radiance: np.ndarray) -> np.ndarray:
        """(V', 3) float32: table radiance (V, 3), then the pieces' interpolated radiance."""
        r = np.asarray(vert_radiance, dtype=np.float32)
        if len(self.source) == 0:
            return r
        extra = np.einsum("kj,kjc->kc", self.weight, r[self.source])
        return np.concatenate([r, extra.astype(np.float32)])


@dataclass
class Solution:
    """A radiosity solution.

    max_depth : lattice depth D (``2**D + 1`` lattice points per patch side)
    patch_corners : (P, 4, 3) float64 world corners (triangles repeat corner 2 in slot 3)
    patch_is_quad : (P,) bool
    patch_material : (P,) int64 material index in the scene
    patch_albedo : (P, 3) float64 albedo used by the solve
    leaf_patch, leaf_level, leaf_i, leaf_j, leaf_flip : (L,) leaves (see ``iat.geometry.quadtree``)
    vert_key : (V,) int64 sorted vertex keys
    vert_radiance : (V, 3) float32 outgoing radiance, linear RGB
    tri_vertices : (T, 3) int32 anchored mesh triangles (indices into the vertex table)
    clip_uv, clip_patch : (C, 3, 2) float64, (C,) int64 panel cells' clip triangles (the scene's)
    patch_transmission : (P,) float32 glass transmittance (empty: all opaque); glass is not drawn
    stats, options : JSON-able dicts
    model_path : the model file it was solved from ("" if built in memory)
    """

    max_depth: int
    patch_corners: np.ndarray
    patch_is_quad: np.ndarray
    patch_material: np.ndarray
    patch_albedo: np.ndarray
    leaf_patch: np.ndarray
    leaf_level: np.ndarray
    leaf_i: np.ndarray
    leaf_j: np.ndarray
    leaf_flip: np.ndarray
    vert_key: np.ndarray
    vert_radiance: np.ndarray
    tri_vertices: np.ndarray
    stats: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    model_path: str = ""
    clip_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 2)))
    clip_patch: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    patch_transmission: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.float32))
    _drawn: DrawnMesh | None = field(default=None, init=False, repr=False, compare=False)

    # -- views ---------------------------------------------------------------
    @property
    def n(self) -> int:
        return 1 << self.max_depth

    @property
    def forest(self) -> qt.Forest:
        """The leaves as a :class:`iat.geometry.quadtree.Forest` (arrays shared, not copied)."""
        return qt.Forest(
            self.max_depth,
            self.patch_is_quad,
            self.leaf_patch,
            self.leaf_level,
            self.leaf_i,
            self.leaf_j,
            self.leaf_flip,
        )

    @property
    def vert_position(self) -> np.ndarray:
        """(V, 3) float64 world positions of the vertices."""
        return qt.keys_to_world(self.patch_corners, self.patch_is_quad, self.vert_key, self.n)

    def drawn_mesh(self) -> DrawnMesh:
        """The mesh as drawn (:func:`drawn_mesh`), made once (the mesh arrays are not changed)."""
        if self._drawn is None:
            self._drawn = drawn_mesh(self)
        return self._drawn

    def patch_depth(self) -> np.ndarray:
        """(P,) int8 deepest leaf level per patch."""
        return self.forest.patch_depth()

    @classmethod
    def from_forest(
        cls,
        forest: qt.Forest,
        patch_corners: np.ndarray,
        patch_material: np.ndarray,
        patch_albedo: np.ndarray,
        vert_key: np.ndarray,
        vert_radiance: np.ndarray,
        **kw,
    ) -> Solution:
        """Assemble a solution; computes the anchored triangulation."""
        return cls(
            max_depth=forest.max_depth,
            patch_corners=np.asarray(patch_corners, dtype=np.float64),
            patch_is_quad=forest.patch_is_quad,
            patch_material=np.asarray(patch_material, dtype=np.int64),
            patch_albedo=np.asarray(patch_albedo, dtype=np.float64),
            leaf_patch=forest.leaf_patch,
            leaf_level=forest.leaf_level,
            leaf_i=forest.leaf_i,
            leaf_j=forest.leaf_j,
            leaf_flip=forest.leaf_flip,
            vert_key=vert_key,
            vert_radiance=np.asarray(vert_radiance, dtype=np.float32),
            tri_vertices=qt.triangulate(forest, vert_key),
            **kw,
        )

    # -- files ---------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        """Write atomically as ``.npz`` (no pickles); the previous file survives a failure.

        Through :func:`iat.fsutil.atomic_write`: a temporary ``.<name>.<random>.tmp`` in the same
        directory, flushed and fsynced before ``os.replace``; stale temporaries of killed writers
        (older than an hour) are removed after a successful write.
        """
        arrays = {k: np.asarray(getattr(self, k), dtype=t) for k, t in _ARRAYS.items()}
        arrays.update({k: np.asarray(getattr(self, k), dtype=t) for k, (t, _) in _OPTIONAL.items()})
        meta = {
            "format": np.array(SOLUTION_FORMAT),
            "version": np.array(SOLUTION_VERSION),
            "max_depth": np.array(self.max_depth),
            "stats": np.array(json.dumps(self.stats)),
            "options": np.array(json.dumps(self.options)),
            "model_path": np.array(self.model_path),
        }
        # temporary ``.<name>.<random>.tmp`` next to the target, fsynced, then renamed over it
        atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays, **meta))

    @classmethod
    def load(cls, path: str | Path) -> Solution:
        """Read a solution; a damaged file or one of another version raises SolutionFileError."""
        path = Path(path)
        if not path.exists():
            raise SolutionFileError("file not found", path)
        if not zipfile.is_zipfile(path):
            raise SolutionFileError("damaged or not an IAT solution file (not an .npz archive)", path)
        try:
            with np.load(path, allow_pickle=False) as z:
                names = set(z.files)
                if "format" not in names or str(z["format"]) != SOLUTION_FORMAT:
                    raise SolutionFileError("not an IAT solution file", path)
                version = int(z["version"])
                if version != SOLUTION_VERSION:
                    raise SolutionFileError(
                        f"solution file version {version}, this IAT reads version {SOLUTION_VERSION};"
                        " solve the model again",
                        path,
                    )
                missing = sorted(set(_ARRAYS) - names)
                if missing:
                    raise SolutionFileError(f"damaged solution file: missing {', '.join(missing)}", path)
                data = {k: np.asarray(z[k], dtype=t) for k, t in _ARRAYS.items()}
                for k, (t, shape) in _OPTIONAL.items():
                    data[k] = np.asarray(z[k], dtype=t) if k in names else np.zeros(shape, dtype=t)
                sol = cls(
                    max_depth=int(z["max_depth"]),
                    stats=json.loads(str(z["stats"])),
                    options=json.loads(str(z["options"])),
                    model_path=str(z["model_path"]),
                    **data,
                )
        except SolutionFileError:
            raise
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError, json.JSONDecodeError) as e:
            raise SolutionFileError(f"damaged solution file ({type(e).__name__}: {e})", path) from e
        sol._validate(path)
        return sol

    def _validate(self, path) -> None:
        v, p = len(self.vert_key), len(self.patch_is_quad)
        ok = (
            self.vert_radiance.shape == (v, 3)
            and self.patch_corners.shape == (p, 4, 3)
            and (
                self.tri_vertices.size == 0 or (0 <= self.tri_vertices.min() and self.tri_vertices.max() < v)
            )
            and (len(self.leaf_patch) == 0 or self.leaf_patch.max() < p)
            and np.isfinite(self.vert_radiance).all()
            and self.clip_uv.shape == (len(self.clip_patch), 3, 2)
            and (len(self.clip_patch) == 0 or (0 <= self.clip_patch.min() and self.clip_patch.max() < p))
            and len(self.patch_transmission) in (0, p)
        )
        if not ok:
            raise SolutionFileError("damaged solution file: inconsistent arrays", path)


def drawn_mesh(solution) -> DrawnMesh:
    """The mesh as drawn (:class:`DrawnMesh`) of a solution, or of any object with its fields
    ``max_depth, patch_corners, patch_is_quad, vert_key, tri_vertices`` (and ``clip_uv``,
    ``clip_patch`` when it has panel cells, ``patch_transmission`` when it has glass): a panel
    cell's triangles cut to its surface, glass left out (drawn fully transparent)."""
    n = 1 << int(solution.max_depth)
    corners = np.asarray(solution.patch_corners, dtype=np.float64).reshape(-1, 4, 3)
    is_quad = np.asarray(solution.patch_is_quad, dtype=bool)
    key = np.asarray(solution.vert_key, dtype=np.int64).reshape(-1)
    pos = qt.keys_to_world(corners, is_quad, key, n)
    p, i, j = qt.decode_key(key, n)
    tri = np.asarray(solution.tri_vertices, dtype=np.int64).reshape(-1, 3)
    tau = np.asarray(getattr(solution, "patch_transmission", np.zeros(0)), dtype=np.float64).reshape(-1)
    if len(tau) and (tau > 0).any() and len(tri):
        tri = tri[tau[p[tri[:, 0]]] <= 0]
    clip_uv = np.asarray(getattr(solution, "clip_uv", np.zeros((0, 3, 2))), dtype=np.float64)
    clip_uv = clip_uv.reshape(-1, 3, 2)
    clip_patch = np.asarray(getattr(solution, "clip_patch", np.zeros(0)), dtype=np.int64).reshape(-1)
    if len(clip_patch) == 0:
        return DrawnMesh(pos, p, tri, np.zeros((0, 3), np.int64), np.zeros((0, 3), np.float32))
    start = np.searchsorted(clip_patch, np.arange(len(is_quad) + 1))
    clipped = np.diff(start) > 0
    tp = p[tri[:, 0]] if len(tri) else np.zeros(0, np.int64)
    cut = clipped[tp]
    uv = np.stack([i, j], axis=1) / n
    piece_uv, w, src = clip_mesh(uv[tri[cut]], tp[cut], clip_uv, start)
    k = len(piece_uv)
    pp = np.repeat(tp[cut][src], 3)
    flat = piece_uv.reshape(-1, 2) * n
    extra_pos = qt.lattice_to_world(corners, is_quad, pp, flat[:, 0], flat[:, 1], n)
    return DrawnMesh(
        position=np.concatenate([pos, extra_pos]),
        patch=np.concatenate([p, pp]),
        triangles=np.concatenate([tri[~cut], len(pos) + np.arange(3 * k).reshape(k, 3)]),
        source=np.repeat(tri[cut][src], 3, axis=0),  # each piece's corners blend its source's corners
        weight=w.reshape(-1, 3).astype(np.float32),
    )
