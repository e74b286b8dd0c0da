"""Lighting states: named lights-and-emission settings a model carries, with their key times.

A model may carry named lighting states in its root ``extras["iat_lighting_states"]``
(:func:`lighting_states` reads and checks them, :func:`apply_lighting_state` applies one)::

    {"morning": {"time": 0.0,
                 "lights": {"living_lamp": 0.0, "desk_lamp": {"intensity": 12.0, "color": [1, 0.9, 0.8]}},
                 "emission": {"window_south": [4.0, 3.4, 2.4], "lamp_panel": 0.0}},
     "noon": {...}, "evening": {...}}

- ``time`` (optional, in [0, 1]): the state's key time on the day slider; when any state
  lacks one, the states are spaced evenly in [0, 1] in the order written (:func:`state_times`).
- ``lights``: by light name; a number is the intensity (glTF candela, read as W/sr per
  unit colour), an object may give ``intensity`` and ``color``. Lights not named keep the
  file's values.
- ``emission``: by material name; a number scales the material's emission as loaded (its
  *strength*: 0 is off, 1 as in the file), a list of three is the emitted radiance itself
  (linear RGB). Materials not named keep the file's emission.
- ``sun`` (daylight, :func:`iat.lighting.sun.sun_states` writes them): ``{"direction": [x, y, z]``
  (where the light travels), ``"intensity"`` (W/m²), ``"color"``, optional
  ``"angular_diameter"`` (degrees)``}``: the scene's directional light named ``sun`` (added
  if there is none; intensity 0 takes it out).
- ``sky``: ``{"kind", "radiance", "sun_direction", "turbidity", "ground"}`` (an
  :class:`iat.io.scene.Sky`; ``null`` takes the sky away).

:func:`union_lighting` lights one scene with every state's sources at once (the mesh that
resolves all of them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from iat.errors import LoadError, OptionError
from iat.io.gltf import GltfDocument
from iat.io.scene import Light, Scene, Sky
from iat.lighting.edits import copy_light, copy_lighting, copy_material

#: root extras key holding the named lighting states
LIGHTING_STATES_KEY = "iat_lighting_states"


def check_states(states: Any, where) -> dict[str, dict]:
    """``states`` as {name: state} once checked; LoadError naming ``where`` for a malformed state."""
    if not isinstance(states, dict):
        raise LoadError(f"{LIGHTING_STATES_KEY} must be an object of named states", where)
    out = {}
    for name, st in states.items():
        if not isinstance(st, dict):
            raise LoadError(f"lighting state {name!r} must be an object", where)
        unknown = set(st) - {"time", "lights", "emission", "label", "sun", "sky", "elevation", "azimuth"}
        if unknown:
            raise LoadError(f"lighting state {name!r}: unknown key(s) {', '.join(sorted(unknown))}", where)
        if "time" in st and not (isinstance(st["time"], int | float) and 0.0 <= float(st["time"]) <= 1.0):
            raise LoadError(f"lighting state {name!r}: time must be a number in [0, 1]", where)
        out[str(name)] = st
    return out


def lighting_states(source) -> dict[str, dict]:
    """The named lighting states of a model: ``source`` is a glTF/GLB path, a Scene (its ``path``),
    or the states dict itself (checked). {} when the model has none (or is not glTF)."""
    if isinstance(source, dict):
        return check_states(source, "lighting states")
    path = Path(source.path if isinstance(source, Scene) else source)
    if not str(path) or path.suffix.lower() not in (".glb", ".gltf") or not path.is_file():
        return {}
    extras = GltfDocument(path).doc.extras
    if not isinstance(extras, dict) or LIGHTING_STATES_KEY not in extras:
        return {}
    return check_states(extras[LIGHTING_STATES_KEY], path)


def state_times(states: dict[str, dict]) -> np.ndarray:
    """(n,) float64 key times of ``states`` in the order given: their ``time`` values when every
    state has one, else evenly spaced in [0, 1]. Times must increase strictly."""
    n = len(states)
    if n and all("time" in st for st in states.values()):
        t = np.array([float(st["time"]) for st in states.values()])
        if n > 1 and not (np.diff(t) > 0).all():
            raise OptionError(f"lighting state times must increase in the order written, got {t.tolist()}")
        return t
    return np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(n)


def apply_lighting_state(scene: Scene, state: dict, base: Scene | None = None) -> Scene:
    """A new Scene with the lights and emission of lighting ``state`` (see the module docstring).

    base : the scene whose emission a strength multiplies (default ``scene``: the file as loaded).
    Raises :class:`~iat.errors.OptionError` naming an unknown light or material.
    """
    base = scene if base is None else base
    lights = [copy_light(lt) for lt in scene.lights]
    names = [lt.name for lt in lights]
    for name, spec in (state.get("lights") or {}).items():
        if name not in names:
            raise OptionError(f"lighting state names light {name!r}, not in the scene ({', '.join(names)})")
        k = names.index(name)
        if isinstance(spec, int | float):
            lights[k] = copy_light(lights[k], intensity=float(spec))
        elif isinstance(spec, dict):
            ch = {}
            if "intensity" in spec:
                ch["intensity"] = float(spec["intensity"])
            if "color" in spec:
                ch["color"] = np.asarray(spec["color"], dtype=np.float64).reshape(3)
            lights[k] = copy_light(lights[k], **ch)
        else:
            raise OptionError(f"lighting state: light {name!r} must be a number or an object")
    mats = [copy_material(m) for m in scene.materials]
    mnames = [m.name for m in mats]
    for name, spec in (state.get("emission") or {}).items():
        if name not in mnames:
            raise OptionError(f"lighting state names material {name!r}, not in the scene")
        k = mnames.index(name)
        if isinstance(spec, int | float):
            if spec < 0:
                raise OptionError(f"lighting state: emission strength of {name!r} must be >= 0")
            e = np.asarray(base.materials[k].emission, dtype=np.float64) * float(spec)
        else:
            e = np.asarray(spec, dtype=np.float64).reshape(3)
            if (e < 0).any() or not np.isfinite(e).all():
                raise OptionError(f"lighting state: emission of {name!r} must be finite and >= 0")
        mats[k] = copy_material(mats[k], emission=e)
    out = copy_lighting(scene, lights=lights, materials=mats)
    if "sun" in state:
        out.lights = _with_sun(out.lights, state["sun"])
    if "sky" in state:
        out.sky = Sky.from_spec(state["sky"])
    return out


def _with_sun(lights: list[Light], spec) -> list[Light]:
    """``lights`` with the directional light ``sun`` set from a state's ``sun`` entry."""
    if not isinstance(spec, dict) or "direction" not in spec:
        raise OptionError("lighting state: sun must be an object with a direction")
    rest = [lt for lt in lights if not (lt.kind == "directional" and lt.name == "sun")]
    intensity = float(spec.get("intensity", 1.0))
    if intensity <= 0:
        return rest
    d = np.asarray(spec["direction"], dtype=np.float64).reshape(3)
    kw = (
        {"angular_diameter": float(np.radians(spec["angular_diameter"]))}
        if "angular_diameter" in spec
        else {}
    )
    sun = Light(
        kind="directional",
        direction=d / max(float(np.linalg.norm(d)), 1e-300),
        color=np.asarray(spec.get("color", [1.0, 1.0, 1.0]), dtype=np.float64).reshape(3),
        intensity=intensity,
        name="sun",
        **kw,
    )
    return [*rest, sun]


