"""Open what a user names on the command line or in the viewer: a model or a solution.

``MODEL`` given where a solution is expected is solved with default options
first (the design's command-line contract).
"""

from __future__ import annotations

from pathlib import Path

from iat.errors import LoadError, SolutionFileError
from iat.geometry.discontinuity import replay_cuts
from iat.io.load import load_scene
from iat.io.scene import Scene

SOLUTION_SUFFIXES = (".npz",)


def is_solution_path(path: str | Path) -> bool:
    return Path(path).suffix.lower() in SOLUTION_SUFFIXES


def open_solution(path: str | Path, options=None, progress=None, load_progress=None):
    """(scene, solution) from a solution file or a model file.

    A solution's model is reloaded from ``solution.model_path`` (for materials
    and detail textures), its roots cut along the shadows the solved scene was cut along
    (``stats["shadow_cuts"]``, :func:`iat.geometry.discontinuity.replay_cuts`), with the suns and
    the sky the solve had
    (:func:`restore_daylight`: ``iat solve --sun/--sky`` puts them in no file); when
    that file is gone the scene is rebuilt from the solution's own patches, without
    detail textures.

    progress : the solve's ``progress(fraction, message) -> bool`` (a model only).
    load_progress : the model load's (:func:`iat.io.load.load_scene`); False cancels.
    """
    from iat.radiosity import Solution, SolveOptions, solve

    path = Path(path)
    if is_solution_path(path):
        sol = Solution.load(path)
        model = Path(sol.model_path) if sol.model_path else None
        if model is not None and not model.is_absolute():
            model = (path.parent / model).resolve() if not model.exists() else model
        if model is not None and model.exists():
            stats = sol.stats if isinstance(sol.stats, dict) else {}
            # sides, cut (a solution without the record was cut along the crossings, then the default)
            kw = SolveOptions.recorded_load_kwargs(sol.options)
            kw = {"cut": "crossings", **kw, **stats.get("load", {})}
            cuts = stats.get("shadow_cuts")
            if cuts is None:  # solved before the cuts were recorded: as the options said
                scene = load_scene(model, progress=load_progress, **kw)
            else:  # the shadows the solved scene was cut along, its suns and lamps added later too
                scene = replay_cuts(
                    load_scene(model, progress=load_progress, **{**kw, "discontinuity": False}), cuts
                )
            if scene.n_patches != len(sol.patch_is_quad):
                raise SolutionFileError(
                    f"solution has {len(sol.patch_is_quad)} patches but {model} has {scene.n_patches};"
                    " the model changed since it was solved",
                    path,
                )
        else:
            scene = scene_from_solution(sol)
        restore_daylight(scene, sol.stats.get("sources") if isinstance(sol.stats, dict) else None)
        return scene, sol
    if not path.exists():
        raise LoadError("file not found", path)
    options = options or SolveOptions()
    scene = load_scene(path, progress=load_progress, **options.load_kwargs())
    return scene, solve(scene, options, progress=progress)


def restore_daylight(scene: Scene, record: dict | None) -> None:
    """Give ``scene`` the suns and the sky of a solve's sources record (``stats["sources"]``,
    :func:`iat.radiosity.sources.sources_record`), in place: its directional lights become the
    recorded suns, and a recorded sky replaces its own. Older records (no such keys) change nothing."""
    from iat.io.scene import Light, Sky

    if not record:
        return
    if "suns" in record:
        suns = [
            Light(
                kind="directional",
                name=d.get("name", ""),
                direction=d["direction"],
                color=d["radiant_intensity"],
                intensity=1.0,
                angular_diameter=float(d["angular_diameter"]),
            )
            for d in record["suns"]
        ]
        scene.lights = [lt for lt in scene.lights if lt.kind != "directional"] + suns
    if record.get("sky") is not None:
        scene.sky = Sky.from_spec(record["sky"])


def scene_from_solution(sol) -> Scene:
    """A Scene rebuilt from a solution's patches (albedo only, no lights, no detail)."""
    import numpy as np

    from iat.io.scene import Material

    p = len(sol.patch_is_quad)
    verts = sol.patch_corners.reshape(-1, 3)
    corners = np.arange(4 * p).reshape(p, 4)
    corners[~sol.patch_is_quad, 3] = -1
    mats = [Material(name=f"patch{k}", albedo=a) for k, a in enumerate(sol.patch_albedo)]
    return Scene(verts, corners, np.arange(p), mats, path=sol.model_path)
