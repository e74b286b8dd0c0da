"""Progressive-refinement radiosity with adaptive quad-tree meshing.

The classic substructured scheme: *receivers* are the mesh vertices (one
radiance value per lattice vertex, the values the baker turns into texels),
*shooters* are the root patches, each shooting the radiance field its vertices
have received and not yet shot (``unshot``, interpolated over its leaves).

A. **Meshing by direct light.** The direct radiance at every vertex (emission,
   plus light reflected from emissive patches and from point / spot lights, with
   ray-traced visibility) is evaluated *exactly* at each vertex. Elements whose
   corner and probe values (edge midpoints and centre, which become the
   children's corners) vary by more than ``tolerance`` are split, the forest is
   2:1 balanced, and only the new points are evaluated (cached by key). This
   repeats until nothing splits. No vertex is ever interpolated from its
   parent; the bias that interpolation *would* have caused is measured and
   reported (``stats['interpolation_bias']``: sum |parent-interpolated - exact|
   over sum exact, luminance of reflected direct light, over the vertices made
   after the first pass).
B. **Progressive refinement on the settled mesh.** Each vertex's unshot
   radiance starts as its reflected direct radiance (the emitters' emission was
   shot in A). The patch with the most unshot power (pi x area x area-weighted
   mean, from a sparse (P, V) averaging matrix) shoots: every vertex in front of
   it receives ``rho * <F * vis * L>`` -- the analytic point-to-polygon form
   factor (:mod:`.formfactor`) times the visible fraction and the shooter's
   radiance, estimated from stratified samples on the shooter's area and
   cosine-distributed directions from the vertex (multiple importance sampling,
   see :meth:`_Context.gather`), with embreex shadow rays (:mod:`.visibility`).
   Faint shots use fewer samples.
C. **Refinement on the total radiance** (``refine_indirect``), once after the
   first bounces (unshot below sqrt(convergence)) and once at convergence: the
   same split test on direct + indirect radiance, so that surfaces lit only
   indirectly get elements too. A new vertex gets its direct light and a gather
   of everything each patch has shot so far (shots add linearly, so one gather
   of their sum equals replaying them all): exact, never interpolated. Its
   unshot radiance is what it received minus what its patch already shot from
   there, so light a coarse element could not hold is shot again, not lost.
   Shooting then continues to ``convergence`` (unshot power over emitted power).

Because every vertex, early or late, receives every shot, the final values are
unbiased with respect to the mesh: no late vertex misses early shots, the trap
the design warns of.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

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
GATHER_BLOCK = 4096

Progress = Callable[[float, str], "bool | None"]


@dataclass
class SolveOptions:
    """Options of :func:`solve` (lengths in scene units).

    max_depth : int, 0..12, typical 6. Deepest quad-tree level; the lattice has
        ``2**max_depth + 1`` points per patch side. Deeper resolves sharper shadows
        at up to 4x the elements (and texels) per level.
    tolerance : float > 0, typical 0.05. Relative radiance variation that splits an
        element (see ``criterion``), relative to the mean of its corners and probes plus
        a small absolute floor (2 % of the scene's mean reflected radiance, so dark
        corners do not split forever). Smaller: more elements, smoother gradients.
    min_element_size : float >= 0, default 0 (no limit). An element is not split
        when its children's longest edge would be shorter than this.
    convergence : float in (0, 1], typical 0.01. Stop shooting when the unshot
        power is below this fraction of the emitted power (patches and lights); the
        light left unshot is missing from the result (about that fraction, amplified
        by interreflection). Smaller costs more shots for the last, faint bounces.
    samples : int 1..1024, typical 16. Per receiver and shot: that many stratified
        points on the shooter's area and as many cosine-distributed directions (both
        rounded up to ``k*k``), rotated per vertex. More samples: less noise on dim,
        indirectly lit surfaces and smoother penumbrae, at proportionally more rays
        (64 takes about twice the time of 16 on the Cornell box).
    max_shots : int >= 0, default 20000. Hard cap on progressive shots (0: direct
        light only).
    max_edge : float > 0 or None. Recorded for the loader's pre-split of long
        patches into a grid of roots (``load_scene(max_edge=...)``); the solver
        itself takes the scene as it is.
    seed : int, default 0. Seed of the sample jitter; a solve is deterministic.
    criterion : "variation" (default) or "interpolation". What ``tolerance`` bounds:
        "variation" splits on max - min over the element's corners and probes (the
        classic test; smooth gradients refine too, so lit surfaces go deep: 56 k
        elements on the Cornell box at depth 6); "interpolation" splits on the
        largest gap between a probe and the value the corners interpolate there
        (linear gradients stay coarse, shadows still go deep; fewer elements for the
        same error, but a feature that falls between the probes can be missed).
    refine_indirect : bool, default True. Refine on the total (direct + indirect)
        radiance after the first bounces and at convergence, so that surfaces lit
        only indirectly (a ceiling) get elements too; new vertices gather everything
        shot so far (exact, never interpolated). Without it such surfaces keep their
        direct-light mesh and their light is under-counted (5-10 % darker rooms).
    """

    max_depth: int = 6
    tolerance: float = 0.05
    min_element_size: float = 0.0
    convergence: float = 0.01
    samples: int = 16
    max_shots: int = 20000
    max_edge: float | None = None
    seed: int = 0
    criterion: str = "variation"
    refine_indirect: bool = True

    def validate(self) -> SolveOptions:
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
        if not isinstance(self.refine_indirect, bool | np.bool_):
            bad("refine_indirect", "must be True or False")
        if self.criterion not in ("variation", "interpolation"):
            bad("criterion", 'must be "variation" or "interpolation"')
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

    key: np.ndarray  # (n,) int64 vertex keys
    patch: np.ndarray  # (n,) int64
    pos: np.ndarray  # (n, 3) world position on the patch
    normal: np.ndarray  # (n, 3)
    ff: np.ndarray  # (n, 3) form-factor point, nudged into its own patch
    origin: np.ndarray  # (n, 3) ray origin, off the surface

    def take(self, idx) -> _Geo:
        return _Geo(
            self.key[idx], self.patch[idx], self.pos[idx], self.normal[idx], self.ff[idx], self.origin[idx]
        )


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
        # a tangent frame per patch (for cosine-distributed directions)
        helper = np.where(np.abs(self.normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(self.normal, helper)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        self.tangent = np.stack([t1, np.cross(self.normal, t1)], axis=1)  # (P, 2, 3)
        self._shooters: dict[int, _Shooter] = {}

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
        return _Geo(np.asarray(keys, dtype=np.int64), p, pos, nrm, ff, origin)

    def pattern(self, s: int, m: int, shot: int) -> np.ndarray:
        """(m*m, 2) stratified jittered (u, v) in [0, 1)^2 for patch s (fixed per seed, patch, shot)."""
        rng = np.random.default_rng([self.opts.seed, int(s), int(shot)])
        a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        return np.stack([(a.ravel() + rng.random(m * m)) / m, (b.ravel() + rng.random(m * m)) / m], axis=1)

    def shooter(self, s: int) -> _Shooter:
        if s not in self._shooters:
            self._shooters[s] = _Shooter(
                self.corners[s], bool(self.is_quad[s]), self.normal[s], float(self.area[s]), self.eps_ray
            )
        return self._shooters[s]

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

    def gather(
        self,
        s: int,
        geo: _Geo,
        m: int,
        shot: int = 0,
        field: np.ndarray | None = None,
        field_mean: np.ndarray | None = None,
    ) -> np.ndarray:
        """Form factor x visible fraction from every vertex of ``geo`` to patch s.

        m : the sample patterns are m x m; shot : index of this patch's shot (0 for the
        direct pass), which fixes the jitter (a vertex re-evaluated later gets the same value).
        field : None for a uniform shooter, returning (n,) ``F * vis``; or the shooter's
        radiance on its lattice, (N+1, N+1, 3), with its area mean ``field_mean`` (3,),
        returning (n, 3) the radiance-weighted form factor: a shooter need not be uniform.

        ``F`` is the analytic form factor and ``vis`` the ratio of two estimates of the
        kernel integral (with and without visibility) from the same samples, so it is
        exact for an unoccluded shooter. A field is split into a constant ``c`` (a control
        variate: the field at the receiver's foot on the shooter for near receivers, the
        shooter's mean for far ones), weighted by ``F * vis``, and the rest, whose kernel
        integral is estimated directly (not as a ratio: a ratio of correlated estimates
        loses energy when the field is bright where the kernel is large). The samples
        combine two strategies with
        the balance heuristic: m x m stratified points on the shooter's area (good when the
        shooter is far and small) and m x m cosine-distributed directions from the receiver
        that hit the shooter (good when it is near and large: the kernel is then too peaked
        for area samples). Both patterns are rotated per receiver (Cranley-Patterson,
        keyed by the vertex), so errors are decorrelated between vertices.
        """
        out = np.zeros(len(geo.patch) if field is None else (len(geo.patch), 3))
        idx = self.receivers(s, geo)
        if len(idx) == 0:
            return out
        f = point_polygon(geo.ff[idx], geo.normal[idx], self.polygon(s))
        keep = f > 1e-12
        idx, f = idx[keep], f[keep]
        sh = self.shooter(s)
        pat = self.pattern(s, m, shot)
        n_s = len(pat)
        salt = (int(self.opts.seed) * 1_000_003 + int(s)) * 1_000_003 + int(shot)
        flat = None if field is None else field.reshape(-1, 3)
        for a in range(0, len(idx), GATHER_BLOCK):
            ii = idx[a : a + GATHER_BLOCK]
            b = len(ii)
            x, nr = geo.ff[ii], geo.normal[ii]
            rot = _hash_uniform(geo.key[ii], salt, 4)
            # area samples: stratified (u, v), rotated per receiver
            ua = (pat[None, :, 0] + rot[:, :1]) % 1.0
            va = (pat[None, :, 1] + rot[:, 1:2]) % 1.0
            if not sh.is_quad:  # area-uniform square -> triangle warp
                su = np.sqrt(ua)
                ua, va = su * (1 - va), su * va
            ya = sh.point(ua, va)  # (b, S, 3)
            da = ya - x[:, None, :]
            r2 = np.einsum("bsc,bsc->bs", da, da)
            ka = np.maximum(np.einsum("bsc,bc->bs", da, nr), 0.0) * np.maximum(-(da @ sh.normal), 0.0)
            ka /= np.pi * np.maximum(r2 * r2, 1e-300)
            pa = 1.0 / sh.jacobian(ua, va)
            wa = ka / (n_s * pa + n_s * ka + 1e-300)
            # direction samples: cosine-distributed about the receiver normal, kept where they hit
            t1, t2 = self.tangent[geo.patch[ii], 0], self.tangent[geo.patch[ii], 1]
            dx, dy = _concentric((pat[None, :, 0] + rot[:, 2:3]) % 1.0, (pat[None, :, 1] + rot[:, 3:4]) % 1.0)
            dz = np.sqrt(np.maximum(1.0 - dx * dx - dy * dy, 0.0))
            w = (
                dx[..., None] * t1[:, None, :]
                + dy[..., None] * t2[:, None, :]
                + dz[..., None] * nr[:, None, :]
            )
            den = w @ sh.normal  # < 0: towards the front of the shooter
            t = ((sh.origin - x) @ sh.normal)[:, None] / np.where(den < 0, den, -1.0)
            yd = x[:, None, :] + t[..., None] * w
            hit = (den < -1e-12) & (t > 0) & sh.inside(yd)
            ud, vd = sh.uv(yd)
            kd = np.where(hit, dz * -den / (np.pi * np.maximum(t * t, 1e-300)), 0.0)
            wd = np.where(hit, kd / (n_s / sh.jacobian(ud, vd) + n_s * kd + 1e-300), 0.0)
            # visibility of the samples that count
            wt = np.concatenate([wa, wd], axis=1)  # (b, 2S)
            wsum = wt.sum(axis=1)
            bi, si = np.nonzero(wt > 0)
            if len(bi) == 0:
                continue
            pts = np.concatenate([ya, yd], axis=1)[bi, si]
            o = geo.origin[ii][bi]
            dr = sh.target(pts) - o
            r = np.sqrt(np.einsum("kc,kc->k", dr, dr))
            vis = ~self.vis.occluded(
                o, dr / np.maximum(r, 1e-300)[:, None], np.maximum(r - 0.5 * self.eps_ray, 0.0)
            )
            wraw = wt[bi, si] * vis  # MIS estimate of the visible kernel integral, per sample
            frac = np.bincount(bi, weights=wraw, minlength=b) / np.where(wsum > 0, wsum, 1.0)
            fv = f[a : a + GATHER_BLOCK] * frac  # analytic F x visible fraction
            if field is None:
                out[ii] = fv
            else:
                nl = field.shape[0] - 1
                # control variate: the field where the receiver's kernel peaks (its foot on the
                # shooter) for near receivers, the shooter's mean for far ones
                foot = x - ((x - sh.origin) @ sh.normal)[:, None] * sh.normal
                fu, fw = sh.uv(foot)
                near = np.minimum(1.0, 2.0 * f[a : a + GATHER_BLOCK])[:, None]
                cv = near * _sample_lattice(flat, nl, fu, fw) + (1.0 - near) * field_mean  # (b, 3)
                lu = np.concatenate([ua, ud], axis=1)[bi, si]
                lv = np.concatenate([va, vd], axis=1)[bi, si]
                rest = (_sample_lattice(flat, nl, lu, lv) - cv[bi]) * wraw[:, None]
                res = np.stack([np.bincount(bi, weights=rest[:, c], minlength=b) for c in range(3)], axis=1)
                out[ii] = np.maximum(fv[:, None] * cv + res, 0.0)
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


def _hash_uniform(keys: np.ndarray, salt: int, k: int = 2) -> np.ndarray:
    """(n, k) float64 in [0, 1): k splitmix64 hashes of (key, salt)."""
    z = np.asarray(keys, dtype=np.int64).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    z ^= np.uint64(salt & 0xFFFFFFFFFFFFFFFF)
    out = []
    for _ in range(k):
        z = z + np.uint64(0x9E3779B97F4A7C15)
        x = z.copy()
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x = x ^ (x >> np.uint64(31))
        out.append((x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53)))
    return np.stack(out, axis=1)


def _concentric(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shirley-Chiu concentric map of the unit square onto the unit disc."""
    a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    phi = np.where(first, (np.pi / 4) * b / safe_a, np.pi / 2 - (np.pi / 4) * a / safe_b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def _cross2(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]


class _Shooter:
    """Geometry of one patch as a shooter: inside test, inverse parametrisation, area Jacobian.

    Quads: ``p(u, v) = c0 + u e1 + v e2 + u v e3`` (bilinear); triangles: ``c0 + u e1 + v e2``.
    """

    def __init__(self, corners: np.ndarray, is_quad: bool, normal: np.ndarray, area: float, eps: float):
        self.is_quad = is_quad
        self.normal = normal
        self.area = area
        c = corners if is_quad else corners[:3]
        self.origin = c[0]
        self.poly = c
        self.e1 = corners[1] - corners[0]
        self.e2 = (corners[3] if is_quad else corners[2]) - corners[0]
        self.e3 = corners[0] - corners[1] + corners[2] - corners[3] if is_quad else np.zeros(3)
        scale = max(np.linalg.norm(self.e1), np.linalg.norm(self.e2))
        self.parallelogram = not is_quad or np.linalg.norm(self.e3) <= 1e-12 * scale
        self.centre = c.mean(axis=0)
        self.eps = eps
        self.shrink = eps / max(float(np.linalg.norm(c - self.centre, axis=1).max()), 1e-300)
        t1 = self.e1 / max(np.linalg.norm(self.e1), 1e-300)
        self.frame = np.stack([t1, np.cross(normal, t1)])  # (2, 3) in-plane axes
        self.edge_n = np.cross(np.roll(c, -1, axis=0) - c, normal)  # (k, 3) outward edge normals
        self.edge_o = c
        self.tol = 1e-9 * max(float(np.abs(c - c.mean(axis=0)).max()), 1e-300)

    def inside(self, pts: np.ndarray) -> np.ndarray:
        """(...) bool: points (..., 3) on the plane inside the convex polygon."""
        ok = np.ones(pts.shape[:-1], dtype=bool)
        for o, en in zip(self.edge_o, self.edge_n, strict=True):
            ok &= (pts - o) @ en <= self.tol * np.linalg.norm(en)
        return ok

    def uv(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice parameters (u, v) of points (..., 3) on the patch plane (clipped to the patch)."""
        h = (pts - self.origin) @ self.frame.T  # (..., 2)
        e, f, g = self.frame @ self.e1, self.frame @ self.e2, self.frame @ self.e3
        if not self.is_quad or np.abs(g).max() <= 1e-12 * max(np.abs(e).max(), np.abs(f).max()):
            det = _cross2(e, f)
            u, v = _cross2(h, f) / det, _cross2(e, h) / det
        else:  # inverse bilinear: k2 v^2 + k1 v + k0 = 0
            k2 = _cross2(g, f)
            k1 = _cross2(e, f) + _cross2(h, g)
            k0 = _cross2(h, e)
            if abs(k2) < 1e-14:
                v = -k0 / np.where(k1 == 0, 1e-300, k1)
            else:
                disc = np.sqrt(np.clip(k1 * k1 - 4 * k0 * k2, 0.0, None))
                v1, v2 = (-k1 - disc) / (2 * k2), (-k1 + disc) / (2 * k2)
                v = np.where((v1 >= -1e-9) & (v1 <= 1 + 1e-9), v1, v2)
            den = e + v[..., None] * g
            u = np.einsum("...c,...c->...", h - v[..., None] * f, den) / np.maximum(
                np.einsum("...c,...c->...", den, den), 1e-300
            )
        u, v = np.clip(u, 0.0, 1.0), np.clip(v, 0.0, 1.0)
        if not self.is_quad:
            over = u + v > 1.0
            tot = np.where(over, u + v, 1.0)
            u, v = u / tot, v / tot
        return u, v

    def point(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(..., 3) points at lattice parameters (u, v)."""
        u, v = np.asarray(u)[..., None], np.asarray(v)[..., None]
        p = self.origin + u * self.e1 + v * self.e2
        return p if self.parallelogram else p + (u * v) * self.e3

    def target(self, pts: np.ndarray) -> np.ndarray:
        """(..., 3) ray targets for points on the patch: ``eps`` off its front, and pulled
        towards its centre by at most ``eps`` (so a target at a corner is not inside a
        neighbouring wall)."""
        return pts + self.eps * self.normal + self.shrink * (self.centre - pts)

    def jacobian(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Area per unit (u, v) of the area samples at lattice parameters (u, v)."""
        if self.parallelogram:  # constant; the square -> triangle warp is area-uniform too
            return np.full(np.shape(u), self.area)
        du = self.e1 + np.asarray(v)[..., None] * self.e3
        dv = self.e2 + np.asarray(u)[..., None] * self.e3
        return np.maximum(np.linalg.norm(np.cross(du, dv), axis=-1), 1e-300)


def _sample_lattice(flat: np.ndarray, n: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(k, 3) piecewise-linear interpolation at lattice parameters u, v (k,) of a lattice
    grid given flat, ((N+1)**2, 3).

    Each lattice cell is split along its anti-diagonal, so triangle patches (points with
    ``u + v <= 1``) only ever read lattice points inside the triangle.
    """
    x, y = u * n, v * n
    a = np.minimum(x.astype(np.int64), n - 1)
    b = np.minimum(y.astype(np.int64), n - 1)
    fx, fy = x - a, y - b
    i00 = a * (n + 1) + b
    lower = fx + fy <= 1.0
    # lower: g00 (1-fx-fy) + g10 fx + g01 fy ; upper: g11 (fx+fy-1) + g01 (1-fx) + g10 (1-fy)
    w_base = np.where(lower, 1.0 - fx - fy, fx + fy - 1.0)
    i_base = np.where(lower, i00, i00 + n + 2)
    w10 = np.where(lower, fx, 1.0 - fy)
    w01 = np.where(lower, fy, 1.0 - fx)
    return flat[i_base] * w_base[:, None] + flat[i00 + n + 1] * w10[:, None] + flat[i00 + 1] * w01[:, None]


class _Lattice:
    """Per-patch radiance on the full lattice from vertex values (the shooters' radiance fields)."""

    def __init__(self, forest: qt.Forest, keys: np.ndarray):
        self.forest = forest
        self.n = forest.n
        self.corner = qt.lookup(keys, qt.leaf_corner_keys(forest))  # (L, 4)
        self.order = np.argsort(forest.leaf_patch, kind="stable")
        self.starts = np.searchsorted(forest.leaf_patch[self.order], np.arange(forest.n_patches + 1))
        self._offsets: dict[int, tuple] = {}

    def _level(self, level: int):
        if level not in self._offsets:
            s = self.n >> level
            a, b = np.meshgrid(np.arange(s + 1), np.arange(s + 1), indexing="ij")
            a, b = a.ravel(), b.ravel()
            x, y = a / s, b / s
            wq = np.stack([(1 - x) * (1 - y), x * (1 - y), x * y, (1 - x) * y], axis=1)
            up = np.flatnonzero(a + b <= s)
            down = np.flatnonzero(a + b >= s)
            wu = np.stack([1 - x - y, x, y, 0 * x], axis=1)[up]  # corners (0,0), (1,0), (0,1)
            wd = np.stack([x + y - 1, 1 - x, 1 - y, 0 * x], axis=1)[down]  # (1,1), (0,1), (1,0)
            self._offsets[level] = (a, b, wq, up, wu, down, wd)
        return self._offsets[level]

    def grid(self, p: int, values: np.ndarray) -> np.ndarray:
        """(N+1, N+1, 3) values of patch p on its lattice, interpolated in its leaves from ``values``."""
        n, fo = self.n, self.forest
        g = np.zeros((n + 1, n + 1, 3))
        leaves = self.order[self.starts[p] : self.starts[p + 1]]
        lvl = fo.leaf_level[leaves]
        for level in np.unique(lvl):
            sel = leaves[lvl == level]
            a, b, wq, up, wu, down, wd = self._level(int(level))
            vals = values[self.corner[sel]]  # (l, 4, 3)
            i0, j0 = fo.leaf_i[sel][:, None], fo.leaf_j[sel][:, None]
            if fo.patch_is_quad[p]:
                g[i0 + a, j0 + b] = np.einsum("gk,lkc->lgc", wq, vals)
                continue
            flip = fo.leaf_flip[sel]
            for mask, pts, w in ((~flip, up, wu), (flip, down, wd)):
                if mask.any():
                    g[i0[mask] + a[pts], j0[mask] + b[pts]] = np.einsum("gk,lkc->lgc", w, vals[mask])
        return g


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


def _probe_interp(forest: qt.Forest) -> np.ndarray:
    """(L, 5, 4) int64 corner slots whose mean interpolates each probe of :func:`_probe_keys`."""
    q = forest.leaf_is_quad
    down = ~q & forest.leaf_flip
    out = np.empty((forest.n_leaves, 5, 4), dtype=np.int64)
    # quad corners 0:(0,0) 1:(s,0) 2:(s,s) 3:(0,s); probes centre, bottom, right, top, left
    out[q] = [[0, 1, 2, 3], [0, 1, 0, 1], [1, 2, 1, 2], [2, 3, 2, 3], [3, 0, 3, 0]]
    # up corners 0:(0,0) 1:(s,0) 2:(0,s); probes (h,0), (h,h), (0,h)
    up = ~q & ~forest.leaf_flip
    out[up] = [[0, 1, 0, 1], [1, 2, 1, 2], [0, 2, 0, 2], [0, 1, 0, 1], [0, 1, 0, 1]]
    # down corners 0:(s,s) 1:(0,s) 2:(s,0); probes (h,s), (h,h), (s,h)
    out[down] = [[0, 1, 0, 1], [1, 2, 1, 2], [0, 2, 0, 2], [0, 1, 0, 1], [0, 1, 0, 1]]
    return out


def _leaf_longest_edge(forest: qt.Forest, corners: np.ndarray) -> np.ndarray:
    """(L,) float64 longest world edge of each leaf."""
    c = qt.leaf_corner_lattice(forest)
    w = qt.lattice_to_world(
        corners,
        forest.patch_is_quad,
        np.repeat(forest.leaf_patch, 4),
        c[..., 0].ravel(),
        c[..., 1].ravel(),
        forest.n,
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


class _Cache:
    """Values (n, 3) at sorted vertex keys (n,), grown by :meth:`add`."""

    def __init__(self, keys=None, vals=None):
        self.keys = np.zeros(0, dtype=np.int64) if keys is None else np.asarray(keys, dtype=np.int64)
        self.vals = np.zeros((0, 3)) if vals is None else np.asarray(vals, dtype=np.float64)

    def find(self, keys: np.ndarray) -> np.ndarray:
        return qt.lookup(self.keys, keys)

    def get(self, keys: np.ndarray) -> np.ndarray:
        """(n, 3) values at ``keys``; 0 where unknown."""
        i = self.find(keys)
        out = np.zeros((len(keys), 3))
        out[i >= 0] = self.vals[i[i >= 0]]
        return out

    def add(self, keys: np.ndarray, vals: np.ndarray) -> None:
        k = np.concatenate([self.keys, keys])
        v = np.concatenate([self.vals, vals])
        order = np.argsort(k, kind="stable")
        self.keys, self.vals = k[order], v[order]


def _refine(ctx: _Context, forest: qt.Forest, cache: _Cache, evaluate, report, label: str, span):
    """Split elements until nothing varies by more than the tolerance (see the module docstring).

    cache : reflected radiance (n, 3) at vertex keys, extended with ``evaluate(new_keys)``.
    Returns (forest, passes); on cancel the last forest whose vertices are all evaluated
    (or the given one) is returned and ``_Cancel`` is re-raised by the caller's check.
    """
    opts, D = ctx.opts, ctx.opts.max_depth
    emission_y = _lum(ctx.emission)
    good, passes = forest, 0
    try:
        while True:
            keys = qt.vertex_keys(forest)
            cand = forest.leaf_level < D
            if opts.min_element_size > 0 and cand.any():
                cand &= _leaf_longest_edge(forest, ctx.corners) / 2 >= opts.min_element_size
            sub = forest.take(cand)
            pk, pvalid = _probe_keys(sub)
            need = np.union1d(keys, pk[pvalid])
            new = need[cache.find(need) < 0]
            report(
                span[0] + (span[1] - span[0]) * passes / (D + 1),
                f"{label}: pass {passes + 1}, {forest.n_leaves} elements, {len(new)} new points",
            )
            cache.add(new, evaluate(new))
            good, passes = forest, passes + 1
            if not cand.any():
                break
            # split test on luminance of the outgoing radiance (emission + reflected)
            refl_y = _lum(cache.vals)
            eps_abs = max(ABS_FLOOR * _area_mean(forest, keys, cache.find(keys), refl_y, ctx), 1e-30)
            y = refl_y + emission_y[qt.decode_key(cache.keys, ctx.n)[0]]
            vy = np.concatenate([y[cache.find(qt.leaf_corner_keys(sub))], y[cache.find(pk)]], axis=1)
            vm = np.concatenate([np.ones((sub.n_leaves, 4), dtype=bool), pvalid], axis=1)
            mean = (vy * vm).sum(axis=1) / vm.sum(axis=1)
            if opts.criterion == "variation":
                hi = np.where(vm, vy, -np.inf).max(axis=1)
                lo = np.where(vm, vy, np.inf).min(axis=1)
                score = hi - lo
            else:
                slots = _probe_interp(sub)
                ck = vy[:, :4]
                interp = (
                    np.take_along_axis(ck, slots.reshape(len(ck), -1), axis=1)
                    .reshape(slots.shape)
                    .mean(axis=2)
                )
                score = np.where(pvalid, np.abs(vy[:, 4:] - interp), 0.0).max(axis=1)
            split = score > opts.tolerance * (mean + eps_abs)
            if not split.any():
                break
            mask = np.zeros(forest.n_leaves, dtype=bool)
            mask[cand] = split
            forest = qt.balance(qt.split(forest, mask))
    except _Cancel:
        return good, passes, True
    return forest, passes, False


def _interpolation_bias(
    keys: np.ndarray, old_keys: np.ndarray, cache: _Cache, ctx: _Context
) -> tuple[float, int]:
    """Mean relative error (sum |interpolated - exact| / sum exact, luminance of reflected radiance)
    that parent interpolation would have given the vertices of ``keys`` not in ``old_keys``."""
    late = keys[qt.lookup(old_keys, keys) < 0]
    if len(late) == 0:
        return 0.0, 0
    pkeys, pw = _parent_interpolation(late, ctx.is_quad, ctx.n)
    pi = cache.find(pkeys)
    ok = (pi >= 0).all(axis=1) & (cache.find(late) >= 0)
    if not ok.any():
        return 0.0, 0
    y = _lum(cache.vals)
    interp = (y[pi[ok]] * pw[ok]).sum(axis=1)
    exact = y[cache.find(late[ok])]
    tot = exact.sum()
    return (float(np.abs(interp - exact).sum() / tot) if tot > 0 else 0.0), int(ok.sum())


def _solve(scene, opts: SolveOptions, progress, vis: Visibility, t_start: float) -> Solution:
    ctx = _Context(scene, opts, vis)
    P = len(ctx.area)
    m_side = _side(opts.samples)
    state = {"cancelled": False, "last": 0.0, "fraction": 0.0, "message": ""}

    def report(fraction: float, message: str) -> None:
        state["fraction"], state["message"] = fraction, message
        if progress is not None and progress(float(min(max(fraction, 0.0), 1.0)), message) is False:
            state["cancelled"] = True
            raise _Cancel

    def check() -> None:  # cheap poll inside long loops, at most 20 times a second
        now = time.perf_counter()
        if progress is not None and now - state["last"] > 0.05:
            state["last"] = now
            report(state["fraction"], state["message"])

    stats: dict = {"interpolation_bias_total": 0.0, "interpolation_bias_total_vertices": 0}
    timings = {}

    # ---- A. meshing by direct light --------------------------------------------------
    t0 = time.perf_counter()
    roots = qt.roots(ctx.is_quad, opts.max_depth)
    root_keys = qt.vertex_keys(roots)
    direct_cache = _Cache()
    forest, passes_a, _ = _refine(
        ctx, roots, direct_cache, lambda k: ctx.direct(k, check), report, "meshing", (0.0, 0.2)
    )
    keys = qt.vertex_keys(forest)
    bias, bias_n = _interpolation_bias(keys, root_keys, direct_cache, ctx)
    timings["meshing_s"] = time.perf_counter() - t0

    # ---- B. progressive refinement -------------------------------------------------
    reflected = direct_cache.get(keys)  # 0 where a cancel left a vertex unevaluated
    unshot_v = reflected.copy()  # per-vertex unshot radiance: shooters need not be uniform
    power0 = ctx.emitted_power()
    target = opts.convergence * power0
    shots = 0
    shot_index = np.ones(P, dtype=np.int64)  # jitter index per patch; 0 was the direct pass
    mesh = {}

    def set_mesh(forest, keys):
        mesh["forest"], mesh["keys"] = forest, keys
        mesh["M"] = _averaging_matrix(forest, keys, ctx.corners, ctx.area)
        mesh["lattice"] = _Lattice(forest, keys)
        mesh["start"] = np.searchsorted(keys, qt.make_key(np.arange(P + 1), 0, 0, ctx.n))
        mesh["geo"] = ctx.geometry(keys) if len(keys) else None
        mesh["rho"] = ctx.albedo[qt.decode_key(keys, ctx.n)[0]]

    def patch_power(unshot_v):
        return np.pi * _lum(mesh["M"] @ unshot_v) * ctx.area

    set_mesh(forest, keys)
    u_start = max(float(patch_power(unshot_v).sum()), 1e-300)

    p_first = [None]  # power of the first (strongest) shot

    def shoot(span, target):
        """Shoot until the unshot power is below ``target`` or max_shots."""
        nonlocal shots, reflected, unshot_v
        if power0 <= 0 or len(mesh["keys"]) == 0:
            return
        span_log = math.log(u_start / target) if u_start > target else 1.0  # progress on a log scale
        while shots < opts.max_shots:
            power = patch_power(unshot_v)
            total = float(power.sum())
            if total <= target:
                break
            done = min(1.0, max(0.0, math.log(u_start / max(total, 1e-300)) / span_log))
            state["fraction"] = span[0] + (span[1] - span[0]) * done
            state["message"] = f"shooting: {shots} shots, unshot {total / power0:.3g} of emitted"
            check()
            s = int(np.argmax(power))
            a, b = mesh["start"][s], mesh["start"][s + 1]
            field = mesh["lattice"].grid(s, unshot_v)
            field_mean = mesh["M"][s] @ unshot_v
            # fewer samples for faint shots: their noise matters less (sqrt keeps power / m flat-ish)
            if p_first[0] is None:
                p_first[0] = float(power[s])
            m = max(2, min(m_side, round(m_side * math.sqrt(float(power[s]) / p_first[0]))))
            g = ctx.gather(s, mesh["geo"], m, int(shot_index[s]), field, np.ravel(field_mean))
            shot_index[s] += 1
            shots += 1
            unshot_v[a:b] = 0.0
            dv = mesh["rho"] * g
            reflected += dv
            unshot_v += dv

    def refine_total(label: str, span) -> None:
        """Phase C: refine on the total radiance. New vertices get their direct light and a
        gather of everything each patch has shot so far (exact: shots are linear, so one
        gather of their sum equals replaying them all), never an interpolated value. Their
        unshot radiance is what they received minus what their patch already shot from
        there, so energy the coarser mesh could not hold is shot again, not lost."""
        nonlocal forest, keys, reflected, unshot_v
        shot_field = reflected - unshot_v
        lattice_b = mesh["lattice"]
        sources = [p for p in range(P) if shot_index[p] > 1]
        grids = {p: lattice_b.grid(p, shot_field) for p in sources}
        means = mesh["M"] @ shot_field
        total_cache = _Cache(keys, reflected.copy())

        def evaluate_total(new: np.ndarray) -> np.ndarray:
            out = direct_cache.get(new)
            missing = direct_cache.find(new) < 0
            if missing.any():
                out[missing] = ctx.direct(new[missing], check)
            if len(new):
                geo = ctx.geometry(new)
                rho = ctx.albedo[geo.patch]
                for p in sources:
                    jitter = int(shot_index[p]) + 1_000_000 * (1 + stats["refine_passes"])
                    out += rho * ctx.gather(p, geo, m_side, jitter, grids[p], means[p])
                    check()
            return out

        old_keys = keys
        forest, passes, _ = _refine(ctx, forest, total_cache, evaluate_total, report, label, span)
        stats["refine_passes"] += passes
        keys = qt.vertex_keys(forest)
        if len(keys) == len(old_keys):
            return
        b, bn = _interpolation_bias(keys, old_keys, total_cache, ctx)
        n_old = stats["interpolation_bias_total_vertices"]
        if bn:  # vertex-weighted mean over the refinement stages
            stats["interpolation_bias_total"] = (stats["interpolation_bias_total"] * n_old + b * bn) / (
                n_old + bn
            )
        stats["interpolation_bias_total_vertices"] = n_old + bn
        old_idx = qt.lookup(old_keys, keys)
        new_unshot = np.zeros((len(keys), 3))
        new_unshot[old_idx >= 0] = unshot_v[old_idx[old_idx >= 0]]
        reflected = total_cache.get(keys)
        p_new, i_new, j_new = qt.decode_key(keys, ctx.n)
        for p in np.unique(p_new[old_idx < 0]):
            sel = np.flatnonzero((old_idx < 0) & (p_new == p))
            shot_here = grids[p][i_new[sel], j_new[sel]] if p in grids else 0.0
            new_unshot[sel] = np.maximum(reflected[sel] - shot_here, 0.0)
        unshot_v = new_unshot
        set_mesh(forest, keys)

    # stages: shoot the first bounces, refine, shoot to convergence, refine, finish
    t_shoot = t_refine = 0.0
    stats["refine_passes"] = 0
    first_target = max(target, math.sqrt(opts.convergence) * power0)
    plan = [("shoot", first_target, (0.2, 0.6)), ("refine", "refining", (0.6, 0.7))]
    plan += [("shoot", target, (0.7, 0.85)), ("refine", "refining again", (0.85, 0.95))]
    plan += [("shoot", target, (0.95, 1.0))]
    try:
        for kind, arg, span in plan:
            if state["cancelled"]:
                break
            t0 = time.perf_counter()
            if kind == "shoot":
                shoot(span, arg)
                t_shoot += time.perf_counter() - t0
            elif opts.refine_indirect and shots:
                refine_total(arg, span)
                t_refine += time.perf_counter() - t0
    except _Cancel:
        pass
    timings["shooting_s"], timings["refining_s"] = t_shoot, t_refine
    unshot_power = patch_power(unshot_v)

    # ---- result ------------------------------------------------------------------
    vpatch = qt.decode_key(keys, ctx.n)[0]
    radiance = ctx.emission[vpatch] + reflected
    if not np.isfinite(radiance).all():
        raise FloatingPointError("radiosity produced non-finite radiance (a solver bug)")
    radiance = np.maximum(radiance, 0.0)
    unshot_fraction = float(unshot_power.sum() / power0) if power0 > 0 else 0.0
    if not state["cancelled"]:
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
        **{k: float(v) for k, v in timings.items()},
        "mesh_passes": int(passes_a),
        "unshot_fraction": unshot_fraction,
        "interpolation_bias": bias,
        "interpolation_bias_vertices": bias_n,
        **stats,
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


def evaluate_direct(scene, keys: np.ndarray, options: SolveOptions | None = None) -> np.ndarray:
    """(n, 3) reflected direct radiance at vertex keys, as the solver's meshing pass computes it.

    Exposed for tests and diagnostics (re-evaluating a solution's vertices exactly).
    """
    opts = (SolveOptions() if options is None else options).validate()
    with Visibility(scene.corner_positions, scene.patch_is_quad) as vis:
        ctx = _Context(scene, opts, vis)
        return ctx.direct(np.asarray(keys, dtype=np.int64), lambda: None)
