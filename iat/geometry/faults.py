"""Which patches carry a fault the loader found (issue 36: show the user what is wrong with a model).

The loader (:func:`iat.io.load.load_scene`) finds four faults on the welded triangles, before the
patches are made, and fixes or counts them (``iat info``):

- ``inside_out``: faces of a closed solid whose every face pointed inward, turned outward
  (:func:`iat.geometry.sides.classify_sides`; ``--sides both``, or IFC under ``auto``);
- ``open_sheet``: faces of an open piece given a back face, so both sides are surface (IFC under
  ``auto``, glTF ``doubleSided`` materials, every format under ``--sides both``);
- ``crossing``: faces cut where a face of another object crosses them (or rests on them, with
  ``--cut all``; :func:`iat.geometry.pierce.cut_pierced`);
- ``coincident``: faces that another face repeated in the same place, the repeat dropped
  (:func:`iat.geometry.sides.repeated_faces`).

:func:`fault_faces` keeps those faces (the loader stores them as ``Scene.faults``, a
:class:`FaultFaces`). The patches are made afterwards (quads merged, panels, pre-splits, back
faces), so :func:`patch_faults` finds each patch's faults by geometry: a patch carries a face's
fault when a sample point of one lies on the other (within :data:`PLANE_TOL` of its plane, inside
it), facing the same way (either way for a face given a back face, and for a dropped repeat).
A patch may carry several (``--sides front`` turns nothing and adds no back, ``--cut none`` cuts
nothing: those kinds then mark no patch, though ``iat info`` still counts them). Overlapping
coplanar faces that do not share their corners are not found (the loader keeps them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

#: the kinds, in the order of their bits (bit k = 1 << k) and of the viewer's checkboxes
FAULTS = ("inside_out", "open_sheet", "crossing", "coincident")
INSIDE_OUT, OPEN_SHEET, CROSSING, COINCIDENT = (1 << k for k in range(len(FAULTS)))
#: what each kind means, for the viewer's panel and ``iat render --faults``'s legend
LABELS = {
    "inside_out": "inside-out solid (turned)",
    "open_sheet": "open sheet (two-sided)",
    "crossing": "cut by a crossing element",
    "coincident": "coincident face (repeat dropped)",
}
#: each kind's tint, linear RGB (a patch carrying several shows the first in :data:`FAULTS` order)
COLORS = {
    "inside_out": (1.0, 0.0, 1.0),
    "open_sheet": (0.0, 0.8, 1.0),
    "crossing": (1.0, 0.1, 0.0),
    "coincident": (1.0, 0.9, 0.0),
}
#: a point lies on a face within this fraction of the scene's diagonal from its plane
PLANE_TOL = 1e-6
#: ... and inside it down to this barycentric coordinate (its edges count as inside)
INSIDE_TOL = 1e-6


@dataclass
class FaultFaces:
    """The faces the loader found faulty (``Scene.faults``; :func:`fault_faces`).

    triangles : (k, 3, 3) float64 world corners (welded, as oriented after the sides step, before
      the cuts: a cut face is kept whole)
    kinds : (k,) uint8 bits of :data:`FAULTS` (``1 << index``)
    either : (k,) bool the face marks patches facing either way (a face given a back face, whose
      twin carries its fault too, and a dropped repeat); else only those facing as it does
    """

    triangles: np.ndarray
    kinds: np.ndarray
    either: np.ndarray


def fault_faces(
    vertices: np.ndarray,
    faces: np.ndarray,
    turned: np.ndarray,
    back: np.ndarray,
    cut: np.ndarray,
    repeats: np.ndarray,
) -> FaultFaces:
    """The loader's faulty faces.

    vertices : (n, 3) float64 welded; faces : (f, 3) int64 after the sides step (turned outward)
    turned : (f,) bool faces of inside-out solids turned; back : (f,) bool faces given a back face
    cut : (f,) bool faces cut in pieces where other geometry pierces them
    repeats : (r, 3, 3) float64 the dropped repeated faces' corners
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    back = np.asarray(back, dtype=bool)
    bits = np.zeros(len(F), dtype=np.uint8)
    bits[np.asarray(turned, dtype=bool)] |= INSIDE_OUT
    bits[back] |= OPEN_SHEET
    bits[np.asarray(cut, dtype=bool)] |= CROSSING
    k = np.flatnonzero(bits)
    rep = np.asarray(repeats, dtype=np.float64).reshape(-1, 3, 3)
    return FaultFaces(
        triangles=np.concatenate([V[F[k]], rep]),
        kinds=np.concatenate([bits[k], np.full(len(rep), COINCIDENT, dtype=np.uint8)]),
        either=np.concatenate([back[k], np.ones(len(rep), dtype=bool)]),
    )


