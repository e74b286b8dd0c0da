"""Progressive-refinement radiosity with adaptive quad-tree meshing.

The classic substructured scheme: *receivers* are the mesh vertices (one
radiance value per lattice vertex, the values the baker turns into texels),
*shooters* are the root patches, each shooting the radiance field its vertices
have received and not yet shot (``unshot``, interpolated over its leaves).

A. **Meshing by direct light.** The direct radiance at every vertex (emission,
   plus light reflected from emissive patches and from point / spot lights, with
   ray-traced visibility) is evaluated *exactly* at each vertex. Elements whose
   corner and probe values (edge midpoints and centre, which become the
   children's corners) deviate by more than ``tolerance`` (see ``criterion``) are
   split, unless their children would be smaller than ``min_element_size``; the
   forest is 2:1 balanced, and only the new points are evaluated (cached by key).
   This repeats until nothing splits. No vertex is ever interpolated from its
   parent; the bias that interpolation *would* have caused is measured and
   reported (``stats['interpolation_bias']``: sum |parent-interpolated - exact|
   over sum exact, luminance of reflected direct light, over the vertices made
   after the first pass).
B. **Progressive refinement on the settled mesh.** Each vertex's unshot
   radiance starts as its reflected direct radiance (the emitters' emission was
   shot in A). The patch with the most unshot power (pi x area x area-weighted
   mean of |unshot|, from a sparse (P, V) averaging matrix) shoots: every vertex
   in front of it receives ``rho * <F * vis * L>`` -- the analytic
   point-to-polygon form factor (:mod:`.formfactor`, cached per shooter for its
   later shots) times the visible fraction and the shooter's radiance, estimated
   from stratified samples on the shooter's area and, for near receivers,
   cosine-distributed directions from the vertex (multiple importance sampling,
   see :meth:`_Context.gather`), with embreex shadow rays (:mod:`.visibility`).
   Whole patches are culled per shot first: behind the shooter or facing away,
   or -- for a shooter's later shots -- found fully occluded by its earlier ones
   (at least ``CULL_RAYS`` rays, none unoccluded). Faint shots use fewer samples.
   *Receiver levels* (after the BF refinement of hierarchical radiosity): a patch
   far from the shooter (its radius under ``COARSE_SIZE`` of the distance) on
   which the shooter's shots add little (under ``COARSE_EPS`` of its radiance,
   judged at the shooter's first shot and kept for its later ones) receives on a
   coarse lattice grid of its own (its corners, or 3 x 3 points) instead of at
   every vertex, and its vertices get the values interpolated from that grid;
   what the grids receive is kept, so the vertices that stage C adds get it too.
C. **Refinement on the total radiance** (``refine_indirect``), once, after the
   first bounces (unshot below sqrt(convergence)): the same split test on
   direct + indirect radiance, so that surfaces lit only indirectly get elements
   too. A new vertex gets its direct light, what the coarse grids of its patch
   received (interpolated, as its old neighbours got it) and a gather of
   everything each patch that reached it at vertex level has shot so far (shots
   add linearly, so one gather of their sum equals replaying them all): never
   interpolated from its parent. Its unshot radiance is what it received minus
   what its patch already shot from there, so light a coarse element could not
   hold is shot again, not lost. Shooting then continues to ``convergence``
   (unshot power over emitted power).
D. **Ambient term** (``ambient``, after Cohen et al. 1988): the light still
   unshot at convergence would, over all its later bounces, add a reflected
   power of ``U * r / (1 - r)`` (``U`` the unshot power, ``r`` the fraction of a
   shot's power that the scene reflects back, measured on the last half of the
   shots, so an open scene's escaping light counts). It is spread as a uniform
   incoming radiance ``E`` (per channel), every vertex adding ``rho * c * E``
   where ``c`` is the closed fraction of its hemisphere (``AMBIENT_RAYS`` rays:
   1 in a closed room, less near an opening): the energy of the result is right,
   only the distribution of the last ``convergence`` of the light is
   approximated (in the house, stopping at 5 % with the ambient term is 1.2 %
   from the converged solution on average, against 4.7 % without it).

Because every vertex, early or late, receives every shot, the final values are
unbiased with respect to the mesh: no late vertex misses early shots, the trap
the design warns of.

Two entry points reuse a settled mesh (for lighting variants whose trees must
align): ``solve(scene, mesh=solution)`` solves afresh on the leaves of
``solution`` (no subdivision; same ``vert_key``), and :func:`resolve` continues
from a previous solution when only the lights / emission changed, shooting only
the difference (radiosity is linear in the sources; the difference field may be
negative and is shot by the magnitude of its power).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields, replace
from types import SimpleNamespace

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
#: ... but at most this fraction of the radius of the patch the ray leaves (or aims at)
RAY_EPS_PATCH = 0.02
#: in-plane nudge of form-factor points off shared edges, fraction of the scene diagonal
FF_EPS = 1e-6
#: receivers per vectorised gather block (bounds the (n, samples) temporaries)
GATHER_BLOCK = 8192
#: ``min_element_size=None`` means this fraction of the square root of the scene's surface
#: area (a length that measures a scene's size whatever its shape: 3.8 cm in the house,
#: 4 cm in the 30 m cave tunnel, 2.3 mm in the Cornell box)
MIN_ELEMENT_FRACTION = 1.0 / 600.0
#: receivers whose form factor to the shooter is below this use area samples only (the
#: kernel is then nearly flat over the shooter); nearer ones add cosine-direction samples
F_DIRECTION = 0.02
#: a receiver patch to which a shooter's earlier gathers traced at least this many rays,
#: none of them unoccluded, is skipped by that shooter's later shots
CULL_RAYS = 64
#: receiver levels of a shot (hierarchical, after Hanrahan's BF refinement): a patch on which a
#: shot adds less than COARSE_EPS[1] of its current radiance receives on its level-1 lattice grid
#: (3 x 3 points, 6 on triangles), less than COARSE_EPS[0] at its corners only, the values
#: interpolated to its vertices; otherwise at every vertex
COARSE_EPS = (0.002, 0.02)
#: ... and only when the patch is far from the shooter: its radius below this fraction of the
#: distance between them (the shot then varies smoothly over it, and the interpolation from the
#: grid stays within a few percent of the shot's small contribution)
COARSE_SIZE = (0.125, 0.25)
#: receivers farther than this many shooter radii get their form factor from a Gauss rule
FF_FAR = 4.0
#: most (receiver, shooter) form factors kept for the shooters' later shots on the same mesh
#: (8 bytes each)
FF_CACHE_ENTRIES = 12_000_000
#: the direct pass (emitters) uses this many times the per-side samples of ``samples``
DIRECT_SAMPLE_FACTOR = 2
#: the strongest shots (the first bounces, which make most of the indirect light) use this many
#: times the per-side samples of ``samples``; fainter ones fewer, down to 1 x 1
SHOT_SAMPLE_FACTOR = 2
#: ... those that shoot at least this fraction of the emitted power; a shot of a smaller share
#: s uses ``sqrt(s / SHOT_FULL_SHARE)`` of them per side (samples in proportion to power)
SHOT_FULL_SHARE = 0.05
#: :func:`resolve` solves afresh on the mesh when the changed sources' power exceeds this
#: fraction of the new emitted power
RESOLVE_MAX_CHANGE = 1.0
#: rays per vertex that measure the closure of its hemisphere for the ambient term
AMBIENT_RAYS = 16
#: upper bound of the measured reflected fraction in the ambient term
MAX_REFLECTANCE = 0.95

Progress = Callable[[float, str], "bool | None"]


@dataclass
class SolveOptions:
    """Options of :func:`solve` (lengths in scene units).

    max_depth : int, 0..12, default 6. Deepest quad-tree level; the lattice has
        ``2**max_depth + 1`` points per patch side. Deeper resolves sharper shadows
        at up to 4x the elements (and texels) per level.
    tolerance : float > 0, default 0.1. Relative radiance error that splits an element
        (see ``criterion``), relative to the mean of its corners and probes plus a
        small absolute floor (2 % of the scene's mean reflected radiance, so dark
        corners do not split forever). Smaller: more elements.
    min_element_size : float >= 0 or None (default). An element is not split when its
        children's longest edge would be shorter than this; 0: no limit; None: 1/600 of the
        square root of the scene's surface area (3.8 cm in the 12 m house, 4 cm in the cave,
        2.3 mm in the Cornell box), which stops the endless subdivision of tiny regions
        along hard shadow edges.
    convergence : float in (0, 1], default 0.02. Stop shooting when the unshot power is
        below this fraction of the emitted power (patches and lights); with ``ambient``
        its later bounces are added as a uniform ambient term, otherwise that light
        (amplified by interreflection) is missing from the result. Smaller costs more
        shots for the last, faint bounces.
    samples : int 1..1024, default 16. Per receiver and shot: that many stratified
        points on the shooter's area and, for near receivers, as many cosine-distributed
        directions (both rounded up to ``k*k``). The direct pass from emissive patches
        uses ``(2k)**2``, as do the strongest shots of reflected light; fainter shots use
        fewer (by the square root of their power), down to one. Shots rotate the pattern per
        receiver (independent errors, which average out over the shots); the gathers that
        give the vertices new in stage C the light shot so far use one pattern for all
        receivers (errors smooth in space: new vertices do not stand out as speckle).
    max_shots : int >= 0, default 20000. Hard cap on progressive shots (0: direct
        light only).
    max_edge : float > 0 or None. Recorded for the loader's pre-split of long
        patches into a grid of roots (``load_scene(max_edge=...)``); the solver
        itself takes the scene as it is.
    seed : int, default 0. Seed of the sample jitter; a solve is deterministic.
    criterion : "interpolation" (default) or "variation". What ``tolerance`` bounds:
        "interpolation" splits on the largest gap between a probe and the value the
        corners interpolate there (linear gradients stay coarse, shadows still go deep:
        the mesh goes where the light has features); "variation" splits on max - min
        over the element's corners and probes (the classic test; smooth gradients
        refine too, so lit surfaces go deep: about 10x the elements).
    refine_indirect : bool, default True. Refine on the total (direct + indirect)
        radiance after the first bounces and at convergence, so that surfaces lit
        only indirectly (a ceiling) get elements too; new vertices gather everything
        shot so far (exact, never interpolated). Without it such surfaces keep their
        direct-light mesh.
    ambient : bool, default True. Add the ambient term for the light still unshot at
        convergence (see the module docstring); False leaves it out (the result is
        then darker by about ``convergence`` times the interreflection gain).
    """

    max_depth: int = 6
    tolerance: float = 0.1
    min_element_size: float | None = None
    convergence: float = 0.05
    samples: int = 16
    max_shots: int = 20000
    max_edge: float | None = None
    seed: int = 0
    criterion: str = "interpolation"
    refine_indirect: bool = True
    ambient: bool = True

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
        if self.min_element_size is not None and not num("min_element_size") >= 0:
            bad("min_element_size", "must be >= 0 or None")
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
        if not isinstance(self.ambient, bool | np.bool_):
            bad("ambient", "must be True or False")
        if self.criterion not in ("variation", "interpolation"):
            bad("criterion", 'must be "variation" or "interpolation"')
        return self

    def to_dict(self) -> dict:
        """JSON-able dict of the options."""
        d = asdict(self)
        return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict) -> SolveOptions:
        """Options from :meth:`to_dict` output (unknown keys, e.g. from a newer version, ignored)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in dict(d).items() if k in names})


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
    start: np.ndarray | None = None  # (P + 1,) first index of each patch when keys are sorted
    cache: dict | None = None  # per-shooter form factors (the mesh's geometry only)

    def take(self, idx) -> _Geo:
        return _Geo(
            self.key[idx], self.patch[idx], self.pos[idx], self.normal[idx], self.ff[idx], self.origin[idx]
        )


