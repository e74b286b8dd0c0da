"""Direct light (:class:`DirectLight`): what emitting patches, point and spot lights, the sun and
the sky put at the vertices, with ray-traced visibility, the element-integrated correction of
point lights (:mod:`.pointlight`), and the scene's emitted power."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from iat.color import LUMINANCE_WEIGHTS
from iat.geometry import quadtree as qt
from iat.radiosity.gathers import Gathers
from iat.radiosity.options import (
    DIRECT_SAMPLE_FACTOR,
    GATHER_BLOCK,
    PENUMBRA_EDGE,
    SKY_NOISE,
    SKY_PASSES,
    SKY_SETTLED,
    SUN_SAMPLES,
    SolveOptions,
)
from iat.radiosity.patches import Patches, ReceiverGeometry
from iat.radiosity.pointlight import lumped_light
from iat.radiosity.sampling import (
    hash_uniform,
    luminance_of,
    pattern_side,
    rotated_disk,
)
from iat.radiosity.sky import SkyTable, sky_radiance
from iat.radiosity.sky_passes import SkyLevel, quarter_sums, settled_strata, sky_levels
from iat.radiosity.sky_traced import REFINED_ERROR, pack_levels, sky_directions, sky_estimate
from iat.radiosity.tasks import TaskPool
from iat.radiosity.traced import sun_escape
from iat.radiosity.visibility import Visibility


class DirectLight:
    """The light sources of a scene (``lights``: its point and spot lights, ``suns``: its
    directional lights that shine, ``sky``: its sky or None) and the direct light they put on
    receivers, gathered with :class:`~iat.radiosity.gathers.Gathers` for emitting patches."""

    def __init__(
        self, scene, patches: Patches, opts: SolveOptions, vis: Visibility, pool: TaskPool, gathers: Gathers
    ):
        self.patches, self.opts, self.vis, self.pool, self.gathers = patches, opts, vis, pool, gathers
        self.lights = [lt for lt in scene.lights if lt.kind in ("point", "spot")]
        self.suns = [lt for lt in scene.lights if lt.kind == "directional" and np.any(lt.radiant_intensity)]
        self.sky = getattr(scene, "sky", None)
        #: the sky as the gathers look it up (a Preetham sky in a table)
        self.sky_table = None if self.sky is None else SkyTable(self.sky)
        #: (SKY_PASSES, 3) per sky estimate: the vertices, the directions traced and those that took
        #: their stratum's value (:meth:`sky_irradiance`)
        self.sky_counts = np.zeros((SKY_PASSES, 3), dtype=np.int64)
        #: sorted keys of the vertices evaluated so far that lie in an emitting patch's penumbra
        #: (:meth:`direct`; :func:`iat.radiosity.meshing.split_test` refines their elements further)
        self.penumbra = np.zeros(0, dtype=np.int64)

    def light_kernel(self, light, geo: ReceiverGeometry) -> tuple[np.ndarray, np.ndarray]:
        """(n,) ``cos * att * vis / r^2`` at the vertices of ``geo`` for a point or spot light (the
        irradiance per unit intensity, with visibility), and (n,) ``max(cos, 0) / r^2`` (no cone, no
        visibility): what :func:`.pointlight.lumped_light` weighs an element's solid angle with."""
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
        if getattr(light, "ies", None) is not None:  # its IES distribution about its nadir (iat.io.ies)
            att = att * light.ies.relative(-u, light.direction)
        near = r > 1e-12 * self.patches.scale
        free = np.where((cos > 0) & near, cos / np.maximum(r * r, 1e-300), 0.0)
        ok = np.flatnonzero((cos > 0) & (att > 0) & near)
        k = np.zeros(len(r))
        if len(ok) == 0:
            return k, free
        do = light.position[None, :] - geo.origin[ok]
        ro = np.linalg.norm(do, axis=1)
        vis = self.vis.visible(
            geo.origin[ok],
            do / ro[:, None],
            np.maximum(ro - 0.5 * self.patches.eps_patch[geo.patch[ok]], 0.0),
        )
        k[ok] = cos[ok] * att[ok] / (r[ok] * r[ok]) * vis
        return k, free

    def light_irradiance(self, light, geo: ReceiverGeometry) -> np.ndarray:
        """(n, 3) irradiance from a point or spot light, with visibility (exact at each vertex)."""
        return self.light_kernel(light, geo)[0][:, None] * light.radiant_intensity[None, :]

    def light_correction(
        self, forest: qt.Forest, keys: np.ndarray, geo: ReceiverGeometry, lights=None, signs=None
    ) -> np.ndarray:
        """(V, 3) what to add to the reflected direct radiance of the vertices ``keys`` of
        ``forest`` to get the radiance their patches must *shoot* for the point / spot lights
        (``lights``, default all, each times its sign in ``signs``): ``rho / pi`` times the
        element-integrated irradiance (:func:`.pointlight.lumped_light`: each element receives
        ``I x`` its solid angle from the light x its visible fraction, finite even when the light
        touches it) minus the exact vertex irradiance (whose 1/d^2 peak next to a light, spread
        over whole elements, would re-emit far more power than the wall received: defect D3)."""
        lights = self.lights if lights is None else lights
        signs = [1.0] * len(lights) if signs is None else signs
        out = np.zeros((len(keys), 3))
        if not lights or forest.n_leaves == 0:
            return out
        corner_idx = qt.lookup(keys, qt.leaf_corner_keys(forest))
        leaf_world = qt.lattice_to_world(
            self.patches.corners,
            forest.patch_is_quad,
            np.repeat(forest.leaf_patch, 4),
            *(c.ravel() for c in np.moveaxis(qt.leaf_corner_lattice(forest), 2, 0)),
            forest.n,
        ).reshape(-1, 4, 3)
        la = qt.leaf_area(forest, self.patches.corners)
        for light, sign in zip(lights, signs, strict=True):
            k, free = self.light_kernel(light, geo)
            lumped = lumped_light(
                light.position,
                leaf_world,
                self.patches.normal[forest.leaf_patch],
                forest.leaf_is_quad,
                corner_idx,
                la,
                k,
                free,
                len(keys),
            )
            out += sign * (lumped - k)[:, None] * light.radiant_intensity[None, :]
        return self.patches.albedo[geo.patch] * out / np.pi

    def emitter_side(self, share: float) -> int:
        """Samples per side of the direct pass's gathers from an emitter with ``share`` of the emitted
        power: ``DIRECT_SAMPLE_FACTOR`` x the per-side samples times ``sqrt(share)`` (samples by
        power, as the shots'), at least the per-side samples."""
        side = pattern_side(self.opts.samples)
        return max(side, round(DIRECT_SAMPLE_FACTOR * side * math.sqrt(share)))

    def emitter_gather(self, e: int, geo: ReceiverGeometry, side: int) -> np.ndarray:
        """(n,) ``F * vis`` from emissive patch e, as the direct pass computes it (per-vertex
        rotated patterns, shot 0), ``side`` samples per side (:meth:`emitter_side`)."""
        return self.gathers.gather(int(e), geo, side)

    def direct(
        self,
        keys: np.ndarray,
        check: Callable[[], None],
        geo: ReceiverGeometry | None = None,
        noise: np.ndarray | None = None,
    ) -> np.ndarray:
        """(n, 3) reflected direct radiance (emission excluded) at vertex keys. ``noise`` (n,), if
        given, receives the standard error of its luminance (W/(m² sr)): the sky's estimate's (the
        other sources' are taken as exact), times the albedo's luminance over pi."""
        out = np.zeros((len(keys), 3))
        if len(keys) == 0:
            return out
        geo = self.patches.geometry(keys) if geo is None else geo
        incoming = np.zeros((len(keys), 3))  # radiance-weighted: rho * incoming = reflected
        seen, free = np.zeros(len(keys)), np.zeros(len(keys))  # luminance from the emitters, unoccluded
        for e in self.patches.emitters:
            side = self.emitter_side(self.patches.emitter_share[e])
            g, f = self.gathers.gather_unoccluded(int(e), geo, side)
            incoming += g[:, None] * self.patches.emission[e]
            y = abs(float(luminance_of(self.patches.emission[e])))
            seen += y * g
            free += y * f
            check()
        self.add_penumbra(keys, seen, free)
        for light in self.lights:
            incoming += self.light_irradiance(light, geo) / np.pi
            check()
        for sun in self.suns:
            incoming += self.sun_irradiance(sun, geo, check) / np.pi
        if self.sky is not None:
            err = np.zeros(len(keys))
            incoming += self.sky_irradiance(geo, check, np.pi * luminance_of(incoming), err) / np.pi
            if noise is not None:
                noise[:] = luminance_of(self.patches.albedo[geo.patch]) * err / np.pi
        elif noise is not None:
            noise[:] = 0.0
        return self.patches.albedo[geo.patch] * incoming

    def add_penumbra(self, keys: np.ndarray, seen: np.ndarray, free: np.ndarray) -> None:
        """Add to :attr:`penumbra` the vertex keys (n,) whose light from the emitting patches
        ``seen`` (n,) is between ``PENUMBRA_EDGE`` and 1 - ``PENUMBRA_EDGE`` of what they would get
        unoccluded, ``free`` (n,) (luminance)."""
        frac = seen / np.where(free > 0, free, 1.0)
        part = (free > 0) & (frac > PENUMBRA_EDGE) & (frac < 1.0 - PENUMBRA_EDGE)
        if part.any():
            self.penumbra = qt.sorted_unique(np.concatenate([self.penumbra, keys[part]]))

    def _escape(self, geo: ReceiverGeometry, idx: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(k, S) float: what of the rays from vertices ``idx`` (k,) along ``dirs`` (k, S, 3) leaves
        the scene (1 free, 0 blocked, a glass's transmittance through it)."""
        k, S = dirs.shape[:2]
        o = np.repeat(geo.origin32()[idx], S, axis=0)
        far = np.full(len(o), 4.0 * self.patches.scale, dtype=np.float32)
        return self.vis.visible(o, dirs.reshape(-1, 3), far).reshape(k, S)

    def sun_irradiance(self, sun, geo: ReceiverGeometry, check: Callable[[], None]) -> np.ndarray:
        """(n, 3) irradiance from a directional light (the sun): ``E cos`` times the fraction of
        its disc (``angular_diameter``) each vertex sees, from ``SUN_SAMPLES`` directions
        stratified on the disc and rotated per vertex (soft shadow edges, exact where it is
        fully seen or hidden)."""
        to_sun = -np.asarray(sun.direction, dtype=np.float64)
        to_sun /= max(float(np.linalg.norm(to_sun)), 1e-300)
        out = np.zeros((len(geo.key), 3))
        cos = geo.normal @ to_sun
        lit = np.flatnonzero(cos > 0)
        if len(lit) == 0:
            return out
        helper = np.array([1.0, 0.0, 0.0]) if abs(to_sun[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t1 = np.cross(to_sun, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(to_sun, t1)
        m = pattern_side(SUN_SAMPLES)
        pat = self.gathers.pattern(self.patches.n_patches, m, 1)
        half = math.tan(0.5 * max(float(sun.angular_diameter), 0.0))

        def block(idx: np.ndarray) -> np.ndarray:  # the fraction of the disc each vertex sees
            rot = hash_uniform(geo.key[idx], int(self.opts.seed) * 7919 + 17, 2)
            far = 4.0 * self.patches.scale
            free = sun_escape(self.vis, pat, rot, to_sun, half, t1, t2, geo.origin32()[idx], far)
            if free is not None:  # made and traced in one kernel (the same directions)
                return free.mean(axis=1)
            dx, dy = rotated_disk(pat, rot[:, :1], rot[:, 1:2])
            d = to_sun + half * (dx[..., None] * t1 + dy[..., None] * t2)
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            return self._escape(geo, idx, d).mean(axis=1)

        blocks = [lit[a : a + GATHER_BLOCK // 4] for a in range(0, len(lit), GATHER_BLOCK // 4)]
        for idx, frac in zip(blocks, self.pool.imap(block, blocks, check), strict=True):
            out[idx] = (cos[idx] * frac)[:, None] * sun.radiant_intensity[None, :]
        return out

    def sky_irradiance(
        self,
        geo: ReceiverGeometry,
        check: Callable[[], None],
        other: np.ndarray | None = None,
        noise: np.ndarray | None = None,
    ) -> np.ndarray:
        """(n, 3) irradiance from the sky through whatever of each vertex's hemisphere is open:
        ``pi`` times the mean sky radiance over cosine-distributed directions that leave the scene,
        ``opts.sky_samples`` of them (stratified, rotated per vertex). A vertex whose estimate's
        standard error (from its pattern's four interleaved quarters, luminance) exceeds
        ``SKY_NOISE`` of its direct light (this sky's, plus ``other`` (n,): the luminance irradiance
        of its other sources, W/m²) is estimated again with 4 x the directions (twice as many strata
        a side: its old directions and 3 new ones in each old stratum, traced where the light can
        change: :mod:`.sky_passes`), up to ``SKY_PASSES`` estimates: through a window most of the
        hemisphere is wall, and the refinement would split on that noise and multiply it. ``noise``
        (n,), if given, receives each estimate's standard error (luminance, W/m²: the quarters' of
        the last grid tested, times ``REFINED_ERROR`` for each estimate after it)."""
        n = len(geo.key)
        side = pattern_side(self.opts.sky_samples)
        pat = self.gathers.pattern(self.patches.n_patches, side, 2)
        rng = np.random.default_rng([int(self.opts.seed), self.patches.n_patches, 2, side, 1])
        levels = sky_levels(pat, side, SKY_PASSES, rng)
        packed = pack_levels(levels)
        other = np.zeros(n) if other is None else other
        size = max(1, GATHER_BLOCK * 16 // len(pat))
        blocks = [np.arange(a, min(a + size, n)) for a in range(0, n, size)]
        out = np.zeros((n, 3))

        def run(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            return self._sky_block(geo, idx, pat, side, levels, packed, other[idx])

        for idx, (e, c, err) in zip(blocks, self.pool.imap(run, blocks, check), strict=True):
            out[idx] = e
            self.sky_counts += c
            if noise is not None:
                noise[idx] = err
        return out

    def _sky_block(
        self, geo: ReceiverGeometry, idx: np.ndarray, pat, side: int, levels: list[SkyLevel], packed, other
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`sky_irradiance` at the vertices ``idx`` (k,) whose other sources give ``other``
        (k,): ((k, 3) irradiance, (SKY_PASSES, 3) int: per estimate the vertices, the rays traced
        and the directions that took their stratum's value, (k,) the standard error). In one kernel
        with the C API (:func:`.sky_traced.sky_estimate`, ``packed``: :func:`.sky_traced.pack_levels`
        of ``levels``), else here, in numpy and embreex, to the same bits."""
        k = len(idx)
        rot = hash_uniform(geo.key[idx], int(self.opts.seed) * 7919 + 29, 2)
        tangent = self.patches.tangent[geo.patch[idx]]
        frame = (tangent[:, 0], tangent[:, 1], geo.normal[idx])
        origin, far = geo.origin32()[idx], 4.0 * self.patches.scale
        dark = not np.any(self.sky.ground)  # below the horizon nothing comes: not traced
        light = self.sky_table.kernel_args()
        got = sky_estimate(self.vis, light, pat, side, packed, SKY_PASSES, rot, frame, origin, far, dark,
                           other, SKY_NOISE, SKY_SETTLED)  # fmt: skip
        if got is not None:
            return got
        counts = np.zeros((SKY_PASSES, 3), dtype=np.int64)
        w, free = self._sky_rays(pat, rot, frame, origin, far, dark, None, None)
        light = self.sky_table.light(w, free)  # (k, S, 3): what each direction brings, its stratum's
        total = np.einsum("ks,ksc->kc", free, light)
        counts[0] = k, free.size - (int(np.count_nonzero(w[..., 1] < 0)) if dark else 0), 0
        rows, out, count, std = np.arange(k), np.zeros((k, 3)), len(pat), np.zeros(k)
        for est in range(SKY_PASSES):
            out[rows] = e = np.pi * total[rows] / count
            if est + 1 == SKY_PASSES and est > 0:
                break
            q = np.pi * quarter_sums(free * luminance_of(light)) / (count / 4)  # the quarters' estimates
            std[rows] = err = np.sqrt(q.var(axis=1, ddof=1) / 4.0)
            keep = err > SKY_NOISE * np.maximum(luminance_of(e) + other[rows], 1e-300)
            if est + 1 == SKY_PASSES or not keep.any():
                break
            rows, free, light = rows[keep], free[keep], light[keep]
            std[rows] *= REFINED_ERROR
            lv = levels[est]
            settled = settled_strata(free, rot[rows], SKY_SETTLED)
            # a settled stratum's 3 new directions bring what its own direction brings
            total[rows] += 3.0 * np.einsum("ks,ksc->kc", settled * free, light)
            given = settled[:, lv.parent]
            vi, pj = np.nonzero(~given)
            sub = tuple(f[rows] for f in frame)
            wp, fp = self._sky_rays(lv.points, rot[rows], sub, origin[rows], far, dark, vi, pj)
            lp = self.sky_table.light(wp, fp)
            for c in range(3):
                total[rows, c] += np.bincount(vi, weights=fp * lp[:, c], minlength=len(rows))
            below = int(np.count_nonzero(wp[:, 1] < 0)) if dark else 0
            counts[est + 1] = len(rows), len(vi) - below, given.sum()
            count *= 4
            if est + 2 < SKY_PASSES:  # the finer grid's strata: the old directions and the new ones
                nf, nl = np.empty((len(rows), count)), np.empty((len(rows), count, 3))
                nf[:, lv.old_cell], nl[:, lv.old_cell] = free, light
                cf, cl = free[:, lv.parent], light[:, lv.parent]
                cf[vi, pj], cl[vi, pj] = fp, lp
                nf[:, lv.cell], nl[:, lv.cell] = cf, cl
                free, light = nf, nl
        return out, counts, std

    def _sky_rays(self, pat, rot, frame, origin, far: float, dark: bool, vi, pj):
        """The sky's directions and what of each leaves the scene, below the horizon 0 when ``dark``:
        pattern ``pat`` (S, 2) rotated by ``rot`` (k, 2) in the frames ``frame`` (t1, t2, normal:
        (k, 3) each) from ``origin`` (k, 3) float32: at every vertex and direction when ``pj`` is
        None (``(w (k, S, 3), free (k, S))``), else direction ``pj`` (m,) of vertex ``vi`` (m,)
        (``(w (m, 3), free (m,))``)."""
        t1, t2, normal = frame
        k = len(rot)
        whole = pj is None
        if whole:
            vi, pj = np.repeat(np.arange(k), len(pat)), np.tile(np.arange(len(pat)), k)
        w = np.empty((len(vi), 3))
        sky_directions(pat, rot, *(np.ascontiguousarray(f, dtype=np.float64) for f in frame), vi, pj, w)
        o = origin[vi]
        if whole:
            w, o = w.reshape(k, len(pat), 3), o.reshape(k, len(pat), 3)
        free = np.zeros(w.shape[:-1])
        todo = w[..., 1] >= 0 if dark else np.ones(free.shape, dtype=bool)
        free[todo] = self.vis.visible(
            np.ascontiguousarray(o[todo]), w[todo], np.full(int(todo.sum()), far, dtype=np.float32)
        )
        return w, free

    def max_mean_reflected(self) -> float:
        """Upper bound of the scene's area-mean reflected luminance radiance: all the emitted power
        received and reflected with the largest albedo, over the scene's area (inf for no area)."""
        a = float(self.patches.area.sum())
        if a <= 0 or not len(self.patches.albedo):
            return math.inf
        return float(luminance_of(self.patches.albedo).max()) * self.emitted_power() / (np.pi * a)

    def emitted_power(self) -> float:
        """Luminance power emitted by emissive patches and lights (W, luminance-weighted); for the
        sun and the sky, what would reach the surfaces if nothing shadowed them (an upper bound)."""
        p = float(np.pi * (self.patches.emission @ LUMINANCE_WEIGHTS * self.patches.area).sum())
        for lt in self.lights:
            p += light_power(lt)
        for sun in self.suns:
            cos = np.maximum(self.patches.normal @ -np.asarray(sun.direction, dtype=np.float64), 0.0)
            p += abs(float(sun.radiant_intensity @ LUMINANCE_WEIGHTS)) * float(
                (cos * self.patches.area).sum()
            )
        if self.sky is not None:  # the brightest of 1024 directions over the whole area
            k = np.arange(1024) + 0.5
            z = 1.0 - 2.0 * k / 1024
            phi = np.pi * (1.0 + 5.0**0.5) * k
            r = np.sqrt(1.0 - z * z)
            dirs = np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1)
            peak = float((sky_radiance(self.sky, dirs) @ LUMINANCE_WEIGHTS).max())
            p += np.pi * max(peak, 0.0) * float(self.patches.area.sum())
        return p


def light_power(lt) -> float:
    """Luminance power of a light (by magnitude: a difference of two lights may be negative)."""
    solid = 4 * np.pi if lt.kind == "point" else 2 * np.pi * (1 - math.cos(lt.outer_cone))
    if getattr(lt, "ies", None) is not None:
        solid = lt.ies.solid_angle()
    return abs(float(lt.radiant_intensity @ LUMINANCE_WEIGHTS)) * solid