def _normals(tri: np.ndarray) -> np.ndarray:
    """(t, 3) unit normals of triangles (t, 3, 3) (zero for a degenerate one)."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def sample_points(tri: np.ndarray) -> np.ndarray:
    """(t, 4, 3) points inside each triangle (t, 3, 3): its centroid and each corner moved a third
    of the way towards it (so that each of two triangles splitting a quad either way gets one)."""
    c = tri.mean(axis=1, keepdims=True)
    return np.concatenate([c, tri + (c - tri) / 3.0], axis=1)


@njit(cache=True, nogil=True)
def _scan(P, order, start, lo, h, dims, T, n, tol, out_i, out_j, fill):
    """Points ``P`` (binned: ``order`` by cell, ``start`` (cells + 1,) of a grid of cell ``h`` from
    ``lo``, ``dims`` (3,)) on each triangle of ``T`` (normals ``n``): the pairs' count, written
    to ``out_i``, ``out_j`` when ``fill``. A triangle visits the cells its box (grown by ``tol``)
    overlaps that its plane passes through."""
    k = 0
    half = 0.5 * h * np.sqrt(3.0) + tol
    c0 = np.empty(3, np.int64)
    c1 = np.empty(3, np.int64)
    for j in range(T.shape[0]):
        ox, oy, oz = T[j, 0, 0], T[j, 0, 1], T[j, 0, 2]
        nx, ny, nz = n[j, 0], n[j, 1], n[j, 2]
        for ax in range(3):
            mn = min(T[j, 0, ax], T[j, 1, ax], T[j, 2, ax]) - tol
            mx = max(T[j, 0, ax], T[j, 1, ax], T[j, 2, ax]) + tol
            c0[ax] = min(max(int(np.floor((mn - lo[ax]) / h)), 0), dims[ax] - 1)
            c1[ax] = min(max(int(np.floor((mx - lo[ax]) / h)), 0), dims[ax] - 1)
        ux, uy, uz = T[j, 1, 0] - ox, T[j, 1, 1] - oy, T[j, 1, 2] - oz
        vx, vy, vz = T[j, 2, 0] - ox, T[j, 2, 1] - oy, T[j, 2, 2] - oz
        d11, d12, d22 = ux * ux + uy * uy + uz * uz, ux * vx + uy * vy + uz * vz, vx * vx + vy * vy + vz * vz
        det = d11 * d22 - d12 * d12
        if det <= 0:
            continue
        for x in range(c0[0], c1[0] + 1):
            for y in range(c0[1], c1[1] + 1):
                for z in range(c0[2], c1[2] + 1):
                    cx, cy, cz = (
                        lo[0] + (x + 0.5) * h - ox,
                        lo[1] + (y + 0.5) * h - oy,
                        lo[2] + (z + 0.5) * h - oz,
                    )
                    if abs(cx * nx + cy * ny + cz * nz) > half:
                        continue
                    cell = (x * dims[1] + y) * dims[2] + z
                    for q in range(start[cell], start[cell + 1]):
                        i = order[q]
                        dx, dy, dz = P[i, 0] - ox, P[i, 1] - oy, P[i, 2] - oz
                        if abs(dx * nx + dy * ny + dz * nz) > tol:
                            continue
                        q1, q2 = dx * ux + dy * uy + dz * uz, dx * vx + dy * vy + dz * vz
                        b = (d22 * q1 - d12 * q2) / det
                        c = (d11 * q2 - d12 * q1) / det
                        if b >= -INSIDE_TOL and c >= -INSIDE_TOL and 1.0 - b - c >= -INSIDE_TOL:
                            if fill:
                                out_i[k] = i
                                out_j[k] = j
                            k += 1
    return k


def points_on_triangles(points: np.ndarray, tri: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``(i, j)`` (m,) int64 each: point ``points[i]`` (n, 3) lies on triangle ``tri[j]`` (t, 3, 3):
    within ``tol`` (scene units) of its plane and inside it (barycentric >= -:data:`INSIDE_TOL`).
    The points are binned in a grid of about one cell a point (compiled with numba)."""
    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    T = np.ascontiguousarray(tri, dtype=np.float64).reshape(-1, 3, 3)
    if len(P) == 0 or len(T) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    lo = P.min(axis=0) - tol
    ext = P.max(axis=0) + tol - lo
    h = max(float(np.linalg.norm(ext)) / len(P) ** (1 / 3), 1e-300)
    dims = (np.floor(ext / h).astype(np.int64) + 1).clip(1)
    cell = np.minimum(((P - lo) / h).astype(np.int64), dims - 1)
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    start = np.searchsorted(key[order], np.arange(int(np.prod(dims)) + 1)).astype(np.int64)
    args = (P, order, start, lo, h, dims, T, _normals(T), float(tol))
    m = _scan(*args, np.zeros(0, np.int64), np.zeros(0, np.int64), False)
    out_i, out_j = np.empty(m, np.int64), np.empty(m, np.int64)
    _scan(*args, out_i, out_j, True)
    return out_i, out_j


