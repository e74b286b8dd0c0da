"""Which side of a surface receives light: inside-out solids turned outward, open sheets given a back.

The solver receives and reflects light on a patch's front only (its normal side). Models written by
real tools break that in two ways (``../shared/real-models/README.md``): closed solids that are
inside out (every triangle facing inward: BIM ceiling coverings) and open sheets with no back
(furniture, doors, window frames, glTF materials with ``doubleSided: true``). The loader
(:func:`iat.io.load.load_scene`, ``sides=``) fixes both on the triangles, before quads and panels
are made:

- :func:`object_ids`: the objects of a loader's arrays (an IFC element's shape, a glTF mesh
  primitive, an OBJ object or group): each uses its own block of vertex indices.
- :func:`classify_sides`: per connected piece of an object (faces joined by shared welded edges),
  *closed* (every edge used by exactly two faces, in opposite directions: a consistently oriented
  manifold surface) or *open* (a boundary or non-manifold edge); a closed piece with negative
  signed volume is *inside out* and its winding is flipped, unless it is an *enclosure* (a room
  modelled from inside: it holds a light or another piece's centre; IFC elements are never
  enclosures); a piece of zero volume is a sheet written with its own back. Faces of open pieces
  (or of double-sided materials) are marked to get a **back face**.
- :func:`add_back_faces`: after the patches are made, a marked patch gets a *twin*: the same
  polygon with reversed winding, its own patch (own quad-tree, radiance and texture). The solver
  already handles back-to-back coincident faces (ray origins are offset along each face's normal;
  ``docs/stability.md``, "double-sided thin walls").
- :func:`twin_patches`: which patches of a solution or scene have a coincident twin facing the
  other way (the renderer culls their back faces so that each side shows its own light).

Every step is vectorised (no Python loop over faces); shapes are in the docstrings.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

#: the loader's choices (``load_scene(sides=...)``, ``--sides``):
#: ``auto`` (default): IFC, whose elements are all physical objects, gets its inside-out solids
#: turned outward and its open sheets a back face; in other formats the faces of glTF
#: ``doubleSided`` materials get a back face, and the rest stays as the file has it (glTF declares
#: its one-sided surfaces; OBJ, PLY, STL, OFF and COLLADA scenes, ours included, are one-sided by
#: convention: rooms face inward, sheets face the space they light);
#: ``both``: every format as IFC under auto (inside-out solids that are not enclosures turned
#: outward, every open sheet given a back face);
#: ``front``: every face as the file has it (light on the front only). All three count.
SIDES = ("auto", "both", "front")
#: a closed piece whose |signed volume| is below this times its area^1.5 is flat (a sheet with its back)
FLAT_VOLUME = 1e-7
#: at most this many probe points (lights, other pieces' centres) are tested against a candidate
MAX_PROBES = 4096
#: probe x triangle pairs per block of the winding-number test
_BLOCK = 1 << 21


@dataclass
class SideReport:
    """What :func:`classify_sides` found and did (``iat info`` prints it).

    mode : the ``sides`` choice; pieces : connected pieces of objects
    closed_solids : closed, consistently oriented pieces of non-zero volume
    inside_out : of them, inward-facing (negative volume) and not enclosures (turned outward when
      ``flipped_faces`` > 0)
    enclosures : inward-facing closed pieces kept as they are (rooms modelled from inside)
    flipped_faces : triangles turned outward (0 under ``front``)
    open_sheets : pieces with a boundary or non-manifold edge
    back_faces : triangles marked for a back face (0 under ``front``)
    twin_patches : patches added as back faces (set by the loader after :func:`add_back_faces`)
    paired_faces : triangles the file already gives a reversed coincident twin (no back added)
    coincident_faces : triangles coinciding with another of the same orientation (duplicates)
    """

    mode: str = "auto"
    pieces: int = 0
    closed_solids: int = 0
    inside_out: int = 0
    enclosures: int = 0
    flipped_faces: int = 0
    open_sheets: int = 0
    back_faces: int = 0
    twin_patches: int = 0
    paired_faces: int = 0
    coincident_faces: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class Sides:
    """:func:`classify_sides`'s result.

    faces : (f, 3) int64, inside-out pieces' winding reversed
    face_uv : (f, 3, 2) float64, permuted with the faces
    back : (f,) bool, faces that get a back face
    piece : (f,) int64 connected piece of each face
    report : :class:`SideReport`
    """

    faces: np.ndarray
    face_uv: np.ndarray
    back: np.ndarray
    piece: np.ndarray
    report: SideReport


def object_ids(faces: np.ndarray) -> np.ndarray:
    """(f,) int64 object of each face of a loader's arrays, whose objects come one after the other,
    each with its own block of vertex indices (as ``iat.io.load`` and ``iat.io.ifc`` concatenate
    them, before welding): an object ends where no later face uses an index as low as one used so far.

    faces : (f, 3) int64. Two objects are never merged; one object whose parts use disjoint
    blocks of its vertices may come out as several (harmless: pieces are classified one by one).
    """
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(F) == 0:
        return np.zeros(0, dtype=np.int64)
    seen_max = np.maximum.accumulate(F.max(axis=1))
    rest_min = np.minimum.accumulate(F.min(axis=1)[::-1])[::-1]
    start = np.zeros(len(F), dtype=bool)
    start[1:] = seen_max[:-1] < rest_min[1:]
    return np.cumsum(start).astype(np.int64)


def _pieces(F: np.ndarray, objects: np.ndarray):
    """Connected pieces of faces joined by shared edges within one object.

    Returns (piece (f,) int64, n_pieces, edge_ok (f,) bool: all three edges of the face are used
    by exactly two faces of its object in opposite directions)."""
    nf = len(F)
    a = F.ravel()
    b = F[:, [1, 2, 0]].ravel()
    hf = np.repeat(np.arange(nf, dtype=np.int64), 3)
    lo, hi, ob = np.minimum(a, b), np.maximum(a, b), objects[hf]
    order = np.lexsort((hi, lo, ob))
    lo_s, hi_s, ob_s = lo[order], hi[order], ob[order]
    new = np.ones(len(order), dtype=bool)
    new[1:] = (lo_s[1:] != lo_s[:-1]) | (hi_s[1:] != hi_s[:-1]) | (ob_s[1:] != ob_s[:-1])
    edge = np.cumsum(new) - 1
    n_e = int(edge[-1]) + 1 if len(edge) else 0
    count = np.bincount(edge, minlength=n_e)
    fwd = np.bincount(edge, weights=(a < b)[order], minlength=n_e)
    ok = (count == 2) & (fwd == 1)
    he_ok = np.empty(len(order), dtype=bool)
    he_ok[order] = ok[edge]
    edge_ok = he_ok.reshape(nf, 3).all(axis=1)
    first = np.flatnonzero(new)[edge]  # each half-edge linked to the first one of its edge
    rows, cols = hf[order], hf[order][first]
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(nf, nf))
    n, piece = connected_components(graph, directed=False)
    return piece.astype(np.int64), int(n), edge_ok


def _coincident(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(paired (f,) bool: another face has the same corners in the reverse order; duplicate (f,)
    bool: another face has the same corners in the same order)."""
    r = np.argmin(F, axis=1)
    idx = (r[:, None] + np.arange(3)) % 3
    canon = np.take_along_axis(F, idx, axis=1)  # smallest index first, orientation kept
    pos = canon[:, 1] < canon[:, 2]
    s = np.sort(F, axis=1)
    order = np.lexsort((s[:, 2], s[:, 1], s[:, 0]))
    ss = s[order]
    new = np.ones(len(F), dtype=bool)
    new[1:] = (ss[1:] != ss[:-1]).any(axis=1)
    g = np.empty(len(F), dtype=np.int64)
    g[order] = np.cumsum(new) - 1
    n_pos = np.bincount(g, weights=pos)
    n_neg = np.bincount(g, weights=~pos)
    paired = np.where(pos, n_neg[g] > 0, n_pos[g] > 0)
    duplicate = np.where(pos, n_pos[g] > 1, n_neg[g] > 1)
    return paired, duplicate


