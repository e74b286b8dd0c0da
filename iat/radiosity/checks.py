"""What the solve entry points check first: the options, the scene, and a given mesh's patches."""

from __future__ import annotations

import warnings

import numpy as np

from iat.errors import IATWarning, OptionError
from iat.radiosity.options import SolveOptions
from iat.radiosity.solution import Solution


def validated_options(options) -> SolveOptions:
    """``options`` (None: the defaults) validated; OptionError if it is not a :class:`SolveOptions`."""
    opts = SolveOptions() if options is None else options
    if not isinstance(opts, SolveOptions):
        raise OptionError(f"solve options must be SolveOptions, not {type(opts).__name__}")
    return opts.validate()


def check_scene(scene) -> None:
    """Raise OptionError for a scene the solver cannot solve (an in-memory scene is not checked
    by a loader): non-finite geometry or light, non-finite albedo, negative emission. Albedo
    outside [0, 1] is clamped by the solve (:func:`iat.radiosity.patches.solver_albedo`) with an
    :class:`iat.errors.IATWarning` naming the materials."""
    c = scene.corner_positions
    if not np.isfinite(c).all():
        raise OptionError("scene: non-finite vertex coordinates")
    alb, em = scene.patch_albedo, scene.patch_emission
    if not (np.isfinite(alb).all() and np.isfinite(em).all()):
        raise OptionError("scene: non-finite albedo or emission")
    if len(alb) and (alb.min() < 0 or alb.max() > 1):
        used = np.unique(np.asarray(scene.patch_material, dtype=np.int64))
        bad = [  # (the loader's wording: iat.io.scene)
            f"{getattr(m, 'name', '') or '(unnamed)'!r} ({', '.join(f'{a:g}' for a in np.ravel(m.albedo))})"
            for k, m in enumerate(scene.materials)
            if k in used and (np.min(m.albedo) < 0 or np.max(m.albedo) > 1)
        ]
        noun = "material" if len(bad) == 1 else "materials"
        shown = ", ".join(bad[:8]) + (f" and {len(bad) - 8} more" if len(bad) > 8 else "")
        warnings.warn(
            f"solve: albedo outside [0, 1] clamped in {len(bad)} {noun}: {shown}", IATWarning, stacklevel=3
        )
    if len(em) and em.min() < 0:
        raise OptionError("scene: negative emission")
    for lt in scene.lights:
        vals = [lt.position, lt.direction, lt.radiant_intensity, [lt.inner_cone, lt.outer_cone]]
        if not all(np.isfinite(np.asarray(v, dtype=np.float64)).all() for v in vals):
            raise OptionError(f"scene: light {getattr(lt, 'name', '')!r} has non-finite values")


def warn_if_unlit(scene) -> None:
    """An :class:`iat.errors.IATWarning` when nothing in ``scene`` emits: the solve goes on (its
    solution is black) but says so."""
    if not scene.has_light_sources:
        where = f"{scene.path}: " if getattr(scene, "path", "") else ""
        warnings.warn(
            f"{where}no light sources (no lights, no sky, no emissive materials): the solution is black",
            IATWarning,
            stacklevel=3,
        )


def check_mesh(sol: Solution, scene, what: str) -> None:
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
