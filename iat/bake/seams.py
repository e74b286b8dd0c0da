"""Seams between neighbouring patches: edge pairing and harmonisation of tile edges.

Neighbouring roots (patches) are subdivided independently, so two textured neighbours
represent their shared edge by different piecewise-linear functions (different depths,
hence different texel counts, and after scaling different texel positions). GL_LINEAR
along a tile's edge is the linear interpolation of the tile's *edge texels* only (for a
triangle's hypotenuse too, thanks to :func:`iat.bake.flatten.extend_triangle`), so two sides
render the same function along a shared segment exactly when their edge texel rows
describe the same polyline there.

:func:`harmonise_rings` makes them do so, on the tiles' boundary rings (:func:`tile_ring`,
written back by :func:`apply_ring`), after flatten + (clamped) scaling and before packing:

- **pairs** (:class:`EdgePairs`, once per solution): every two patch boundary edges that
  share a world-space segment (whole edges, or partial overlaps: T-junctions between
  patches of different sizes) and whose patches should show one continuous radiance there:
  same material, normals within :data:`MAX_ANGLE_DEG`, on opposite sides of the segment.
  Non-coplanar neighbours (a wall meeting a floor) are left alone: their radiance differs
  physically at the corner, and the mesh keeps it apart too.
- **master**: of the two sides, the one with the larger texel spacing along the segment
  (the coarser) defines the function; a tie goes to the lower patch index. A mesh patch
  (below the threshold) is always the master of a textured neighbour: its edge function is
  its solution vertices along the edge (the row of its scale-1 ``bilinear`` tile), which
  the mesh part draws.
- **slave**: its edge texels inside the segment (ends included) take the master's polyline
  evaluated at their positions. With texel counts ``2**k + 1`` on dyadic patches (every
  scale ``2**-j``: 1, 0.5, 0.25) the coarse knots are a subset of the fine ones and both
  sides then render the identical function; on other scales (the budget ladder) the fine
  side is the coarse polyline sampled at its own knots (exact at every shared knot, off by
  the coarse polyline's bend in between).
- **corners** where 3-4 patches meet (diagonal neighbours never share an edge) form
  groups (:attr:`EdgePairs.corner_group`); every textured corner of a group takes the value
  of its top member (a mesh patch, else the fewest texels, else the lowest index), which no
  whole-edge partner overwrites. Edge copies and corner groups are repeated (Jacobi) until
  nothing changes: 2-3 passes here, at most :data:`MAX_PASSES`.
- triangle tiles get their outer half refilled (:func:`~iat.bake.flatten.extend_triangle`) after
  their hypotenuse changed, so bilinear filtering stays exact at the diagonal.

The Baker consumes these pure steps (it owns their caches: the pairs, the original rings per
tile key, and each harmonised box per box key with the ring it was built from, reused while
that ring is unchanged, so a threshold step rebuilds only the boxes near the change): the rings
of :func:`involved_patches` at :func:`ring_sides`, harmonised by :func:`harmonise_rings`, are
written into the boxes (:func:`iat.bake.boxes.build_boxes`). Harmonisation applies
(:func:`applies`) to ``clamped`` scaling of every method (``bilinear``, ``scan``, ``bicubic``:
all are drawn with GL_LINEAR) and to scale 1 (which the tile cache shares between the two
modes); ``naive`` scaling at other scales is left as the report did it, to show its
correspondence errors.

Left over: scales whose sides are not ``2**k + 1`` (see above), a T-junction point that is
not a knot of the long side, a vertex where two *mesh* patches disagree (the texture can
follow one), a mesh neighbour finer than the scaled texture (sampled at the texture's
knots), and the rounding of quantised formats (rgba8, rgb9e5) at the finer side's extra
knots. Figures: docs/baking.md, section 3.

The seam measures (``seam_measure``, ``seam_error``) are in :mod:`iat.measure.seams`.
"""

from __future__ import annotations

import numpy as np

from iat.bake.flatten import TileCache, extend_triangle, scaled_side, tile_side
from iat.geometry.mesh import patch_normals

__all__ = [
    "MAX_ANGLE_DEG",
    "EdgePairs",
    "applies",
    "apply_ring",
    "edge_pairs",
    "harmonise_rings",
    "involved_patches",
    "ring_index",
    "ring_sides",
    "solution_pairs",
    "tile_ring",
]

