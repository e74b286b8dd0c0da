"""Seam measures: the radiance mismatch along edges shared by neighbouring patches, of a bake
(sampled in its atlas as GL_LINEAR does) or of a solution's own mesh.

:func:`seam_error` compares whole, coplanar edges (textured patches of a Baked, or every patch of
a Solution); :func:`seam_measure` samples every shared segment of a bake densely from both sides,
partial overlaps and textured-vs-mesh edges included. ``python -m iat.measure.seams SOLUTION.npz``
prints the seam and harmonisation figures of docs/baking.md.
"""

from __future__ import annotations

import numpy as np

from iat.bake.baker import Baker
from iat.bake.flatten import flatten, sample_tile
from iat.bake.policy import BakePolicy
from iat.bake.seams import EdgePairs, solution_pairs
from iat.geometry.mesh import patch_normals
from iat.radiosity.solution import Solution

__all__ = ["sample_pages", "seam_error", "seam_measure"]


def sample_pages(pages: np.ndarray, layer, uv) -> np.ndarray:
    """Bilinear lookup like GL_LINEAR with clamp-to-edge: (k,) layers, (k, 2) uv -> (k, 3)."""
    _, H, W, _ = pages.shape
    x = np.clip(uv[:, 0] * W - 0.5, 0, W - 1)
    y = np.clip(uv[:, 1] * H - 0.5, 0, H - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(W - 2, 0))
    y0 = np.minimum(np.floor(y).astype(np.int64), max(H - 2, 0))
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
    p = pages.astype(np.float64) if pages.dtype != np.float64 else pages
    L = np.asarray(layer, dtype=np.int64)
    return (
        (1 - fx) * (1 - fy) * p[L, y0, x0]
        + fx * (1 - fy) * p[L, y0, x1]
        + (1 - fx) * fy * p[L, y1, x0]
        + fx * fy * p[L, y1, x1]
    )