def _ranges(start: np.ndarray, patches: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(start[p], start[p + 1])`` over ``patches`` (sorted)."""
    a, b = start[patches], start[patches + 1]
    n = b - a
    keep = n > 0
    a, n = a[keep], n[keep]
    if len(n) == 0:
        return np.zeros(0, dtype=np.int64)
    off = np.repeat(a - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    return np.arange(int(n.sum()), dtype=np.int64) + off


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
        self.n_patches = len(self.area)
        self.n_corners = np.where(self.is_quad, 4, 3)
        self.centre = np.where(
            self.is_quad[:, None], self.corners.mean(axis=1), self.corners[:, :3].mean(axis=1)
        )
        self.radius = np.linalg.norm(self.corners - self.centre[:, None, :], axis=2).max(axis=1)
        lo, hi = scene.bounds if self.n_patches else (np.zeros(3), np.zeros(3))
        self.scale = max(float(np.linalg.norm(hi - lo)), 1e-12)
        self.eps_ray = RAY_EPS * self.scale
        # per patch: no more than a fiftieth of the patch's radius (a 1 cm object in a 100 m scene
        # keeps its shadow), no less than 32 float32 steps at the scene's extent (embree's precision)
        extent = float(np.abs(np.stack([lo, hi])).max()) if self.n_patches else 1.0
        floor = 32.0 * float(np.spacing(np.float32(max(extent, 1e-30))))
        self.eps_patch = np.clip(RAY_EPS_PATCH * self.radius, min(floor, self.eps_ray), self.eps_ray)
        self.eps_ff = FF_EPS * self.scale
        mes = opts.min_element_size
        self.min_size = (
            MIN_ELEMENT_FRACTION * math.sqrt(float(self.area.sum())) if mes is None else float(mes)
        )
        self.n = 1 << opts.max_depth
        self.vis = vis
        self.lights = [lt for lt in scene.lights if lt.kind in ("point", "spot")]
        self.emitters = np.flatnonzero((self.emission > 0).any(axis=1))
        # a tangent frame per patch (for cosine-distributed directions)
        helper = np.where(np.abs(self.normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(self.normal, helper)
        t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-300)
        self.tangent = np.stack([t1, np.cross(self.normal, t1)], axis=1)  # (P, 2, 3)
        # receiver corners' heights (P, 4) over their own patch centre, for the plane tests
        self._valid_corner = np.arange(4)[None, :] < self.n_corners[:, None]
        self._shooters: dict[int, _Shooter] = {}
        self._cand: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        # per shooter: rays traced to each receiver patch and how many were unoccluded
        self._vis_rays: dict[int, np.ndarray] = {}
        self._vis_seen: dict[int, np.ndarray] = {}

    # -- geometry -------------------------------------------------------------
    def polygon(self, s: int) -> np.ndarray:
        return self.corners[s, : self.n_corners[s]]

    def geometry(self, keys: np.ndarray) -> _Geo:
        keys = np.asarray(keys, dtype=np.int64)
        p, i, j = qt.decode_key(keys, self.n)
        pos = qt.lattice_to_world(self.corners, self.is_quad, p, i, j, self.n)
        nrm = self.normal[p]
        t = self.centre[p] - pos
        t -= np.einsum("nc,nc->n", t, nrm)[:, None] * nrm
        tl = np.linalg.norm(t, axis=1)
        that = t / np.maximum(tl, 1e-300)[:, None]
        ff = pos + np.minimum(self.eps_ff, 0.5 * tl)[:, None] * that
        eps = self.eps_patch[p][:, None]
        origin = pos + eps * nrm + np.minimum(eps, 0.5 * tl[:, None]) * that
        start = None
        if len(keys) == 0 or np.all(keys[1:] > keys[:-1]):
            start = np.searchsorted(keys, qt.make_key(np.arange(self.n_patches + 1), 0, 0, self.n))
        return _Geo(keys, p, pos, nrm, ff, origin, start)

    def pattern(self, s: int, m: int, shot: int) -> np.ndarray:
        """(m*m, 2) stratified jittered (u, v) in [0, 1)^2 for patch s (fixed per seed, patch, shot)."""
        rng = np.random.default_rng([self.opts.seed, int(s), int(shot), int(m)])
        a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        return np.stack([(a.ravel() + rng.random(m * m)) / m, (b.ravel() + rng.random(m * m)) / m], axis=1)

    def shooter(self, s: int) -> _Shooter:
        if s not in self._shooters:
            self._shooters[s] = _Shooter(
                self.corners[s],
                bool(self.is_quad[s]),
                self.normal[s],
                float(self.area[s]),
                float(self.eps_patch[s]),
            )
        return self._shooters[s]

    # -- kernels --------------------------------------------------------------
    def candidates(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(P,) bool ``full, part``: receiver patches that can see the front of patch s, entirely
        in front of its plane (``full``) or straddling it (``part``: test per vertex)."""
        if s not in self._cand:
            poly = self.polygon(s)
            # some corner of s strictly in front of the receiver's plane
            h = np.einsum("pkc,pc->pk", poly[None, :, :] - self.centre[:, None, :], self.normal)
            sees = (h > 1e-9 * self.scale).any(axis=1)
            sees[s] = False
            # receiver corners in front of the plane of s
            hr = np.einsum("pkc,c->pk", self.corners - self.centre[s], self.normal[s])
            ahead = hr > 0.1 * self.eps_ff + 1e-9 * self.scale
            any_ahead = (ahead & self._valid_corner).any(axis=1)
            all_ahead = (ahead | ~self._valid_corner).all(axis=1)
            self._cand[s] = (sees & all_ahead, sees & any_ahead & ~all_ahead)
        return self._cand[s]

    def allowed(self, s: int, cull: bool, patches: np.ndarray | None) -> np.ndarray | None:
        """(P,) bool receiver patches allowed for s (``patches``, less the ones earlier gathers
        of s found fully occluded when ``cull``), or None for all."""
        ok = None if patches is None else np.asarray(patches, dtype=bool)
        if cull and s in self._vis_rays:
            hidden = (self._vis_rays[s] >= CULL_RAYS) & (self._vis_seen[s] == 0)
            ok = ~hidden if ok is None else ok & ~hidden
        return ok

    def receivers(self, s: int, geo: _Geo, allowed: np.ndarray | None = None) -> np.ndarray:
        """Sorted indices into ``geo`` of vertices that can receive from patch s (front side,
        other patch, on an ``allowed`` patch)."""
        full, part = self.candidates(s)
        if allowed is not None:
            full, part = full & allowed, part & allowed
        if geo.start is not None:
            idx_full = _ranges(geo.start, np.flatnonzero(full))
            idx_part = _ranges(geo.start, np.flatnonzero(part))
        else:
            idx_full = np.flatnonzero(full[geo.patch])
            idx_part = np.flatnonzero(part[geo.patch])
        front = (geo.ff[idx_part] - self.centre[s]) @ self.normal[s] > 0.1 * self.eps_ff
        return np.sort(np.concatenate([idx_full, idx_part[front]]))

    def form_factors(
        self, s: int, geo: _Geo, cull: bool = False, patches: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Receivers of s in ``geo`` with a form factor > 0 (indices) and their analytic form
        factors, on the allowed patches (see :meth:`allowed`). With ``geo.cache`` (a mesh's
        geometry) they are kept per shooter and receiver patch, since a patch shoots several
        times on the same mesh; the oldest shooters go first when the cache is full."""
        ok = self.allowed(s, cull, patches)
        cache = geo.cache
        entry = None if cache is None else cache.get(s)
        if cache is not None and entry is None:
            entry = cache[s] = [
                np.zeros(0, dtype=np.int64),
                np.zeros(0, dtype=np.float32),
                np.zeros(self.n_patches, dtype=bool),
            ]
        need = ok if entry is None else (~entry[2] if ok is None else ok & ~entry[2])
        if entry is None or need.any():
            idx = self.receivers(s, geo, need)
            f = self._form_factors(s, geo.ff[idx], geo.normal[idx])
            keep = f > 1e-12
            idx, f = idx[keep], f[keep]
            if entry is None:
                return idx, f
            entry[0] = np.concatenate([entry[0], idx])
            entry[1] = np.concatenate([entry[1], f.astype(np.float32)])
            entry[2] |= True if need is None else need
            size = cache.get("_size", 0) + len(idx)
            while size > FF_CACHE_ENTRIES and len(cache) > 2:
                old = next(k for k in cache if k not in ("_size", s))
                size -= len(cache.pop(old)[0])
            cache["_size"] = size
        idx, f = entry[0], entry[1]
        if ok is not None:
            sel = ok[geo.patch[idx]]
            idx, f = idx[sel], f[sel]
        return idx, f

    def _form_factors(self, s: int, x: np.ndarray, nr: np.ndarray) -> np.ndarray:
        """(n,) point-to-polygon form factors from points x with normals nr to patch s: the
        analytic contour integral, or for receivers farther than ``FF_FAR`` shooter radii that
        see all of it, a Gauss rule over the shooter (2 x 2 points on quads, Dunavant's 6 on
        triangles; within 0.5 % of the analytic value there, 0.06 % on average)."""
        f = np.zeros(len(x))
        if len(x) == 0:
            return f
        poly = self.polygon(s)
        h = np.einsum("kc,nc->nk", poly, nr) - np.einsum("nc,nc->n", x, nr)[:, None]
        dist = np.linalg.norm(x - self.centre[s], axis=1)
        far = (dist > FF_FAR * self.radius[s]) & (h > 0).all(axis=1)
        near = ~far
        if near.any():
            f[near] = point_polygon(x[near], nr[near], poly)
        if far.any():
            sh = self.shooter(s)
            (gu, gv), gw = _GAUSS_QUAD if sh.is_quad else _GAUSS_TRI
            d0 = sh.origin - x[far]
            k = sh.kernel(gu, gv, d0, nr[far]) * sh.jacobian(gu, gv)
            f[far] = k @ gw
        return f

    def culled_fraction(self) -> float:
        """Fraction of (shooter, candidate receiver patch) pairs found fully occluded."""
        tot = hid = 0
        for s, rays in self._vis_rays.items():
            full, part = self.candidates(s)
            tot += int((full | part).sum())
            hid += int(((rays >= CULL_RAYS) & (self._vis_seen[s] == 0) & (full | part)).sum())
        return hid / tot if tot else 0.0

    def gather(
        self,
        s: int,
        geo: _Geo,
        m: int,
        shot: int = 0,
        field: np.ndarray | None = None,
        field_mean: np.ndarray | None = None,
        *,
        correlated: bool = False,
        cull: bool = False,
        patches: np.ndarray | None = None,
    ) -> np.ndarray:
        """Form factor x visible fraction from every vertex of ``geo`` to patch s.

        m : the sample patterns are m x m; shot : index of this patch's shot (0 for the
        direct pass), which fixes the jitter (a vertex re-evaluated later gets the same value).
        field : None for a uniform shooter, returning (n,) ``F * vis``; or the shooter's
        radiance on its lattice, (N+1, N+1, 3), with its area mean ``field_mean`` (3,),
        returning (n, 3) the radiance-weighted form factor: a shooter need not be uniform.
        correlated : one sample pattern for all receivers (errors vary smoothly over the
        receivers: no speckle), instead of the pattern rotated per receiver (errors
        independent per receiver: penumbrae become noise instead of banding).
        cull : skip receiver patches that earlier gathers from s found fully occluded.
        patches : (P,) bool, receive only on these patches (None: all).

        ``F`` is the analytic form factor and ``vis`` the ratio of two estimates of the
        kernel integral (with and without visibility) from the same samples, so it is
        exact for an unoccluded shooter. A field is split into a constant ``c`` (a control
        variate: the field at the receiver's foot on the shooter for near receivers, the
        shooter's mean for far ones), weighted by ``F * vis``, and the rest, whose kernel
        integral is estimated directly (not as a ratio: a ratio of correlated estimates
        loses energy when the field is bright where the kernel is large). Near receivers
        (``F >= F_DIRECTION``) combine two strategies with the balance heuristic: m x m
        stratified points on the shooter's area (good when the shooter is far and small)
        and m x m cosine-distributed directions from the receiver that hit the shooter
        (good when it is near and large: the kernel is then too peaked for area samples);
        far receivers use the area samples alone. All kernel terms are computed from
        per-receiver scalars (no (n, samples, 3) arrays).
        """
        n_geo = len(geo.key)
        out = np.zeros(n_geo if field is None else (n_geo, 3))
        idx, f = self.form_factors(s, geo, cull, patches)
        if len(idx) == 0:
            return out
        sh = self.shooter(s)
        pat = self.pattern(s, m, shot)
        n_s = len(pat)
        salt = (int(self.opts.seed) * 1_000_003 + int(s)) * 1_000_003 + int(shot)
        flat = None if field is None else field.reshape(-1, 3)
        if field is not None:
            lo, hi = float(flat.min()), float(flat.max())
            clamp_lo = 0.0 if lo >= 0 else None  # a field of one sign gives results of that sign
            clamp_hi = 0.0 if hi <= 0 else None
        rays_p = np.zeros(self.n_patches)
        seen_p = np.zeros(self.n_patches)
        for a in range(0, len(idx), GATHER_BLOCK):
            ii = idx[a : a + GATHER_BLOCK]
            fb = f[a : a + GATHER_BLOCK]
            b = len(ii)
            x, nr = geo.ff[ii], geo.normal[ii]
            rot = _hash_uniform(np.zeros(1, dtype=np.int64) if correlated else geo.key[ii], salt, 4)
            # area samples: stratified (u, v), rotated per receiver (or once for all)
            ua = (pat[None, :, 0] + rot[:, :1]) % 1.0
            va = (pat[None, :, 1] + rot[:, 1:2]) % 1.0
            if not sh.is_quad:  # area-uniform square -> triangle warp
                su = np.sqrt(ua)
                ua, va = su * (1 - va), su * va
            d0 = sh.origin - x  # (b, 3) receiver -> shooter origin
            ka = sh.kernel(ua, va, d0, nr)  # (b or 1.., S) broadcast to (b, S)
            ja = sh.jacobian(ua, va)
            near = fb >= F_DIRECTION
            wa = ka / (n_s / ja + n_s * ka * near[:, None] + 1e-300)
            ua, va = np.broadcast_to(ua, wa.shape), np.broadcast_to(va, wa.shape)
            # direction samples (near receivers): cosine-distributed about the normal, kept where they hit
            sub = np.flatnonzero(near)
            if len(sub):
                wd, ud, vd = self._direction_samples(sh, pat, rot, sub, x, nr, geo.patch[ii], n_s, correlated)
                wt = np.concatenate([wa, np.zeros_like(wa)], axis=1)  # (b, 2S)
                wt[sub, n_s:] = wd
                uu = np.concatenate([ua, np.zeros_like(wa)], axis=1)
                vv = np.concatenate([va, np.zeros_like(wa)], axis=1)
                uu[sub, n_s:], vv[sub, n_s:] = ud, vd
            else:
                wt, uu, vv = wa, ua, va
            wsum = wt.sum(axis=1)
            bi, si = np.nonzero(wt > 0)
            if len(bi) == 0:
                continue
            lu, lv = uu[bi, si], vv[bi, si]
            o = geo.origin[ii][bi]
            dr = sh.target_uv(lu, lv) - o
            r = np.sqrt(dr[:, 0] * dr[:, 0] + dr[:, 1] * dr[:, 1] + dr[:, 2] * dr[:, 2])
            vis = ~self.vis.occluded(
                o, dr / np.maximum(r, 1e-300)[:, None], np.maximum(r - 0.5 * sh.eps, 0.0)
            )
            rp = geo.patch[ii][bi]
            rays_p += np.bincount(rp, minlength=self.n_patches)
            seen_p += np.bincount(rp, weights=vis, minlength=self.n_patches)
            wraw = wt[bi, si] * vis  # MIS estimate of the visible kernel integral, per sample
            frac = np.bincount(bi, weights=wraw, minlength=b) / np.where(wsum > 0, wsum, 1.0)
            fv = fb * frac  # analytic F x visible fraction
            if field is None:
                out[ii] = fv
            else:
                nl = field.shape[0] - 1
                # control variate: the field where the receiver's kernel peaks (its foot on the
                # shooter) for near receivers, the shooter's mean for far ones
                fu, fw = sh.foot_uv(x)
                w_near = np.minimum(1.0, 2.0 * fb)[:, None]
                cv = w_near * _sample_lattice(flat, nl, fu, fw) + (1.0 - w_near) * field_mean  # (b, 3)
                rest = (_sample_lattice(flat, nl, lu, lv) - cv[bi]) * wraw[:, None]
                res = np.stack([np.bincount(bi, weights=rest[:, c], minlength=b) for c in range(3)], axis=1)
                val = fv[:, None] * cv + res
                if clamp_lo is not None:
                    val = np.maximum(val, clamp_lo)
                if clamp_hi is not None:
                    val = np.minimum(val, clamp_hi)
                out[ii] = val
        if s in self._vis_rays:
            self._vis_rays[s] += rays_p
            self._vis_seen[s] += seen_p
        else:
            self._vis_rays[s], self._vis_seen[s] = rays_p, seen_p
        return out

    def _direction_samples(self, sh, pat, rot, sub, x, nr, rpatch, n_s, correlated):
        """MIS weights (k, S) and lattice parameters of the cosine-direction samples of the
        receivers ``sub`` (rows of the block) that hit the shooter (weight 0 elsewhere)."""
        r = rot if correlated else rot[sub]
        dx, dy = _concentric((pat[None, :, 0] + r[:, 2:3]) % 1.0, (pat[None, :, 1] + r[:, 3:4]) % 1.0)
        dz = np.sqrt(np.maximum(1.0 - dx * dx - dy * dy, 0.0))
        t1, t2 = self.tangent[rpatch[sub], 0], self.tangent[rpatch[sub], 1]
        xs, ns = x[sub], nr[sub]

        def proj(g):  # w . g for the sample directions w, (k, S)
            return dx * (t1 @ g)[:, None] + dy * (t2 @ g)[:, None] + dz * (ns @ g)[:, None]

        den = proj(sh.normal)  # < 0: towards the front of the shooter
        hx = (xs - sh.origin) @ sh.normal  # receiver height over the shooter's plane (> 0)
        ok = den < -1e-12
        t = np.where(ok, hx[:, None] / np.where(ok, -den, 1.0), 0.0)
        if sh.parallelogram:
            ud = ((xs - sh.origin) @ sh.a1)[:, None] + t * proj(sh.a1)
            vd = ((xs - sh.origin) @ sh.a2)[:, None] + t * proj(sh.a2)
            hit = ok & (t > 0) & sh.inside_uv(ud, vd)
            ud, vd = sh.clip_uv(ud, vd)
            jd = sh.area
        else:
            w = (
                dx[..., None] * t1[:, None, :]
                + dy[..., None] * t2[:, None, :]
                + dz[..., None] * ns[:, None, :]
            )
            yd = xs[:, None, :] + t[..., None] * w
            hit = ok & (t > 0) & sh.inside(yd)
            ud, vd = sh.uv(yd)
            jd = sh.jacobian(ud, vd)
        kd = np.where(hit, dz * -den / (np.pi * np.maximum(t * t, 1e-300)), 0.0)
        wd = np.where(hit, kd / (n_s / jd + n_s * kd + 1e-300), 0.0)
        return wd, np.broadcast_to(ud, wd.shape), np.broadcast_to(vd, wd.shape)

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
        occ = self.vis.occluded(
            geo.origin[ok], do / ro[:, None], np.maximum(ro - 0.5 * self.eps_patch[geo.patch[ok]], 0.0)
        )
        k = cos[ok] * att[ok] / (r[ok] * r[ok]) * ~occ
        e[ok] = k[:, None] * light.radiant_intensity[None, :]
        return e

    def emitter_gather(self, e: int, geo: _Geo) -> np.ndarray:
        """(n,) ``F * vis`` from emissive patch e, as the direct pass computes it (per-vertex
        rotated patterns, ``DIRECT_SAMPLE_FACTOR`` x the per-side samples, shot 0)."""
        return self.gather(int(e), geo, DIRECT_SAMPLE_FACTOR * _side(self.opts.samples))

    def direct(self, keys: np.ndarray, check: Callable[[], None], geo: _Geo | None = None) -> np.ndarray:
        """(n, 3) reflected direct radiance (emission excluded) at vertex keys."""
        out = np.zeros((len(keys), 3))
        if len(keys) == 0:
            return out
        geo = self.geometry(keys) if geo is None else geo
        incoming = np.zeros((len(keys), 3))  # radiance-weighted: rho * incoming = reflected
        for e in self.emitters:
            incoming += self.emitter_gather(e, geo)[:, None] * self.emission[e]
            check()
        for light in self.lights:
            incoming += self.light_irradiance(light, geo) / np.pi
            check()
        return self.albedo[geo.patch] * incoming

    def emitted_power(self) -> float:
        """Luminance power emitted by emissive patches and lights (W, luminance-weighted)."""
        p = float(np.pi * (self.emission @ LUMINANCE * self.area).sum())
        for lt in self.lights:
            p += _light_power(lt)
        return p


def _light_power(lt) -> float:
    """Luminance power of a light (by magnitude: a difference of two lights may be negative)."""
    solid = 4 * np.pi if lt.kind == "point" else 2 * np.pi * (1 - math.cos(lt.outer_cone))
    return abs(float(lt.radiant_intensity @ LUMINANCE)) * solid


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


_G2 = 0.5 + np.array([-0.5, 0.5]) / math.sqrt(3.0)
#: ((u, v) (1, G) each, weights (G,)) of the Gauss rules in lattice parameters: 2 x 2 on the
#: unit square (weights x Jacobian), Dunavant's degree-4 rule on triangles (weights x area:
#: the triangles' Jacobian is their area)
_GAUSS_QUAD = (
    (np.repeat(_G2, 2)[None, :], np.tile(_G2, 2)[None, :]),
    np.full(4, 0.25),
)
_DA, _DB = 0.445948490915965, 0.091576213509771
_GAUSS_TRI = (
    (
        np.array([[_DA, 1 - 2 * _DA, _DA, _DB, 1 - 2 * _DB, _DB]]),
        np.array([[_DA, _DA, 1 - 2 * _DA, _DB, _DB, 1 - 2 * _DB]]),
    ),
    np.array([0.223381589678011] * 3 + [0.109951743655322] * 3),
)


def _cross2(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]


class _Shooter:
    """Geometry of one patch as a shooter: kernel terms, inside test, inverse parametrisation,
    area Jacobian.

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
        # dual basis of (e1, e2) in the plane: (y - origin) . a1 = u for parallelograms
        cn = float(np.cross(self.e1, self.e2) @ normal)
        cn = cn if abs(cn) > 1e-300 else 1e-300
        self.a1 = np.cross(self.e2, normal) / cn
        self.a2 = np.cross(normal, self.e1) / cn
        # Gram terms of the parametrisation, for kernels from per-receiver scalars
        self.basis = np.stack([self.e1, self.e2, self.e3])  # (3, 3)
        self.gram = self.basis @ self.basis.T
        self.bn = self.basis @ normal
        cr = np.stack([np.cross(self.e1, self.e2), np.cross(self.e1, self.e3), np.cross(self.e3, self.e2)])
        self.cgram = cr @ cr.T

    def kernel(self, u: np.ndarray, v: np.ndarray, d0: np.ndarray, nr: np.ndarray) -> np.ndarray:
        """(b, S) ``cos_r cos_s / (pi r^2)`` at points p(u, v) (u, v: (b or 1, S)) seen from
        receivers with normals nr (b, 3) at ``origin - d0`` (d0: (b, 3))."""
        g, bn = self.gram, self.bn
        d0n = np.einsum("bc,bc->b", d0, nr)[:, None]
        dd = np.einsum("bc,bc->b", d0, d0)[:, None]
        de = d0 @ self.basis.T  # (b, 3): d0 . e1, d0 . e2, d0 . e3
        en = nr @ self.basis.T  # (b, 3)
        h = (d0 @ self.normal)[:, None]
        dn = d0n + u * en[:, :1] + v * en[:, 1:2]  # d . nr, d = p - x
        ds = h + u * bn[0] + v * bn[1]  # d . n_s (< 0 in front)
        r2 = (
            dd
            + 2 * u * de[:, :1]
            + 2 * v * de[:, 1:2]
            + u * u * g[0, 0]
            + v * v * g[1, 1]
            + 2 * u * v * g[0, 1]
        )
        if not self.parallelogram:
            uv = u * v
            dn = dn + uv * en[:, 2:3]
            ds = ds + uv * bn[2]
            r2 = r2 + 2 * uv * de[:, 2:3] + uv * uv * g[2, 2] + 2 * uv * (u * g[0, 2] + v * g[1, 2])
        return np.maximum(dn, 0.0) * np.maximum(-ds, 0.0) / (np.pi * np.maximum(r2 * r2, 1e-300))

    def inside(self, pts: np.ndarray) -> np.ndarray:
        """(...) bool: points (..., 3) on the plane inside the convex polygon."""
        ok = np.ones(pts.shape[:-1], dtype=bool)
        for o, en in zip(self.edge_o, self.edge_n, strict=True):
            ok &= (pts - o) @ en <= self.tol * np.linalg.norm(en)
        return ok

    def inside_uv(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(...) bool: parallelogram / triangle parameters inside the patch."""
        t = 1e-9
        ok = (u >= -t) & (v >= -t)
        return ok & (u + v <= 1 + t) if not self.is_quad else ok & (u <= 1 + t) & (v <= 1 + t)

    def clip_uv(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, v = np.clip(u, 0.0, 1.0), np.clip(v, 0.0, 1.0)
        if not self.is_quad:
            tot = np.maximum(u + v, 1.0)
            u, v = u / tot, v / tot
        return u, v

    def foot_uv(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice parameters of the feet of points x (b, 3) on the patch plane (clipped)."""
        if self.parallelogram:
            rel = x - self.origin
            return self.clip_uv(rel @ self.a1, rel @ self.a2)
        foot = x - ((x - self.origin) @ self.normal)[:, None] * self.normal
        return self.uv(foot)

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
        return self.clip_uv(u, v)

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

    def target_uv(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(k, 3) :meth:`target` of the points at lattice parameters u, v (k,)."""
        k = 1.0 - self.shrink
        base = k * self.origin + self.eps * self.normal + self.shrink * self.centre
        out = base + np.outer(u, k * self.e1) + np.outer(v, k * self.e2)
        return out if self.parallelogram else out + np.outer(u * v, k * self.e3)

    def jacobian(self, u: np.ndarray, v: np.ndarray) -> np.ndarray | float:
        """Area per unit (u, v) of the area samples at lattice parameters (u, v)."""
        if self.parallelogram:  # constant; the square -> triangle warp is area-uniform too
            return self.area
        c = self.cgram
        j2 = (
            c[0, 0]
            + u * u * c[1, 1]
            + v * v * c[2, 2]
            + 2 * u * c[0, 1]
            + 2 * v * c[0, 2]
            + 2 * u * v * c[1, 2]
        )
        return np.maximum(np.sqrt(np.maximum(j2, 0.0)), 1e-300)


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


def _coarse_keys(is_quad: np.ndarray, level: int, n: int) -> np.ndarray:
    """(Vc,) sorted keys of every patch's lattice grid at ``level`` (triangles: i + j <= n)."""
    k, s = 1 << level, n >> level
    a, b = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    a, b = a.ravel(), b.ravel()
    p = np.arange(len(is_quad))
    keys = qt.make_key(p[:, None], a[None, :] * s, b[None, :] * s, n)
    tri = a + b <= k
    return np.sort(np.concatenate([keys[is_quad].ravel(), keys[~is_quad][:, tri].ravel()]))


def _coarse_weights(keys: np.ndarray, coarse: np.ndarray, is_quad: np.ndarray, level: int, n: int):
    """(V, Vc) sparse CSR: values at ``keys`` interpolated (bilinear / barycentric) in the
    level-``level`` cells of their patches from values at the grid keys ``coarse``."""
    p, i, j = qt.decode_key(keys, n)
    k, s = 1 << level, n >> level
    a, b = np.minimum(i // s, k - 1), np.minimum(j // s, k - 1)
    fx, fy = (i - a * s) / s, (j - b * s) / s
    quad = is_quad[p]
    lower = fx + fy <= 1.0
    ci = np.stack([a, a + 1, a + 1, a], axis=1)
    cj = np.stack([b, b, b + 1, b + 1], axis=1)
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), fx * fy, (1 - fx) * fy], axis=1)
    tl, tu = ~quad & lower, ~quad & ~lower
    ci[tl], cj[tl] = np.stack([a, a + 1, a, a], 1)[tl], np.stack([b, b, b + 1, b + 1], 1)[tl]
    w[tl] = np.stack([1 - fx - fy, fx, fy, 0 * fx], 1)[tl]
    ci[tu], cj[tu] = np.stack([a + 1, a, a + 1, a + 1], 1)[tu], np.stack([b + 1, b + 1, b, b], 1)[tu]
    w[tu] = np.stack([fx + fy - 1, 1 - fx, 1 - fy, 0 * fx], 1)[tu]
    cols = qt.lookup(coarse, qt.make_key(p[:, None], ci * s, cj * s, n))
    ok = w > 0
    rows = np.repeat(np.arange(len(keys)), 4).reshape(-1, 4)
    return sparse.csr_matrix((w[ok], (rows[ok], cols[ok])), shape=(len(keys), len(coarse)))


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
    """Split elements until nothing deviates by more than the tolerance (see the module docstring).

    cache : reflected radiance (n, 3) at vertex keys, extended with ``evaluate(new_keys)``.
    Returns (forest, passes, cancelled); on cancel the last forest whose vertices are all
    evaluated (or the given one) is returned.
    """
    opts, D = ctx.opts, ctx.opts.max_depth
    emission_y = _lum(ctx.emission)
    good, passes = forest, 0
    try:
        while True:
            keys = qt.vertex_keys(forest)
            cand = forest.leaf_level < D
            if ctx.min_size > 0 and cand.any():
                cand[cand] = _leaf_longest_edge(forest.take(cand), ctx.corners) / 2 >= ctx.min_size
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


def _sources(ctx: _Context) -> dict:
    """JSON-able description of the light sources of a solve (for :func:`resolve`)."""
    return {
        "lights": [_sources_light(lt) for lt in ctx.lights],
        "emitters": [[int(p), *(float(x) for x in ctx.emission[p])] for p in ctx.emitters],
    }


def _sources_light(lt) -> dict:
    return {
        "kind": lt.kind,
        "position": [float(x) for x in lt.position],
        "direction": [float(x) for x in lt.direction],
        "radiant_intensity": [float(x) for x in lt.radiant_intensity],
        "inner_cone": float(lt.inner_cone),
        "outer_cone": float(lt.outer_cone),
    }


def _light_from(d: dict):
    """A light-like object (what :meth:`_Context.light_irradiance` reads) from :func:`_sources`."""
    return SimpleNamespace(
        kind=d["kind"],
        position=np.asarray(d["position"], dtype=np.float64),
        direction=np.asarray(d["direction"], dtype=np.float64),
        radiant_intensity=np.asarray(d["radiant_intensity"], dtype=np.float64),
        inner_cone=float(d["inner_cone"]),
        outer_cone=float(d["outer_cone"]),
    )


class _Run:
    """The state of one solve: the mesh, per-vertex reflected and unshot radiance, stats."""

    def __init__(self, scene, opts: SolveOptions, progress, vis: Visibility, t_start: float):
        self.scene, self.opts, self.vis, self.t_start = scene, opts, vis, t_start
        self.progress = progress
        self.ctx = ctx = _Context(scene, opts, vis)
        self.P = len(ctx.area)
        self.m_side = _side(opts.samples)
        self.state = {"cancelled": False, "last": 0.0, "fraction": 0.0, "message": ""}
        self.stats: dict = {
            "interpolation_bias": 0.0,
            "interpolation_bias_vertices": 0,
            "interpolation_bias_total": 0.0,
            "interpolation_bias_total_vertices": 0,
            "mesh_passes": 0,
            "refine_passes": 0,
        }
        self.timings = {"meshing_s": 0.0, "shooting_s": 0.0, "refining_s": 0.0}
        self.shots = 0
        self.shot_index = np.ones(self.P, dtype=np.int64)  # jitter index per patch; 0 was the direct pass
        self.shot_power = np.zeros(self.P)  # luminance power each patch has shot so far
        self.shot_log: list[tuple[np.ndarray, np.ndarray]] = []  # (shot, received-and-reflected) power
        self.power0 = ctx.emitted_power()
        self.mesh: dict = {}
        self.coarse: list[dict] | None = None  # coarse receiver grids, with what they received
        self.levels: dict[int, np.ndarray] = {}  # per shooter: receiver level of each patch (-1: vertices)
        self.reflected = np.zeros((0, 3))
        self.unshot = np.zeros((0, 3))

    # -- progress -----------------------------------------------------------------
    def report(self, fraction: float, message: str) -> None:
        st = self.state
        st["fraction"], st["message"] = fraction, message
        if self.progress is not None and self.progress(float(min(max(fraction, 0.0), 1.0)), message) is False:
            st["cancelled"] = True
            raise _Cancel

    def check(self) -> None:  # cheap poll inside long loops, at most 20 times a second
        now = time.perf_counter()
        if self.progress is not None and now - self.state["last"] > 0.05:
            self.state["last"] = now
            self.report(self.state["fraction"], self.state["message"])

    # -- the mesh -----------------------------------------------------------------
    def set_mesh(self, forest: qt.Forest, keys: np.ndarray) -> None:
        ctx, mesh = self.ctx, self.mesh
        mesh["forest"], mesh["keys"] = forest, keys
        mesh["M"] = _averaging_matrix(forest, keys, ctx.corners, ctx.area)
        mesh["lattice"] = _Lattice(forest, keys)
        mesh["start"] = np.searchsorted(keys, qt.make_key(np.arange(self.P + 1), 0, 0, ctx.n))
        mesh["geo"] = ctx.geometry(keys)
        mesh["geo"].cache = {}
        mesh["rho"] = ctx.albedo[qt.decode_key(keys, ctx.n)[0]]
        mesh["nverts"] = np.diff(mesh["start"])
        if self.coarse is None:  # the coarse receiver grids do not depend on the mesh
            self.coarse = []
            for level in range(min(len(COARSE_EPS), ctx.opts.max_depth)):
                ck = _coarse_keys(ctx.is_quad, level, ctx.n)
                cgeo = ctx.geometry(ck)
                cgeo.cache = {}
                self.coarse.append(
                    {
                        "keys": ck,
                        "geo": cgeo,
                        "npts": np.diff(cgeo.start),
                        "rho": ctx.albedo[cgeo.patch],
                        "acc": np.zeros((len(ck), 3)),
                    }
                )
        mesh["coarse_w"] = [
            _coarse_weights(keys, c["keys"], ctx.is_quad, lv, ctx.n) for lv, c in enumerate(self.coarse)
        ]

    @property
    def forest(self) -> qt.Forest:
        return self.mesh["forest"]

    @property
    def keys(self) -> np.ndarray:
        return self.mesh["keys"]

    def mesh_by_direct_light(self) -> None:
        """Stage A."""
        ctx = self.ctx
        t0 = time.perf_counter()
        roots = qt.roots(ctx.is_quad, self.opts.max_depth)
        self.direct_cache = _Cache()
        forest, passes, _ = _refine(
            ctx,
            roots,
            self.direct_cache,
            lambda k: ctx.direct(k, self.check),
            self.report,
            "meshing",
            (0.0, 0.2),
        )
        keys = qt.vertex_keys(forest)
        bias, bias_n = _interpolation_bias(keys, qt.vertex_keys(roots), self.direct_cache, ctx)
        self.stats.update(
            mesh_passes=int(passes), interpolation_bias=bias, interpolation_bias_vertices=bias_n
        )
        self.set_mesh(forest, keys)
        self.reflected = self.direct_cache.get(keys)  # 0 where a cancel left a vertex unevaluated
        self.unshot = self.reflected.copy()
        self.timings["meshing_s"] = time.perf_counter() - t0

    def take_mesh(self, sol: Solution) -> None:
        """The leaves and vertices of ``sol``, unchanged."""
        forest = qt.Forest(
            sol.max_depth,
            np.asarray(sol.patch_is_quad, dtype=bool),
            np.asarray(sol.leaf_patch, dtype=np.int32),
            np.asarray(sol.leaf_level, dtype=np.int8),
            np.asarray(sol.leaf_i, dtype=np.int32),
            np.asarray(sol.leaf_j, dtype=np.int32),
            np.asarray(sol.leaf_flip, dtype=bool),
        )
        self.set_mesh(forest, np.asarray(sol.vert_key, dtype=np.int64))
        self.reflected = np.zeros((len(self.keys), 3))
        self.unshot = np.zeros((len(self.keys), 3))

    def direct_on_mesh(self) -> None:
        """Direct light at every vertex of the given mesh (no subdivision)."""
        t0 = time.perf_counter()
        self.report(0.0, f"direct light on the given mesh: {len(self.keys)} vertices")
        try:
            self.reflected = self.ctx.direct(self.keys, self.check, self.mesh["geo"])
        except _Cancel:
            self.reflected = np.zeros((len(self.keys), 3))
        self.unshot = self.reflected.copy()
        self.timings["meshing_s"] = time.perf_counter() - t0

    # -- shooting -----------------------------------------------------------------
    def patch_power(self, unshot: np.ndarray) -> np.ndarray:
        """(P,) luminance power of each patch's unshot field (by magnitude: it may be signed)."""
        return np.pi * _lum(self.mesh["M"] @ np.abs(unshot)) * self.ctx.area

    def shoot(self, span, target: float) -> None:
        """Shoot until the unshot power is below ``target`` or max_shots."""
        ctx, mesh, opts = self.ctx, self.mesh, self.opts
        if self.power0 <= 0 or len(self.keys) == 0:
            return
        t0 = time.perf_counter()
        u_start = self.u_start
        span_log = math.log(u_start / target) if u_start > target > 0 else 1.0  # progress on a log scale
        try:
            while self.shots < opts.max_shots:
                power = self.patch_power(self.unshot)
                total = float(power.sum())
                if total <= target:
                    break
                done = min(1.0, max(0.0, math.log(u_start / max(total, 1e-300)) / span_log))
                self.state["fraction"] = span[0] + (span[1] - span[0]) * done
                self.state["message"] = (
                    f"shooting: {self.shots} shots, unshot {total / self.power0:.3g} of emitted"
                )
                self.check()
                s = int(np.argmax(power))
                a, b = mesh["start"][s], mesh["start"][s + 1]
                field = mesh["lattice"].grid(s, self.unshot)
                field_mean = np.ravel(mesh["M"][s] @ self.unshot)
                # fewer samples for faint shots: their noise matters less (sqrt keeps power / m flat-ish)
                m_hi = SHOT_SAMPLE_FACTOR * self.m_side
                share = float(power[s]) / (SHOT_FULL_SHARE * self.power0)
                m = max(1, min(m_hi, round(m_hi * math.sqrt(share))))
                dv = self.shot_gather(s, m, field, field_mean)
                self.shot_index[s] += 1
                self.shot_power[s] += float(power[s])
                self.shots += 1
                self.unshot[a:b] = 0.0
                self.reflected += dv
                self.unshot += dv
                received = np.pi * (ctx.area[:, None] * (mesh["M"] @ dv)).sum(axis=0)
                self.shot_log.append((np.pi * ctx.area[s] * field_mean, received))
        finally:
            self.timings["shooting_s"] += time.perf_counter() - t0

    def receiver_levels(self, s: int, field_mean: np.ndarray) -> np.ndarray:
        """(P,) int8 receiver level of each patch for the shots of s: -1 at every vertex, k on
        the coarse grid of level k (``COARSE_EPS``). Decided at the first shot of s, from the
        largest form factor of a patch's corners to s, the shot's radiance and the patch's
        radiance then, and kept for its later (fainter) shots, so that every shot of s reaches a
        patch at the same level (what :meth:`refine_total` relies on)."""
        if s in self.levels:
            return self.levels[s]
        ctx, mesh = self.ctx, self.mesh
        lvl = np.full(self.P, -1, dtype=np.int8)
        if self.coarse:
            cgeo = self.coarse[0]["geo"]  # the patches' corners
            idx, f = ctx.form_factors(s, cgeo)
            fmax = np.zeros(self.P)
            np.maximum.at(fmax, cgeo.patch[idx], f)
            y = mesh["M"] @ _lum(self.reflected) + _lum(ctx.emission)
            floor = ABS_FLOOR * float((y * ctx.area).sum() / max(ctx.area.sum(), 1e-300))
            rel = fmax * float(_lum(np.abs(field_mean))) * _lum(ctx.albedo) / (y + max(floor, 1e-30))
            dist = np.linalg.norm(ctx.centre - ctx.centre[s], axis=1) - ctx.radius[s]
            size = ctx.radius / np.maximum(dist, 1e-300)
            size[dist <= 0] = np.inf
            for level in range(len(self.coarse) - 1, -1, -1):  # the coarsest that is fine enough
                sel = (rel < COARSE_EPS[level]) & (size < COARSE_SIZE[level])
                sel &= mesh["nverts"] > self.coarse[level]["npts"]
                lvl[sel] = level
        self.levels[s] = lvl
        return lvl

    def shot_gather(self, s: int, m: int, field: np.ndarray, field_mean: np.ndarray) -> np.ndarray:
        """(V, 3) reflected radiance one shot from s adds at every vertex: gathered at the
        vertices of the patches it lights noticeably, interpolated from coarse grids on the
        others (whose gathered values are kept, per grid point, in the grids' ``acc``)."""
        ctx, mesh = self.ctx, self.mesh
        shot = int(self.shot_index[s])
        lvl = self.receiver_levels(s, field_mean)
        g = ctx.gather(
            s, mesh["geo"], m, shot, field, field_mean, correlated=False, cull=True, patches=lvl < 0
        )
        dv = mesh["rho"] * g
        for level, (c, w) in enumerate(zip(self.coarse or [], mesh["coarse_w"], strict=True)):
            sel = lvl == level
            if sel.any():
                gc = c["rho"] * ctx.gather(
                    s, c["geo"], m, shot, field, field_mean, correlated=False, cull=True, patches=sel
                )
                c["acc"] += gc
                dv += w @ gc
        return dv

    def refine_total(self, label: str, span) -> None:
        """Stage C: refine on the total radiance. New vertices get their direct light and a
        gather of everything each patch has shot so far (exact: shots are linear, so one
        gather of their sum equals replaying them all), never an interpolated value. Their
        unshot radiance is what they received minus what their patch already shot from
        there, so energy the coarser mesh could not hold is shot again, not lost."""
        ctx, mesh = self.ctx, self.mesh
        t0 = time.perf_counter()
        keys = self.keys
        shot_field = self.reflected - self.unshot
        lattice_b = mesh["lattice"]
        sources = np.flatnonzero(self.shot_index > 1)
        grids = {int(p): lattice_b.grid(int(p), shot_field) for p in sources}
        means = mesh["M"] @ shot_field
        total_cache = _Cache(keys, self.reflected.copy())
        # samples per source by the share of the power it has shot (as the shots themselves)
        ref = max(SHOT_FULL_SHARE * self.power0, 1e-300)
        m_src = {
            int(p): max(1, min(self.m_side, round(self.m_side * math.sqrt(self.shot_power[p] / ref))))
            for p in sources
        }
        n_pass = self.stats["refine_passes"]

        def evaluate_total(new: np.ndarray) -> np.ndarray:
            out = self.direct_cache.get(new)
            missing = self.direct_cache.find(new) < 0
            if missing.any():
                out[missing] = ctx.direct(new[missing], self.check)
            if len(new):
                geo = ctx.geometry(new)
                rho = ctx.albedo[geo.patch]
                on = np.zeros(self.P, dtype=bool)
                on[geo.patch] = True
                # what the coarse grids received, interpolated as at the old vertices
                for level, c in enumerate(self.coarse or []):
                    out += _coarse_weights(new, c["keys"], ctx.is_quad, level, ctx.n) @ c["acc"]
                # and a gather of what each source shot at the vertices of these patches
                for p in sources:
                    p = int(p)
                    fine = self.levels[p] < 0 if p in self.levels else None
                    if fine is not None and not (fine & on).any():
                        continue
                    jitter = int(self.shot_index[p]) + 1_000_000 * (1 + n_pass)
                    out += rho * ctx.gather(
                        p, geo, m_src[p], jitter, grids[p], means[p], correlated=True, cull=True, patches=fine
                    )
                    self.check()
            return out

        old_keys = keys
        forest, passes, _ = _refine(ctx, self.forest, total_cache, evaluate_total, self.report, label, span)
        self.stats["refine_passes"] += passes
        keys = qt.vertex_keys(forest)
        self.timings["refining_s"] += time.perf_counter() - t0
        if len(keys) == len(old_keys):
            return
        b, bn = _interpolation_bias(keys, old_keys, total_cache, ctx)
        n_old = self.stats["interpolation_bias_total_vertices"]
        if bn:  # vertex-weighted mean over the refinement stages
            self.stats["interpolation_bias_total"] = (
                self.stats["interpolation_bias_total"] * n_old + b * bn
            ) / (n_old + bn)
        self.stats["interpolation_bias_total_vertices"] = n_old + bn
        old_idx = qt.lookup(old_keys, keys)
        new_unshot = np.zeros((len(keys), 3))
        new_unshot[old_idx >= 0] = self.unshot[old_idx[old_idx >= 0]]
        self.reflected = total_cache.get(keys)
        p_new, i_new, j_new = qt.decode_key(keys, ctx.n)
        for p in np.unique(p_new[old_idx < 0]):
            sel = np.flatnonzero((old_idx < 0) & (p_new == p))
            shot_here = grids[int(p)][i_new[sel], j_new[sel]] if int(p) in grids else 0.0
            new_unshot[sel] = np.maximum(self.reflected[sel] - shot_here, 0.0)
        self.unshot = new_unshot
        self.set_mesh(forest, keys)

    def run_plan(self, plan) -> None:
        self.u_start = max(float(self.patch_power(self.unshot).sum()), 1e-300)
        try:
            for kind, arg, span in plan:
                if self.state["cancelled"]:
                    break
                if kind == "shoot":
                    self.shoot(span, arg)
                elif self.opts.refine_indirect and self.shots:
                    self.refine_total(arg, span)
        except _Cancel:
            pass

    # -- the result ---------------------------------------------------------------
    def closure(self) -> np.ndarray:
        """(V,) fraction of each vertex's cosine-weighted hemisphere that meets the scene (1 in
        a closed room, less near an opening), from ``AMBIENT_RAYS`` directions in one pattern for
        all vertices (so it varies smoothly)."""
        ctx, geo = self.ctx, self.mesh["geo"]
        m = _side(AMBIENT_RAYS)
        pat = ctx.pattern(self.P, m, 0)  # (a patch index no shooter has)
        dx, dy = _concentric(pat[:, 0], pat[:, 1])
        dz = np.sqrt(np.maximum(1.0 - dx * dx - dy * dy, 0.0))
        out = np.zeros(len(geo.key))
        for a in range(0, len(geo.key), GATHER_BLOCK):
            sl = slice(a, a + GATHER_BLOCK)
            t1, t2 = ctx.tangent[geo.patch[sl], 0], ctx.tangent[geo.patch[sl], 1]
            w = (
                dx[None, :, None] * t1[:, None]
                + dy[None, :, None] * t2[:, None]
                + dz[None, :, None] * geo.normal[sl][:, None]
            )
            o = np.repeat(geo.origin[sl], len(pat), axis=0)
            hit = self.vis.occluded(o, w.reshape(-1, 3), np.full(len(o), 4.0 * ctx.scale))
            out[sl] = hit.reshape(-1, len(pat)).mean(axis=1)
            self.check()
        return out

    def ambient(self, fallback_reflectance=None) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) reflected radiance standing for the unshot light's later bounces: a uniform
        incoming radiance ``E`` times each vertex's albedo and :meth:`closure`; and the (3,)
        reflected fraction r it was derived from (see the module docstring)."""
        ctx, mesh = self.ctx, self.mesh
        log = self.shot_log[len(self.shot_log) // 2 :]
        if log:
            sp = np.sum([np.abs(a) for a, _ in log], axis=0)
            rp = np.sum([np.abs(b) for _, b in log], axis=0)
            r = np.where(sp > 0, rp / np.where(sp > 0, sp, 1.0), 0.0)
        elif fallback_reflectance is not None and len(fallback_reflectance) == 3:
            r = np.asarray(fallback_reflectance, dtype=np.float64)
        else:
            return np.zeros((len(self.keys), 3)), np.zeros(3)
        r = np.clip(r, 0.0, MAX_REFLECTANCE)
        phi_u = np.pi * (ctx.area[:, None] * (mesh["M"] @ self.unshot)).sum(axis=0)
        if not np.any(phi_u):
            return np.zeros((len(self.keys), 3)), r
        weight = mesh["rho"] * self.closure()[:, None]  # reflected per unit of incoming E
        denom = np.pi * (ctx.area[:, None] * (mesh["M"] @ weight)).sum(axis=0)
        e = np.where(denom > 0, phi_u * r / (1.0 - r) / np.where(denom > 0, denom, 1.0), 0.0)
        return weight * e, r

    def finish(self, mode="solve", fallback_reflectance=None, extra=None) -> Solution:
        ctx, opts = self.ctx, self.opts
        forest, keys = self.forest, self.keys
        unshot_power = self.patch_power(self.unshot)
        vpatch = qt.decode_key(keys, ctx.n)[0]
        reflected = self.reflected
        amb, refl_frac = np.zeros((len(keys), 3)), np.zeros(3)
        if opts.ambient and opts.max_shots > 0 and len(keys) and not self.state["cancelled"]:
            try:
                amb, refl_frac = self.ambient(fallback_reflectance)
            except _Cancel:
                amb = np.zeros((len(keys), 3))
            reflected = reflected + amb
        radiance = ctx.emission[vpatch] + reflected
        if not np.isfinite(radiance).all():
            raise FloatingPointError("radiosity produced non-finite radiance (a solver bug)")
        radiance = np.maximum(radiance, 0.0)
        unshot_fraction = float(unshot_power.sum() / self.power0) if self.power0 > 0 else 0.0
        if not self.state["cancelled"]:
            try:
                self.report(1.0, f"done: {self.shots} shots, {len(keys)} vertices")
            except _Cancel:
                pass
        elapsed = time.perf_counter() - self.t_start
        vis = self.vis
        sol = Solution.from_forest(
            forest,
            ctx.corners,
            self.scene.patch_material,
            ctx.albedo,
            keys,
            radiance,
            options=opts.to_dict(),
            model_path=str(getattr(self.scene, "path", "") or ""),
        )
        area_tot = float(ctx.area.sum())
        sol.stats = {
            "elements": int(forest.n_leaves),
            "vertices": int(len(keys)),
            "triangles": int(len(sol.tri_vertices)),
            "shots": int(self.shots),
            "rays": int(vis.rays),
            "rays_per_s": float(vis.rays / vis.seconds) if vis.seconds > 0 else 0.0,
            "time_s": float(elapsed),
            **{k: float(v) for k, v in self.timings.items()},
            "unshot_fraction": unshot_fraction,
            **self.stats,
            "max_depth_reached": int(forest.leaf_level.max()) if forest.n_leaves else 0,
            "min_element_size": float(ctx.min_size),
            "emitted_power": float(self.power0),
            "ambient_luminance_fraction": float(
                np.pi * (ctx.area * _lum(self.mesh["M"] @ amb)).sum() / self.power0
            )
            if self.power0 > 0 and area_tot > 0
            else 0.0,
            "reflectance": [float(x) for x in refl_frac],
            "culled_pairs": float(ctx.culled_fraction()),
            "mode": mode,
            "sources": _sources(ctx),
            "cancelled": bool(self.state["cancelled"]),
            "options": opts.to_dict(),
            **(extra or {}),
        }
        return sol


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


# -- the solver ------------------------------------------------------------------
def _options(options) -> SolveOptions:
    opts = SolveOptions() if options is None else options
    if not isinstance(opts, SolveOptions):
        raise OptionError(f"solve options must be SolveOptions, not {type(opts).__name__}")
    return opts.validate()


def _check_scene(scene) -> None:
    """Raise OptionError for a scene the solver cannot solve (an in-memory scene is not checked
    by a loader): non-finite geometry or light, albedo outside [0, 1], negative emission."""
    c = scene.corner_positions
    if not np.isfinite(c).all():
        raise OptionError("scene: non-finite vertex coordinates")
    alb, em = scene.patch_albedo, scene.patch_emission
    if not (np.isfinite(alb).all() and np.isfinite(em).all()):
        raise OptionError("scene: non-finite albedo or emission")
    if len(alb) and (alb.min() < 0 or alb.max() > 1):
        raise OptionError(f"scene: albedo must be in [0, 1] (found {alb.min():g} .. {alb.max():g})")
    if len(em) and em.min() < 0:
        raise OptionError("scene: negative emission")
    for lt in scene.lights:
        vals = [lt.position, lt.direction, lt.radiant_intensity, [lt.inner_cone, lt.outer_cone]]
        if not all(np.isfinite(np.asarray(v, dtype=np.float64)).all() for v in vals):
            raise OptionError(f"scene: light {getattr(lt, 'name', '')!r} has non-finite values")


def _check_mesh(sol: Solution, scene, what: str) -> None:
    """Raise OptionError unless ``sol`` was solved on the patches of ``scene``."""
    if not isinstance(sol, Solution):
        raise OptionError(f"{what} must be a Solution, not {type(sol).__name__}")
    corners = scene.corner_positions
    same = (
        sol.patch_corners.shape == corners.shape
        and np.array_equal(np.asarray(sol.patch_is_quad, dtype=bool), scene.patch_is_quad)
        and np.allclose(
            sol.patch_corners, corners, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(corners).max(initial=0)))
        )
    )
    if not same:
        raise OptionError(f"{what}: the solution was solved on other patches than this scene's")


def solve(
    scene,
    options: SolveOptions | None = None,
    progress: Progress | None = None,
    *,
    mesh: Solution | None = None,
) -> Solution:
    """Solve diffuse global illumination of ``scene``; see the module docstring.

    progress : ``progress(fraction, message) -> bool``; returning False cancels. A
      cancelled solve returns a consistent partial :class:`Solution` (the mesh
      settled so far, its direct light, the shots done) with
      ``stats['cancelled'] = True``.
    mesh : a :class:`Solution` of the same patches, or None. When given, its leaves and
      vertices are kept exactly (no subdivision, the same ``vert_key``; ``max_depth`` is
      taken from it) and only the radiance is solved afresh, so solutions of different
      lighting share one tree and can be blended per vertex or texel.
    Raises :class:`iat.errors.OptionError` for invalid options or a mesh of other patches.
    """
    opts = _options(options)
    _check_scene(scene)
    if mesh is not None:
        _check_mesh(mesh, scene, "solve mesh")
        opts = replace(opts, max_depth=int(mesh.max_depth)).validate()
    t_start = time.perf_counter()
    with Visibility(scene.corner_positions, scene.patch_is_quad) as vis:
        run = _Run(scene, opts, progress, vis, t_start)
        target = opts.convergence * run.power0
        if mesh is None:
            run.mesh_by_direct_light()
            first_target = max(target, math.sqrt(opts.convergence) * run.power0)
            plan = [("shoot", first_target, (0.2, 0.6)), ("refine", "refining", (0.6, 0.75))]
            plan += [("shoot", target, (0.75, 1.0))]
        else:
            run.take_mesh(mesh)
            if not run.state["cancelled"]:
                run.direct_on_mesh()
            plan = [("shoot", target, (0.2, 1.0))]
        if not run.state["cancelled"]:
            run.run_plan(plan)
        return run.finish(mode="solve" if mesh is None else "mesh")


def resolve(
    previous: Solution, scene, options: SolveOptions | None = None, progress: Progress | None = None
) -> Solution:
    """Continue from ``previous`` after the lights or the emission of ``scene`` changed.

    The geometry and the albedos must be those ``previous`` was solved with (else
    :class:`iat.errors.OptionError`); the lights (point / spot) and the emission may differ.
    Radiosity is linear in the sources, so only the difference is solved, on the leaves and
    vertices of ``previous`` (the same ``vert_key``): the direct light of the sources that
    changed -- new minus old, at every vertex, exactly as a fresh solve computes it (lights
    present in both cancel and are not traced again) -- is added to the previous reflected
    radiance, and that difference field, which may be negative, is shot progressively (by
    the magnitude of its power) until its unshot power is below ``convergence`` times the
    smaller of the changed sources' power and the new emitted power: the difference is
    converged as a scene of its own, since its light sits where the sources changed and
    the uniform ambient term would spread it badly. The result matches
    ``solve(scene, mesh=previous)`` within the solver's noise and convergence, in a fraction
    of its time when a part of the light changed (``stats['mode'] == 'resolve'``).

    When the changed power exceeds the new emitted power (most of the light went away), the
    previous solution's noise would dominate the result: the scene is then solved afresh on
    the mesh (``stats['mode'] == 'mesh'``), as it is for a solution that lacks the record of
    its sources (``stats['sources']``).

    options : None takes ``previous``'s options (``max_depth`` always comes from it).
    """
    _check_scene(scene)
    _check_mesh(previous, scene, "resolve")
    opts = SolveOptions.from_dict(previous.options) if options is None else options
    opts = replace(_options(opts), max_depth=int(previous.max_depth)).validate()
    if not np.allclose(previous.patch_albedo, scene.patch_albedo, rtol=1e-6, atol=1e-9):
        raise OptionError("resolve: the albedos changed since the previous solution; solve again")
    src = previous.stats.get("sources") if isinstance(previous.stats, dict) else None
    if not src:
        return solve(scene, opts, progress, mesh=previous)
    # what changed: emission per patch, lights added or removed (equal ones cancel)
    emission = scene.patch_emission
    area = scene.patch_area
    old_emission = np.zeros_like(emission)
    for row in src.get("emitters", []):
        old_emission[int(row[0])] = row[1:4]
    diff = emission - old_emission
    changed_patches = np.flatnonzero((diff != 0).any(axis=1))
    new_lights = [lt for lt in scene.lights if lt.kind in ("point", "spot")]
    removed = [_light_from(d) for d in src.get("lights", [])]
    added = []
    for lt in new_lights:  # equal lights cancel; a light whose intensity changed adds the difference
        sig = _light_signature(lt)
        sigs = [_light_signature(o) for o in removed]  # (lights hold arrays: match by index)
        i = next((k for k, o in enumerate(sigs) if o == sig), None)
        if i is None:
            i = next((k for k, o in enumerate(sigs) if o[:-1] == sig[:-1]), None)
            if i is None:
                added.append(lt)
                continue
            d = _light_from(_sources_light(lt))
            d.radiant_intensity = d.radiant_intensity - removed[i].radiant_intensity
            added.append(d)
        del removed[i]
    delta_power = float(np.pi * (np.abs(diff @ LUMINANCE) * area).sum())
    delta_power += sum(_light_power(lt) for lt in added + removed)
    new_power = float(np.pi * (emission @ LUMINANCE * area).sum())
    new_power += sum(_light_power(lt) for lt in scene.lights if lt.kind in ("point", "spot"))
    if delta_power > RESOLVE_MAX_CHANGE * new_power:
        return solve(scene, opts, progress, mesh=previous)
    t_start = time.perf_counter()
    with Visibility(scene.corner_positions, scene.patch_is_quad) as vis:
        run = _Run(scene, opts, progress, vis, t_start)
        ctx = run.ctx
        run.take_mesh(previous)
        keys, geo = run.keys, run.mesh["geo"]
        old_reflected = np.asarray(previous.vert_radiance, dtype=np.float64) - old_emission[geo.patch]
        t0 = time.perf_counter()
        try:
            n_changed = len(changed_patches) + len(added) + len(removed)
            run.report(0.0, f"resolving: direct light of {n_changed} changed sources")
            incoming = np.zeros((len(keys), 3))
            for e in changed_patches:
                incoming += ctx.emitter_gather(int(e), geo)[:, None] * diff[e]
                run.check()
            for sign, group in ((1.0, added), (-1.0, removed)):
                for lt in group:
                    incoming += sign * ctx.light_irradiance(lt, geo) / np.pi
                    run.check()
            delta = ctx.albedo[geo.patch] * incoming
        except _Cancel:
            delta = np.zeros((len(keys), 3))
        run.timings["meshing_s"] = time.perf_counter() - t0
        run.reflected = old_reflected + delta
        run.unshot = delta.copy()
        if not run.state["cancelled"]:
            run.run_plan([("shoot", opts.convergence * min(run.power0, delta_power), (0.2, 1.0))])
        return run.finish(
            mode="resolve",
            fallback_reflectance=previous.stats.get("reflectance"),
            extra={
                "changed_sources": int(len(changed_patches) + len(added) + len(removed)),
                "changed_power_fraction": float(delta_power / new_power) if new_power > 0 else 0.0,
            },
        )


def _light_signature(lt) -> tuple:
    """Kind, position, direction, cones, and last the intensity of a light (for matching)."""
    return (
        lt.kind,
        tuple(np.round(np.asarray(lt.position, dtype=np.float64), 12)),
        tuple(np.round(np.asarray(lt.direction, dtype=np.float64), 12)),
        round(float(lt.inner_cone), 12),
        round(float(lt.outer_cone), 12),
        tuple(np.round(np.asarray(lt.radiant_intensity, dtype=np.float64), 12)),
    )


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