#: neighbours whose normals differ by more than this are not harmonised (their light differs)
MAX_ANGLE_DEG = 1.0
#: collinearity / overlap tolerance, relative to the model's size
REL_TOL = 1e-6
#: at most this many Jacobi passes (corners shared by chains of masters)
MAX_PASSES = 8
#: a shared segment whose two sides differ by more than this on average at the knots they share
#: (a corner group: at its vertex), relative to the larger value, is a real discontinuity (light
#: under a wall standing on the edge, a shadow line on a patch edge): it is left as the solution
#: has it. At shared knots, independent subdivision leaves only solver noise.
MAX_STEP = 0.4

# polygon edges: slot a -> slot b
_QUAD_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
_TRI_EDGES = np.array([[0, 1], [1, 2], [2, 0], [0, 0]])  # row 3 unused


# ---------------------------------------------------------------------------
# pairing (geometry only)


class EdgePairs:
    """Shared segments between boundary edges of neighbouring patches (one solution's geometry).

    Corners where segments of paired patches end on both sides at once (a vertex shared by
    2-4 patches) form groups: ``corner_node`` (k,) ``patch * 4 + slot``, ``corner_group`` (k,)
    (connected through pairs, so diagonal neighbours at a vertex share a group).

    Arrays, one row per pair ``(side 0, side 1)`` with ``patch[:, 0] < patch[:, 1]``:
    patch (n, 2) int64, edge (n, 2) int64 (edge ``e`` runs from corner slot ``e`` to the next:
    quads 0-1, 1-2, 2-3, 3-0; triangles 0-1, 1-2 (the hypotenuse), 2-0), lo / hi (n, 2)
    float64: the segment as parameters ``t`` in [0, 1] along each side's own edge (``lo`` maps
    to ``lo``; the other end to ``hi``), length (n, 2) float64 world lengths of the two edges.
    ``t`` of side 1 = ``lo[:, 1] + (t0 - lo[:, 0]) (hi[:, 1] - lo[:, 1]) / (hi[:, 0] - lo[:, 0])``.
    """

    def __init__(self, patch, edge, lo, hi, length, n_patches: int, is_quad=None):
        self.patch = np.asarray(patch, dtype=np.int64).reshape(-1, 2)
        self.edge = np.asarray(edge, dtype=np.int64).reshape(-1, 2)
        self.lo = np.asarray(lo, dtype=np.float64).reshape(-1, 2)
        self.hi = np.asarray(hi, dtype=np.float64).reshape(-1, 2)
        self.length = np.asarray(length, dtype=np.float64).reshape(-1, 2)
        self.n_patches = int(n_patches)
        self.corner_node, self.corner_group = _corner_groups(self, is_quad)

    def __len__(self) -> int:
        return len(self.patch)


def _corner_groups(pairs, is_quad):
    """Group patch corners that coincide at a segment end on both sides (see :class:`EdgePairs`)."""
    if not len(pairs.patch) or is_quad is None:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    nv = np.where(np.asarray(is_quad, dtype=bool)[pairs.patch], 4, 3)  # (n, 2)
    links = []
    for end in (pairs.lo, pairs.hi):
        at0, at1 = end <= 1e-6, end >= 1 - 1e-6
        both = (at0 | at1).all(axis=1)
        slot = np.where(at0, pairs.edge, (pairs.edge + 1) % nv)
        node = pairs.patch * 4 + slot
        links.append(node[both])
    links = np.concatenate(links)
    if not len(links):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    nodes, inv = np.unique(links, return_inverse=True)
    inv = inv.reshape(-1, 2)
    g = coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(len(nodes), len(nodes)))
    _, label = connected_components(g, directed=False)
    return nodes.astype(np.int64), label.astype(np.int64)


