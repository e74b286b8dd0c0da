"""The ambient term (stage D of :mod:`iat.radiosity.solver`): what the light still unshot at
convergence adds over all its later bounces, by a final gather of it.

Every vertex casts ``ambient_rays`` (:class:`~iat.radiosity.options.SolveOptions`) cosine-
distributed rays (one stratified pattern for all, so the result varies smoothly) and takes, where
each first meets a front face, the unshot radiance there (the patch's field on its ``AMBIENT_GRID``
x ``AMBIENT_GRID`` lattice, times its shot gain): their mean times the vertex's albedo is the
remainder's first bounce ``R1``, at the resolution of the unshot light (a sunlit patch of floor
lights what faces it, not its whole room). A second gather, with ``AMBIENT_SECOND_SHARE`` of the
rays, reads ``R1`` where they land for the second bounce ``R2`` (a patch's light is uneven: the
Cornell box's walls are one patch each), except on panel cells (clipped patches), which give their
patch mean over their surface (their lattice square reaches past it); it gives only ``R2``'s shape
within a patch, its power per patch coming from the first gather's rays (below). The bounces after
are solved on the patches.

What the vertices gather gives each bounce its shape; how much power a patch holds comes from the
same rays read the other way. A vertex's rays, weighted by the power its radiance stands for,
carry that power to the patches they meet (``F_v`` transposed: every watt lands somewhere or
leaves the scene), and each bounce's vertex values are scaled, patch by patch, to hold the power
their patch so receives (:func:`ambient_term`'s ``fit``). Linear interpolation between vertices
that gathered the light is not kept: the light a coarse element misses between its corners (a
wall lit by a sun patch on the floor is dark at its foot and bright above) would be lost at every
bounce, 3.5 % of the first in a near-white box, and a room of albedo 0.97 multiplies that by ~30.
The later bounces' power ``Phi`` (P, 3) is the series ``Phi = rho T (Phi2 + Phi)``, ``T`` the same
rays' patch-to-patch transfer of uniform light, and each vertex adds ``rho F_v`` of the bounces'
radiance, fitted to it. A patch's mean counts only the vertices that can be seen, and only the
part of its area that can be seen holds and sends its light (:func:`seen_average`: the floor under
a cupboard is not lit, and the wall behind it sends nothing), and patches that overlap in a plane
hold and send their light as one surface (:func:`overlap_shares`). Rays that
leave the scene or meet a back face bring nothing, so an open scene's remainder escapes as it would.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from iat.geometry.sides import overlap_groups
from iat.radiosity.ambient_kernels import ambient_hits, cosine_rays
from iat.radiosity.options import (
    AMBIENT_BLOCK_RAYS,
    AMBIENT_BOUNCE_TOL,
    AMBIENT_FIT_LIMIT,
    AMBIENT_GRID,
    AMBIENT_MAX_BOUNCES,
    AMBIENT_SECOND_SHARE,
    AMBIENT_SEEN_FLOOR,
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
    """``(mean, fv, buried)``: (V, 3) each vertex's mean, over its :func:`hemisphere_rays`, of the
    radiance ``grids`` ((P, g+1, g+1, 3): each patch's field on a g x g lattice) where they meet a
    front face; when ``tally``, the (V, P) CSR fraction of each vertex's rays that meet each patch
    (else None); (V,) the fraction of its rays that meet a back face (a vertex inside a solid).
    geo : the vertices' :class:`~iat.radiosity.patches.ReceiverGeometry`; tri_patch (T,), tri_uv
    (T, 3, 2): the patch and lattice (u, v) of each of ``vis``'s opaque triangles."""
    g = grids.shape[1] - 1
    pt = ctx.patches
    flat = np.ascontiguousarray(grids.reshape(-1, 3))
    means = np.ascontiguousarray(grids.reshape(len(grids), -1, 3).mean(axis=1))  # (P, 3), for twins
    mean, buried = np.zeros((len(geo.key), 3)), np.zeros(len(geo.key))
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
            buried[sl],
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
        return mean, None, buried
    indptr = np.concatenate([[0], np.cumsum(np.concatenate(per_vertex))])
    shape = (len(geo.key), ctx.patches.n_patches)
    fv = sparse.csr_matrix((np.concatenate(counts), np.concatenate(cols), indptr), shape=shape)
    return mean, fv, buried


def seen_average(avg: sparse.csr_matrix, buried: np.ndarray) -> tuple[sparse.csr_matrix, np.ndarray]:
    """``(seen_avg, seen)``: the patch-mean matrix ``avg`` (P, V) with each vertex weighted by the
    fraction of its hemisphere that is not inside a solid (1 - ``buried`` (V,)), rows summed to 1
    again: the mean over the part of a patch that can be seen (a floor under a cupboard, a wall's
    foot in a slab hold no light, and would dilute the patch's mean and its rows of F at every later
    bounce); and (P,) that part's share of each patch's area, at least ``AMBIENT_SEEN_FLOOR``. A
    patch buried whole keeps its row and counts whole."""
    w = avg @ sparse.diags(np.clip(1.0 - buried, 0.0, 1.0))
    s = np.asarray(w.sum(axis=1)).ravel()
    keep = s > 1e-9
    w = sparse.diags(np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)) @ w
    seen = np.where(keep, np.clip(s, AMBIENT_SEEN_FLOOR, 1.0), 1.0)
    return sparse.csr_matrix(w + sparse.diags(~keep * 1.0) @ avg), seen


