"""The ambient term (stage D of :mod:`iat.radiosity.solver`): what the light still unshot at
convergence adds over all its later bounces, by a final gather of it.

Every vertex casts ``ambient_rays`` (:class:`~iat.radiosity.options.SolveOptions`) cosine-
distributed rays (one stratified pattern for all, so the result varies smoothly) and takes, where
each first meets a front face, the unshot radiance there (the patch's field on its ``AMBIENT_GRID``
x ``AMBIENT_GRID`` lattice, times its shot gain): their mean times the vertex's albedo is the
remainder's first bounce ``R1``, at the resolution of the unshot light (a sunlit patch of floor
lights what faces it, not its whole room). The same rays, traced again, read ``R1`` where they land
for the second bounce ``R2`` (a patch's light is uneven: the Cornell box's walls are one patch
each), except on panel cells (clipped patches), which give their patch mean over their surface
(their lattice square reaches past it). The bounces after are solved on the patches: the rays, averaged
over each patch, give a sampled patch-to-patch form-factor matrix ``F = M F_v`` (P, P); the later
reflected radiance ``B`` (P, 3) solves ``B = rho F (R2 + B)`` (``R2`` as patch means), and each
vertex adds ``rho F_v (R2 + B)``. Rays that leave the scene or meet a back face bring nothing, so an
open scene's remainder escapes as it would.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from iat.radiosity.kernels import ambient_hits, cosine_rays
from iat.radiosity.options import (
    AMBIENT_BLOCK_RAYS,
    AMBIENT_BOUNCE_TOL,
    AMBIENT_GRID,
    AMBIENT_MAX_BOUNCES,
    MAX_REFLECTANCE,
)
from iat.radiosity.sampling import concentric_disk, pattern_side
from iat.radiosity.state import Mesh


def hemisphere_rays(ctx, geo, rays: int):
    """Per block of vertices (``AMBIENT_BLOCK_RAYS`` rays at most, or one vertex): their slice,
    their ``rays`` (rounded up to a square) cosine-distributed rays in vertex order (the same pattern at every
    vertex) as embreex takes them, origins and directions (b k, 3) float32, the directions (b k, 3)
    float64, and k. The arrays are reused for the next block."""
    m = pattern_side(rays)
    pat = ctx.gathers.pattern(ctx.patches.n_patches, m, 0)  # (a patch index no shooter has)
    dx, dy = concentric_disk(pat[:, 0], pat[:, 1])
    k = pat.shape[0]
    size = max(1, AMBIENT_BLOCK_RAYS // k)  # vertices a block
    n = min(size, len(geo.key)) * k
    w, o, d = np.empty((n, 3)), np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
    origin32 = geo.origin32()
    for a in range(0, len(geo.key), size):
        sl = slice(a, min(a + size, len(geo.key)))
        t1, t2 = ctx.patches.tangent[geo.patch[sl], 0], ctx.patches.tangent[geo.patch[sl], 1]
        b = (sl.stop - sl.start) * k
        cosine_rays(dx, dy, t1, t2, np.ascontiguousarray(geo.normal[sl]), origin32[sl], w[:b], o[:b], d[:b])
        yield sl, o[:b], d[:b], w[:b], k


def hemisphere_gather(ctx, geo, vis, tri_patch, tri_uv, grids: np.ndarray, rays: int, check, tally: bool):
    """(V, 3) each vertex's mean, over its :func:`hemisphere_rays`, of the radiance ``grids``
    ((P, g+1, g+1, 3): each patch's field on a g x g lattice) where they meet a front face, and,
    when ``tally``, the (V, P) CSR fraction of each vertex's rays that meet each patch (else None).
    geo : the vertices' :class:`~iat.radiosity.patches.ReceiverGeometry`; tri_patch (T,), tri_uv
    (T, 3, 2): the patch and lattice (u, v) of each of ``vis``'s opaque triangles."""
    g = grids.shape[1] - 1
    pt = ctx.patches
    flat = np.ascontiguousarray(grids.reshape(-1, 3))
    means = np.ascontiguousarray(grids.reshape(len(grids), -1, 3).mean(axis=1))  # (P, 3), for twins
    mean = np.zeros((len(geo.key), 3))
    per_vertex, cols, counts = [], [], []  # (V, P) CSR by rows: the kernel writes them in vertex order
    for sl, o, d, w, k in hemisphere_rays(ctx, geo, rays):
        tri, bary = vis.first_hits(o, d, np.full(len(o), 4.0 * ctx.patches.scale, dtype=np.float32))
        r, c, f = np.empty(len(o), np.int64), np.empty(len(o), np.int64), np.empty(len(o))
        m = ambient_hits(
            tri,
            bary,
            w,
            tri_patch,
            tri_uv,
            pt.normal,
            pt.twin,
            pt.twin_swap,
            means,
            flat,
            g,
            k,
            mean[sl],
            r,
            c,
            f,
        )
        if tally:
            per_vertex.append(np.bincount(r[:m], minlength=sl.stop - sl.start))
            cols.append(c[:m].astype(np.int32))
            counts.append(f[:m])
        check()
    if not tally:
        return mean, None
    indptr = np.concatenate([[0], np.cumsum(np.concatenate(per_vertex))])
    shape = (len(geo.key), ctx.patches.n_patches)
    return mean, sparse.csr_matrix((np.concatenate(counts), np.concatenate(cols), indptr), shape=shape)


def ambient_term(
    ctx, mesh: Mesh, vis, scene, unshot: np.ndarray, gain: np.ndarray, rays: int, check
) -> np.ndarray:
    """(V, 3) the reflected radiance the unshot light adds over all its later bounces (see the
    module docstring), on the solve's ``mesh`` (V vertices).

    unshot : (V, 3) unshot radiance; gain : (P,) each patch's shot gain; rays : per vertex."""
    geo, avg, rho, lattice = mesh.geo, mesh.M, mesh.rho, mesh.lattice
    g = min(AMBIENT_GRID, ctx.patches.n)
    tris = scene.world_triangle_patch()[vis.opaque], scene.world_triangle_uv()[vis.opaque]
    grids = lattice.coarse_grids(unshot, g) * gain[:, None, None, None]
    first, fv = hemisphere_gather(ctx, geo, vis, *tris, grids, rays, check, True)
    r1 = rho * first
    grids = lattice.coarse_grids(r1, g)
    grids[ctx.patches.clipped] = np.asarray(avg @ r1)[ctx.patches.clipped][:, None, None, :]
    second, _ = hemisphere_gather(ctx, geo, vis, *tris, grids, rays, check, False)  # the same rays again
    r2 = rho * second
    rho_p = np.minimum(np.asarray(ctx.patches.albedo, dtype=np.float64), MAX_REFLECTANCE)
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