def edge_pairs(
    corners, is_quad, material=None, max_angle_deg: float = MAX_ANGLE_DEG, rel_tol: float = REL_TOL
) -> EdgePairs:
    """Find every shared segment between boundary edges of different patches.

    corners : (P, 4, 3) world corners (triangles repeat corner 2 in slot 3); is_quad : (P,) bool
    material : (P,) ints or None; pairs of different materials are left out
    max_angle_deg : pairs whose normals differ more are left out (None keeps every angle)

    Edges on one line are found with a k-d tree on (direction, foot point), then checked
    exactly (distance from the line and overlap longer than ``rel_tol`` x model size).
    """
    from scipy.spatial import cKDTree

    corners = np.asarray(corners, dtype=np.float64)
    is_quad = np.asarray(is_quad, dtype=bool)
    P = len(is_quad)
    empty = EdgePairs(
        np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)), P
    )
    if P < 2:
        return empty
    ne = np.where(is_quad, 4, 3)
    ep = np.repeat(np.arange(P), ne)
    ee = np.arange(len(ep)) - np.repeat(np.cumsum(ne) - ne, ne)
    slots = np.where(is_quad[ep, None], _QUAD_EDGES[ee], _TRI_EDGES[ee])
    lo_c, hi_c = corners.reshape(-1, 3).min(0), corners.reshape(-1, 3).max(0)
    centre = 0.5 * (lo_c + hi_c)
    size = max(float((hi_c - lo_c).max()), 1e-12)
    tol = rel_tol * size
    A = corners[ep, slots[:, 0]] - centre
    B = corners[ep, slots[:, 1]] - centre
    L = np.linalg.norm(B - A, axis=1)
    ok = L > tol
    ep, ee, A, B, L = ep[ok], ee[ok], A[ok], B[ok], L[ok]
    d = (B - A) / L[:, None]
    foot = A - (A * d).sum(1, keepdims=True) * d
    f = foot / size
    feat = np.concatenate([np.concatenate([d, f], 1), np.concatenate([-d, f], 1)])
    n_e = len(ep)
    cand = cKDTree(feat).query_pairs(r=1e-4, output_type="ndarray")
    if not len(cand):
        return empty
    i, j = cand[:, 0] % n_e, cand[:, 1] % n_e
    key = np.unique(np.sort(np.stack([i, j], 1), axis=1), axis=0)
    i, j = key[:, 0], key[:, 1]
    keep = ep[i] != ep[j]
    if material is not None:
        mat = np.asarray(material)
        keep &= mat[ep[i]] == mat[ep[j]]
    nrm = patch_normals(corners, is_quad)
    cos = (nrm[ep[i]] * nrm[ep[j]]).sum(1)
    if max_angle_deg is not None:
        keep &= cos >= np.cos(np.radians(max_angle_deg))
    i, j = i[keep], j[keep]
    # exact check: j's end points on i's line, overlap of positive length
    sA = ((A[j] - A[i]) * d[i]).sum(1)
    sB = ((B[j] - A[i]) * d[i]).sum(1)
    rA = np.linalg.norm(A[j] - A[i] - sA[:, None] * d[i], axis=1)
    rB = np.linalg.norm(B[j] - A[i] - sB[:, None] * d[i], axis=1)
    s0 = np.maximum(0.0, np.minimum(sA, sB))
    s1 = np.minimum(L[i], np.maximum(sA, sB))
    keep = (rA <= 10 * tol) & (rB <= 10 * tol) & (s1 - s0 > 10 * tol)
    # opposite sides of the segment (not two overlapping patches on one side)
    pc = corners.mean(axis=1) - centre
    side_n = np.cross(nrm[ep[i]], d[i])
    ci = ((pc[ep[i]] - A[i]) * side_n).sum(1)
    cj = ((pc[ep[j]] - A[i]) * side_n).sum(1)
    keep &= ci * cj < 0
    i, j, s0, s1, sA, sB = i[keep], j[keep], s0[keep], s1[keep], sA[keep], sB[keep]
    # parameters: side i runs s0 -> s1; side j's t of the same points
    ti0, ti1 = s0 / L[i], s1 / L[i]
    tj0 = (s0 - sA) / (sB - sA)
    tj1 = (s1 - sA) / (sB - sA)
    lo = np.stack([ti0, np.clip(tj0, 0, 1)], 1)
    hi = np.stack([ti1, np.clip(tj1, 0, 1)], 1)
    patch = np.stack([ep[i], ep[j]], 1)
    edge = np.stack([ee[i], ee[j]], 1)
    length = np.stack([L[i], L[j]], 1)
    sw = patch[:, 0] > patch[:, 1]
    for a in (patch, edge, lo, hi, length):
        a[sw] = a[sw][:, ::-1]
    order = np.lexsort((edge[:, 1], edge[:, 0], patch[:, 1], patch[:, 0]))
    return EdgePairs(patch[order], edge[order], lo[order], hi[order], length[order], P, is_quad)