def repeated_faces(faces: np.ndarray) -> np.ndarray:
    """(f,) bool: faces (f, 3) int64 (welded) that repeat an earlier face with the same corners in
    the same orientation. Two coincident surfaces facing the same way would each receive the whole
    light there and reflect it twice (a closed room at albedo 0.97 with every face doubled diverges):
    the loader keeps the first of each."""
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(F) == 0:
        return np.zeros(0, dtype=bool)
    r = np.argmin(F, axis=1)
    canon = np.take_along_axis(F, (r[:, None] + np.arange(3)) % 3, axis=1)  # rotation kept, orientation too
    _, first = np.unique(canon, axis=0, return_index=True)
    out = np.ones(len(F), dtype=bool)
    out[first] = False
    return out


def winding_numbers(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(k,) float64 generalised winding numbers of ``points`` (k, 3) about the closed surface
    ``triangles`` (t, 3, 3) (Van Oosterom-Strackee solid angles over 4 pi): +1 inside an outward
    surface, -1 inside an inward one, 0 outside."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    T = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    out = np.zeros(len(P))
    if len(P) == 0 or len(T) == 0:
        return out
    step = max(1, _BLOCK // len(T))
    for s in range(0, len(P), step):
        d = T[None, :, :, :] - P[s : s + step, None, None, :]  # (k, t, 3, 3)
        a, b, c = d[:, :, 0], d[:, :, 1], d[:, :, 2]
        la, lb, lc = (np.sqrt((x * x).sum(-1)) for x in (a, b, c))
        num = (a * np.cross(b, c)).sum(-1)
        den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out[s : s + step] = (2.0 * np.arctan2(num, den)).sum(axis=1) / (4.0 * np.pi)
    return out


def classify_sides(
    vertices: np.ndarray,
    faces: np.ndarray,
    objects: np.ndarray,
    face_material: np.ndarray,
    face_uv: np.ndarray | None = None,
    *,
    mode: str = "auto",
    double_sided: np.ndarray | None = None,
    one_sided: np.ndarray | None = None,
    sheets_two_sided: bool = True,
    turn_solids: bool = True,
    enclosures: bool = True,
    probes: np.ndarray | None = None,
) -> Sides:
    """Classify each object's pieces, flip inside-out solids, mark the faces that get a back face.

    vertices : (n, 3) float64, welded (faces that share an edge share its two indices)
    faces : (f, 3) int64, non-degenerate; objects : (f,) int64 (:func:`object_ids`)
    face_material : (f,) int64; face_uv : (f, 3, 2) float64 or None
    mode : one of :data:`SIDES` (``front``: classify and count, change nothing)
    double_sided : (materials,) bool, materials whose faces get a back face wherever they are open
    one_sided : (materials,) bool, materials that never get one (emitters, glass)
    sheets_two_sided : whether open pieces get a back face whatever their material (the loader:
      IFC, or ``both``); mode ``both`` implies it
    turn_solids : whether inside-out closed pieces are turned outward (the loader: IFC, or
      ``both``); mode ``both`` implies it
    enclosures : whether an inward closed piece holding a probe or another piece's centre is a room
      modelled from inside, kept as it is (False for IFC: its elements are all solids)
    probes : (k, 3) float64 extra points that mark an enclosure (the file's lights)
    """
    if mode not in SIDES:
        raise ValueError(f"sides must be one of {', '.join(SIDES)}, got {mode!r}")
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3).copy()
    nf = len(F)
    UV = np.zeros((nf, 3, 2)) if face_uv is None else np.asarray(face_uv, dtype=np.float64).copy()
    M = np.asarray(face_material, dtype=np.int64).reshape(-1)
    obj = np.asarray(objects, dtype=np.int64).reshape(-1)
    report = SideReport(mode=mode)
    if nf == 0:
        return Sides(F, UV, np.zeros(0, bool), np.zeros(0, np.int64), report)
    piece, n, edge_ok = _pieces(F, obj)
    closed = np.bincount(piece, weights=~edge_ok, minlength=n) == 0
    # signed volume about each piece's first corner (less cancellation than about the origin)
    first = np.zeros(n, dtype=np.int64)
    first[piece[::-1]] = np.arange(nf)[::-1]
    ref = V[F[first, 0]][piece]
    v0, v1, v2 = V[F[:, 0]] - ref, V[F[:, 1]] - ref, V[F[:, 2]] - ref
    cr = np.cross(v1 - v0, v2 - v0)
    vol = np.bincount(piece, weights=(v0 * np.cross(v1, v2)).sum(1) / 6.0, minlength=n)
    area = np.bincount(piece, weights=0.5 * np.sqrt((cr * cr).sum(1)), minlength=n)
    flat = np.abs(vol) <= FLAT_VOLUME * area**1.5
    solid = closed & ~flat
    inward = solid & (vol < 0)
    enclosed = np.zeros(n, dtype=bool)
    if enclosures and inward.any():
        enclosed = _enclosures(V, F, piece, n, inward, probes)
    flip = inward & ~enclosed & (turn_solids or mode == "both")
    paired, duplicate = _coincident(F)
    report.pieces = n
    report.closed_solids = int(solid.sum())
    report.inside_out = int((inward & ~enclosed).sum())
    report.enclosures = int(enclosed.sum())
    report.open_sheets = int((~closed).sum())
    report.paired_faces = int(paired.sum())
    report.coincident_faces = int(duplicate.sum())
    back = np.zeros(nf, dtype=bool)
    if mode == "front":
        return Sides(F, UV, back, piece, report)
    fl = flip[piece]
    F[fl] = F[fl][:, ::-1]
    UV[fl] = UV[fl][:, ::-1]
    report.flipped_faces = int(fl.sum())
    n_mat = int(M.max()) + 1 if nf else 0
    ds = np.zeros(n_mat, bool) if double_sided is None else np.asarray(double_sided, bool)
    never = np.zeros(n_mat, bool) if one_sided is None else np.asarray(one_sided, bool)
    wants = np.full(nf, sheets_two_sided or mode == "both") | ds[M]
    back = wants & ~closed[piece] & ~paired & ~never[M]
    report.back_faces = int(back.sum())
    return Sides(F, UV, back, piece, report)


def _enclosures(V, F, piece, n, inward, probes) -> np.ndarray:
    """(n,) bool: inward closed pieces that hold a probe or another piece's vertex mean."""
    cnt = np.maximum(np.bincount(piece, minlength=n), 1)
    centre = np.stack(
        [np.bincount(piece, weights=V[F, k].mean(axis=1), minlength=n) / cnt for k in range(3)], axis=1
    )
    extra = np.zeros((0, 3)) if probes is None else np.asarray(probes, dtype=np.float64).reshape(-1, 3)
    pts = np.concatenate([centre, extra])
    owner = np.concatenate([np.arange(n), np.full(len(extra), -1)])
    if len(pts) > MAX_PROBES:  # evenly spaced subset, the file's probes always kept
        keep = np.unique(
            np.r_[np.linspace(0, n - 1, MAX_PROBES - len(extra)).astype(np.int64), np.arange(n, len(pts))]
        )
        pts, owner = pts[keep], owner[keep]
    out = np.zeros(n, dtype=bool)
    order = np.argsort(piece, kind="stable")
    starts = np.searchsorted(piece[order], np.arange(n + 1))
    for c in np.flatnonzero(inward):  # the inward closed pieces: few (a loop over them, not faces)
        tri = V[F[order[starts[c] : starts[c + 1]]]]
        p = pts[owner != c]
        out[c] = bool((np.abs(winding_numbers(p, tri)) > 0.5).any())
    return out


def add_back_faces(
    corners: np.ndarray,
    material: np.ndarray,
    uv: np.ndarray,
    clip_uv: np.ndarray | None,
    clip_patch: np.ndarray | None,
    which: np.ndarray,
):
    """Append a twin to each patch in ``which``: the same polygon, winding reversed.

    corners : (p, 4) int64 (-1 in column 3 for triangles); material : (p,) int64;
    uv : (p, 4, 2) float64 detail uvs; clip_uv : (C, 3, 2) float64 clip triangles in their
    patch's lattice (u, v), rows sorted by ``clip_patch`` (C,) int64 (None: none); which : (p,) bool.
    A quad ``c0 c1 c2 c3`` becomes ``c0 c3 c2 c1`` and a triangle ``c0 c1 c2`` becomes
    ``c0 c2 c1``: the twin's lattice point (u, v) is the patch's (v, u), so a clip triangle's
    (u, v) are swapped (and its corners reversed, keeping its orientation in the lattice).
    Returns (corners, material, uv, clip_uv, clip_patch) with the twins after the ``p`` patches,
    in the order of their originals.
    """
    C = np.asarray(corners, dtype=np.int64)
    which = np.asarray(which, dtype=bool)
    src = np.flatnonzero(which)
    quad = C[src, 3] >= 0
    perm = np.where(quad[:, None], np.array([0, 3, 2, 1]), np.array([0, 2, 1, 1]))
    tc = np.take_along_axis(C[src], perm, axis=1)
    tc[~quad, 3] = -1
    tuv = np.take_along_axis(np.asarray(uv, dtype=np.float64)[src], perm[:, :, None], axis=1)
    out_c = np.concatenate([C, tc])
    out_m = np.concatenate([np.asarray(material, dtype=np.int64), np.asarray(material, dtype=np.int64)[src]])
    out_uv = np.concatenate([np.asarray(uv, dtype=np.float64), tuv])
    if clip_patch is None or len(clip_patch) == 0:
        return out_c, out_m, out_uv, clip_uv, clip_patch
    cp = np.asarray(clip_patch, dtype=np.int64)
    cu = np.asarray(clip_uv, dtype=np.float64)
    new_index = np.full(len(C), -1, dtype=np.int64)
    new_index[src] = len(C) + np.arange(len(src))
    rows = np.flatnonzero(which[cp])
    twin_uv = cu[rows][:, ::-1, ::-1]  # corners reversed, (u, v) -> (v, u)
    return (
        out_c,
        out_m,
        out_uv,
        np.concatenate([cu, twin_uv]),
        np.concatenate([cp, new_index[cp[rows]]]),
    )


def twin_patches(corner_positions: np.ndarray, is_quad: np.ndarray) -> np.ndarray:
    """(P,) bool: patches with a coincident twin facing the other way (same corner positions,
    opposite normal), such as :func:`add_back_faces` makes and files with double-sided walls have.

    corner_positions : (P, 4, 3) float (a triangle's slot 3 repeats slot 2); is_quad : (P,) bool.
    Positions are compared exactly (twins share their vertices)."""
    return twin_index(corner_positions, is_quad)[0] >= 0


def twin_index(corner_positions: np.ndarray, is_quad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(twin, swap)``: (P,) int64 the patch's coincident twin facing the other way (-1: none; of
    several, one), and (P,) bool whether the twin's lattice point (u, v) is this patch's (v, u)
    (the twins :func:`add_back_faces` makes: same first corner, the rest reversed). Arguments as
    :func:`twin_patches`."""
    pos = np.asarray(corner_positions, dtype=np.float64).reshape(-1, 4, 3)
    P = len(pos)
    if P == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    q = np.asarray(is_quad, dtype=bool).reshape(-1)
    pts = pos.copy()
    pts[~q, 3] = np.inf  # triangles: three corners, the fourth slot sorts last on both twins
    # corners sorted lexicographically per patch: the same set gives the same row
    o = np.lexsort((pts[..., 2], pts[..., 1], pts[..., 0]), axis=-1)
    key = np.take_along_axis(pts, o[..., None], axis=1).reshape(P, 12)
    n = np.cross(pos[:, 2] - pos[:, 0], np.where(q[:, None], pos[:, 3] - pos[:, 1], pos[:, 1] - pos[:, 0]))
    n[~q] = -n[~q]  # triangle normal (c1 - c0) x (c2 - c0) = -(c2 - c0) x (c1 - c0)
    rows = np.lexsort(key.T[::-1])
    ks = key[rows]
    new = np.ones(P, dtype=bool)
    new[1:] = (ks[1:] != ks[:-1]).any(axis=1)
    g = np.empty(P, dtype=np.int64)
    g[rows] = np.cumsum(new) - 1
    lead = rows[new][g]  # each group's first patch: its normal is the reference
    pos_side = (n * n[lead]).sum(axis=1) > 0
    # per group, one patch of each side (the last written): each side's twin is the other's
    one_pos = np.full(g.max() + 1, -1, dtype=np.int64)
    one_neg = np.full(g.max() + 1, -1, dtype=np.int64)
    one_pos[g[pos_side]] = np.flatnonzero(pos_side)
    one_neg[g[~pos_side]] = np.flatnonzero(~pos_side)
    twin = np.where(pos_side, one_neg[g], one_pos[g])
    has = twin >= 0
    t = np.where(has, twin, 0)
    last = np.where(q, 3, 2)  # the corner after c0 going the other way round
    swap = has & (pos[t, 0] == pos[:, 0]).all(axis=1)
    swap &= (pos[t, 1] == pos[np.arange(P), last]).all(axis=1)
    return twin, swap


def overlap_groups(
    corner_positions: np.ndarray, is_quad: np.ndarray, normal: np.ndarray, tol: float
) -> np.ndarray:
    """(P,) int64: for each patch that overlaps another patch of the same plane facing the same way
    (a cladding panel on its wall, a finish on its slab; the centre of one lies inside the other),
    the label of its group of such patches (0, 1, ...); -1 for the rest. Two planes are one when
    their normals agree to 1e-3 and their offsets to ``tol`` (m); a partial overlap that covers
    neither centre is not found.

    corner_positions : (P, 4, 3) (a triangle's slot 3 repeats slot 2); is_quad : (P,) bool;
    normal : (P, 3) unit normals, the corners counter-clockwise about them."""
    pos = np.asarray(corner_positions, dtype=np.float64).reshape(-1, 4, 3)
    q = np.asarray(is_quad, dtype=bool)
    nrm = np.asarray(normal, dtype=np.float64)
    P = len(pos)
    if P < 2:
        return np.full(P, -1, dtype=np.int64)
    centre = np.where(q[:, None], pos.mean(axis=1), pos[:, :3].mean(axis=1))
    key = np.column_stack([np.round(nrm / 1e-3), np.round((nrm * centre).sum(axis=1) / max(tol, 1e-300))])
    order = np.lexsort(key.T[::-1])
    ks = key[order]
    cut = np.flatnonzero((ks[1:] != ks[:-1]).any(axis=1)) + 1
    # edges (P, 4, 3): a triangle's last edge closes it, its fourth is empty
    nxt = np.where(q[:, None], np.array([1, 2, 3, 0]), np.array([1, 2, 0, 0]))
    edge = np.take_along_axis(pos, nxt[..., None], axis=1) - pos
    edge[~q, 3] = 0.0
    lo, hi = pos.min(axis=1) - tol, pos.max(axis=1) + tol  # (a triangle's slot 3 is a corner too)
    pairs = []
    for group in np.split(order, cut):
        if len(group) < 2:
            continue
        for a in range(0, len(group), 1024):  # the centres tested, in blocks
            rows = group[a : a + 1024]
            c = centre[rows][:, None, :]
            # candidates: the boxes that hold the centre; then the centre inside every edge
            i, j = np.nonzero(((lo[group][None] <= c) & (c <= hi[group][None])).all(axis=-1))
            i, j = rows[i], group[j]
            keep = i != j
            i, j = i[keep], j[keep]
            rel = centre[i][:, None, :] - pos[j]  # (k, 4, 3)
            side = (np.cross(edge[j], rel) * nrm[j][:, None, :]).sum(axis=-1)
            size = np.linalg.norm(edge[j], axis=-1).max(axis=-1)
            empty = ~q[j][:, None] & (np.arange(4) == 3)  # a triangle's fourth edge
            inside = ((side > 1e-9 * size[:, None] ** 2) | empty).all(axis=-1)
            pairs.append(np.column_stack([i[inside], j[inside]]))
    pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    label = np.full(P, -1, dtype=np.int64)
    if len(pairs):
        member = np.unique(pairs)
        at = np.searchsorted(member, pairs)
        graph = coo_matrix((np.ones(len(at)), (at[:, 0], at[:, 1])), shape=(len(member), len(member)))
        label[member] = connected_components(graph, directed=False)[1]
    return label
