"""Discontinuity meshing: roots split along the hard shadow boundaries of point, spot and sun lights.

The report's §5.3: an axis-aligned quad-tree draws a diagonal shadow as stairs of its finest
elements; a root whose *edge* lies on the shadow line needs no elements there at all. So, before
the solve, :func:`split_discontinuities` cuts the receiving roots along the lines where occluder
edges' shadows fall, and the quad-tree of each piece meets a smooth light.

For each point or spot light (a sun: parallel projection along its direction):

1. **Occluder edges**: the edges of the surface's triangles (welded) that are boundary edges or
   silhouettes as seen from the light (their triangles face it differently).
2. **Rays** (Embree, :data:`EDGE_SPACING` apart along each edge): from the light past each sample,
   offset a little to either side of the *wedge* plane (light + edge). An edge casts a boundary
   at a sample when one side's ray stops at the edge (the occluder) and the other goes on to a
   receiver that faces the light; an edge in shadow itself, or between coplanar faces, casts none.
3. **Segments**: for each (edge, receiver) pair the edge's part whose samples reached that
   receiver, projected from the light (along the sun) onto the receiver's plane lifted by
   :data:`CUT_LIFT` x the scene diagonal: the shadow the solver sees, since its rays leave that
   far above the surface and step towards the root's centre, so vertices on the cut take the
   light of their own side.
4. **Cuts**: each receiver, a convex polygon in its plane, is cut along its segments' lines
   (longest first); a cut splits only the pieces the segment crosses over a good part of their
   chord (:data:`MIN_CHORD`), and is skipped when a piece would be a sliver (:data:`MIN_PIECE`);
   long thin pieces are halved across (:data:`PIECE_ASPECT`). Convex pieces become roots:
   triangles, near-parallelogram quads (:data:`iat.geometry.mesh.QUAD_SKEW_TOL`), else fans from
   the corner that gives the best worst triangle, each triangle turned so that no shadow line is its
   hypotenuse where another edge is free (:func:`iat.geometry.polycut.legs_on_lines`). At most
   :data:`MAX_CUTS_PER_PATCH` cuts per root, and new roots at most :data:`MAX_NEW_FRACTION` of the
   scene's roots (at least :data:`MIN_NEW_PATCHES`, at most :data:`MAX_NEW_PATCHES`; receivers with
   the longest boundary first), so a real model cannot explode.

Panel cells covered only in part (clip triangles) are not cut: their clip triangles are in the
cell's lattice and a piece would need its own; they keep stair-stepped shadows. Glass neither
occludes nor receives. Area emitters' soft shadows and a spot's cone boundary are not followed.
A sheet's two faces (coincident twins, :func:`iat.geometry.sides.twin_index`) are cut as one, so
they stay twins.

The loader cuts along the file's lights; a sun added after loading (the default daylight, ``iat
solve --sun``) is cut along by :func:`cut_new_lights`. ``Scene.shadow_cuts`` lists what each cut
followed (:func:`shadow_key`); a solution records it, and :func:`replay_cuts` cuts its model, loaded
again, the same way. Lights moved after the solve (the viewer's sun panel) keep the roots as cut.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from iat.geometry import polycut
from iat.geometry.mesh import QUAD_SKEW_TOL, compact_vertices, weld_vertices
from iat.geometry.sides import twin_index

#: the cut follows the shadow seen this far above the receiver, fraction of the scene diagonal (the
#: solver's ray offset, ``iat.radiosity.options.RAY_EPS``; tests check they agree)
CUT_LIFT = 1e-4
#: ray offset to either side of an edge's wedge plane, fraction of the scene diagonal
SIDE_OFFSET = 1e-5
#: a ray that stops within this fraction of the scene diagonal of the edge stopped at the occluder
EDGE_MARGIN = 1e-3
#: samples along an occluder edge, this fraction of the scene diagonal apart (at least 4, at most 64)
EDGE_SPACING = 1.0 / 256.0
#: a cut is skipped where the segment crosses a piece over less than this fraction of the square root
#: of the scene's surface area, or leaves a piece narrower (twice its area over its longest side) or of
#: less area than its square (3x the solver's default smallest element, which a sliver root would be)
MIN_PIECE = 1.0 / 200.0
#: a segment cuts a piece only where it covers at least this fraction of the piece's chord along its
#: line (a short shadow does not slice a big root from end to end: the quad-tree follows it there)
MIN_CHORD = 0.25
#: a cut piece whose longest side is over this times its width, and over :data:`PIECE_LENGTH` x the
#: square root of the scene's surface area, is cut across in halves (the solver splits elements that
#: long, ``iat.radiosity.options.MAX_ELEMENT_FRACTION``, so a sliver root costs a sliver quad-tree)
PIECE_ASPECT = 2.0
PIECE_LENGTH = 1.0 / 24.0
#: most cuts per root, and most new roots in all (the receivers with the longest boundary first)
MAX_CUTS_PER_PATCH = 8
MAX_NEW_PATCHES = 20000
#: ... and at most this fraction of the scene's roots, or :data:`MIN_NEW_PATCHES` if more: each root
#: shoots on its own, so the solve's shots grow with them (the cave, 2 528 roots: all its cuts +50 %
#: roots, +43 % shots, +55 % CPU time; 632 new +25 %, +19 %, +28-39 %; 256 new +10 %, +7 %, +8 %;
#: docs/benchmarks.md, "Discontinuity meshing by default")
MAX_NEW_FRACTION = 0.1
MIN_NEW_PATCHES = 256


def _unit(a: np.ndarray) -> np.ndarray:
    return a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-300)


def occluder_edges(tri: np.ndarray, light) -> tuple[np.ndarray, np.ndarray]:
    """Boundary and silhouette edges of triangles ``tri`` (T, 3, 3) float64 world as seen from a light
    (:class:`iat.io.scene.Light`: its position, or for a directional one its direction).

    Returns (a, b): (E, 3) float64 world end points. Vertices are welded first, so triangles of
    different patches that share a corner share the edge.
    """
    t = len(tri)
    if t == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    V, F = weld_vertices(tri.reshape(-1, 3), np.arange(3 * t).reshape(t, 3))
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if light.kind == "directional":
        facing = n @ -np.asarray(light.direction, np.float64) > 0
    else:
        facing = np.einsum("tc,tc->t", n, light.position - tri.mean(axis=1)) > 0
    lo = np.minimum(F, np.roll(F, -1, axis=1)).ravel()
    hi = np.maximum(F, np.roll(F, -1, axis=1)).ravel()
    keys, inv, count = np.unique(lo * len(V) + hi, return_inverse=True, return_counts=True)
    f = np.repeat(facing, 3)
    some = np.zeros(len(keys), bool)
    every = np.ones(len(keys), bool)
    np.logical_or.at(some, inv, f)
    np.logical_and.at(every, inv, f)
    keep = ((count == 1) | (some != every)) & (keys // len(V) != keys % len(V))
    return V[keys[keep] // len(V)], V[keys[keep] % len(V)]


class RayCaster:
    """First hits against world triangles ``tri`` (T, 3, 3) float64 (one embreex scene, float32)."""

    def __init__(self, tri: np.ndarray):
        self.scene = rtcs.EmbreeScene()
        v = np.ascontiguousarray(tri.reshape(-1, 3), dtype=np.float32)
        self.mesh = TriangleMesh(self.scene, v, np.arange(len(v), dtype=np.int32).reshape(-1, 3))

    def first_hit(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(prim (n,) int64, -1 on a miss; t (n,) float64) of rays o, d (n, 3), d unit."""
        prim, dist = [], []
        for a in range(0, len(o), 1 << 16):
            r = self.scene.run(
                np.ascontiguousarray(o[a : a + (1 << 16)], np.float32),
                np.ascontiguousarray(d[a : a + (1 << 16)], np.float32),
                output=1,
            )
            prim.append(r["primID"].astype(np.int64))
            dist.append(r["tfar"].astype(np.float64))
        if not prim:
            return np.zeros(0, np.int64), np.zeros(0)
        return np.concatenate(prim), np.concatenate(dist)


