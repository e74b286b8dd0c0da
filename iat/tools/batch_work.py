"""The work a batch's tasks do on the workers (:mod:`iat.tools.batch` schedules them): load a model
once (:func:`load_model`), then solve, bake and render (:func:`run_task`); warnings raised there
come back as one-line strings, since the client does not see a worker's warnings."""

from __future__ import annotations

import contextlib
import tempfile
import time
import warnings
from pathlib import Path

from iat.errors import OptionError


def load_model(model: str, load_kwargs: dict, daylight=None):
    """``(Scene of model, [one-line warnings])`` (a task: its result stays on the cluster for the
    tasks that need it; the warnings reach the client through the first of them). ``daylight``: a
    :class:`~iat.lighting.daylight_default.DaylightRequest` applied to the scene (its one line
    joins the warnings)."""
    from iat.io.load import load_scene

    with warnings_caught() as caught:
        scene = load_scene(model, **load_kwargs)
    if daylight is not None:
        from iat.geometry.discontinuity import cut_new_lights
        from iat.lighting.daylight_default import apply_daylight

        line = apply_daylight(scene, daylight)
        if line:
            caught.append(line)
        if load_kwargs.get("discontinuity"):  # a sun the daylight added: its shadows cut as the file's
            scene = cut_new_lights(scene)
    return scene, caught


@contextlib.contextmanager
def warnings_caught():
    """Collect the warnings raised inside as one-line strings (a worker's warnings are not seen by
    the client otherwise); a repeated message is kept once."""
    out: list[str] = []
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        yield out
    for w in rec:
        text = " ".join(str(w.message).split())
        if text not in out:
            out.append(text)


def _solution(x):
    return x["solution"] if isinstance(x, dict) else x


def _state_scene(scene, states: dict, state: str | None):
    from iat.lighting.states import apply_lighting_state, union_lighting

    if state is not None:
        return apply_lighting_state(scene, states[state])
    return union_lighting([apply_lighting_state(scene, st) for st in states.values()])


def run_task(kind: str, loaded, options, states, state, bake, render, *deps) -> dict:
    """One task's work (on a worker): ``{"solution", "glb" (bytes or None), "image" (linear (h, w, 3)
    or None), "seconds", "warnings"}``. ``loaded`` is :func:`load_model`'s result (None for a merge);
    ``deps`` are the results (or Solutions) of its inputs' tasks. ``warnings``: the one-line warnings
    of its model's loading and of its own work."""
    scene, load_warnings = loaded if loaded is not None else (None, [])
    with warnings_caught() as caught:
        out = _run_task(kind, scene, options, states, state, bake, render, *deps)
    out["warnings"] = [*load_warnings, *(w for w in caught if w not in load_warnings)]
    return out


def _run_task(kind: str, scene, options, states, state, bake, render, *deps) -> dict:
    from iat.radiosity import solve

    t0 = time.perf_counter()
    if kind == "mesh" and deps:  # merge: the union of the states' own trees
        from iat.lighting.solution_set import merge_meshes

        sol = merge_meshes([_solution(d) for d in deps])
    elif kind == "solve":
        sol = solve(scene, options)
    else:
        sc = _state_scene(scene, states, state)
        mesh = _solution(deps[0]) if (kind == "state" and deps) else None
        sol = solve(sc, options, mesh=mesh)
        if kind == "state":
            from iat.lighting.states import state_times

            t = dict(zip(states, state_times(states), strict=True))[state]
            sol.stats = {**sol.stats, "lighting_state": state, "lighting_time": float(t)}
            scene = sc
    sol.model_path = str(scene.path) if getattr(scene, "path", None) else sol.model_path
    out = {"solution": sol, "glb": None, "image": None}
    if kind in ("solve", "state") and (bake is not None or render is not None):
        out.update(_bake_and_render(sol, scene, bake, render))
    out["seconds"] = time.perf_counter() - t0
    return out


def _bake_and_render(sol, scene, bake, render) -> dict:
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy

    out = {}
    policy = BakePolicy(**bake) if bake is not None else BakePolicy()
    baked = None
    if bake is not None:
        from iat.export.gltf import export_glb

        baked = Baker(sol, scene).bake(policy)
        with tempfile.TemporaryDirectory() as d:
            glb = export_glb(baked, Path(d) / "out.glb", scene=scene)
            out["glb"] = glb.read_bytes()
    if render is not None:
        from iat.render.renderer import Renderer

        cams = scene.cameras
        k = render.get("camera")
        if k is not None and not (0 <= k < len(cams)):
            raise OptionError(f"render camera {k}: the file has {len(cams)} camera(s)")
        cam = cams[k if k is not None else 0] if cams else scene.default_camera()
        r = Renderer()
        try:
            r.set_scene(scene)
            r.set_sky(scene.sky)
            if render["mode"] != "preview":
                r.set_solution(sol)
            if render["mode"] == "iat":
                r.set_baked(baked if baked is not None else Baker(sol, scene).bake(policy))
            out["image"] = r.render(cam, size=tuple(render["size"]), mode=render["mode"])
        finally:
            r.release()
    return out
