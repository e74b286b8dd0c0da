"""The ambient term (stage D of :mod:`iat.radiosity.solver`): what the light still unshot at
convergence adds over all its later bounces, by a final gather of it.

Every vertex casts ``AMBIENT_RAYS`` cosine-distributed rays (one stratified pattern for all, so
the result varies smoothly) and takes, where each first meets a front face, the unshot radiance
there (the patch's field on its ``AMBIENT_GRID`` x ``AMBIENT_GRID`` lattice, times its shot gain):
their mean times the vertex's albedo is the remainder's first bounce ``R1``, at the resolution of
the unshot light (a sunlit patch of floor lights what faces it, not its whole room). The same rays,
traced again, read ``R1`` where they land for the second bounce ``R2`` (a patch's light is uneven:
the Cornell box's walls are one patch each), except on panel cells (clipped patches), which give
their patch mean: their lattice square reaches past their surface, and their vertex field read
there put the sunlit IFC house's interior at 0.84 of Mitsuba instead of 0.92. The bounces after
are solved on the patches: the rays, averaged over each patch, give a sampled patch-to-patch
form-factor matrix ``F = M F_v`` (P, P); the later reflected radiance ``B`` (P, 3) solves
``B = rho F (R2 + B)`` (``R2`` as patch means), and each vertex adds ``rho F_v (R2 + B)``. Rays
that leave the scene or meet a back face bring nothing, so an open scene's remainder escapes as
it would.
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


def hemisphere_gather(ctx, geo, vis, tri_patch, tri_uv, grids: np.ndarray, check, tally: bool):
    """(V, 3) each vertex's mean, over its :func:`hemisphere_rays`, of the radiance ``grids``
    ((P, g+1, g+1, 3): each patch's field on a g x g lattice) where they meet a front face, and,
    when ``tally``, the (V, P) CSR fraction of each vertex's rays that meet each patch (else None).
    geo : the vertices' :class:`~iat.radiosity.context.ReceiverGeometry`; tri_patch (T,), tri_uv
    (T, 3, 2): the patch and lattice (u, v) of each of ``vis``'s opaque triangles."""
    g = grids.shape[1] - 1
    flat = np.ascontiguousarray(grids.reshape(-1, 3))
    mean = np.zeros((len(geo.key), 3))
    per_vertex, cols, counts = [], [], []  # (V, P) CSR by rows: the kernel writes them in vertex order
    for sl, o, w, k in hemisphere_rays(ctx, geo):
        tri, bary = vis.first_hits(o, w, np.full(len(o), 4.0 * ctx.scale))
        r, c, f = np.empty(len(o), np.int64), np.empty(len(o), np.int64), np.empty(len(o))
        m = ambient_hits(tri, bary, w, tri_patch, tri_uv, ctx.normal, flat, g, k, mean[sl], r, c, f)
        if tally:
            per_vertex.append(np.bincount(r[:m], minlength=sl.stop - sl.start))
            cols.append(c[:m].astype(np.int32))
            counts.append(f[:m])
        check()
    if not tally:
        return mean, None
    indptr = np.concatenate([[0], np.cumsum(np.concatenate(per_vertex))])
    shape = (len(geo.key), ctx.n_patches)
    return mean, sparse.csr_matrix((np.concatenate(counts), np.concatenate(cols), indptr), shape=shape)


def ambient_term(ctx, mesh: dict, vis, scene, unshot: np.ndarray, gain: np.ndarray, check) -> np.ndarray:
    """(V, 3) the reflected radiance the unshot light adds over all its later bounces (see the
    module docstring).

    mesh : the solve's mesh (``geo`` the vertices' geometry, ``M`` the (P, V) averaging matrix,
    ``rho`` (V, 3) the vertices' albedo, ``lattice`` its :class:`~iat.radiosity.sampling.Lattice`)
    unshot : (V, 3) unshot radiance; gain : (P,) each patch's shot gain."""
    geo, avg, rho, lattice = mesh["geo"], mesh["M"], mesh["rho"], mesh["lattice"]
    g = min(AMBIENT_GRID, ctx.n)
    tris = scene.world_triangle_patch()[vis.opaque], scene.world_triangle_uv()[vis.opaque]
    grids = lattice.coarse_grids(unshot, g) * gain[:, None, None, None]
    first, fv = hemisphere_gather(ctx, geo, vis, *tris, grids, check, True)
    r1 = rho * first
    grids = lattice.coarse_grids(r1, g)
    grids[ctx.clipped] = np.asarray(avg @ r1)[ctx.clipped][:, None, None, :]
    second, _ = hemisphere_gather(ctx, geo, vis, *tris, grids, check, False)  # the same rays again
    r2 = rho * second
    rho_p = np.minimum(np.asarray(ctx.albedo, dtype=np.float64), MAX_REFLECTANCE)
    src = np.asarray(avg @ r2)

    def bounce(x):  # rho F x, F = M F_v (P, P) not formed: in a large building it holds every
        return rho_p * np.asarray(avg @ np.asarray(fv @ x))  # pair of patches that see each other

    # B = rho F (R2 + B): its Neumann series, summed to a tolerance (rho F's norm < MAX_REFLECTANCE)
    later = np.zeros_like(src)
    term = bounce(src)
    scale = max(float(np.abs(src).sum()), 1e-300)
    for _ in range(AMBIENT_MAX_BOUNCES):
        later += term
        if np.abs(term).sum() <= AMBIENT_BOUNCE_TOL * scale:
            break
        term = bounce(term)
    return r1 + r2 + rho * np.asarray(fv @ (src + later))