def shadow_segments(
    scene, light, rays: RayCaster, tri: np.ndarray, tri_patch: np.ndarray, receivers: np.ndarray
):
    """The shadow boundaries one light casts on the scene's receivers.

    scene : :class:`iat.io.scene.Scene`; light : a point, spot or directional
    :class:`iat.io.scene.Light`; rays (:class:`RayCaster` of ``tri``), tri (T, 3, 3), tri_patch (T,):
    the opaque triangles and their patches; receivers : (P,) bool, the patches that may be cut.
    Returns (patch (S,) int64, p0 (S, 3), p1 (S, 3) float64): segments in world space on their
    patch's plane (lifted by :data:`CUT_LIFT`), one per (edge, receiver) pair.
    """
    lo, hi = scene.bounds
    diag = max(float(np.linalg.norm(hi - lo)), 1e-12)
    a, b = occluder_edges(tri, light)
    if len(a) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    sun = light.kind == "directional"
    sun_dir = _unit(np.asarray(light.direction, np.float64))
    n_s = np.clip(np.ceil(np.linalg.norm(b - a, axis=1) / (EDGE_SPACING * diag)), 4, 64).astype(np.int64)
    edge = np.repeat(np.arange(len(a)), n_s)
    s = (np.arange(n_s.sum()) - np.repeat(np.cumsum(n_s) - n_s, n_s) + 0.5) / n_s[edge]
    x = a[edge] + s[:, None] * (b - a)[edge]
    # each sample's ray from the light (or from beyond the scene, against the sun's direction)
    if sun:
        w = _unit(np.cross(b - a, sun_dir))[edge]
        start = x - 2.0 * diag * sun_dir
    else:
        w = _unit(np.cross(b - a, a - light.position))[edge]
        start = np.broadcast_to(light.position, x.shape)
    off, margin = SIDE_OFFSET * diag, EDGE_MARGIN * diag
    hits = []
    for sign in (1.0, -1.0):
        target = x + sign * off * w
        dirs = _unit(target - start)
        prim, t = rays.first_hit(start, dirs)
        hits.append((prim, t, np.linalg.norm(target - start, axis=1), dirs))
    (pa, ta, da, ua), (pb, tb, db, ub) = hits
    stop_a, stop_b = np.abs(ta - da) < margin, np.abs(tb - db) < margin
    on_a = stop_b & (pa >= 0) & (ta > da + margin)  # side a passes the occluder (on side b)
    on_b = stop_a & (pb >= 0) & (tb > db + margin)
    keep = on_a | on_b
    prim = np.where(on_a, pa, pb)[keep]
    edge, s, ray = edge[keep], s[keep], np.where(on_a[:, None], ua, ub)[keep]
    patch = tri_patch[np.maximum(prim, 0)]
    normal = scene.patch_normal[patch]
    lit = receivers[patch] & ((ray * normal).sum(axis=1) < 0)
    if light.kind == "spot":
        axis = _unit(np.asarray(light.direction, np.float64))
        lit &= ray @ axis > np.cos(light.outer_cone)
    edge, s, patch = edge[lit], s[lit], patch[lit]
    if len(edge) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    # one segment per (edge, receiver): its samples' range of s, a sample's spacing wider each side
    pair = edge * scene.n_patches + patch
    pairs, inv = np.unique(pair, return_inverse=True)
    s_lo = np.full(len(pairs), np.inf)
    s_hi = np.full(len(pairs), -np.inf)
    np.minimum.at(s_lo, inv, s)
    np.maximum.at(s_hi, inv, s)
    e, p = pairs // scene.n_patches, pairs % scene.n_patches
    step = 1.0 / n_s[e]
    nrm = scene.patch_normal[p]
    plane = (nrm * scene.corner_positions[p, 0]).sum(axis=1) + CUT_LIFT * diag
    ends, good = [], np.ones(len(p), bool)
    for sv, grow in ((s_lo, -step), (s_hi, step)):
        wide, ok_w = _project(a[e] + np.clip(sv + grow, 0, 1)[:, None] * (b - a)[e], nrm, plane, light)
        own, ok_s = _project(a[e] + sv[:, None] * (b - a)[e], nrm, plane, light)
        ends.append(np.where(ok_w[:, None], wide, own))
        good &= ok_w | ok_s
    return p[good], ends[0][good], ends[1][good]


