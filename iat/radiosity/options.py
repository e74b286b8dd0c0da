"""Options of the radiosity solver (:class:`SolveOptions`) and the constants that tune it."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from iat.errors import OptionError

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
#: elements longer than this fraction of the square root of the scene's surface area (5.7 cm in
#: the Cornell box, 1.6 m in the house) split on a tighter tolerance (0: no such elements): the
#: interpolation test alone left large elements whose light curves by up to ``tolerance``, all
#: below the real light where it is concave, 3 % too dark on average in the Cornell box
MAX_ELEMENT_FRACTION = 1.0 / 24.0
#: ... and they split on this fraction of ``tolerance`` (a large element's error covers much area;
#: the light that is linear over it, which interpolation represents exactly, still never splits).
#: Cornell box, tolerance 0.1: 1/4 gave 0.30 of uniform subdivision's elements at equal surface
#: error, 1/8 0.25 (1/16 0.24; 1/2 0.38, no rule 0.77); the house gains 0.3 % elements
BIG_TOLERANCE = 0.125
#: ... only on the levels above the last BIG_LEVELS (so a shallow solve keeps shallow patches)
BIG_LEVELS = 2
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
#: the gathers that give stage C's new vertices the light shot so far (one sample pattern for all
#: of them, so its error is one coherent offset of them all, not speckle) use this many times the
#: per-side samples of ``samples`` for a source that shot at least ``SHOT_FULL_SHARE`` of the
#: emitted power, fewer for a fainter one (by the square root of its share), as the strongest shots
#: do. With 1 x (4 x 4 samples) the Cornell box floor's light reached the new vertices up to 9 %
#: off (one offset per solve: -5 % on the new vertices of the seed-0 solve), and refinement chased
#: that error: the adaptive mesh stayed ~1.5 % darker than uniform subdivision whatever the
#: tolerance (13.5 k elements at tolerance 0.05 instead of 9.2 k); 4 x halves the rest of the
#: offset but doubles the Cornell box's time and adds 30 % to the house's
REFINE_SAMPLE_FACTOR = 2
#: a patch shoots its unshot field (linear in its leaves) times its *gain*: the power of its light
#: integrated with the probes every split test evaluates (quadratic per leaf) over the power of the
#: linear interpolant, kept within 1 / (1 + GAIN_LIMIT) .. 1 + GAIN_LIMIT. An element that stays
#: coarse under concave light interpolates below it; shooting the interpolant lost that light from
#: every surface's indirect light (the Cornell box's vertices 1.1 % dark, the closed lit box 2.8 %)
GAIN_LIMIT = 0.25
#: :func:`resolve` solves afresh on the mesh when the changed sources' power exceeds this
#: fraction of the new emitted power
RESOLVE_MAX_CHANGE = 1.0
#: rays per vertex that measure the closure of its hemisphere for the ambient term
AMBIENT_RAYS = 16
#: upper bound of the measured reflected fraction in the ambient term
MAX_REFLECTANCE = 0.95



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
    min_element_size : float >= 0 or None (default). An element is not split when its
        children's longest edge would be shorter than this; 0: no limit; None: 1/600 of the
        square root of the scene's surface area (3.8 cm in the 12 m house, 4 cm in the cave,
        2.3 mm in the Cornell box), which stops the endless subdivision of tiny regions
        along hard shadow edges.
    convergence : float in (0, 1], default 0.05. Stop shooting when the unshot power is
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
        receivers (errors smooth in space: new vertices do not stand out as speckle) and,
        since that pattern's error is common to them all, the strongest shots' samples.
    max_shots : int >= 0, default 20000. Hard cap on progressive shots (0: direct
        light only).
    max_edge : float > 0 or None. Recorded for the loader's pre-split of long
        patches into a grid of roots (``load_scene(max_edge=...)``); the solver
        itself takes the scene as it is.
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
        if self.criterion not in ("variation", "interpolation", "uniform"):
            bad("criterion", 'must be "variation", "interpolation" or "uniform"')
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