def seam_error(
    obj, solution=None, samples: int = 17, coplanar_only: bool = True, method: str = "scan"
) -> dict:
    """Radiance mismatch along world-space edges shared by neighbouring patches.

    obj : a :class:`Baked` (its textured patches; both sides sampled bilinearly in the atlas,
      as GL_LINEAR does) or a Solution (every patch; each side is its own mesh along the edge,
      i.e. the edge row of its ``scan`` tile, or of another ``method``)
    solution : with a Baked, the solution: its albedo turns incoming light back into radiance
      on detail patches (without it, stored values are compared); ignored for a Solution
    samples : points per edge, corners included
    coplanar_only : only pairs of patches whose normals agree (a wall and a floor meeting at
      an edge differ physically)

    Shared edges are polygon edges with the same two end points (within 1e-6 of the model
    size), either direction. Returns dict(max=, mean=, edges=, samples=) of the absolute
    radiance difference (max over channels); zeros when no edge is shared.
    """
    none = {"max": 0.0, "mean": 0.0, "edges": 0, "samples": 0}
    t = np.linspace(0.0, 1.0, int(samples))
    is_sol = isinstance(obj, Solution)
    if is_sol:
        sol = obj
        ps = np.arange(len(sol.patch_is_quad))
        corners = np.asarray(sol.patch_corners, dtype=np.float64)
        is_quad = np.asarray(sol.patch_is_quad, dtype=bool)
        # patch (u, v) of the corner slots
        uvc = np.where(
            is_quad[:, None, None],
            np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64),
            np.array([[0, 0], [1, 0], [0, 1], [0, 1]], dtype=np.float64),
        )
    else:
        baked, sol = obj, solution
        if not len(baked.tex_patch):
            return none
        ps, first = np.unique(baked.tex_patch, return_index=True)
        nv = np.bincount(baked.tex_patch)[ps]
        is_quad = nv == 4
        sl = first[:, None] + np.minimum(np.arange(4)[None, :], nv[:, None] - 1)
        corners = baked.tex_positions[sl].astype(np.float64)  # (k, 4, 3); triangles repeat corner 2
        uvc = baked.tex_uv[sl].astype(np.float64)  # atlas uv of the corner slots
        layer = baked.tex_layer[first].astype(np.int64)
    k = len(ps)
    if k < 2:
        return none
    # polygon edges: slot a -> slot b (triangles: 0-1, 1-2, 2-0)
    b_slot = np.where(is_quad[:, None], np.array([1, 2, 3, 0]), np.array([1, 2, 0, 0]))
    e_p, e_s = np.nonzero(np.where(is_quad[:, None], True, np.arange(4)[None, :] < 3))
    ea, eb = e_s, b_slot[e_p, e_s]
    size = float(np.ptp(corners.reshape(-1, 3), axis=0).max())
    eps = max(size, 1e-12) * 1e-6
    qa = np.round(corners[e_p, ea] / eps).astype(np.int64)
    qb = np.round(corners[e_p, eb] / eps).astype(np.int64)
    diff = qa - qb
    a_less = diff[np.arange(len(diff)), np.argmax(diff != 0, axis=1)] < 0
    keyrows = np.concatenate([np.where(a_less[:, None], qa, qb), np.where(a_less[:, None], qb, qa)], axis=1)
    _, inv = np.unique(keyrows, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    order = np.argsort(inv, kind="stable")
    same = inv[order[1:]] == inv[order[:-1]]
    e1, e2 = order[:-1][same], order[1:][same]
    keep = e_p[e1] != e_p[e2]
    if coplanar_only:
        nrm = patch_normals(corners, is_quad)
        keep &= (nrm[e_p[e1]] * nrm[e_p[e2]]).sum(axis=1) > 1 - 1e-6
    e1, e2 = e1[keep], e2[keep]
    if not len(e1):
        return none
    same_dir = (qa[e1] == qa[e2]).all(axis=1)  # edge 2 starts where edge 1 starts
    t1 = np.broadcast_to(t, (len(e1), len(t)))
    t2 = np.where(same_dir[:, None], t1, 1.0 - t1)

    def points(e, tt):
        w = tt[..., None]
        return uvc[e_p[e], ea[e]][:, None] * (1 - w) + uvc[e_p[e], eb[e]][:, None] * w  # (E, S, 2)

    if is_sol:
        used = np.unique(np.concatenate([e_p[e1], e_p[e2]]))
        tiles = flatten(sol, ps[used], method)

        def values(e, tt):
            uv = points(e, tt)
            out = np.empty(uv.shape[:2] + (3,))
            pe = e_p[e]
            for q in np.unique(pe).tolist():  # one call per patch, vectorised over its samples
                r = np.flatnonzero(pe == q)
                out[r] = sample_tile(tiles[int(ps[q])], uv[r, :, 0].ravel(), uv[r, :, 1].ravel()).reshape(
                    len(r), -1, 3
                )
            return out.reshape(-1, 3)

    else:

        def values(e, tt):
            uv = points(e, tt).reshape(-1, 2)
            q = np.repeat(e_p[e], tt.shape[1])
            val = sample_pages(baked.pages, layer[q], uv)
            if sol is not None and len(baked.tex_detail):
                det = baked.tex_detail[first[q]] > 0
                alb = np.asarray(sol.patch_albedo, dtype=np.float64)[ps[q]]
                val = np.where(det[:, None], val * alb, val)
            return val

    d = np.abs(values(e1, t1) - values(e2, t2)).max(axis=1)
    return {"max": float(d.max()), "mean": float(d.mean()), "edges": int(len(e1)), "samples": int(len(d))}


def seam_measure(
    baked, solution, samples: int = 33, include_mesh: bool = True, pairs: EdgePairs | None = None
) -> dict:
    """Largest and mean radiance difference along shared segments, sampled from both sides.

    baked : a :class:`~iat.bake.baked.Baked`; textured sides are read bilinearly in its atlas (as
      GL_LINEAR does; detail patches times their albedo), mesh sides (``include_mesh``) from the
      solution (the mesh along the edge)
    samples : points per segment, ends included
    pairs : :class:`EdgePairs` (default :func:`solution_pairs`: same material, coplanar within
      :data:`~iat.bake.seams.MAX_ANGLE_DEG`), partial overlaps included
    Returns dict(max=, mean=, segments=, samples=, textured=: the same over textured-textured
    segments only); zeros when none.
    """
    pairs = solution_pairs(solution) if pairs is None else pairs
    none = {"max": 0.0, "mean": 0.0, "segments": 0, "samples": 0}
    textured = np.asarray(baked.patch_textured, dtype=bool)
    if not len(pairs) or not len(baked.tex_patch):
        return {**none, "textured": dict(none)}
    tp = textured[pairs.patch]
    use = tp.any(1) if include_mesh else tp.all(1)
    if not use.any():
        return {**none, "textured": dict(none)}
    P_, E_, LO, HI = pairs.patch[use], pairs.edge[use], pairs.lo[use], pairs.hi[use]
    tex = textured[P_]
    w = np.linspace(0.0, 1.0, int(samples))[None, :]
    # per textured patch: atlas uv of its corner slots, layer
    ptex, first = np.unique(baked.tex_patch, return_index=True)
    slot_of = np.full(len(textured), -1, dtype=np.int64)
    slot_of[ptex] = first
    nv = np.bincount(baked.tex_patch, minlength=len(textured))
    is_quad = np.asarray(solution.patch_is_quad, dtype=bool)
    albedo = np.asarray(solution.patch_albedo, dtype=np.float64)
    pages = baked.pages
    mesh_ps = np.unique(P_[~tex])
    mesh_tiles = flatten(solution, mesh_ps, "bilinear") if len(mesh_ps) else {}
    uv_corner = np.where(
        is_quad[:, None, None],
        np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64),
        np.array([[0, 0], [1, 0], [0, 1], [0, 1]], dtype=np.float64),
    )
    vals = []
    for s in (0, 1):
        p, e = P_[:, s], E_[:, s]
        t = LO[:, s, None] + (HI[:, s, None] - LO[:, s, None]) * w  # (n, S)
        sa = e
        sb = np.where(is_quad[p], (e + 1) % 4, (e + 1) % 3)
        out = np.zeros(t.shape + (3,))
        tx = tex[:, s]
        if tx.any():
            q = np.flatnonzero(tx)
            f0 = slot_of[p[q]]
            n_q = nv[p[q]]
            ua = baked.tex_uv[f0 + np.minimum(sa[q], n_q - 1)].astype(np.float64)
            ub = baked.tex_uv[f0 + np.minimum(sb[q], n_q - 1)].astype(np.float64)
            uv = ua[:, None] * (1 - t[q, :, None]) + ub[:, None] * t[q, :, None]
            layer = np.repeat(baked.tex_layer[f0].astype(np.int64), t.shape[1])
            v = sample_pages(pages, layer, uv.reshape(-1, 2)).reshape(len(q), -1, 3)
            if len(baked.tex_detail):
                det = baked.tex_detail[f0] > 0
                v = np.where(det[:, None, None], v * albedo[p[q]][:, None, :], v)
            out[q] = v
        if (~tx).any():
            q = np.flatnonzero(~tx)
            ca = uv_corner[p[q], sa[q]]
            cb = uv_corner[p[q], sb[q]]
            uvp = ca[:, None] * (1 - t[q, :, None]) + cb[:, None] * t[q, :, None]
            for pp in np.unique(p[q]).tolist():
                rr = np.flatnonzero(p[q] == pp)
                out[q[rr]] = sample_tile(
                    mesh_tiles[pp], uvp[rr, :, 0].ravel(), uvp[rr, :, 1].ravel()
                ).reshape(len(rr), -1, 3)
        vals.append(out)
    d = np.abs(vals[0] - vals[1]).max(axis=2)  # (n, S)

    def summary(sel):
        if not sel.any():
            return dict(none)
        x = d[sel]
        return {
            "max": float(x.max()),
            "mean": float(x.mean()),
            "segments": int(sel.sum()),
            "samples": int(x.size),
        }

    res = summary(np.ones(len(d), dtype=bool))
    res["textured"] = summary(tex.all(1))
    return res