def _project(q: np.ndarray, nrm: np.ndarray, plane: np.ndarray, light) -> tuple[np.ndarray, np.ndarray]:
    """Points q (n, 3) projected from the light (along a sun's direction) onto the planes
    ``nrm . x = plane`` (n, 3), (n,); returns (points (n, 3), ok (n,) bool: q between the light and
    the plane, in front of it)."""
    h = (nrm * q).sum(axis=1) - plane
    if light.kind == "directional":
        d = _unit(np.asarray(light.direction, np.float64))
        den = nrm @ d
        ok = (h > 0) & (den < 0)
        return q - (h / np.where(ok, den, -1.0))[:, None] * d, ok
    hl = nrm @ light.position - plane
    ok = (h > 0) & (h < hl * (1 - 1e-6))
    t = hl / np.where(ok, hl - h, 1.0)
    return light.position + t[:, None] * (q - light.position), ok


def _lattice_uv(corners2: np.ndarray, is_quad: bool, pts: np.ndarray) -> np.ndarray:
    """(n, 2) lattice (u, v) of points ``pts`` (n, 2) of a patch whose corners in its plane are
    ``corners2`` (4, 2): barycentric for a triangle, the bilinear map inverted (Newton) for a quad."""
    c = corners2
    jac = np.stack([c[1] - c[0], (c[3] if is_quad else c[2]) - c[0]], axis=1)
    uv = np.linalg.solve(jac, (pts - c[0]).T).T
    if not is_quad:
        return uv
    for _ in range(8):
        u, v = uv[:, :1], uv[:, 1:]
        f = (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3] - pts
        du = (1 - v) * (c[1] - c[0]) + v * (c[2] - c[3])
        dv = (1 - u) * (c[3] - c[0]) + u * (c[2] - c[1])
        det = du[:, 0] * dv[:, 1] - du[:, 1] * dv[:, 0]
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        step_u = (dv[:, 1] * f[:, 0] - dv[:, 0] * f[:, 1]) / det
        step_v = (du[:, 0] * f[:, 1] - du[:, 1] * f[:, 0]) / det
        uv = uv - np.stack([step_u, step_v], axis=1)
    return uv


