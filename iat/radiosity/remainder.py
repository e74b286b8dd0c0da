"""The ambient term (stage D of :mod:`iat.radiosity.solver`): what the light still unshot at
convergence adds over all its later bounces, by one final gather of it.

Every vertex casts ``AMBIENT_RAYS`` cosine-distributed rays (one stratified pattern for all, so
the result varies smoothly) and takes, where each first meets a front face, the unshot radiance
there (the patch's field on its ``AMBIENT_GRID`` x ``AMBIENT_GRID`` lattice, times its shot gain):
their mean times the vertex's albedo is the remainder's first bounce, at the resolution of the
unshot light (a sunlit patch of floor lights what faces it, not its whole room). The bounces after
are solved on the patches: the same rays, averaged over each patch, give a sampled patch-to-patch
form-factor matrix ``F`` (P, P); the later reflected radiance ``B`` (P, 3) solves
``B = rho F (R1 + B)`` (``R1`` the first bounce's patch means), and each vertex adds
``rho (F_v (R1 + B))``. Rays that leave the scene or meet a back face bring nothing, so an open
scene's remainder escapes as it would.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from iat.radiosity.kernels import ambient_hits
from iat.radiosity.options import (
    AMBIENT_BOUNCE_TOL,
    AMBIENT_GRID,
    AMBIENT_MAX_BOUNCES,
    AMBIENT_RAYS,
    GATHER_BLOCK,
    MAX_REFLECTANCE,
)
from iat.radiosity.sampling import concentric_disk, disk_to_hemisphere, pattern_side


def hemisphere_rays(ctx, geo):
    """Per block of at most ``GATHER_BLOCK`` vertices: their slice and their ``AMBIENT_RAYS``
    cosine-distributed rays, origins and directions (b k, 3) in vertex order, the same pattern
    at every vertex, and k."""
    m = pattern_side(AMBIENT_RAYS)
    pat = ctx.pattern(ctx.n_patches, m, 0)  # (a patch index no shooter has)
    dx, dy = concentric_disk(pat[None, :, 0], pat[None, :, 1])
    k = pat.shape[0]
    for a in range(0, len(geo.key), GATHER_BLOCK):
        sl = slice(a, min(a + GATHER_BLOCK, len(geo.key)))
        t1, t2 = ctx.tangent[geo.patch[sl], 0], ctx.tangent[geo.patch[sl], 1]
        w = disk_to_hemisphere(dx, dy, t1, t2, geo.normal[sl]).reshape(-1, 3)
        yield sl, np.repeat(geo.origin[sl], k, axis=0), w, k


def ambient_term(ctx, mesh: dict, vis, scene, unshot: np.ndarray, gain: np.ndarray, check) -> np.ndarray:
    """(V, 3) the reflected radiance the unshot light adds over all its later bounces (see the
    module docstring).

    mesh : the solve's mesh (``geo`` the vertices' geometry, ``M`` the (P, V) averaging matrix,
    ``rho`` (V, 3) the vertices' albedo, ``lattice`` its :class:`~iat.radiosity.sampling.Lattice`)
    unshot : (V, 3) unshot radiance; gain : (P,) each patch's shot gain."""
    geo, avg, rho, lattice = mesh["geo"], mesh["M"], mesh["rho"], mesh["lattice"]
    g = min(AMBIENT_GRID, ctx.n)
    flat = (lattice.coarse_grids(unshot, g) * gain[:, None, None, None]).reshape(-1, 3)
    opaque = vis.opaque
    tri_patch, tri_uv = scene.world_triangle_patch()[opaque], scene.world_triangle_uv()[opaque]
    n_v, n_p = len(geo.key), ctx.n_patches
    first = np.zeros((n_v, 3))
    per_vertex, cols, counts = [], [], []  # (V, P) CSR by rows: the kernel writes them in vertex order
    for sl, o, w, k in hemisphere_rays(ctx, geo):
        tri, bary = vis.first_hits(o, w, np.full(len(o), 4.0 * ctx.scale))
        r, c, f = np.empty(len(o), np.int64), np.empty(len(o), np.int64), np.empty(len(o))
        m = ambient_hits(tri, bary, w, tri_patch, tri_uv, ctx.normal, flat, g, k, first[sl], r, c, f)
        per_vertex.append(np.bincount(r[:m], minlength=sl.stop - sl.start))
        cols.append(c[:m].astype(np.int32))
        counts.append(f[:m])
        check()
    indptr = np.concatenate([[0], np.cumsum(np.concatenate(per_vertex))])
    fv = sparse.csr_matrix((np.concatenate(counts), np.concatenate(cols), indptr), shape=(n_v, n_p))
    r1 = rho * first
    rho_p = np.minimum(np.asarray(ctx.albedo, dtype=np.float64), MAX_REFLECTANCE)
    src = np.asarray(avg @ r1)

    def bounce(x):  # rho F x, F = M F_v (P, P) not formed: in a large building it holds every
        return rho_p * np.asarray(avg @ np.asarray(fv @ x))  # pair of patches that see each other

    # B = rho F (R1 + B): its Neumann series, summed to a tolerance (rho F's norm < MAX_REFLECTANCE)
    later = np.zeros_like(src)
    term = bounce(src)
    scale = max(float(np.abs(src).sum()), 1e-300)
    for _ in range(AMBIENT_MAX_BOUNCES):
        later += term
        if np.abs(term).sum() <= AMBIENT_BOUNCE_TOL * scale:
            break
        term = bounce(term)
    return r1 + rho * np.asarray(fv @ (src + later))