# ---------------------------------------------------------------------------
# figures for docs/baking.md: python -m iat.measure.seams SOLUTION.npz [more.npz ...]


def _main(argv=None) -> None:  # pragma: no cover - a measuring script
    import argparse
    import time

    ap = argparse.ArgumentParser(description="seams and harmonisation cost of solutions (docs/baking.md)")
    ap.add_argument("solutions", nargs="+")
    args = ap.parse_args(argv)
    for path in args.solutions:
        sol = Solution.load(path)
        baker = Baker(sol)
        t = time.perf_counter()
        st_pairs = solution_pairs(sol)
        print(
            f"{path}: {len(sol.leaf_patch)} elements, {len(st_pairs)} pairs, pairing "
            f"{(time.perf_counter() - t) * 1e3:.0f} ms"
        )
        for scale in (1.0, 0.5, 0.25):
            c = seam_error(baker.bake(BakePolicy(threshold=0, scale=scale, detail=False)), sol)
            n = seam_error(
                baker.bake(BakePolicy(threshold=0, scale=scale, scale_mode="naive", detail=False)), sol
            )
            m = seam_measure(baker.bake(BakePolicy(threshold=0, scale=scale, detail=False)), sol)
            print(
                f"  scale {scale}: seam_error clamped {c['max']:.4g} / naive {n['max']:.4g} "
                f"({c['edges']} edges); seam_measure clamped {m['max']:.4g} ({m['segments']} segments)"
            )

        def timed(pol, cold, baker=baker):
            baker.forget_pages(seams=cold)
            return baker.bake(pol).timings

        for scale in (1.0, 0.5, 0.25):
            pol = BakePolicy(threshold=0, scale=scale, detail=False)
            timed(pol, False)
            tms = [timed(pol, True) for _ in range(3)]
            print(
                f"  cold harmonisation, scale {scale}: {np.median([x['seams'] for x in tms]) * 1e3:.1f} ms "
                f"(bake {np.median([x['total'] for x in tms]) * 1e3:.1f} ms)"
            )
        ws, tot = [], []
        for scale in (1.0, 0.5):
            for thr in list(range(8)) + list(range(7, -1, -1)):
                tm = timed(BakePolicy(threshold=thr, scale=scale, detail=False), False)
                ws.append(tm.get("seams", 0.0))
                tot.append(tm["total"])
        p = np.percentile(np.array(ws) * 1e3, [50, 95])
        q = np.percentile(np.array(tot) * 1e3, [50, 95])
        print(
            f"  threshold walk (32 steps): seams p50 {p[0]:.1f} p95 {p[1]:.1f} ms; "
            f"bake p50 {q[0]:.1f} p95 {q[1]:.1f} ms"
        )


if __name__ == "__main__":  # pragma: no cover
    _main()