def _detail_uv(puv: np.ndarray, is_quad: bool, uv: np.ndarray) -> np.ndarray:
    """(n, 2) detail UVs at lattice points uv (n, 2) of a patch with corner UVs ``puv`` (4, 2)."""
    u, v = uv[:, :1], uv[:, 1:]
    if is_quad:
        return (1 - u) * (1 - v) * puv[0] + u * (1 - v) * puv[1] + u * v * puv[2] + (1 - u) * v * puv[3]
    return (1 - u - v) * puv[0] + u * puv[1] + v * puv[2]


def _cut_patch(poly: np.ndarray, segs: np.ndarray, size: float) -> tuple[list[np.ndarray], np.ndarray]:
    """Convex pieces of ``poly`` (k, 2) cut along segments ``segs`` (s, 2, 2), longest first, at most
    :data:`MAX_CUTS_PER_PATCH` of them, none leaving a piece narrower than ``size`` (scene units).
    Returns (pieces, lines (c, 2, 2): the segments that cut)."""
    tol = 1e-7 * size
    pieces, lines = [poly], []
    order = np.argsort(-np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1), kind="stable")
    cuts = 0
    for p0, p1 in segs[order]:
        if cuts >= MAX_CUTS_PER_PATCH:
            break
        out, cut = [], False
        for piece in pieces:
            halves = None
            inside = polycut.clip_segment(piece, p0, p1)
            reach = 4.0 * float(np.ptp(piece, axis=0).max()) / max(float(np.linalg.norm(p1 - p0)), 1e-300)
            chord = polycut.clip_segment(piece, p0 - reach * (p1 - p0), p1 + reach * (p1 - p0))
            if inside > size and inside >= MIN_CHORD * chord:
                halves = polycut.split(piece, p0, p1, tol)
            if halves is not None:
                halves = [polycut.simplify(h, tol) for h in halves]
                if any(len(h) < 3 or polycut.width(h) < size or polycut.area(h) < size**2 for h in halves):
                    halves = None
            if halves is None:
                out.append(piece)
            else:
                out.extend(halves)
                cut = True
        pieces = out
        cuts += cut
        if cut:
            lines.append((p0, p1))
    return pieces, np.array(lines, np.float64).reshape(-1, 2, 2)


