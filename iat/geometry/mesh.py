"""Mesh processing on plain arrays: welding, zero-area faces, quad merging, pre-splitting.

The loader's array steps (:func:`iat.io.load.load_scene` runs them in this order):
:func:`weld_vertices` merges coincident positions, :func:`degenerate_faces` finds
zero-area triangles, :func:`merge_quads` pairs coplanar triangles back into convex
quads (patch corners ``(p, 4)`` int64 with ``-1`` in column 3 for triangles) and
:func:`split_patches` pre-splits big patches into regular grids. Every function
is vectorised and works on numpy arrays only (positions in scene units).
"""

from __future__ import annotations

import numpy as np

from iat.errors import OptionError

#: Coplanarity tolerance for merging triangle pairs into quads (radians between normals).
QUAD_ANGLE_TOL = 1e-4
#: a pair becomes a quad root only when its corners are within this of a parallelogram:
#: |c0 - c1 + c2 - c3| (the bilinear twist, 4x the centre's offset from the affine split)
#: over the mean diagonal; a skewed quad's bilinear lattice would be textured affinely per triangle
QUAD_SKEW_TOL = 0.02
#: Positions closer than this times the bounding-box diagonal are welded.
WELD_REL_TOL = 1e-9


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (faster than np.cross on big arrays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _norm(a: np.ndarray) -> np.ndarray:
    return np.sqrt((a * a).sum(axis=-1))


def corner_positions(vertices: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(p, 4, 3) float64 corner positions of patches ``corners`` (p, 4) int64 (-1 in column 3 for
    triangles, whose 4th corner then repeats their 3rd)."""
    c = np.asarray(corners, dtype=np.int64).copy()
    tri = c[:, 3] < 0
    c[tri, 3] = c[tri, 2]
    return np.asarray(vertices, dtype=np.float64)[c]


def patch_normals(corners: np.ndarray, is_quad: np.ndarray) -> np.ndarray:
    """(P, 3) unit normals of patches with corners (P, 4, 3) (triangles: slots 0-2), is_quad (P,)."""
    n = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    tri = ~np.asarray(is_quad, dtype=bool)
    n[tri] = np.cross(corners[tri, 1] - corners[tri, 0], corners[tri, 2] - corners[tri, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def patch_areas(corners: np.ndarray, is_quad: np.ndarray) -> np.ndarray:
    """(P,) areas of patches with corners (P, 4, 3): a quad as its two triangles (0, 1, 2), (0, 2, 3)."""
    a = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    q = np.asarray(is_quad, dtype=bool)
    a[q] += 0.5 * np.linalg.norm(
        np.cross(corners[q, 2] - corners[q, 0], corners[q, 3] - corners[q, 0]), axis=1
    )
    return a


def quad_twist(c0: np.ndarray, c1: np.ndarray, c2: np.ndarray, c3: np.ndarray) -> np.ndarray:
    """(n,) how far quads (corners (n, 3) each, in order) are from parallelograms:
    ``|c0 - c1 + c2 - c3|`` (the bilinear twist) over the mean diagonal (:data:`QUAD_SKEW_TOL`)."""
    return _norm(c0 - c1 + c2 - c3) / np.maximum(0.5 * (_norm(c2 - c0) + _norm(c3 - c1)), 1e-300)


def _group_rows(key: np.ndarray):
    """Group equal rows of an (n, 3) int64 array.

    Returns (order, new_group): ``key[order]`` has equal rows adjacent and
    ``new_group[i]`` is True where sorted row i starts a new group.
    """
    # sort one int64 hash instead of three columns; check the hash did not merge distinct rows
    with np.errstate(over="ignore"):
        h = key[:, 0] * np.int64(-7046029254386353131) + key[:, 1] * np.int64(0x5851F42D4C957F2D)
        h = (h ^ (h >> np.int64(29))) + key[:, 2] * np.int64(0x2545F4914F6CDD1D)
    order = np.argsort(h, kind="stable")
    hs = h[order]
    new_group = np.ones(len(key), dtype=bool)
    new_group[1:] = hs[1:] != hs[:-1]
    ks = key[order]
    same = ~new_group[1:]
    if same.any() and (ks[1:][same] != ks[:-1][same]).any():  # hash collision: sort by the rows
        order = np.lexsort(key.T[::-1])
        ks = key[order]
        new_group[1:] = (ks[1:] != ks[:-1]).any(axis=1)
    return order, new_group


def weld_vertices(vertices: np.ndarray, faces: np.ndarray, rel_tol: float = WELD_REL_TOL):
    """Merge vertices whose positions agree within ``rel_tol`` x bounding-box diagonal.

    vertices : (n, 3) float64; faces : (..., k) int64 indices (negative entries kept as they are)
    Returns (vertices (m, 3) float64 of the used vertices only, faces remapped).
    Unused vertices are dropped; the order follows a spatial hash, not the input.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    valid = faces >= 0
    used_mask = np.zeros(len(vertices), dtype=bool)
    used_mask[faces[valid]] = True
    used = np.flatnonzero(used_mask)
    if len(used) == 0:
        return np.zeros((0, 3)), faces.copy()
    V = vertices[used]
    lo = V.min(axis=0)
    diag = float(np.linalg.norm(V.max(axis=0) - lo))
    q = max(diag * rel_tol, 1e-300)
    key = np.round((V - lo) / q).astype(np.int64)
    order, new_group = _group_rows(key)
    group = np.cumsum(new_group) - 1
    inv_used = np.empty(len(V), dtype=np.int64)
    inv_used[order] = group
    out_v = V[order[new_group]]  # representative: the first of each group
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = inv_used
    out_f = faces.copy()
    out_f[valid] = remap[faces[valid]]
    return out_v, out_f


def _weld_some(vertices: np.ndarray, faces: np.ndarray, weldable: np.ndarray, rel_tol: float = WELD_REL_TOL):
    """:func:`weld_vertices` restricted to the ``weldable`` (n,) bool vertices; the others stay distinct."""
    faces = np.asarray(faces, dtype=np.int64)
    w = np.flatnonzero(weldable)
    Vw = vertices[w]
    lo = Vw.min(axis=0)
    q = max(float(np.linalg.norm(Vw.max(axis=0) - lo)) * rel_tol, 1e-300)
    order, new_group = _group_rows(np.round((Vw - lo) / q).astype(np.int64))
    remap = np.empty(len(vertices), dtype=np.int64)
    remap[w[order]] = np.cumsum(new_group) - 1
    n_w = int(new_group.sum())
    rest = np.flatnonzero(~weldable)
    remap[rest] = n_w + np.arange(len(rest))
    out_v = np.concatenate([Vw[order[new_group]], vertices[rest]])
    valid = faces >= 0
    out_f = faces.copy()
    out_f[valid] = remap[faces[valid]]
    return compact_vertices(out_v, out_f)


def compact_vertices(vertices: np.ndarray, faces: np.ndarray):
    """Drop the vertices no face uses, keeping the order of the others.

    vertices : (n, 3); faces : (..., k) int64 (negative entries kept as they are)
    Returns (vertices (m, 3), faces remapped).
    """
    faces = np.asarray(faces, dtype=np.int64)
    valid = faces >= 0
    used = np.zeros(len(vertices), dtype=bool)
    used[faces[valid]] = True
    remap = np.cumsum(used) - 1
    out_f = faces.copy()
    out_f[valid] = remap[faces[valid]]
    return np.asarray(vertices)[used], out_f


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f,) float64 areas of triangles ``faces`` (f, 3)."""
    v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return 0.5 * _norm(_cross(v1 - v0, v2 - v0))


def degenerate_faces(vertices: np.ndarray, faces: np.ndarray, rel: float = 1e-12) -> np.ndarray:
    """(f,) bool: zero-area triangles (repeated corners, or twice the area below ``rel`` x longest edge²)."""
    v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    e0, e1, e2 = v1 - v0, v2 - v1, v0 - v2
    cr = _norm(_cross(e0, -e2))
    longest2 = np.maximum(np.maximum((e0 * e0).sum(1), (e1 * e1).sum(1)), (e2 * e2).sum(1))
    rep = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    return rep | (cr <= rel * longest2) | (longest2 == 0)


def merge_quads(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_material: np.ndarray,
    face_uv: np.ndarray | None = None,
    angle_tol: float = QUAD_ANGLE_TOL,
    uv_tol: float = 1e-6,
    skew_tol: float = QUAD_SKEW_TOL,
):
    """Merge coplanar triangle pairs back into convex quads.

    Two triangles pair when they share an edge (in opposite directions; edges
    used by up to 8 triangles are searched), have the same material, the same detail UVs on the
    shared corners, normals within ``angle_tol`` radians, and their union is a
    strictly convex quad. A greedy matching (best-shaped quads first: largest
    smallest corner sine, ties broken by a fixed-seed shuffle) picks disjoint
    pairs; every step is vectorised.

    vertices : (n, 3) float64; faces : (f, 3) int64, non-degenerate
    face_material : (f,) int64; face_uv : (f, 3, 2) float64 or None
    Returns patch_corners (p, 4) int64 (-1 in column 3 for triangles),
    patch_material (p,) int64, patch_uv (p, 4, 2) float64. Quads keep the
    triangles' winding (a split ``[0,1,2],[2,3,0]`` comes back as ``[0,1,2,3]``);
    patches come in the order of their first triangle.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    M = np.asarray(face_material, dtype=np.int64).reshape(-1)
    nf = len(F)
    UV = np.zeros((nf, 3, 2)) if face_uv is None else np.asarray(face_uv, dtype=np.float64).reshape(nf, 3, 2)
    if nf == 0:
        return np.zeros((0, 4), dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 4, 2))

    Ff = F.ravel()  # corner h = 3 f + k; half-edge h goes from Ff[h] to Ff[next(h)]
    UVf = UV.reshape(-1, 2)
    v0, v1, v2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    N = _cross(v1 - v0, v2 - v0)
    N /= np.maximum(_norm(N), 1e-300)[:, None]

    h = np.arange(3 * nf)
    h_next = h - h % 3 + (h % 3 + 1) % 3
    h_to = Ff[h_next]
    nv = int(F.max()) + 1
    key = np.minimum(Ff, h_to) * nv + np.maximum(Ff, h_to)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    start = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    length = np.diff(np.r_[start, len(ks)])
    # candidate pairs: every two half-edges on the same edge (an edge shared by more than two
    # triangles, as in double-sided walls, gives all its pairs; the filters below pick the valid ones)
    cand_a, cand_b = [], []
    for c in np.unique(length[(length >= 2) & (length <= 8)]):
        st = start[length == c]
        ii, jj = np.triu_indices(int(c), 1)
        cand_a.append(order[(st[:, None] + ii).ravel()])
        cand_b.append(order[(st[:, None] + jj).ravel()])
    ha = np.concatenate(cand_a) if cand_a else np.zeros(0, dtype=np.int64)
    hb = np.concatenate(cand_b) if cand_b else np.zeros(0, dtype=np.int64)
    del key, order, ks, start, length, cand_a, cand_b

    fa, fb = ha // 3, hb // 3
    ok = (Ff[ha] == h_to[hb]) & (fa != fb) & (M[fa] == M[fb])
    ha, hb, fa, fb = ha[ok], hb[ok], fa[ok], fb[ok]
    ok = (N[fa] * N[fb]).sum(axis=1) >= np.cos(angle_tol)
    ha, hb, fa, fb = ha[ok], hb[ok], fa[ok], fb[ok]
    ha1, hb1 = h_next[ha], h_next[hb]
    ha2, hb2 = h_next[ha1], h_next[hb1]
    # same UVs at the two shared corners: a[k] == b[k'+1] and a[k+1] == b[k']
    du = np.maximum(np.abs(UVf[ha] - UVf[hb1]).max(axis=1), np.abs(UVf[ha1] - UVf[hb]).max(axis=1))
    ok = du <= uv_tol * np.maximum(1.0, np.abs(UVf[ha]).max(axis=1))
    ha, hb, fa, fb, ha1, ha2, hb2 = (x[ok] for x in (ha, hb, fa, fb, ha1, ha2, hb2))

    # quad around a's winding: a[k+1], a[k+2], a[k], b's opposite corner; corners 1 and 3
    # are triangle corners (convex by construction), corners 0 and 2 end the shared diagonal
    p0, p1, p2, p3 = V[Ff[ha1]], V[Ff[ha2]], V[Ff[ha]], V[Ff[hb2]]
    n = N[fa]
    e01, e12, e23, e30 = p1 - p0, p2 - p1, p3 - p2, p0 - p3
    l01, l12, l23, l30 = _norm(e01), _norm(e12), _norm(e23), _norm(e30)
    s0 = (_cross(e30, e01) * n).sum(1) / np.maximum(l30 * l01, 1e-300)
    s1 = (_cross(e01, e12) * n).sum(1) / np.maximum(l01 * l12, 1e-300)
    s2 = (_cross(e12, e23) * n).sum(1) / np.maximum(l12 * l23, 1e-300)
    s3 = (_cross(e23, e30) * n).sum(1) / np.maximum(l23 * l30, 1e-300)
    score = np.minimum(np.minimum(s0, s1), np.minimum(s2, s3))
    ok = (s0 > 1e-6) & (s2 > 1e-6) & (quad_twist(p0, p1, p2, p3) <= skew_tol)
    ha, hb, fa, fb, ha1, ha2, hb2, score = (x[ok] for x in (ha, hb, fa, fb, ha1, ha2, hb2, score))

    # greedy matching: a candidate wins when it ranks best at both of its faces
    m = len(ha)
    rng = np.random.default_rng(0)
    rank = np.empty(m, dtype=np.int64)
    rank[np.lexsort((rng.random(m), -np.round(score, 3)))] = np.arange(m)
    matched = np.zeros(nf, dtype=bool)
    best = np.full(nf, m, dtype=np.int64)
    idx = np.arange(m)
    chosen = []
    while len(idx):
        a_, b_, r = fa[idx], fb[idx], rank[idx]
        best[a_] = m
        best[b_] = m
        np.minimum.at(best, a_, r)
        np.minimum.at(best, b_, r)
        win = (best[a_] == r) & (best[b_] == r)
        chosen.append(idx[win])
        matched[a_[win]] = True
        matched[b_[win]] = True
        idx = idx[~(matched[a_] | matched[b_])]
    win = np.concatenate(chosen) if chosen else np.zeros(0, dtype=np.int64)

    qa, qb = fa[win], fb[win]
    qh = np.stack([ha1[win], ha2[win], ha[win], hb2[win]], axis=1)
    q_corners = Ff[qh]
    q_uv = UVf[qh]
    tri = np.flatnonzero(~matched)
    t_corners = np.concatenate([F[tri], np.full((len(tri), 1), -1, dtype=np.int64)], axis=1)
    t_uv = UV[tri][:, [0, 1, 2, 2]]

    first = np.concatenate([np.minimum(qa, qb), tri])
    o = np.argsort(first, kind="stable")
    corners = np.concatenate([q_corners, t_corners])[o]
    material = np.concatenate([M[qa], M[tri]])[o]
    uv = np.concatenate([q_uv, t_uv])[o]
    return corners, material, uv