def patch_faults(scene) -> np.ndarray:
    """(P,) uint8 the :data:`FAULTS` bits each patch of ``scene`` carries (0: none; all 0 when
    ``scene.faults`` is None: a scene built in memory).

    A patch carries a fault face's kind when a sample point (:func:`sample_points`) of one of its
    surface triangles (:meth:`~iat.io.scene.Scene.world_triangles`) lies on the face, or one of the
    face's lies on the patch, facing the same way (or either way: :attr:`FaultFaces.either`).
    """
    out = np.zeros(scene.n_patches, dtype=np.uint8)
    f = getattr(scene, "faults", None)
    if f is None or len(f.kinds) == 0 or scene.n_patches == 0:
        return out
    tri, tp = scene.world_triangles(), scene.world_triangle_patch()
    lo, hi = scene.bounds
    tol = PLANE_TOL * max(float(np.linalg.norm(hi - lo)), 1e-300)
    n_tri, n_fault = _normals(tri), _normals(f.triangles)
    # patch samples on fault faces, and fault samples on patches: (surface triangle, fault face) pairs
    i, j = points_on_triangles(sample_points(tri).reshape(-1, 3), f.triangles, tol)
    k, m = points_on_triangles(sample_points(f.triangles).reshape(-1, 3), tri, tol)
    t = np.concatenate([i // 4, m])
    g = np.concatenate([j, k // 4])
    same = (n_tri[t] * n_fault[g]).sum(axis=1) > 0
    keep = same | f.either[g]
    np.bitwise_or.at(out, tp[t[keep]], f.kinds[g[keep]])
    return out


def fault_counts(bits: np.ndarray) -> dict[str, int]:
    """{kind: patches carrying it} of :func:`patch_faults`' bits (P,) uint8."""
    b = np.asarray(bits, dtype=np.uint8)
    return {k: int((b & (1 << i) > 0).sum()) for i, k in enumerate(FAULTS)}