def split_discontinuities(scene, lights=None):
    """A copy of ``scene`` whose roots are cut along the hard shadow boundaries of its point, spot
    and directional lights (``lights``: those instead), as the module docstring says.

    Children replace their parent in place (materials copied, detail UVs interpolated, the normal
    kept); panel cells' clip triangles follow their (uncut) cells. Returns a new
    :class:`iat.io.scene.Scene` (``dataclasses.replace``: the same lights, cameras, sky and path), or
    ``scene`` itself when nothing is cut.
    """
    lights = [lt for lt in (scene.lights if lights is None else lights) if casts_cut_shadows(lt)]
    if not lights:
        return scene
    done = [*scene.shadow_cuts, [shadow_key(lt) for lt in lights]]
    opaque = scene.patch_transmission <= 0
    tri, tri_patch = scene.world_triangles(), scene.world_triangle_patch()
    solid = opaque[tri_patch]
    tri, tri_patch = tri[solid], tri_patch[solid]
    receivers = opaque & ~scene.patch_clipped
    if len(tri) == 0:
        return dataclasses.replace(scene, shadow_cuts=done)
    rays = RayCaster(tri)
    found = [shadow_segments(scene, lt, rays, tri, tri_patch, receivers) for lt in lights]
    # a patch and its coincident twin (a sheet's two faces) are cut as one: the lower index cuts with
    # the segments of both, the twin takes the same pieces wound the other way (iat.geometry.sides)
    twin = twin_index(scene.corner_positions, scene.patch_is_quad)[0]
    paired = (twin >= 0) & (twin[np.maximum(twin, 0)] == np.arange(scene.n_patches))
    twin = np.where(paired, twin, -1)
    seg_patch = np.concatenate([f[0] for f in found])
    seg_patch = np.where(twin[seg_patch] >= 0, np.minimum(seg_patch, twin[seg_patch]), seg_patch)
    seg = np.stack([np.concatenate([f[1] for f in found]), np.concatenate([f[2] for f in found])], axis=1)
    corners3 = scene.corner_positions
    normal, is_quad = scene.patch_normal, scene.patch_is_quad
    root_size = float(np.sqrt(scene.patch_area.sum()))
    min_piece = MIN_PIECE * root_size
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    total = np.bincount(seg_patch, weights=length, minlength=scene.n_patches)
    children: dict[int, tuple[np.ndarray, list[list[int]], np.ndarray]] = {}
    new_roots, most = 0, min(MAX_NEW_PATCHES, max(MIN_NEW_PATCHES, int(MAX_NEW_FRACTION * scene.n_patches)))
    for p in np.argsort(-total, kind="stable")[: np.count_nonzero(total)]:
        if new_roots >= most:
            break
        k = 4 if is_quad[p] else 3
        origin, axes = polycut.plane_frame(corners3[p], normal[p])
        poly = (corners3[p, :k] - origin) @ axes.T
        mine = seg[seg_patch == p]
        pieces, lines = _cut_patch(poly, (mine - origin) @ axes.T, min_piece)
        if len(pieces) < 2:
            continue
        pieces = [
            q for piece in pieces for q in polycut.shorten(piece, PIECE_ASPECT, PIECE_LENGTH * root_size)
        ]
        pts, roots = [], []
        for piece in pieces:
            base = sum(len(x) for x in pts)
            for r in polycut.to_roots(piece, QUAD_SKEW_TOL):
                if len(r) == 3:  # a shadow line on a leg, not the hypotenuse (the texture's lattice)
                    r = polycut.legs_on_lines(piece, r, lines, 1e-6 * min_piece)
                roots.append([base + i for i in r])
            pts.append(piece)
        pts2 = np.concatenate(pts)
        children[int(p)] = (origin + pts2 @ axes, roots, pts2)
        new_roots += len(roots) - 1
        if twin[p] >= 0:  # same first corner, the rest reversed (as add_back_faces winds a twin)
            children[int(twin[p])] = (children[int(p)][0], [[r[0], *r[:0:-1]] for r in roots], None)
            new_roots += len(roots) - 1
    if not children:
        return dataclasses.replace(scene, shadow_cuts=done)
    # children in place of their parent
    V = [scene.vertices]
    corners, material, puv, new_index = [], [], [], np.empty(scene.n_patches, np.int64)
    old_family = np.arange(scene.n_patches) if scene.patch_family is None else scene.patch_family
    family = []
    n_v, n_p = len(scene.vertices), 0
    corners2 = np.stack([(corners3[:, i] - corners3[:, 0]) for i in range(4)], axis=1)
    for p in range(scene.n_patches):
        new_index[p] = n_p
        if p not in children:
            corners.append(scene.patch_corners[p][None])
            material.append(scene.patch_material[p : p + 1])
            puv.append(scene.patch_uv[p][None])
            family.append(old_family[p : p + 1])
            n_p += 1
            continue
        world, roots, pts2 = children[p]
        origin, axes = polycut.plane_frame(corners3[p], normal[p])
        pts2 = (world - origin) @ axes.T if pts2 is None else pts2  # a twin's: in its own frame
        uv = _lattice_uv(corners2[p] @ axes.T, bool(is_quad[p]), pts2)
        duv = _detail_uv(scene.patch_uv[p], bool(is_quad[p]), uv)
        for r in roots:
            c = np.array(r + [r[-1]] * (4 - len(r)))
            corners.append(np.where(np.arange(4) < len(r), n_v + c, -1)[None])
            puv.append(duv[c][None])
        material.append(np.full(len(roots), scene.patch_material[p]))
        family.append(np.full(len(roots), old_family[p]))
        V.append(world)
        n_v += len(world)
        n_p += len(roots)
    verts, pc = weld_vertices(np.concatenate(V), np.concatenate(corners))
    verts, pc = compact_vertices(verts, pc)
    return dataclasses.replace(
        scene,
        vertices=verts,
        patch_corners=pc,
        patch_material=np.concatenate(material),
        patch_uv=np.concatenate(puv),
        clip_patch=new_index[scene.clip_patch],
        patch_family=np.concatenate(family).astype(np.int64),
        shadow_cuts=done,
    )