def split_patches(
    vertices: np.ndarray,
    patch_corners: np.ndarray,
    patch_material: np.ndarray,
    patch_uv: np.ndarray,
    max_edge: float,
):
    """Pre-split patches longer than ``max_edge`` into regular grids of root patches.

    A quad whose longest edge exceeds ``max_edge`` becomes ``n x m`` quads with
    ``n = ceil(longest u-edge / max_edge)``, ``m = ceil(longest v-edge / max_edge)``
    (bilinear in its own parametrisation); a triangle becomes ``4**k`` triangles,
    ``k = ceil(log2(longest edge / max_edge))``. Materials are copied, UVs
    interpolated, windings kept; new vertices are welded to their neighbours.

    vertices : (n, 3) float64; patch_corners : (p, 4) int64; patch_material : (p,) int64;
    patch_uv : (p, 4, 2) float64.
    Returns (vertices, patch_corners, patch_material, patch_uv), children in
    place of their parent.
    """
    if not (max_edge > 0 and np.isfinite(max_edge)):
        raise OptionError(f"max_edge must be a positive number, got {max_edge!r}")
    V = np.asarray(vertices, dtype=np.float64)
    C = np.asarray(patch_corners, dtype=np.int64).reshape(-1, 4)
    Mat = np.asarray(patch_material, dtype=np.int64).reshape(-1)
    UV = np.asarray(patch_uv, dtype=np.float64).reshape(-1, 4, 2)
    is_quad = C[:, 3] >= 0
    P = V[np.where(is_quad[:, None], C, C[:, [0, 1, 2, 2]])]

    pts, on_edge, kids, kid_mat, kid_uv, kid_parent = [], [], [], [], [], []
    n_pts = len(V)  # index of the next new point

    # quads: an (n + 1) x (m + 1) lattice of points per parent, point (a, b) at base + b (n + 1) + a
    q = np.flatnonzero(is_quad)
    c = P[q]
    n = np.ceil(np.maximum(_norm(c[:, 1] - c[:, 0]), _norm(c[:, 2] - c[:, 3])) / max_edge)
    m = np.ceil(np.maximum(_norm(c[:, 3] - c[:, 0]), _norm(c[:, 2] - c[:, 1])) / max_edge)
    n, m = np.maximum(n, 1).astype(np.int64), np.maximum(m, 1).astype(np.int64)
    sel = (n > 1) | (m > 1)
    q, c, n, m = q[sel], c[sel], n[sel], m[sel]
    if len(q):
        cnt = (n + 1) * (m + 1)
        base = n_pts + np.cumsum(cnt) - cnt
        pid = np.repeat(np.arange(len(q)), cnt)
        local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        a, b = local % (n[pid] + 1), local // (n[pid] + 1)
        u, v = a / n[pid], b / m[pid]
        w = [(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v]
        acc = w[0][:, None] * c[pid, 0]
        for i in range(1, 4):
            acc += w[i][:, None] * c[pid, i]
        pts.append(acc)
        on_edge.append((a == 0) | (b == 0) | (a == n[pid]) | (b == m[pid]))
        n_pts += len(u)
        del acc, w, u, v, a, b, local, pid
        cnt = n * m
        pid = np.repeat(np.arange(len(q)), cnt)
        local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        nn, mm = n[pid], m[pid]
        a, b = local % nn, local // nn
        row = nn + 1
        first = base[pid] + b * row + a
        kids.append(np.stack([first, first + 1, first + row + 1, first + row], axis=1))
        uvq = UV[q]
        if uvq.any():
            us = np.stack([a, a + 1, a + 1, a], axis=1) / nn[:, None]
            vs = np.stack([b, b, b + 1, b + 1], axis=1) / mm[:, None]
            uvp = uvq[pid]
            kid_uv.append(
                ((1 - us) * (1 - vs))[..., None] * uvp[:, None, 0]
                + (us * (1 - vs))[..., None] * uvp[:, None, 1]
                + (us * vs)[..., None] * uvp[:, None, 2]
                + ((1 - us) * vs)[..., None] * uvp[:, None, 3]
            )
        else:
            kid_uv.append(np.zeros((len(pid), 4, 2)))
        kid_mat.append(Mat[q][pid])
        kid_parent.append(q[pid])

    # triangles: the lattice i + j <= N, N = 2**k, per parent
    t = np.flatnonzero(~is_quad)
    c = P[t][:, :3]
    longest = np.maximum(
        np.maximum(_norm(c[:, 1] - c[:, 0]), _norm(c[:, 2] - c[:, 1])), _norm(c[:, 0] - c[:, 2])
    )
    k = np.zeros(len(t), dtype=np.int64)
    big = longest > max_edge
    k[big] = np.ceil(np.log2(longest[big] / max_edge)).astype(np.int64)
    for level in np.unique(k[big]):
        sel = t[k == level]
        cs = P[sel][:, :3]
        N = 1 << int(level)
        i, j = np.meshgrid(np.arange(N + 1), np.arange(N + 1), indexing="ij")
        inside = (i + j) <= N
        table = np.full((N + 1, N + 1), -1, dtype=np.int64)
        table[inside] = np.arange(int(inside.sum()))
        li, lj = i[inside], j[inside]
        u, v = li / N, lj / N
        w = np.stack([1 - u - v, u, v])  # (3, s)
        pts.append(np.einsum("ws,twd->tsd", w, cs).reshape(-1, 3))
        n_lat = len(li)
        on_edge.append(np.tile((li == 0) | (lj == 0) | (li + lj == N), len(sel)))
        bases = n_pts + n_lat * np.arange(len(sel))
        n_pts += n_lat * len(sel)
        i, j = i[:N, :N], j[:N, :N]
        up, dn = (i + j) <= N - 1, (i + j) <= N - 2
        iu, ju, idn, jdn = i[up], j[up], i[dn], j[dn]
        # the down triangles keep the parent's winding: (i+1, j+1), (i, j+1), (i+1, j)
        ci = np.concatenate([np.stack([iu, iu + 1, iu], 1), np.stack([idn + 1, idn, idn + 1], 1)])
        cj = np.concatenate([np.stack([ju, ju, ju + 1], 1), np.stack([jdn + 1, jdn + 1, jdn], 1)])
        sub = table[ci, cj]  # (s, 3)
        s = len(sub)
        tri = (bases[:, None, None] + sub[None]).reshape(-1, 3)
        kids.append(np.concatenate([tri, np.full((len(tri), 1), -1, dtype=np.int64)], axis=1))
        u, v = ci / N, cj / N
        wt = np.stack([1 - u - v, u, v], axis=2)  # (s, 3, 3)
        uvs = np.einsum("scw,twd->tscd", wt, UV[sel][:, :3]).reshape(-1, 3, 2)
        kid_uv.append(uvs[:, [0, 1, 2, 2]])
        kid_mat.append(np.repeat(Mat[sel], s))
        kid_parent.append(np.repeat(sel, s))
    if not kids:
        V, C = compact_vertices(V, C)
        return V, C, Mat, UV

    split = np.zeros(len(C), dtype=bool)
    split[q] = True
    split[t[big]] = True
    keep = np.flatnonzero(~split)
    allV = np.concatenate([V, *pts])
    corners = np.concatenate([C[keep], *kids])
    material = np.concatenate([Mat[keep], *kid_mat])
    uv = np.concatenate([UV[keep], *kid_uv])
    parent = np.concatenate([keep, *kid_parent])
    o = np.argsort(parent, kind="stable")
    # only points on a parent's boundary can coincide with others: weld those, keep the interior as is
    weldable = np.concatenate([np.ones(len(V), dtype=bool), *on_edge])
    allV, corners = _weld_some(allV, corners[o], weldable)
    return allV, corners, material[o], uv[o]