def state_scenes(scene: Scene, states: dict[str, dict] | None = None) -> dict[str, Scene]:
    """{name: Scene} of every lighting state (default: the model's own, :func:`lighting_states`)."""
    states = lighting_states(scene) if states is None else states
    return {name: apply_lighting_state(scene, st) for name, st in states.items()}


def union_lighting(scenes: list[Scene]) -> Scene:
    """One scene lit by every source of ``scenes`` at once (lights at their brightest, emission
    the per-channel maximum): its solve settles a mesh that resolves the features of every
    state (the shadows of lamps that are only on in the evening, ...)."""
    if not scenes:
        raise OptionError("union_lighting needs at least one scene")
    first = scenes[0]
    lights: list[Light] = []
    for sc in scenes:
        for lt in sc.lights:
            if lt.intensity <= 0 or not np.any(lt.color > 0):
                continue
            same = next(
                (
                    x
                    for x in lights
                    if x.kind == lt.kind
                    and np.allclose(x.position, lt.position)
                    and np.allclose(x.direction, lt.direction)
                    and x.inner_cone == lt.inner_cone
                    and x.outer_cone == lt.outer_cone
                ),
                None,
            )
            if same is None:
                lights.append(copy_light(lt))
            else:
                ri = np.maximum(same.radiant_intensity, lt.radiant_intensity)
                s = float(ri.max())
                same.intensity, same.color = s, (ri / s if s > 0 else ri)
    mats = [
        copy_material(m, emission=np.max([sc.materials[i].emission for sc in scenes], axis=0))
        for i, m in enumerate(first.materials)
    ]
    out = copy_lighting(first, lights=lights, materials=mats)
    skies = [sc.sky for sc in scenes if getattr(sc, "sky", None) is not None]
    if skies:  # the brightest sky (the mesh it settles resolves the others' smoother light)
        out.sky = max(skies, key=lambda k: float(np.max(k.radiance)))
    return out
