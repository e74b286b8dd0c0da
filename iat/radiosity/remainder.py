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

from iat.radiosity.options import (
    AMBIENT_BOUNCE_TOL,
    AMBIENT_GRID,
    AMBIENT_MAX_BOUNCES,
    AMBIENT_RAYS,
    GATHER_BLOCK,
    MAX_REFLECTANCE,
)
from iat.radiosity.sampling import concentric_disk, pattern_side, sample_lattice


def hemisphere_hits(ctx, geo, vis, tri_patch: np.ndarray, tri_uv: np.ndarray, check):
    """Per block of vertices: what their ``AMBIENT_RAYS`` cosine-distributed rays meet first.

    ctx : the solve's :class:`~iat.radiosity.context.Context`; geo : the vertices' geometry
    tri_patch : (T_opaque,) patch of each opaque triangle; tri_uv : (T_opaque, 3, 2) its lattice (u, v)
    Yields ``(vertices, k, patch, u, v)``: the block's vertex indices (b,), the rays per vertex,
    and for the rays that meet a front face (in vertex order) their vertex (h,), patch and
    lattice parameters (h,) there."""
    m = pattern_side(AMBIENT_RAYS)
    pat = ctx.pattern(ctx.n_patches, m, 0)  # (a patch index no shooter has)
    dx, dy = concentric_disk(pat[:, 0], pat[:, 1])
    dx, dy = dx[None, :, None], dy[None, :, None]
    dz = np.sqrt(np.maximum(1.0 - dx * dx - dy * dy, 0.0))
    k = pat.shape[0]
    for a in range(0, len(geo.key), GATHER_BLOCK):
        sl = slice(a, a + GATHER_BLOCK)
        t1, t2, nz = ctx.tangent[geo.patch[sl], 0], ctx.tangent[geo.patch[sl], 1], geo.normal[sl]
        w = (dx * t1[:, None] + dy * t2[:, None] + dz * nz[:, None]).reshape(-1, 3)
        o = np.repeat(geo.origin[sl], k, axis=0)
        tri, bary = vis.first_hits(o, w, np.full(len(o), 4.0 * ctx.scale))
        hp = tri_patch[np.maximum(tri, 0)]
        front = np.flatnonzero((tri >= 0) & (np.einsum("nc,nc->n", w, ctx.normal[hp]) < 0))
        t, b = tri_uv[tri[front]], bary[front]
        uv = (1.0 - b[:, :1] - b[:, 1:]) * t[:, 0] + b[:, :1] * t[:, 1] + b[:, 1:] * t[:, 2]
        uv = np.clip(uv, 0.0, 1.0)
        verts = np.arange(a, min(a + GATHER_BLOCK, len(geo.key)))
        yield verts, k, a + front // k, hp[front], uv[:, 0], uv[:, 1]
        check()


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
    rows, cols, counts = [], [], []
    for verts, k, v, p, u, w in hemisphere_hits(ctx, geo, vis, tri_patch, tri_uv, check):
        val = sample_lattice(flat, g, u, w, p * (g + 1) ** 2)
        for c in range(3):
            first[verts, c] = np.bincount(v - verts[0], weights=val[:, c], minlength=len(verts)) / k
        pair, count = np.unique(v * n_p + p, return_counts=True)
        rows.append(pair // n_p)
        cols.append(pair % n_p)
        counts.append(count / k)
    fv = sparse.csr_matrix(
        (np.concatenate(counts), (np.concatenate(rows), np.concatenate(cols))), shape=(n_v, n_p)
    )
    r1 = rho * first
    fp = (avg @ fv).tocsr()  # (P, P) the fraction of a patch's hemisphere each patch fills
    rho_p = np.minimum(np.asarray(ctx.albedo, dtype=np.float64), MAX_REFLECTANCE)
    src = np.asarray(avg @ r1)
    # B = rho F (R1 + B): its Neumann series, summed to a tolerance (rho F's norm < MAX_REFLECTANCE)
    later = np.zeros_like(src)
    term = rho_p * np.asarray(fp @ src)
    scale = max(float(np.abs(src).sum()), 1e-300)
    for _ in range(AMBIENT_MAX_BOUNCES):
        later += term
        if np.abs(term).sum() <= AMBIENT_BOUNCE_TOL * scale:
            break
        term = rho_p * np.asarray(fp @ term)
    return r1 + rho * np.asarray(fv @ (src + later))
