"""Options of the radiosity solver (:class:`SolveOptions`) and the constants that tune it (how they were
chosen: docs/benchmarks.md, "Solver constants: how they were chosen")."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from iat.errors import OptionError

#: split test's absolute floor, fraction of the mean reflected direct radiance (dark corners stop splitting)
ABS_FLOOR = 0.02
#: ray-origin offset along the normal and to the patch centre, fraction of the scene diagonal (no self-hits)
RAY_EPS = 1e-4
#: ... at most this fraction of the radius of the patch the ray leaves or aims at (small patches stay hit)
RAY_EPS_PATCH = 0.02
#: in-plane nudge of form-factor points off shared edges, fraction of the scene diagonal (singular there)
FF_EPS = 1e-6
#: receivers per vectorised gather block, a count (bounds the memory of the (n, samples) temporaries)
GATHER_BLOCK = 8192
#: a gather from one shooter to at least this many receivers is split into a block per thread
SPLIT_RECEIVERS = 1024
#: ``min_element_size=None``: this fraction of sqrt(scene surface area) (ends subdivision along hard shadows)
MIN_ELEMENT_FRACTION = 1.0 / 600.0
#: elements longer than this fraction of sqrt(scene surface area) split on BIG_TOLERANCE (0: none; else dark)
MAX_ELEMENT_FRACTION = 1.0 / 24.0
#: ... as this fraction of ``tolerance`` (a large element's error covers much area)
BIG_TOLERANCE = 0.125
#: ... on all but the last BIG_LEVELS levels, a count (a shallow solve keeps shallow patches)
BIG_LEVELS = 2
#: form factor below which a receiver uses area samples only (the kernel is flat); nearer ones add directions
F_DIRECTION = 0.02
#: rays of a shooter's gathers, none unoccluded, after which its later shots skip a receiver patch (culling)
CULL_RAYS = 64
#: a shot adding under [1] / [0] of a patch's radiance is received on its 3 x 3 grid / corners (fewer gathers)
COARSE_EPS = (0.002, 0.02)
#: ... only if the patch's radius is under this fraction of its distance to the shooter (the shot is smooth)
COARSE_SIZE = (0.125, 0.25)
#: distance in shooter radii beyond which a form factor comes from a Gauss rule (cheaper, accurate far off)
FF_FAR = 4.0
#: (receiver, shooter) form factors kept for the shooters' later shots on one mesh, a count (12 bytes each)
FF_CACHE_ENTRIES = 12_000_000
#: sample patterns kept for reuse (stage C gathers every source with one pattern per pass), in (u, v) pairs
PATTERN_CACHE_POINTS = 1_000_000
#: per-side multiple of ``samples`` for the direct pass from an emitter of all the emitted power (the
#: direct light shapes the mesh); one of share s gets sqrt(s) of it, at least ``samples`` (samples by power).
#: 4, not 2: its noise in penumbrae split elements on nothing (the Cornell box: 4630 -> 4072 elements)
DIRECT_SAMPLE_FACTOR = 4
#: a vertex that gets between this fraction and 1 - this of what the emitting patches would give it
#: unoccluded (luminance) is in their penumbra ...
PENUMBRA_EDGE = 0.15
#: ... and the elements it is a corner or probe of split on this fraction of ``tolerance``: a soft
#: shadow is real structure that a 10 % interpolation gap leaves creased (the Cornell box's tall block's
#: on the red wall: wall noise 0.56 -> 0.42 %)
PENUMBRA_TOLERANCE = 0.35
#: per-side multiple of ``samples`` for the strongest shots (the first bounces make most indirect light;
#: 2.5, not 2: the Cornell box's ceiling, lit by them alone, was mottled)
SHOT_SAMPLE_FACTOR = 2.5
#: emitted-power share from which a shot gets all of those; share s gets sqrt(s / this) (samples by power)
SHOT_FULL_SHARE = 0.05
#: shooters whose shots run at once: the strongest and up to this many - 1 more (a count; not the
#: thread count, so that results do not depend on it) ...
SHOT_GROUP = 2
#: ... that have at least this fraction of its unshot power (weaker ones wait for its light)
SHOT_GROUP_RATIO = 0.5
#: per-side multiple of ``samples`` for stage C's gathers at new vertices (one pattern: its error is
#: common to them, and they stand out of the old vertices by it: 3, not 2, takes the Cornell box's
#: ceiling from 0.34-0.60 % of noise over ten seeds to 0.33-0.46 %, for +25 % of its rays)
REFINE_SAMPLE_FACTOR = 3
#: a patch's shot gain (probe-integrated / interpolated power) kept in [1/(1+this), 1+this] (concave light)
GAIN_LIMIT = 0.25
#: a shot whose receivers get more than this times the power it sent (its sampled form factors sum
#: above 1) is scaled back to what it sent; the house's shots reach 1.14 (quadrature noise)
FF_SUM_LIMIT = 1.25
#: a solve whose reflected or unshot power exceeds this times what the albedos allow (rho / (1 - rho)
#: of the power received, rho the largest albedo) stops with :class:`iat.errors.SolveError`
ENERGY_SLACK = 1.25
#: changed sources' power, fraction of the new emitted power, above which ``resolve`` solves afresh (noise)
RESOLVE_MAX_CHANGE = 1.0
#: a shooter whose field peaks above this times its mean (:func:`iat.radiosity.sampling.peak_factor`:
#: a sun patch on a floor) has its area samples drawn by its light
#: (:func:`iat.radiosity.sampling.field_importance`): a density piecewise constant on IMPORTANCE_SIDE x
#: IMPORTANCE_SIDE cells of its square, IMPORTANCE_MIX of it uniform, the rest by the field's luminance;
#: and its samples per side are raised by ``peak_factor`` up to IMPORTANCE_PEAK_LIMIT
PEAK_RATIO = 4.0
IMPORTANCE_SIDE = 16
IMPORTANCE_MIX = 0.5
IMPORTANCE_PEAK_LIMIT = 1.5
#: rays of the ambient term traced and read at a time, a count (their buffers stay in the caches)
AMBIENT_BLOCK_RAYS = 1 << 17
#: side of the grid, a power of 2, on which the ambient term reads a patch's unshot light where its rays
#: land (each point the tent-weighted mean around it: :meth:`iat.radiosity.sampling.Lattice.coarse_grids`)
AMBIENT_GRID = 8
#: the ambient term's second bounce gathers with this share of ``ambient_rays`` (its power per patch
#: comes from the first gather's rays: the second's give only its shape within a patch)
AMBIENT_SECOND_SHARE = 0.5
#: the ambient term's later bounces are summed until a bounce adds under this fraction of the first
AMBIENT_BOUNCE_TOL = 1e-4
#: ... or this many bounces, a count
AMBIENT_MAX_BOUNCES = 500
#: the ambient term scales a patch's bounce by at most this (or 1 / this) to hold the power its
#: patch receives: a patch whose vertices miss more of its light know its shape too little to scale
#: it. With each patch's seen area (``remainder.seen_average``) the furnished room's slot beside its
#: cabinet no longer reaches it; at 4 the generated near-white room (floor view, default / fine) is
#: 2.8 / 2.1 % off Mitsuba against 3.75 / 2.1 % at 1.5, its coincident faces 4.5 / 3.9 % against
#: 4.3 / 3.6 %
AMBIENT_FIT_LIMIT = 1.5
#: the ambient term counts at least this share of a partly buried patch's area as seen
#: (``remainder.seen_average``): its seen share comes from its vertices, and a sliver whose few
#: vertices all stand in walls while rays still land on it would read its light over a seen area
#: far too small (Madrid: a few vertices 0.3 -> 250 cd/m²-like luminance with no floor)
AMBIENT_SEEN_FLOOR = 0.25
#: upper bound of the albedo in the ambient term's later bounces and of the measured reflected
#: fraction r (keeps their sum finite in an albedo-1 room; at 0.95 a room of albedo 0.97 was 16 % dark)
MAX_REFLECTANCE = 0.99
#: stage C refines once the unshot power is below this times ``convergence`` of the received power
#: (it was sqrt(convergence), 22 % at the default: a daylit room's indirect light was then 10 %
#: low against Mitsuba, 2.4 % now; the house: 38.0 k -> 43.6 k elements, 57 -> 78 s, one run)
REFINE_UNSHOT = 2.0
#: side of the coverage grid that tells a panel cell's area samples on its surface from off it
SHOOTER_COVERAGE = 256
#: directions per vertex on the sun's disc (soft shadow edges), a count
SUN_SAMPLES = 64
#: a vertex's sky estimate whose standard error, as its four interleaved quarters tell it (on the
#: window-lit room's back wall 1.2x the spread between seeds), is above this fraction of the vertex's
#: direct light (the sky's and the other sources') is estimated again with 4 x the directions (the old
#: ones kept), up to SKY_PASSES estimates (benchmarks/window_room.py: noise 1.45 -> 0.32 %, elements
#: 17.7 k -> 5.7 k)
SKY_NOISE = 0.01
SKY_PASSES = 2
#: the split test asks a probe's deviation from the interpolation to exceed the tolerance by this many
#: of the deviation's standard errors (the sky's estimates', :func:`.meshing.split_test`): noise is not
#: light to resolve, and elements split on it only multiply it
SPLIT_NOISE = 1.0
#: a later sky estimate traces its new directions only in the strata whose value differs from one
#: within this many strata on the grid before it; the others take their stratum's (:mod:`.sky_passes`);
#: -1 traces them all
SKY_SETTLED = 2


@dataclass
class SolveOptions:
    """Options of :func:`solve` (lengths in scene units).

    max_depth : int, 0..12, default 6. Deepest quad-tree level; the lattice has
        ``2**max_depth + 1`` points per patch side. Deeper resolves sharper shadows
        at up to 4x the elements (and texels) per level.
    tolerance : float > 0, default 0.1. Relative radiance error that splits an element
        (see ``criterion``), relative to the mean of its corners and probes plus a
        small absolute floor (2 % of the scene's mean reflected radiance, so dark
        corners do not split forever). Smaller: more elements. Elements longer than 1/24
        of the square root of the scene's surface area (``MAX_ELEMENT_FRACTION``; 5.7 cm in
        the Cornell box) split on an eighth of it (``BIG_TOLERANCE``), except on the last
        two levels: large elements under curved light were all too dark where it is concave.
        Elements in an emitting patch's penumbra split on 0.35 of it (``PENUMBRA_TOLERANCE``).
    min_element_size : float >= 0 or None (default). An element is not split when its
        children's longest edge would be shorter than this; 0: no limit; None: 1/600 of the
        square root of the scene's surface area (3.8 cm in the 12 m house, 4 cm in the cave,
        2.3 mm in the Cornell box), which stops the endless subdivision of tiny regions
        along hard shadow edges.
    convergence : float in (0, 1], default 0.05. Stop shooting when the unshot power is
        below this fraction of the power the surfaces received from the sources in the direct
        pass (in a closed scene the emitted power; in an open or daylit one what came in,
        so an interior gets its bounces even when most of the light escapes); with ``ambient``
        it is added by a final gather of it (all its later bounces), otherwise that light
        (amplified by interreflection) is missing from the result. Smaller costs more
        shots for the last, faint bounces.
    samples : int 1..1024, default 16. Per receiver and shot: that many stratified
        points on the shooter's area and, for near receivers, as many cosine-distributed
        directions (both rounded up to ``k*k``). The direct pass from an emissive patch
        uses ``(4k)**2`` times its share of the emitted power (at least ``k*k``), the strongest
        shots of reflected light ``(2.5k)**2``; fainter shots use fewer (by the square root of
        their power per side), down to one. Shots rotate the pattern per
        receiver (independent errors, which average out over the shots); the gathers that
        give the vertices new in stage C the light shot so far use one pattern for all
        receivers (errors smooth in space: new vertices do not stand out as speckle) and,
        since that pattern's error is common to them all, the strongest shots' samples.
    max_shots : int >= 0, default 20000. Hard cap on progressive shots (0: direct
        light only).
    max_edge : float > 0 or None. Recorded for the loader's pre-split of long
        patches into a grid of roots (``load_scene(max_edge=...)``); the solver
        itself takes the scene as it is.
    panels : bool, default True. Recorded for the loader too (``load_scene(panels=...)``):
        coplanar patches holding triangles become panels (:mod:`iat.geometry.panels`).
    discontinuity : bool, default True. Recorded for the loader too
        (``load_scene(discontinuity=...)``): roots are cut along the hard shadow boundaries of the
        model's point, spot and sun lights (:mod:`iat.geometry.discontinuity`), so element edges
        follow the shadows instead of stair-stepping across them (new roots at most a tenth of
        the model's or 256: ``MAX_NEW_FRACTION``). Solutions recorded without it were not cut.
    seed : int, default 0. Seed of the sample jitter; a solve is deterministic.
    criterion : "interpolation" (default), "variation" or "uniform". What ``tolerance`` bounds:
        "interpolation" splits on the largest gap between a probe and the value the
        corners interpolate there (linear gradients stay coarse, shadows still go deep:
        the mesh goes where the light has features); "variation" splits on max - min
        over the element's corners and probes (the classic test; smooth gradients
        refine too, so lit surfaces go deep: about 10x the elements); "uniform" splits every
        element to ``max_depth`` (no smaller than ``min_element_size``; ``tolerance`` is not
        used): the uniform subdivision the adaptive mesh is benchmarked against.
    refine_indirect : bool, default True. Refine on the total (direct + indirect)
        radiance after the first bounces and at convergence, so that surfaces lit
        only indirectly (a ceiling) get elements too; new vertices gather everything
        shot so far (exact, never interpolated). Without it such surfaces keep their
        direct-light mesh.
    ambient : bool, default True. Add the ambient term for the light still unshot at
        convergence: a final gather of it from every vertex, its later bounces summed on the
        patches (see :mod:`iat.radiosity.solver`, D); False leaves it out (the result is then
        darker by about ``convergence`` times the interreflection gain).
    ambient_rays : int, default 256. Rays per vertex of the ambient term's final gather (draft 64,
        fine and final 1024). In a sunlit room whose bounced light is nearly all in that term, its
        noise is most of the error: 64 rays 7.7 %, 256 5.1 % against Mitsuba (the daylit test room
        of tests/test_real_daylight.py; docs/benchmarks.md, "The ambient term's rays").
    sky_samples : int 4..4096, default 1024. Cosine-distributed directions per vertex towards the
        sky (rounded up to ``k*k``), before a noisy vertex's second estimate (``SKY_NOISE``).
        Through a window, the ~5 % of a room's hemisphere it is, that is ~5 % noise per vertex at
        1024. :meth:`preview` takes 64.
    """

    max_depth: int = 6
    tolerance: float = 0.1
    min_element_size: float | None = None
    convergence: float = 0.05
    samples: int = 16
    max_shots: int = 20000
    max_edge: float | None = None
    panels: bool = True
    discontinuity: bool = True
    seed: int = 0
    criterion: str = "interpolation"
    refine_indirect: bool = True
    ambient: bool = True
    ambient_rays: int = 256
    sky_samples: int = 1024

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
        if not 1 <= integer("ambient_rays") <= 4096:
            bad("ambient_rays", "must be between 1 and 4096")
        if not 4 <= integer("sky_samples") <= 4096:
            bad("sky_samples", "must be between 4 and 4096")
        if not integer("max_shots") >= 0:
            bad("max_shots", "must be >= 0")
        if self.max_edge is not None and not num("max_edge") > 0:
            bad("max_edge", "must be > 0 or None")
        integer("seed")
        if not isinstance(self.refine_indirect, bool | np.bool_):
            bad("refine_indirect", "must be True or False")
        if not isinstance(self.ambient, bool | np.bool_):
            bad("ambient", "must be True or False")
        if not isinstance(self.panels, bool | np.bool_):
            bad("panels", "must be True or False")
        if not isinstance(self.discontinuity, bool | np.bool_):
            bad("discontinuity", "must be True or False")
        if self.criterion not in ("variation", "interpolation", "uniform"):
            bad("criterion", 'must be "variation", "interpolation" or "uniform"')
        return self

    def to_dict(self) -> dict:
        """JSON-able dict of the options."""
        d = asdict(self)
        return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in d.items()}

    def load_kwargs(self) -> dict:
        """The loader's keywords these options record (``load_scene(path, **opts.load_kwargs())``)."""
        return {
            "max_edge": self.max_edge,
            "panels": bool(self.panels),
            "discontinuity": bool(self.discontinuity),
        }

    @staticmethod
    def recorded_load_kwargs(d: dict) -> dict:
        """:meth:`load_kwargs` of a solution's recorded options (solved before panels or discontinuity
        meshing: none)."""
        return {
            "max_edge": d.get("max_edge"),
            "panels": bool(d.get("panels", False)),
            "discontinuity": bool(d.get("discontinuity", False)),
        }

    @classmethod
    def preset(cls, quality: str = "default", **overrides) -> SolveOptions:
        """The options of a :data:`QUALITY_PRESETS` level ("draft", "default", "fine", "final"),
        with ``overrides`` (other fields) on top; OptionError naming the levels for another name."""
        if quality not in QUALITY_PRESETS:
            raise OptionError(f"unknown quality {quality!r} (choose from {', '.join(QUALITY_PRESETS)})")
        return cls(**{**QUALITY_PRESETS[quality], **overrides}).validate()

    def preview(self) -> SolveOptions:
        """These options for a first look on a mesh solved before (``solve(scene, opts.preview(),
        mesh=previous)``): the direct light, the strongest shots and the ambient term, with fewer rays
        (:data:`PREVIEW`). The open house by a new sun: 1.9 s against 12.7 s at these options, 2.2 %
        off per vertex (docs/benchmarks.md, "A first sunlit image")."""
        return replace(self, **PREVIEW).validate()

    @classmethod
    def from_dict(cls, d: dict) -> SolveOptions:
        """Options from :meth:`to_dict` output (unknown keys, e.g. from a newer version, ignored)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in dict(d).items() if k in names})


#: quality levels of :meth:`SolveOptions.preset` (``--quality``), each spending time where it
#: lowered the Cornell box's error against a 4096-spp Mitsuba reference the most (docs/benchmarks.md,
#: "Quality presets"): the mesh (depth, tolerance) buys little past the defaults; the unshot
#: remainder (convergence) and the samples do; fine's tolerance 0.07 lowers the Cornell walls' noise,
#: which its finer convergence alone raised, and fine and final trace 2 048 and 4 096 sky directions a
#: vertex: the window-lit room's noisy sky estimates no longer split elements (final: 15 k -> 3.7 k
#: elements, 0.81 -> 0.57 % block error; "The Cornell box's walls")
QUALITY_PRESETS: dict[str, dict] = {
    "draft": {"max_depth": 4, "samples": 8, "ambient_rays": 64},
    "default": {},
    "fine": {"convergence": 0.01, "tolerance": 0.07, "ambient_rays": 1024, "sky_samples": 2048},
    "final": {
        "convergence": 0.005,
        "tolerance": 0.05,
        "samples": 32,
        "ambient_rays": 1024,
        "sky_samples": 4096,
    },
}

#: what :meth:`SolveOptions.preview` changes: convergence 0.2 shoots only the strongest patches (a sun
#: patch's first bounce; the rest of the reflected light is the ambient term's: tests/test_preview.py's
#: sunlit room 7.8 % off per vertex with no shots, 3.3 % with its 6), a sixteenth of the sky's and a
#: quarter of the ambient term's rays
PREVIEW: dict = {"convergence": 0.2, "samples": 8, "ambient_rays": 64, "sky_samples": 64}