def casts_cut_shadows(light) -> bool:
    """Whether :func:`split_discontinuities` follows ``light``'s shadows: a point, spot or directional
    light that emits."""
    return light.kind in ("point", "spot", "directional") and bool(np.any(light.radiant_intensity > 0))


def shadow_key(light) -> tuple:
    """What fixes a light's hard shadow lines, JSON-able: ``(kind, x, y, z, dx, dy, dz, outer_cone)``
    (position and direction in world units, the cone in radians)."""
    return (
        str(light.kind),
        *(float(x) for x in light.position),
        *(float(x) for x in light.direction),
        float(light.outer_cone),
    )


def cut_new_lights(scene):
    """``scene`` cut (:func:`split_discontinuities`) along the shadows of its lights that no earlier
    cut followed (``Scene.shadow_cuts``): a sun or lamp added after loading (``iat solve --sun``, the
    default daylight of an IFC). Returns ``scene`` itself when there is none."""
    seen = {tuple(k) for group in scene.shadow_cuts for k in group}
    new = [lt for lt in scene.lights if casts_cut_shadows(lt) and shadow_key(lt) not in seen]
    return split_discontinuities(scene, new) if new else scene


def replay_cuts(scene, cuts):
    """``scene`` cut again as ``cuts`` (a solution's ``stats["shadow_cuts"]``: ``Scene.shadow_cuts``
    of the scene it was solved on, each a list of :func:`shadow_key`) says, in order: the same roots
    as then, from the model loaded without discontinuity meshing."""
    for group in cuts:
        lights = [
            SimpleNamespace(
                kind=k[0],
                position=np.array(k[1:4], np.float64),
                direction=np.array(k[4:7], np.float64),
                outer_cone=float(k[7]),
                radiant_intensity=np.ones(3),
            )
            for k in group
        ]
        scene = split_discontinuities(scene, lights)
    return scene