def solution_pairs(solution, max_angle_deg: float = MAX_ANGLE_DEG) -> EdgePairs:
    """:func:`edge_pairs` of a solution's patches (same material, normals within ``max_angle_deg``)."""
    return edge_pairs(
        solution.patch_corners, solution.patch_is_quad, solution.patch_material, max_angle_deg=max_angle_deg
    )


# ---------------------------------------------------------------------------
# rings: a tile's boundary texels in edge order


_RING_CACHE: dict = {}


def ring_index(m: int, is_tri: bool) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of a tile's boundary texels in ring order: edge ``e`` knot ``k`` (``k`` from
    the edge's first corner) is ring entry ``e (m - 1) + k`` (mod the ring length); the last knot
    of an edge is the first of the next."""
    key = (int(m), bool(is_tri))
    hit = _RING_CACHE.get(key)
    if hit is not None:
        return hit
    k = np.arange(m - 1)
    if is_tri:  # 0-1: row 0; 1-2: hypotenuse (a = m-1-k, b = k); 2-0: column 0 downwards
        rows = np.concatenate([np.zeros_like(k), k, m - 1 - k])
        cols = np.concatenate([k, m - 1 - k, np.zeros_like(k)])
    else:  # 0-1: row 0; 1-2: column m-1; 2-3: row m-1 leftwards; 3-0: column 0 downwards
        rows = np.concatenate([np.zeros_like(k), k, np.full_like(k, m - 1), m - 1 - k])
        cols = np.concatenate([k, np.full_like(k, m - 1), m - 1 - k, np.zeros_like(k)])
    _RING_CACHE[key] = (rows, cols)
    return rows, cols


def tile_ring(tile: np.ndarray, is_tri: bool) -> np.ndarray:
    """(ring length, 3) float64 boundary texels of a tile in ring order (:func:`ring_index`)."""
    rows, cols = ring_index(tile.shape[0], is_tri)
    return np.asarray(tile[rows, cols], dtype=np.float64)


def apply_ring(tile: np.ndarray, ring: np.ndarray, is_tri: bool) -> np.ndarray:
    """A float32 copy of ``tile`` with its boundary texels set to ``ring`` (triangles: outer
    half refilled by :func:`~iat.bake.flatten.extend_triangle`, so the hypotenuse filters exactly)."""
    out = np.array(tile, dtype=np.float32, copy=True)
    rows, cols = ring_index(out.shape[0], is_tri)
    out[rows, cols] = ring
    if is_tri:
        extend_triangle(out[None])
    return out


def _max3(x: np.ndarray) -> np.ndarray:
    """``x.max(axis=1)`` of an (n, 3) array, written out (numpy's short-axis reductions are slow)."""
    return np.maximum(np.maximum(x[:, 0], x[:, 1]), x[:, 2])


def _relative_step(a: np.ndarray, b: np.ndarray, peak: float) -> np.ndarray:
    """(n,) largest channel difference of ``a`` and ``b`` (n, 3), relative to the larger of the two
    (values below 1e-3 of ``peak`` count as that floor, so dark edges are not all "steps")."""
    d = _max3(np.abs(a - b))
    s = np.maximum(_max3(np.abs(a)), _max3(np.abs(b)))
    return d / np.maximum(s, 1e-3 * peak)


def harmonise_rings(
    rings: dict,
    sides: np.ndarray,
    textured: np.ndarray,
    is_quad: np.ndarray,
    pairs: EdgePairs,
    judge: dict | None = None,
) -> tuple[dict, dict]:
    """Make neighbours' boundary rings describe the same polyline along every shared segment.

    rings : {patch: (ring length, 3) ring} of every patch to take part: textured ones, and mesh
      ones (``textured`` False: their ring is the mesh along their edges, never written)
    sides : (P,) texels per side of each ring's tile
    judge : rings of the same layout that decide which pairs are real discontinuities
      (:data:`MAX_STEP`; default ``rings``): a bicubic fit overshoots where a shadow crosses an
      edge, so the baker judges on the bilinear rings, the solution's own vertex values
    Returns ``(new, info)``: new {patch: (ring length, 3) float64} for the textured patches whose
    ring changed; info: pairs, passes, texels written.
    """
    info = {"pairs": 0, "passes": 0, "texels": 0, "discontinuities": 0}
    if not len(pairs) or not rings:
        return {}, info
    have = np.zeros(len(textured), dtype=bool)
    have[np.fromiter(rings.keys(), np.int64, len(rings))] = True
    tp = textured[pairs.patch]
    use = (tp[:, 0] | tp[:, 1]) & have[pairs.patch].all(1)
    if not use.any():
        return {}, info
    P_, E_, LO, HI, LEN = (x[use] for x in (pairs.patch, pairs.edge, pairs.lo, pairs.hi, pairs.length))
    m = sides[P_].astype(np.int64)  # (n, 2)
    h = LEN / np.maximum(m - 1, 1)  # world texel spacing along each side's edge
    tex = textured[P_]
    # master: the mesh side if one side is mesh; else the coarser; a tie -> lower patch index (side 0)
    close = np.abs(h[:, 0] - h[:, 1]) <= 1e-9 * np.maximum(h[:, 0], h[:, 1])
    coarser1 = np.where(close, False, h[:, 1] > h[:, 0])
    master = np.where(~tex[:, 0], 0, np.where(~tex[:, 1], 1, coarser1.astype(np.int64)))
    r = np.arange(len(P_))
    sl = 1 - master
    # one flat ring store
    involved = np.unique(P_)
    mm = sides[involved].astype(np.int64)
    rlen = np.where(is_quad[involved], 4, 3) * (mm - 1)
    off = np.zeros(len(textured), dtype=np.int64)
    off[involved] = np.concatenate([[0], np.cumsum(rlen)[:-1]])
    ring_len = np.zeros(len(textured), dtype=np.int64)
    ring_len[involved] = rlen
    parts = [rings[p] for p in involved.tolist()]
    if [len(x) for x in parts] != rlen.tolist():
        raise ValueError("harmonise_rings: a ring's length does not match its tile side in `sides`")
    R = np.concatenate(parts).astype(np.float64)
    RJ = R if judge is None else np.concatenate([judge[p] for p in involved.tolist()]).astype(np.float64)
    # slave knots inside each segment (ends included), the master's polyline there
    pm, pl = P_[r, master], P_[r, sl]
    em, el = E_[r, master], E_[r, sl]
    mM, mL = m[r, master], m[r, sl]
    loM, hiM, loL, hiL = LO[r, master], HI[r, master], LO[r, sl], HI[r, sl]
    k0 = np.maximum(np.ceil(np.minimum(loL, hiL) * (mL - 1) - 1e-7).astype(np.int64), 0)
    k1 = np.minimum(np.floor(np.maximum(loL, hiL) * (mL - 1) + 1e-7).astype(np.int64), mL - 1)
    cnt = np.maximum(k1 - k0 + 1, 0)
    rep = np.repeat(r, cnt)
    k = k0[rep] + np.arange(len(rep)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    tL = k / (mL[rep] - 1)
    span = hiL[rep] - loL[rep]
    tM = loM[rep] + (tL - loL[rep]) * (hiM[rep] - loM[rep]) / np.where(span == 0, 1.0, span)
    q = np.clip(tM, 0.0, 1.0) * (mM[rep] - 1)
    qr = np.rint(q)
    q = np.where(np.abs(q - qr) < 1e-7, qr, q)  # knots that coincide: exact copies
    i0 = np.minimum(np.floor(q).astype(np.int64), mM[rep] - 2)
    fr = (q - i0)[:, None]
    base_m = off[pm[rep]] + em[rep] * (mM[rep] - 1)
    ia = off[pm[rep]] + (base_m - off[pm[rep]] + i0) % ring_len[pm[rep]]
    ib = off[pm[rep]] + (base_m - off[pm[rep]] + i0 + 1) % ring_len[pm[rep]]
    dst = off[pl[rep]] + (el[rep] * (mL[rep] - 1) + k) % ring_len[pl[rep]]
    # real discontinuities (relative step above MAX_STEP anywhere on the segment) stay as they are
    R0 = R.copy()
    peak = max(float(np.abs(RJ).max()), 1e-30)
    # judged by the mean step at the knots the two sides share (equal world points, where
    # independent subdivision leaves only solver noise: a vertex in a room's corner can be off by
    # half, a wall standing on the edge differs all along); without shared knots, at all knots
    step = _relative_step((1.0 - fr) * RJ[ia] + fr * RJ[ib], RJ[dst], peak)
    shared = (fr[:, 0] == 0.0) | (fr[:, 0] == 1.0)
    n = len(P_)
    n_sh = np.bincount(rep[shared], minlength=n)
    pair_step = np.where(
        n_sh > 0,
        np.bincount(rep[shared], step[shared], minlength=n) / np.maximum(n_sh, 1),
        np.bincount(rep, step, minlength=n) / np.maximum(np.bincount(rep, minlength=n), 1),
    )
    smooth = pair_step <= MAX_STEP
    keep = smooth[rep]
    dst, ia, ib, fr = dst[keep], ia[keep], ib[keep], fr[keep]
    info["discontinuities"] = int((~smooth).sum())
    info["pairs"] = int(smooth.sum())
    info["texels"] = int(len(dst))
    if not len(dst):
        return {}, info
    # corner groups: every textured corner at a shared vertex takes the value of the group's top
    # member (a mesh patch, else the fewest texels, else the lowest index), which no full-edge
    # partner overwrites -- so diagonal neighbours at a vertex agree too
    cn, cg = pairs.corner_node, pairs.corner_group
    cp, cs = cn // 4, cn % 4
    ok = ring_len[cp] > 0
    cn, cg, cp, cs = cn[ok], cg[ok], cp[ok], cs[ok]
    order = np.lexsort((cp, sides[cp], textured[cp], cg))
    cg_o = cg[order]
    start = np.r_[True, cg_o[1:] != cg_o[:-1]]
    top_of = order[np.flatnonzero(start)][np.cumsum(start) - 1]  # each ordered node's group top
    cring = off[cp] + cs * (sides[cp] - 1)
    c_dst, c_src = cring[order], cring[top_of]
    w = textured[cp[order]] & (c_dst != c_src)
    c_dst, c_src = c_dst[w], c_src[w]
    w = _relative_step(RJ[c_src], RJ[c_dst], peak) <= MAX_STEP
    c_dst, c_src = c_dst[w], c_src[w]
    # Jacobi passes: edge copies, then corner groups, until nothing changes (a slave's corner
    # may be another pair's master knot)
    watch = np.r_[dst, c_dst]
    for it in range(MAX_PASSES):
        before = R[watch]
        R[dst] = (1.0 - fr) * R[ia] + fr * R[ib]
        R[c_dst] = R[c_src]
        info["passes"] = it + 1
        if float(np.abs(R[watch] - before).max(initial=0.0)) <= 1e-9 * peak:
            break
    ne = R != R0
    changed = ne[:, 0] | ne[:, 1] | ne[:, 2]
    hit = (np.add.reduceat(changed, off[involved]) > 0) & textured[involved]
    return {p: R[off[p] : off[p] + ring_len[p]] for p in involved[hit].tolist()}, info


# ---------------------------------------------------------------------------
# what the Baker harmonises


def applies(policy) -> bool:
    """Whether a policy's bake is harmonised: clamped scaling, or scale 1 (either mode)."""
    return TileCache.key(policy.method, policy.scale, policy.scale_mode)[2] == "clamped"


def ring_sides(depth: np.ndarray, ps: np.ndarray, scale: float) -> np.ndarray:
    """(P,) int64 texels per side of each patch's ring: the scaled tile of the textured ``ps``,
    the scale-1 tile (the mesh along its edges) of the others; ``depth`` (P,) tree depths."""
    sides = tile_side(depth).astype(np.int64)
    sides[ps] = scaled_side(tile_side(depth[ps]), scale)
    return sides


def involved_patches(pairs: EdgePairs, textured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(textured, mesh)`` patches of the pairs with a textured side (sorted int64 arrays): whose
    rings :func:`harmonise_rings` needs (``textured`` (P,) bool)."""
    if len(pairs):
        involved = np.unique(pairs.patch[textured[pairs.patch].any(axis=1)])
    else:
        involved = np.zeros(0, np.int64)
    return involved[textured[involved]], involved[~textured[involved]]