def overlap_shares(pt, area: np.ndarray):
    """``(share, pooled)`` of the patches ``pt`` for the ambient term's powers, ``area`` (P,) the
    area of each that holds light (m²): where patches overlap in a plane
    (:func:`iat.geometry.sides.overlap_groups`: a cladding panel on its wall) the rays that land
    there meet one or the other by chance, so such a group holds and sends its light as one surface
    of its largest member's area. share (P,): the part of its area a patch sends from (that area
    over the group's summed area; 1 elsewhere); pooled(power (P, 3)) -> (P, 3) the power per unit
    area of each patch, of its group's summed power over that area where grouped."""
    group = overlap_groups(pt.corners, pt.is_quad, pt.normal, pt.eps_ray)
    grouped = group >= 0
    share = np.ones(len(group))
    if not grouped.any():
        return share, lambda power: power / area[:, None]
    g = group[grouped]
    span = np.zeros(g.max() + 1)
    np.maximum.at(span, g, area[grouped])
    share[grouped] = span[g] / np.bincount(g, weights=area[grouped])[g]

    def pooled(power):
        out = power / area[:, None]
        sums = np.stack([np.bincount(g, weights=power[grouped, c]) for c in range(3)], axis=1)
        out[grouped] = sums[g] / span[g][:, None]
        return out

    return share, pooled


def ambient_term(
    ctx, mesh: Mesh, vis, scene, unshot: np.ndarray, gain: np.ndarray, rays: int, check
) -> np.ndarray:
    """(V, 3) the reflected radiance the unshot light adds over all its later bounces (see the
    module docstring), on the solve's ``mesh`` (V vertices).

    unshot : (V, 3) unshot radiance; gain : (P,) each patch's shot gain; rays : per vertex."""
    geo, rho, lattice, pt = mesh.geo, mesh.rho, mesh.lattice, ctx.patches
    g = min(AMBIENT_GRID, pt.n)
    tris = scene.world_triangle_patch()[vis.opaque], scene.world_triangle_uv()[vis.opaque]
    grids = lattice.coarse_grids(unshot, g) * gain[:, None, None, None]
    first, fv, buried = hemisphere_gather(ctx, geo, vis, *tris, grids, rays, check, True)
    avg, seen = seen_average(mesh.M, buried)
    area = pt.area * seen  # (P,) what of each patch can be seen: it holds and sends the light
    share, pooled = overlap_shares(pt, area)
    unfit = share < 1.0
    vp = np.pi * np.asarray(avg.T @ (area * share))  # (V,) the power (W) of unit radiance at each
    albedo = np.asarray(pt.albedo, dtype=np.float64)
    fvt = fv.T  # (P, V), CSC: no copy

    def sent(field):  # (P, 3) the power the vertices' radiance field (V, 3) sends to each patch
        return np.asarray(fvt @ (vp[:, None] * field))

    def fit(r, power):  # r (V, 3) scaled patch by patch to hold the power (P, 3) its patch receives
        held = np.pi * area[:, None] * np.asarray(avg @ r)
        ok = held > 1e-300
        c = np.where(ok & ~unfit[:, None], power / np.where(ok, held, 1.0), 1.0)
        return r * np.clip(c, 1.0 / AMBIENT_FIT_LIMIT, AMBIENT_FIT_LIMIT)[geo.patch]

    r1 = fit(rho * first, albedo * sent(unshot * gain[geo.patch][:, None]))
    grids = lattice.coarse_grids(r1, g)
    grids[pt.clipped] = np.asarray(avg @ r1)[pt.clipped][:, None, None, :]
    few = max(1, round(rays * AMBIENT_SECOND_SHARE))
    second, _, _ = hemisphere_gather(ctx, geo, vis, *tris, grids, few, check, False)
    power2 = albedo * sent(r1)
    r2 = fit(rho * second, power2)
    rho_p = np.minimum(albedo, MAX_REFLECTANCE)

    def radiance(power):  # (P, 3) the uniform radiance of each patch's power, pooled where they overlap
        return pooled(power) / np.pi

    def bounce(power):  # (P, 3) the power reflected from what each patch's uniform light sends
        return rho_p * sent(radiance(power)[geo.patch])

    # the later bounces' power, a Neumann series summed to a tolerance (each bounce < MAX_REFLECTANCE)
    later = np.zeros_like(power2)
    term = bounce(power2)
    scale = max(float(np.abs(power2).sum()), 1e-300)
    for _ in range(AMBIENT_MAX_BOUNCES):
        later += term
        if np.abs(term).sum() <= AMBIENT_BOUNCE_TOL * scale:
            break
        term = bounce(term)
    r3 = fit(rho * np.asarray(fv @ radiance(power2 + later)), later)
    return r1 + r2 + r3
