"""Progressive-refinement radiosity with adaptive quad-tree meshing.

The classic substructured scheme: *receivers* are the mesh vertices (one
radiance value per lattice vertex, the values the baker turns into texels),
*shooters* are the root patches (each with one unshot radiance ``dL``).

1. **Meshing by direct light.** The direct radiance at every vertex (emission,
   plus light reflected from emissive patches and from point / spot lights, with
   ray-traced visibility) is evaluated *exactly* at each vertex. Elements whose
   corner and probe values (edge midpoints and centre, which become the
   children's corners) vary by more than ``tolerance`` are split, the forest is
   2:1 balanced, and only the new vertices are evaluated (cached by key). This
   repeats until nothing splits. No vertex is ever interpolated from its
   parent, so the mesh carries no bias; the bias that interpolation *would*
   have caused is measured and reported (``stats['interpolation_bias']``).
2. **Progressive refinement on the settled mesh.** Each patch's unshot radiance
   starts as the area-weighted mean of its reflected direct radiance (the
   emitters' emission was shot in step 1). The patch with the most unshot power
   shoots: every vertex in front of it receives ``rho * dL * F * vis`` with
   ``F`` the analytic point-to-polygon form factor and ``vis`` the
   cosine-weighted visible fraction of jittered, stratified points on the
   shooter. Receiving patches gain the area-weighted mean of what their
   vertices received as new unshot radiance. Stop when the unshot power falls
   below ``convergence`` times the emitted power, or after ``max_shots``.

Because the mesh is settled before any shooting, every vertex receives every
shot: the final values are unbiased with respect to the mesh (no late vertex
misses early shots, the trap the design warns of).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np
from scipy import sparse

from .. import quadtree as qt
from ..errors import OptionError
from .formfactor import point_polygon
from .solution import Solution
from .visibility import Visibility

#: Rec. 709 luminance weights for "power" and variation tests
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: relative floor of the split test, as a fraction of the mean reflected direct radiance
ABS_FLOOR = 0.02
#: ray-origin offset (normal and towards the patch centre), fraction of the scene diagonal
RAY_EPS = 1e-4
#: in-plane nudge of form-factor points off shared edges, fraction of the scene diagonal
FF_EPS = 1e-6
#: receivers per vectorised gather block (bounds the (n, samples, 3) temporaries)
GATHER_BLOCK = 16384

Progress = Callable[[float, str], "bool | None"]


@dataclass
class SolveOptions:
    """Options of :func:`solve` (lengths in scene units).

    max_depth : int, 0..12, typical 6. Deepest quad-tree level; the lattice has
        ``2**max_depth + 1`` points per patch side. Deeper resolves sharper shadows
        at up to 4x the elements (and texels) per level.
    tolerance : float > 0, typical 0.05. Relative radiance variation (max - min over
        an element's corners and probes, over their mean plus a small absolute floor)
        that splits an element. Smaller means more elements and smoother gradients.
    min_element_size : float >= 0, default 0 (no limit). An element is not split
        when its children's longest edge would be shorter than this.
    convergence : float in (0, 1], typical 0.01. Stop shooting when the unshot
        power is below this fraction of the emitted power (patches and lights).
        Smaller costs more shots for the last, faint bounces.
    samples : int 1..1024, typical 16. Jittered points (a square stratified grid,
        rounded up to ``k*k``) on the shooter per receiver for visibility. More
        samples give smoother penumbrae at proportionally more rays.
    max_shots : int >= 0, default 20000. Hard cap on progressive shots (0: direct
        light only).
    max_edge : float > 0 or None. Recorded for the loader's pre-split of long
        patches into a grid of roots (``load_scene(max_edge=...)``); the solver
        itself takes the scene as it is.
    seed : int, default 0. Seed of the sample jitter; a solve is deterministic.
    """

    max_depth: int = 6
    tolerance: float = 0.05
    min_element_size: float = 0.0
    convergence: float = 0.01
    samples: int = 16
    max_shots: int = 20000
    max_edge: float | None = None
    seed: int = 0

    def validate(self) -> "SolveOptions":
        """Raise :class:`iat.errors.OptionError` on an out-of-range option; return self."""

        def bad(name, why):
            raise OptionError(f"solve option {name}={getattr(self, name)!r}: {why}")

        def num(name):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
                bad(name, "must be a number")
            if not math.isfinite(float(v)):
                bad(name, "must be finite")
            return v

        def integer(name):
            v = num(name)
            if int(v) != v:
                bad(name, "must be an integer")
            return int(v)

        if not 0 <= integer("max_depth") <= 12:
            bad("max_depth", "must be between 0 and 12")
        if not num("tolerance") > 0:
            bad("tolerance", "must be > 0")
        if not num("min_element_size") >= 0:
            bad("min_element_size", "must be >= 0")
        if not 0 < num("convergence") <= 1:
            bad("convergence", "must be in (0, 1]")
        if not 1 <= integer("samples") <= 1024:
            bad("samples", "must be between 1 and 1024")
        if not integer("max_shots") >= 0:
            bad("max_shots", "must be >= 0")
        if self.max_edge is not None and not num("max_edge") > 0:
            bad("max_edge", "must be > 0 or None")
        integer("seed")
        return self

    def to_dict(self) -> dict:
        """JSON-able dict of the options."""
        d = asdict(self)
        return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in d.items()}


class _Cancel(Exception):
    """Internal: the progress callback asked to stop."""


@dataclass
class _Geo:
    """Receiver geometry of a set of vertices (all (n, ...) arrays)."""

    patch: np.ndarray  # (n,) int64
    pos: np.ndarray  # (n, 3) world position on the patch
    normal: np.ndarray  # (n, 3)
    ff: np.ndarray  # (n, 3) form-factor point, nudged into its own patch
    origin: np.ndarray  # (n, 3) ray origin, off the surface

    def take(self, idx) -> "_Geo":
        return _Geo(self.patch[idx], self.pos[idx], self.normal[idx], self.ff[idx], self.origin[idx])


class _Context:
    """Per-solve constant data and the shared gather kernels."""

    def __init__(self, scene, opts: SolveOptions, vis: Visibility):
        self.opts = opts
        self.corners = scene.corner_positions
        self.is_quad = scene.patch_is_quad
        self.normal = scene.patch_normal
        self.area = scene.patch_area
        self.albedo = scene.patch_albedo
        self.emission = scene.patch_emission
        self.n_corners = np.where(self.is_quad, 4, 3)
        self.centre = np.where(
            self.is_quad[:, None], self.corners.mean(axis=1), self.corners[:, :3].mean(axis=1)
        )
        lo, hi = scene.bounds
        self.scale = max(float(np.linalg.norm(hi - lo)), 1e-12)
        self.eps_ray = RAY_EPS * self.scale
        self.eps_ff = FF_EPS * self.scale
        self.n = 1 << opts.max_depth
        self.vis = vis
        self.lights = [lt for lt in scene.lights if lt.kind in ("point", "spot")]
        self.emitters = np.flatnonzero((self.emission > 0).any(axis=1))
        self.shot_count = np.zeros(len(self.area), dtype=np.int64)

    # -- geometry -------------------------------------------------------------
    def polygon(self, s: int) -> np.ndarray:
        return self.corners[s, : self.n_corners[s]]

    def geometry(self, keys: np.ndarray) -> _Geo:
        p, i, j = qt.decode_key(keys, self.n)
        pos = qt.lattice_to_world(self.corners, self.is_quad, p, i, j, self.n)
        nrm = self.normal[p]
        t = self.centre[p] - pos
        t -= np.einsum("nc,nc->n", t, nrm)[:, None] * nrm
        tl = np.linalg.norm(t, axis=1)
        that = t / np.maximum(tl, 1e-300)[:, None]
        ff = pos + np.minimum(self.eps_ff, 0.5 * tl)[:, None] * that
        origin = pos + self.eps_ray * nrm + np.minimum(self.eps_ray, 0.5 * tl)[:, None] * that
        return _Geo(p, pos, nrm, ff, origin)

    def samples(self, s: int, m: int) -> np.ndarray:
        """(m*m, 3) stratified jittered points on patch s, offset off its front side."""
        rng = np.random.default_rng([self.opts.seed, int(s), int(self.shot_count[s])])
        a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        u = ((a.ravel() + rng.random(m * m)) / m)[:, None]
        v = ((b.ravel() + rng.random(m * m)) / m)[:, None]
        c = self.corners[s]
        if self.is_quad[s]:
            pts = (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3]
        else:
            su = np.sqrt(u)
            pts = (1 - su) * c[0] + su * (1 - v) * c[1] + su * v * c[2]
        toward = self.centre[s] - pts
        tl = np.linalg.norm(toward, axis=1, keepdims=True)
        pts = pts + np.minimum(self.eps_ray, 0.5 * tl) * toward / np.maximum(tl, 1e-300)
        return pts + self.eps_ray * self.normal[s]

    # -- kernels --------------------------------------------------------------
    def receivers(self, s: int, geo: _Geo) -> np.ndarray:
        """Indices into ``geo`` of vertices that can receive from patch s (front side, other patch)."""
        poly = self.polygon(s)
        # patches with some corner of s strictly in front of their plane
        h = np.einsum("pkc,pc->pk", poly[None, :, :] - self.centre[:, None, :], self.normal)
        sees = (h > 1e-9 * self.scale).any(axis=1)
        sees[s] = False
        front = np.einsum("nc,c->n", geo.ff - self.centre[s], self.normal[s]) > 0.1 * self.eps_ff
        return np.flatnonzero(front & sees[geo.patch])

    def gather(self, s: int, geo: _Geo, m: int) -> np.ndarray:
        """(n,) form factor x visible fraction from every vertex of ``geo`` to patch s."""
        out = np.zeros(len(geo.patch))
        idx = self.receivers(s, geo)
        if len(idx) == 0:
            return out
        f = point_polygon(geo.ff[idx], geo.normal[idx], self.polygon(s))
        keep = f > 1e-12
        idx, f = idx[keep], f[keep]
        y = self.samples(s, m)
        ns = self.normal[s]
        floor_r2 = self.area[s] / len(y)
        for a in range(0, len(idx), GATHER_BLOCK):
            ii = idx[a : a + GATHER_BLOCK]
            o = geo.origin[ii]
            d = y[None, :, :] - o[:, None, :]  # (b, S, 3)
            r = np.linalg.norm(d, axis=2)
            u = d / np.maximum(r, 1e-300)[..., None]
            cos_r = np.einsum("bsc,bc->bs", u, geo.normal[ii])
            cos_s = -(u @ ns)
            w = np.clip(cos_r, 0, None) * np.clip(cos_s, 0, None) / np.maximum(r * r, floor_r2)
            need = w > 0
            occ = np.zeros(need.shape, dtype=bool)
            if need.any():
                ob = np.broadcast_to(o[:, None, :], d.shape)
                occ[need] = self.vis.occluded(
                    ob[need], u[need], np.maximum(r[need] - 0.5 * self.eps_ray, 0.0)
                )
            wsum = w.sum(axis=1)
            frac = np.where(wsum > 0, (w * ~occ).sum(axis=1) / np.where(wsum > 0, wsum, 1.0), 0.0)
            out[ii] = f[a : a + GATHER_BLOCK] * frac
        return out

    def light_irradiance(self, light, geo: _Geo) -> np.ndarray:
        """(n, 3) irradiance from a point or spot light, with visibility."""
        d = light.position[None, :] - geo.pos
        r = np.linalg.norm(d, axis=1)
        u = d / np.maximum(r, 1e-300)[:, None]
        cos = np.einsum("nc,nc->n", u, geo.normal)
        att = np.ones(len(r))
        if light.kind == "spot":
            di = light.direction / max(np.linalg.norm(light.direction), 1e-300)
            cd = -(u @ di)
            co, ci = math.cos(light.outer_cone), math.cos(light.inner_cone)
            scale = 1.0 / max(1e-3, ci - co)
            att = np.clip((cd - co) * scale, 0.0, 1.0) ** 2
        ok = np.flatnonzero((cos > 0) & (att > 0) & (r > 1e-12 * self.scale))
        e = np.zeros((len(r), 3))
        if len(ok) == 0:
            return e
        do = light.position[None, :] - geo.origin[ok]
        ro = np.linalg.norm(do, axis=1)
        occ = self.vis.occluded(geo.origin[ok], do / ro[:, None], np.maximum(ro - 0.5 * self.eps_ray, 0.0))
        k = cos[ok] * att[ok] / (r[ok] * r[ok]) * ~occ
        e[ok] = k[:, None] * light.radiant_intensity[None, :]
        return e

    def direct(self, keys: np.ndarray, check: Callable[[], None]) -> np.ndarray:
        """(n, 3) reflected direct radiance (emission excluded) at vertex keys."""
        out = np.zeros((len(keys), 3))
        if len(keys) == 0:
            return out
        geo = self.geometry(keys)
        incoming = np.zeros((len(keys), 3))  # radiance-weighted: rho * incoming = reflected
        m = _side(self.opts.samples)
        for e in self.emitters:
            incoming += self.gather(int(e), geo, m)[:, None] * self.emission[e]
            check()
        for light in self.lights:
            incoming += self.light_irradiance(light, geo) / np.pi
            check()
        return self.albedo[geo.patch] * incoming

    def emitted_power(self) -> float:
        """Luminance power emitted by emissive patches and lights (W, luminance-weighted)."""
        p = float(np.pi * (self.emission @ LUMINANCE * self.area).sum())
        for lt in self.lights:
            solid = 4 * np.pi if lt.kind == "point" else 2 * np.pi * (1 - math.cos(lt.outer_cone))
            p += float(lt.radiant_intensity @ LUMINANCE) * solid
        return p


def _side(samples: int) -> int:
    return max(1, math.ceil(math.sqrt(samples) - 1e-9))


def _lum(x: np.ndarray) -> np.ndarray:
    return np.asarray(x) @ LUMINANCE


# -- meshing helpers ------------------------------------------------------------
def _probe_keys(forest: qt.Forest) -> tuple[np.ndarray, np.ndarray]:
    """(L, 5) int64 keys of the points that become corners when a leaf splits, and (L, 5) bool validity.

    Quads: centre and the four edge midpoints. Triangles: the three edge midpoints.
    """
    s = forest.leaf_size
    h = s // 2
    i = forest.leaf_i.astype(np.int64)
    j = forest.leaf_j.astype(np.int64)
    q = forest.leaf_is_quad
    down = ~q & forest.leaf_flip
    pi = np.stack([i + h, i + h, i + s, i + h, i], axis=1)
    pj = np.stack([j + h, j, j + h, j + s, j + h], axis=1)
    # up triangle (i,j),(i+s,j),(i,j+s): midpoints (i+h,j), (i+h,j+h), (i,j+h)
    # down triangle (i+s,j+s),(i,j+s),(i+s,j): midpoints (i+h,j+s), (i+h,j+h), (i+s,j+h)
    tri = ~q
    pi[tri, :3] = np.stack([i + h, i + h, np.where(down, i + s, i)], axis=1)[tri]
    pj[tri, :3] = np.stack([np.where(down, j + s, j), j + h, j + h], axis=1)[tri]
    pi[tri, 3:] = pi[tri, :1]
    pj[tri, 3:] = pj[tri, :1]
    valid = np.ones((forest.n_leaves, 5), dtype=bool)
    valid[tri, 3:] = False
    return qt.make_key(forest.leaf_patch[:, None], pi, pj, forest.n), valid


def _leaf_longest_edge(forest: qt.Forest, corners: np.ndarray) -> np.ndarray:
    """(L,) float64 longest world edge of each leaf."""
    c = qt.leaf_corner_lattice(forest)
    w = qt.lattice_to_world(
        corners, forest.patch_is_quad, np.repeat(forest.leaf_patch, 4), c[..., 0].ravel(), c[..., 1].ravel(), forest.n
    ).reshape(-1, 4, 3)
    e = np.linalg.norm(np.roll(w, -1, axis=1) - w, axis=2)
    tri = ~forest.leaf_is_quad
    e[tri, 2] = np.linalg.norm(w[tri, 0] - w[tri, 2], axis=1)
    return e.max(axis=1)


def _parent_interpolation(keys: np.ndarray, is_quad: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """For non-root vertex keys: (k, 4) keys of the parent-edge ends (or parent corners) and (k, 4) weights.

    A vertex first appears as the midpoint of an edge (or the centre of a quad) of
    the leaf whose split created it; its naive interpolated value is the mean of
    that edge's ends (or of the quad's four corners).
    """
    p, i, j = qt.decode_key(keys, n)
    low = (i | j) & -(i | j)  # largest power of two dividing both: the level's leaf size
    s2 = 2 * low
    a, b = i - i % s2, j - j % s2
    x, y = i % s2, j % s2
    quad = is_quad[p]
    ci = np.stack([a, a + s2, a, a + s2], axis=1)
    cj = np.stack([b, b, b + s2, b + s2], axis=1)
    w = np.full((len(keys), 4), 0.25)
    horiz = (x > 0) & (y == 0)
    vert = (x == 0) & (y > 0)
    diag = (x > 0) & (y > 0) & ~quad
    for mask, e0, e1 in (
        (horiz, (a, j), (a + s2, j)),
        (vert, (i, b), (i, b + s2)),
        (diag, (a + s2, b), (a, b + s2)),
    ):
        ci[mask, 0], cj[mask, 0] = e0[0][mask], e0[1][mask]
        ci[mask, 1], cj[mask, 1] = e1[0][mask], e1[1][mask]
        ci[mask, 2:], cj[mask, 2:] = ci[mask, :1], cj[mask, :1]
        w[mask] = (0.5, 0.5, 0.0, 0.0)
    return qt.make_key(p[:, None], ci, cj, n), w


def _averaging_matrix(forest: qt.Forest, keys: np.ndarray, corners: np.ndarray, area: np.ndarray):
    """(P, V) scipy.sparse CSR: row p averages vertex values over patch p (area-weighted leaf means)."""
    idx = qt.lookup(keys, qt.leaf_corner_keys(forest))
    la = qt.leaf_area(forest, corners)
    wl = la / np.maximum(area[forest.leaf_patch], 1e-300)
    q = forest.leaf_is_quad
    wc = np.where(q, 0.25, 1.0 / 3.0)[:, None] * wl[:, None] * np.ones((1, 4))
    wc[~q, 3] = 0.0
    rows = np.repeat(forest.leaf_patch.astype(np.int64), 4)
    return sparse.csr_matrix((wc.ravel(), (rows, idx.ravel())), shape=(len(area), len(keys)))


# -- the solver ------------------------------------------------------------------
def solve(scene, options: SolveOptions | None = None, progress: Progress | None = None) -> Solution:
    """Solve diffuse global illumination of ``scene``; see the module docstring.

    progress : ``progress(fraction, message) -> bool``; returning False cancels. A
      cancelled solve returns a consistent partial :class:`Solution` (the mesh
      settled so far, its direct light, the shots done) with
      ``stats['cancelled'] = True``.
    Raises :class:`iat.errors.OptionError` for invalid options.
    """
    opts = SolveOptions() if options is None else options
    if not isinstance(opts, SolveOptions):
        raise OptionError(f"solve options must be SolveOptions, not {type(opts).__name__}")
    opts.validate()
    t_start = time.perf_counter()
    vis = Visibility(scene.corner_positions, scene.patch_is_quad)
    try:
        return _solve(scene, opts, progress, vis, t_start)
    finally:
        vis.close()


def _solve(scene, opts: SolveOptions, progress, vis: Visibility, t_start: float) -> Solution:
    ctx = _Context(scene, opts, vis)
    D = opts.max_depth
    state = {"cancelled": False, "last": 0.0}

    def report(fraction: float, message: str) -> None:
        if progress is not None and progress(float(min(max(fraction, 0.0), 1.0)), message) is False:
            state["cancelled"] = True
            raise _Cancel

    def check() -> None:  # cheap poll inside long loops, at most 20 times a second
        now = time.perf_counter()
        if progress is not None and now - state["last"] > 0.05:
            state["last"] = now
            report(state.get("fraction", 0.0), state.get("message", ""))

    # ---- 1. meshing by direct light -------------------------------------------
    forest = qt.roots(ctx.is_quad, D)
    good = forest
    known_k = np.zeros(0, dtype=np.int64)
    known_v = np.zeros((0, 3))
    root_keys = qt.vertex_keys(forest)
    iterations = 0
    t_mesh = time.perf_counter()
    try:
        while True:
            keys = qt.vertex_keys(forest)
            cand = forest.leaf_level < D
            if opts.min_element_size > 0 and cand.any():
                cand &= _leaf_longest_edge(forest, ctx.corners) / 2 >= opts.min_element_size
            pk, pvalid = _probe_keys(forest.take(cand))
            need = np.union1d(keys, pk[pvalid])
            new = need[qt.lookup(known_k, need) < 0]
            state["fraction"] = 0.3 * iterations / (D + 1)
            state["message"] = f"meshing: pass {iterations + 1}, {forest.n_leaves} elements, {len(new)} new points"
            report(state["fraction"], state["message"])
            vals = ctx.direct(new, check)
            known_k = np.concatenate([known_k, new])
            known_v = np.concatenate([known_v, vals])
            order = np.argsort(known_k, kind="stable")
            known_k, known_v = known_k[order], known_v[order]
            good = forest
            iterations += 1
            # split test on total direct radiance (luminance)
            y_all = _lum(known_v)
            refl_mean = _area_mean(forest, keys, qt.lookup(known_k, keys), y_all, ctx)
            eps_abs = max(ABS_FLOOR * refl_mean, 1e-30)
            y_all = y_all + _lum(ctx.emission)[qt.decode_key(known_k, ctx.n)[0]]
            if not cand.any():
                break
            sub = forest.take(cand)
            vy = np.concatenate(
                [y_all[qt.lookup(known_k, qt.leaf_corner_keys(sub))], y_all[qt.lookup(known_k, pk)]], axis=1
            )
            vm = np.concatenate([np.ones((sub.n_leaves, 4), dtype=bool), pvalid], axis=1)
            hi = np.where(vm, vy, -np.inf).max(axis=1)
            lo = np.where(vm, vy, np.inf).min(axis=1)
            mean = (vy * vm).sum(axis=1) / vm.sum(axis=1)
            split = hi - lo > opts.tolerance * (mean + eps_abs)
            if not split.any():
                break
            mask = np.zeros(forest.n_leaves, dtype=bool)
            mask[cand] = split
            forest = qt.balance(qt.split(forest, mask))
    except _Cancel:
        forest = good
    t_mesh = time.perf_counter() - t_mesh

    keys = qt.vertex_keys(forest)
    vidx = qt.lookup(known_k, keys)
    if len(keys) and (vidx < 0).any():  # cancelled before the roots were evaluated
        forest = qt.roots(ctx.is_quad, D)
        keys = qt.vertex_keys(forest)
        vidx = qt.lookup(known_k, keys)
    direct = np.where((vidx >= 0)[:, None], known_v[np.maximum(vidx, 0)], 0.0) if len(known_k) else np.zeros(
        (len(keys), 3)
    )
    vpatch = qt.decode_key(keys, ctx.n)[0]
    emission_v = ctx.emission[vpatch]

    # ---- bias that parent interpolation would have had --------------------------
    late = qt.lookup(root_keys, keys) < 0
    bias, bias_n = 0.0, 0
    if late.any() and len(known_k):
        pkeys, pw = _parent_interpolation(keys[late], ctx.is_quad, ctx.n)
        pi = qt.lookup(known_k, pkeys)
        ok = (pi >= 0).all(axis=1)
        if ok.any():
            interp = (_lum(known_v[pi[ok]]) * pw[ok]).sum(axis=1)
            exact = _lum(direct[late][ok])
            tot = exact.sum()
            bias = float(np.abs(interp - exact).sum() / tot) if tot > 0 else 0.0
            bias_n = int(ok.sum())

    # ---- 2. progressive refinement --------------------------------------------
    M = _averaging_matrix(forest, keys, ctx.corners, ctx.area)
    vert_w = np.asarray(M.sum(axis=0)).ravel()  # one non-zero per column: weight in its own patch
    radiance = emission_v + direct
    unshot = M @ direct
    power0 = ctx.emitted_power()
    shots = 0
    t_shoot = time.perf_counter()
    unshot_power = np.pi * _lum(unshot) * ctx.area
    u_start = max(float(unshot_power.sum()), 1e-300)
    target = opts.convergence * power0
    geo = ctx.geometry(keys) if len(keys) else None
    rho_v = ctx.albedo[vpatch]
    if not state["cancelled"]:
        try:
            while shots < opts.max_shots and power0 > 0:
                total = float(unshot_power.sum())
                if total <= target:
                    break
                span = math.log(u_start / target) if u_start > target else 1.0
                frac = 0.3 + 0.7 * min(1.0, max(0.0, math.log(u_start / max(total, 1e-300)) / span))
                state["fraction"] = frac
                state["message"] = f"shooting: {shots} shots, unshot {total / power0:.3g} of emitted"
                report(frac, state["message"])
                s = int(np.argmax(unshot_power))
                d_l = unshot[s].copy()
                unshot[s] = 0.0
                unshot_power[s] = 0.0
                m = _side(opts.samples)
                f = ctx.gather(s, geo, m)
                ctx.shot_count[s] += 1
                hit = np.flatnonzero(f > 0)
                dv = rho_v[hit] * d_l[None, :] * f[hit, None]
                radiance[hit] += dv
                add = np.stack(
                    [np.bincount(vpatch[hit], weights=vert_w[hit] * dv[:, c], minlength=len(ctx.area)) for c in range(3)],
                    axis=1,
                )
                unshot += add
                changed = np.flatnonzero(add.any(axis=1))
                unshot_power[changed] = np.pi * _lum(unshot[changed]) * ctx.area[changed]
                shots += 1
        except _Cancel:
            pass
    t_shoot = time.perf_counter() - t_shoot

    # ---- result ------------------------------------------------------------------
    if not np.isfinite(radiance).all():
        raise FloatingPointError("radiosity produced non-finite radiance (a solver bug)")
    radiance = np.maximum(radiance, 0.0)
    unshot_fraction = float(unshot_power.sum() / power0) if power0 > 0 else 0.0
    if not state["cancelled"] and progress is not None:
        try:
            report(1.0, f"done: {shots} shots, {len(keys)} vertices")
        except _Cancel:
            pass
    elapsed = time.perf_counter() - t_start
    sol = Solution.from_forest(
        forest,
        ctx.corners,
        scene.patch_material,
        ctx.albedo,
        keys,
        radiance,
        options=opts.to_dict(),
        model_path=str(getattr(scene, "path", "") or ""),
    )
    sol.stats = {
        "elements": int(forest.n_leaves),
        "vertices": int(len(keys)),
        "triangles": int(len(sol.tri_vertices)),
        "shots": int(shots),
        "rays": int(vis.rays),
        "rays_per_s": float(vis.rays / vis.seconds) if vis.seconds > 0 else 0.0,
        "time_s": float(elapsed),
        "meshing_s": float(t_mesh),
        "shooting_s": float(t_shoot),
        "mesh_passes": int(iterations),
        "unshot_fraction": unshot_fraction,
        "interpolation_bias": bias,
        "interpolation_bias_vertices": bias_n,
        "max_depth_reached": int(forest.leaf_level.max()) if forest.n_leaves else 0,
        "emitted_power": float(power0),
        "cancelled": bool(state["cancelled"]),
        "options": opts.to_dict(),
    }
    return sol


def _area_mean(forest: qt.Forest, keys: np.ndarray, kidx: np.ndarray, y: np.ndarray, ctx: _Context) -> float:
    """Area-weighted mean over the scene of per-vertex values ``y[kidx]`` (leaf-corner means)."""
    if forest.n_leaves == 0:
        return 0.0
    yv = y[kidx]
    corner = qt.lookup(keys, qt.leaf_corner_keys(forest))
    q = forest.leaf_is_quad
    vals = yv[corner]
    leaf_mean = np.where(q, vals.mean(axis=1), vals[:, :3].mean(axis=1))
    la = qt.leaf_area(forest, ctx.corners)
    return float((leaf_mean * la).sum() / max(la.sum(), 1e-300))


def evaluate_direct(scene, positions_keys: np.ndarray, options: SolveOptions | None = None) -> np.ndarray:
    """(n, 3) reflected direct radiance at vertex keys, as the solver's meshing pass computes it.

    Exposed for tests and diagnostics (re-evaluating a solution's vertices exactly).
    """
    opts = (SolveOptions() if options is None else options).validate()
    with Visibility(scene.corner_positions, scene.patch_is_quad) as vis:
        ctx = _Context(scene, opts, vis)
        return ctx.direct(np.asarray(positions_keys, dtype=np.int64), lambda: None)
