"""Lighting you can change: edit lights and emission, save them back to glTF, re-solve in the background.

Everything here works on :class:`~iat.scene.Scene` objects and never changes one
in place: an edit returns a new Scene that shares the geometry arrays (vertices,
patches, UVs, detail textures) and owns copies of its lights and materials, so a
background solve can keep the scene it started from while the user edits on.

Edits (:func:`edit_light`, :func:`add_light`, :func:`delete_light`,
:func:`set_emission`) and :class:`LightEditor`, which keeps the edited scene,
where each light came from in the file, and each emissive material's strength
(a multiplier on its emission as loaded).

Lighting states (:func:`lighting_states`, :func:`apply_lighting_state`): a model may
carry named lighting states in its root ``extras["iat_lighting_states"]``::

    {"morning": {"time": 0.0,
                 "lights": {"living_lamp": 0.0, "desk_lamp": {"intensity": 12.0, "color": [1, 0.9, 0.8]}},
                 "emission": {"window_south": [4.0, 3.4, 2.4], "lamp_panel": 0.0}},
     "noon": {...}, "evening": {...}}

- ``time`` (optional, in [0, 1]): the state's key time on the day slider; when any state
  lacks one, the states are spaced evenly in [0, 1] in the order written.
- ``lights``: by light name; a number is the intensity (glTF candela, read as W/sr per
  unit colour), an object may give ``intensity`` and ``color``. Lights not named keep the
  file's values.
- ``emission``: by material name; a number scales the material's emission as loaded (its
  *strength*: 0 is off, 1 as in the file), a list of three is the emitted radiance itself
  (linear RGB). Materials not named keep the file's emission.

Saving (:func:`save_gltf`): the source glTF's JSON is patched with pygltflib
(``KHR_lights_punctual`` light definitions and their nodes, emissive factors and
``KHR_materials_emissive_strength``, the lighting states) and written next to the
geometry bytes, which are copied unchanged, atomically (temporary file, fsync, rename).

Background re-solve (:class:`Relighter`): after an edit that changed only lights or
emission, :func:`iat.radiosity.resolve` continues from the last converged solution
(shooting only the difference) on the same mesh; the work is re-run with increasing
effort (a coarse convergence first, then the final one), each result published as it
arrives so the view improves step by step. A newer edit cancels the work in progress.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import struct
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from iat.errors import IATError, LoadError, OptionError
from iat.io.scene import Light, Material, Scene
from iat.worker import LatestWorker

log = logging.getLogger(__name__)

__all__ = [
    "LIGHTING_STATES_KEY",
    "LightEditor",
    "RelightResult",
    "Relighter",
    "add_light",
    "apply_lighting_state",
    "copy_lighting",
    "delete_light",
    "edit_light",
    "emissive_materials",
    "lighting_states",
    "lights_only_changed",
    "save_gltf",
    "set_emission",
    "state_scenes",
    "state_times",
    "union_lighting",
]

#: root extras key holding the named lighting states
LIGHTING_STATES_KEY = "iat_lighting_states"
EXT_LIGHTS = "KHR_lights_punctual"
EXT_STRENGTH = "KHR_materials_emissive_strength"
LIGHT_KINDS = ("point", "spot")


# -- copies and edits ---------------------------------------------------------------------------------
def _copy_light(lt: Light, **changes) -> Light:
    kw = {
        "kind": lt.kind,
        "position": np.array(lt.position, dtype=np.float64),
        "direction": np.array(lt.direction, dtype=np.float64),
        "color": np.array(lt.color, dtype=np.float64),
        "intensity": float(lt.intensity),
        "inner_cone": float(lt.inner_cone),
        "outer_cone": float(lt.outer_cone),
        "name": lt.name,
    }
    kw.update(changes)
    return _checked_light(Light(**kw))


def _copy_material(m: Material, **changes) -> Material:
    kw = {"name": m.name, "albedo": np.array(m.albedo), "emission": np.array(m.emission), "detail": m.detail}
    kw.update(changes)
    return Material(**kw)


def _checked_light(lt: Light) -> Light:
    if lt.kind not in LIGHT_KINDS:
        raise OptionError(f"light {lt.name!r}: kind must be one of {', '.join(LIGHT_KINDS)}, got {lt.kind!r}")
    for name in ("position", "direction", "color"):
        v = getattr(lt, name)
        if v.shape != (3,) or not np.isfinite(v).all():
            raise OptionError(f"light {lt.name!r}: {name} must be three finite numbers, got {v.tolist()}")
    if not (math.isfinite(lt.intensity) and lt.intensity >= 0):
        raise OptionError(f"light {lt.name!r}: intensity must be a finite number >= 0, got {lt.intensity!r}")
    if (lt.color < 0).any():
        raise OptionError(f"light {lt.name!r}: color must be >= 0, got {lt.color.tolist()}")
    n = float(np.linalg.norm(lt.direction))
    if n <= 0:
        raise OptionError(f"light {lt.name!r}: direction must not be zero")
    lt.direction = lt.direction / n
    if lt.kind == "spot" and not (0.0 <= lt.inner_cone < lt.outer_cone <= math.pi / 2):
        raise OptionError(
            f"light {lt.name!r}: spot cones need 0 <= inner < outer <= pi/2, got "
            f"{lt.inner_cone:.3g}, {lt.outer_cone:.3g}"
        )
    return lt


def copy_lighting(
    scene: Scene, lights: list[Light] | None = None, materials: list[Material] | None = None
) -> Scene:
    """A new Scene sharing ``scene``'s geometry arrays, with its own copies of the lights and
    materials (or the ones given)."""
    lights = [_copy_light(lt) for lt in scene.lights] if lights is None else list(lights)
    materials = [_copy_material(m) for m in scene.materials] if materials is None else list(materials)
    return dataclasses.replace(scene, lights=lights, materials=materials)


def _named_index(names: list[str], index: int | str, what: str) -> int:
    """Position of ``index`` (a name, or a position) among ``names``; an OptionError naming ``what``."""
    if isinstance(index, str):
        if index not in names:
            raise OptionError(f"no {what} named {index!r} ({what}s: {', '.join(names) or 'none'})")
        return names.index(index)
    i = int(index)
    if not 0 <= i < len(names):
        raise OptionError(f"{what} {i} does not exist (the scene has {len(names)})")
    return i


def _light_index(scene: Scene, index: int | str) -> int:
    return _named_index([lt.name for lt in scene.lights], index, "light")


def _material_index(scene: Scene, material: int | str) -> int:
    return _named_index([m.name for m in scene.materials], material, "material")


def edit_light(scene: Scene, index: int | str, **changes) -> Scene:
    """A new Scene with light ``index`` (or name) changed: any of ``position``, ``direction``,
    ``color``, ``intensity``, ``inner_cone``, ``outer_cone``, ``kind``, ``name``.
    Raises :class:`~iat.errors.OptionError` on an unknown field or a bad value."""
    i = _light_index(scene, index)
    allowed = {"position", "direction", "color", "intensity", "inner_cone", "outer_cone", "kind", "name"}
    bad = set(changes) - allowed
    if bad:
        raise OptionError(f"unknown light field(s): {', '.join(sorted(bad))}")
    conv = {
        k: (np.asarray(v, dtype=np.float64).reshape(-1) if k in ("position", "direction", "color") else v)
        for k, v in changes.items()
    }
    for k in ("intensity", "inner_cone", "outer_cone"):
        if k in conv:
            conv[k] = float(conv[k])
    lights = [_copy_light(lt) for lt in scene.lights]
    lights[i] = _copy_light(scene.lights[i], **conv)
    return copy_lighting(scene, lights=lights)


def add_light(
    scene: Scene,
    kind: str = "point",
    position=None,
    *,
    direction=(0.0, -1.0, 0.0),
    color=(1.0, 1.0, 1.0),
    intensity: float | None = None,
    inner_cone: float = 0.3,
    outer_cone: float = 0.6,
    name: str | None = None,
) -> Scene:
    """A new Scene with one more light (appended, so existing indices stay).

    position : (3,) world; None puts it at the middle of the bounds, 85 % of the way up
    intensity : None picks one that lights the bounds' diagonal-sized room moderately
      (``diagonal**2 / 4`` W/sr)
    name : None makes a unique ``"<kind> <n>"``
    """
    lo, hi = scene.bounds
    if position is None:
        position = [(lo[0] + hi[0]) / 2, lo[1] + 0.85 * (hi[1] - lo[1]), (lo[2] + hi[2]) / 2]
    if intensity is None:
        intensity = float(np.linalg.norm(hi - lo)) ** 2 / 4.0
    names = {lt.name for lt in scene.lights}
    if name is None:
        k = 1
        while f"{kind} {k}" in names:
            k += 1
        name = f"{kind} {k}"
    lt = _checked_light(
        Light(
            kind=kind,
            position=np.asarray(position, dtype=np.float64),
            direction=np.asarray(direction, dtype=np.float64),
            color=np.asarray(color, dtype=np.float64),
            intensity=float(intensity),
            inner_cone=float(inner_cone),
            outer_cone=float(outer_cone),
            name=name,
        )
    )
    return copy_lighting(scene, lights=[_copy_light(x) for x in scene.lights] + [lt])


def delete_light(scene: Scene, index: int | str) -> Scene:
    """A new Scene without light ``index`` (or name); later lights move down by one."""
    i = _light_index(scene, index)
    return copy_lighting(scene, lights=[_copy_light(lt) for k, lt in enumerate(scene.lights) if k != i])


def set_emission(scene: Scene, material: int | str, emission) -> Scene:
    """A new Scene whose material ``material`` (index or name) emits ``emission``: (3,) linear
    RGB radiance, or a number (grey)."""
    i = _material_index(scene, material)
    e = np.broadcast_to(np.asarray(emission, dtype=np.float64), (3,)).copy()
    if not np.isfinite(e).all() or (e < 0).any():
        raise OptionError(
            f"emission of {scene.materials[i].name!r} must be finite and >= 0, got {e.tolist()}"
        )
    mats = [_copy_material(m) for m in scene.materials]
    mats[i] = _copy_material(scene.materials[i], emission=e)
    return copy_lighting(scene, materials=mats)


def emissive_materials(scene: Scene) -> list[int]:
    """Indices of the materials that emit (and are used by some patch)."""
    used = set(np.unique(scene.patch_material).tolist())
    return [i for i, m in enumerate(scene.materials) if i in used and np.any(m.emission > 0)]


def lights_only_changed(a: Scene, b: Scene) -> bool:
    """True when ``b`` differs from ``a`` at most in lights and emission (same patches, same
    albedos): then :func:`iat.radiosity.resolve` can continue from a solution of ``a``."""
    if a.n_patches != b.n_patches or len(a.materials) != len(b.materials):
        return False
    if not (a.vertices is b.vertices or np.array_equal(a.vertices, b.vertices)):
        return False
    if not np.array_equal(a.patch_corners, b.patch_corners) or not np.array_equal(
        a.patch_material, b.patch_material
    ):
        return False
    return all(np.array_equal(x.albedo, y.albedo) for x, y in zip(a.materials, b.materials, strict=True))


# -- lighting states ----------------------------------------------------------------------------------
def _read_gltf_json(path: Path) -> dict:
    """The JSON of a .glb / .gltf file (no buffers read)."""
    data = path.read_bytes()
    if path.suffix.lower() == ".glb" or data[:4] == b"glTF":
        if len(data) < 20 or data[:4] != b"glTF":
            raise LoadError("not a GLB file", path)
        length, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A:
            raise LoadError("GLB without a JSON chunk first", path)
        text = data[20 : 20 + length]
    else:
        text = data
    try:
        return json.loads(text)
    except (ValueError, UnicodeDecodeError) as e:
        raise LoadError(f"cannot parse the glTF JSON ({e})", path) from e


def _check_states(states: Any, where) -> dict[str, dict]:
    if not isinstance(states, dict):
        raise LoadError(f"{LIGHTING_STATES_KEY} must be an object of named states", where)
    out = {}
    for name, st in states.items():
        if not isinstance(st, dict):
            raise LoadError(f"lighting state {name!r} must be an object", where)
        unknown = set(st) - {"time", "lights", "emission", "label"}
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
        return _check_states(source, "lighting states")
    path = Path(source.path if isinstance(source, Scene) else source)
    if not str(path) or path.suffix.lower() not in (".glb", ".gltf") or not path.is_file():
        return {}
    doc = _read_gltf_json(path)
    extras = doc.get("extras")
    if not isinstance(extras, dict) or LIGHTING_STATES_KEY not in extras:
        return {}
    return _check_states(extras[LIGHTING_STATES_KEY], path)


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
    lights = [_copy_light(lt) for lt in scene.lights]
    names = [lt.name for lt in lights]
    for name, spec in (state.get("lights") or {}).items():
        if name not in names:
            raise OptionError(f"lighting state names light {name!r}, not in the scene ({', '.join(names)})")
        k = names.index(name)
        if isinstance(spec, int | float):
            lights[k] = _copy_light(lights[k], intensity=float(spec))
        elif isinstance(spec, dict):
            ch = {}
            if "intensity" in spec:
                ch["intensity"] = float(spec["intensity"])
            if "color" in spec:
                ch["color"] = np.asarray(spec["color"], dtype=np.float64).reshape(3)
            lights[k] = _copy_light(lights[k], **ch)
        else:
            raise OptionError(f"lighting state: light {name!r} must be a number or an object")
    mats = [_copy_material(m) for m in scene.materials]
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
        mats[k] = _copy_material(mats[k], emission=e)
    return copy_lighting(scene, lights=lights, materials=mats)


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
                lights.append(_copy_light(lt))
            else:
                ri = np.maximum(same.radiant_intensity, lt.radiant_intensity)
                s = float(ri.max())
                same.intensity, same.color = s, (ri / s if s > 0 else ri)
    mats = [
        _copy_material(m, emission=np.max([sc.materials[i].emission for sc in scenes], axis=0))
        for i, m in enumerate(first.materials)
    ]
    return copy_lighting(first, lights=lights, materials=mats)


# -- the editor ----------------------------------------------------------------------------------------
class LightEditor:
    """The lights of a scene being edited (the viewer's Lighting panel works through one).

    scene : the edited Scene (replaced, never changed in place, by every edit)
    base : the scene as loaded (its emission is what a strength of 1 means)
    sources : per light of ``scene``, its index among the file's point / spot lights in load
      order (None for a light added here): :func:`save_gltf` moves those nodes
    version : bumped by every edit (the background solve compares it)
    """

    def __init__(self, scene: Scene, sources: list[int | None] | None = None):
        self.base = scene
        self.scene = scene
        self.sources: list[int | None] = list(range(len(scene.lights))) if sources is None else list(sources)
        self.version = 0

    def _set(self, scene: Scene) -> Scene:
        self.scene = scene
        self.version += 1
        return scene

    @property
    def lights(self) -> list[Light]:
        return self.scene.lights

    def move(self, index: int, position) -> Scene:
        return self._set(edit_light(self.scene, index, position=position))

    def edit(self, index: int, **changes) -> Scene:
        return self._set(edit_light(self.scene, index, **changes))

    def add(self, kind: str = "point", position=None, **kw) -> int:
        """Add a light; returns its index."""
        self._set(add_light(self.scene, kind, position, **kw))
        self.sources.append(None)
        return len(self.scene.lights) - 1

    def delete(self, index: int) -> Scene:
        i = _light_index(self.scene, index)
        del self.sources[i]
        return self._set(delete_light(self.scene, i))

    def emissive(self) -> list[int]:
        """Materials that emit in the scene as loaded (their strength can be changed)."""
        return emissive_materials(self.base)

    def strength(self, material: int) -> float:
        """The emission of ``material`` now over its emission as loaded (by the largest channel)."""
        b = float(np.max(self.base.materials[material].emission))
        return float(np.max(self.scene.materials[material].emission)) / b if b > 0 else 0.0

    def set_strength(self, material: int, strength: float) -> Scene:
        """Emission of ``material`` = ``strength`` x its emission as loaded (0 switches it off)."""
        if not (math.isfinite(strength) and strength >= 0):
            raise OptionError(f"emission strength must be >= 0, got {strength!r}")
        e = np.asarray(self.base.materials[material].emission, dtype=np.float64) * float(strength)
        return self._set(set_emission(self.scene, material, e))

    def apply_state(self, state: dict) -> Scene:
        """Take the lights and emission of a lighting state (see :func:`apply_lighting_state`)."""
        return self._set(apply_lighting_state(self.scene, state, base=self.base))

    def save(self, dst, src=None, lighting_states: dict | None = None) -> Path:
        """Write the edited lights and emission into a copy of ``src`` (default: the scene's file)."""
        src = src if src is not None else self.base.path
        if not src:
            raise OptionError("the scene was not loaded from a file: give the glTF to patch (src=)")
        return save_gltf(self.scene, src, dst, sources=self.sources, lighting_states=lighting_states)


# -- saving back to glTF ------------------------------------------------------------------------------
def _quat_from_direction(direction) -> list[float]:
    """Rotation quaternion (x, y, z, w) taking the node's -Z to ``direction``."""
    from iat.io.glb import look_rotation, quat_from_matrix

    return [float(x) for x in quat_from_matrix(look_rotation(np.asarray(direction, dtype=np.float64)))]


def _atomic_write(path: Path, data: bytes) -> None:
    from iat.fsutil import atomic_write

    atomic_write(path, lambda f: f.write(data))


def _glb_bytes(json_text: str, blob: bytes | None) -> bytes:
    js = json_text.encode("utf-8")
    js += b" " * (-len(js) % 4)
    chunks = struct.pack("<II", len(js), 0x4E4F534A) + js
    if blob:
        b = bytes(blob) + b"\0" * (-len(blob) % 4)
        chunks += struct.pack("<II", len(b), 0x004E4942) + b
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def _emissive_write(mat, emission: np.ndarray, old: np.ndarray) -> bool:
    """Set a pygltflib material's emissiveFactor / strength so that it emits ``emission``
    (the file's own emission is ``old``); returns whether the strength extension is used."""
    emission = np.asarray(emission, dtype=np.float64)
    factor0 = np.asarray(mat.emissiveFactor or [0.0, 0.0, 0.0], dtype=np.float64)[:3]
    ext = dict(mat.extensions or {})
    s0 = float((ext.get(EXT_STRENGTH) or {}).get("emissiveStrength", 1.0))
    eff0 = factor0 * s0
    # keep an emissive texture's modulation: scale per channel where the file emitted
    ratio_ok = (old > 0) & (eff0 > 0)
    eff = np.where(ratio_ok, eff0 * np.divide(emission, old, out=np.zeros(3), where=old > 0), emission)
    strength = max(1.0, float(eff.max()))
    mat.emissiveFactor = [float(x) for x in eff / strength]
    if strength > 1.0:
        ext[EXT_STRENGTH] = {"emissiveStrength": strength}
    else:
        ext.pop(EXT_STRENGTH, None)
    mat.extensions = ext
    return strength > 1.0


def save_gltf(
    scene: Scene,
    src,
    dst,
    *,
    sources: list[int | None] | None = None,
    lighting_states: dict | None = None,
) -> Path:
    """Write ``dst``: the glTF ``src`` with ``scene``'s lights and emission (and lighting states).

    Patches the JSON with pygltflib and keeps the geometry bytes (a GLB's binary chunk is
    copied unchanged; a .gltf keeps its buffer URIs). Written atomically.

    - Lights: every point / spot light of ``src`` is replaced by ``scene.lights``: light k
      takes over the file's light ``sources[k]`` (its node is moved, or, when that node also
      holds a mesh, a camera or children, the light moves to a new node of its own), new
      lights (``None``) get new root nodes, file lights not taken over are removed from their
      nodes. ``sources`` None: by order when the counts match, else by name.
      Directional lights of the file stay.
    - Emission: materials are matched by name; where the emission differs from the file's,
      ``emissiveFactor`` and ``KHR_materials_emissive_strength`` are rewritten.
    - ``lighting_states``: written as the root ``extras["iat_lighting_states"]`` (checked).
    Returns ``dst``. Raises LoadError for an unreadable ``src``, OptionError for bad input.
    """
    from pygltflib import Node

    from iat.io.scene import _Gltf

    src, dst = Path(src), Path(dst)
    if not src.is_file():
        raise LoadError("no such file", src)
    gl = _Gltf(src)
    doc = gl.doc
    world = gl.node_world()
    ext = dict(doc.extensions or {})
    defs = list((ext.get(EXT_LIGHTS) or {}).get("lights", []))

    # the file's point / spot lights in load order: (node, definition)
    file_lights = []
    for i in sorted(world):
        node = doc.nodes[i]
        li = ((node.extensions or {}).get(EXT_LIGHTS) or {}).get("light")
        if li is None or not 0 <= li < len(defs):
            continue
        if defs[li].get("type", "point") in LIGHT_KINDS:
            file_lights.append((i, li))
    if sources is None:
        if len(file_lights) == len(scene.lights):
            sources = list(range(len(scene.lights)))
        else:
            names = [defs[li].get("name") or doc.nodes[i].name for i, li in file_lights]
            sources = [names.index(lt.name) if lt.name in names else None for lt in scene.lights]
    if len(sources) != len(scene.lights):
        raise OptionError(f"{len(sources)} light sources given for {len(scene.lights)} lights")

    # the definitions kept: those of nodes that are not point / spot lights (directional)
    kept_defs: list[dict] = []
    remap: dict[int, int] = {}
    for i, node in enumerate(doc.nodes):
        li = ((node.extensions or {}).get(EXT_LIGHTS) or {}).get("light")
        if li is None:
            continue
        if any(i == fi for fi, _ in file_lights) or not 0 <= li < len(defs):
            e = dict(node.extensions)
            e.pop(EXT_LIGHTS, None)
            node.extensions = e
            continue
        if li not in remap:
            remap[li] = len(kept_defs)
            kept_defs.append(defs[li])
        node.extensions = {**node.extensions, EXT_LIGHTS: {"light": remap[li]}}

    scene_index = (
        doc.scene if doc.scene is not None and doc.scenes and 0 <= doc.scene < len(doc.scenes) else 0
    )
    used_nodes: set[int] = set()
    for k, lt in enumerate(scene.lights):
        lt = _checked_light(_copy_light(lt))
        d: dict = {"name": lt.name or f"light_{k}", "type": lt.kind}
        d["color"] = [float(x) for x in lt.color]
        d["intensity"] = float(lt.intensity)
        if lt.kind == "spot":
            d["spot"] = {"innerConeAngle": float(lt.inner_cone), "outerConeAngle": float(lt.outer_cone)}
        src_k = sources[k]
        node_i = None
        if src_k is not None:
            if not 0 <= int(src_k) < len(file_lights):
                raise OptionError(
                    f"light {k}: source {src_k} is not one of the file's {len(file_lights)} lights"
                )
            node_i = file_lights[int(src_k)][0]
            node = doc.nodes[node_i]
            old = defs[file_lights[int(src_k)][1]]
            for key in ("range", "extras", "extensions"):
                if key in old:
                    d[key] = old[key]
            if (
                node_i in used_nodes
                or node.mesh is not None
                or node.camera is not None
                or node.children
                or node.skin is not None
            ):
                node_i = None  # the node carries more than the light: give the light a node of its own
        li = len(kept_defs)
        kept_defs.append(d)
        rot = _quat_from_direction(lt.direction) if lt.kind == "spot" else None
        if node_i is None:
            node = Node(
                name=d["name"],
                translation=[float(x) for x in lt.position],
                rotation=_quat_from_direction(lt.direction),
                extensions={EXT_LIGHTS: {"light": li}},
            )
            doc.nodes.append(node)
            node_i = len(doc.nodes) - 1
            if doc.scenes:
                doc.scenes[scene_index].nodes = list(doc.scenes[scene_index].nodes or []) + [node_i]
        else:
            node = doc.nodes[node_i]
            from iat.io.scene import _node_local

            parent = world[node_i] @ np.linalg.inv(_node_local(node))
            target = np.eye(4)
            if rot is not None:
                from iat.io.scene import _quat_matrix

                target[:3, :3] = _quat_matrix(rot)
            else:  # a point light keeps its orientation
                r = world[node_i][:3, :3]
                u, _, vt = np.linalg.svd(r)
                target[:3, :3] = u @ vt
            target[:3, 3] = lt.position
            if np.allclose(parent, np.eye(4), atol=1e-12):
                from iat.io.glb import quat_from_matrix

                node.matrix = None
                node.scale = None
                node.translation = [float(x) for x in lt.position]
                node.rotation = [float(x) for x in quat_from_matrix(target[:3, :3])]
            else:
                local = np.linalg.inv(parent) @ target
                node.matrix = [float(x) for x in local.T.reshape(-1)]
                node.translation = node.rotation = node.scale = None
            node.extensions = {**(node.extensions or {}), EXT_LIGHTS: {"light": li}}
        used_nodes.add(node_i)

    used = set(doc.extensionsUsed or [])
    if kept_defs:
        ext[EXT_LIGHTS] = {**(ext.get(EXT_LIGHTS) or {}), "lights": kept_defs}
        used.add(EXT_LIGHTS)
    else:
        ext.pop(EXT_LIGHTS, None)
        used.discard(EXT_LIGHTS)
    doc.extensions = ext

    # emission, by material name
    by_name = {m.name: m for m in scene.materials}
    strength_used = False
    for gi, gm in enumerate(doc.materials or []):
        name = gm.name or f"material_{gi}"
        m = by_name.get(name)
        old = np.asarray(gl.material(gi).emission, dtype=np.float64)
        if m is not None and not np.allclose(m.emission, old, rtol=1e-9, atol=0.0):
            strength_used |= _emissive_write(gm, m.emission, old)
        else:
            strength_used |= EXT_STRENGTH in (gm.extensions or {})
    if strength_used:
        used.add(EXT_STRENGTH)
    else:
        used.discard(EXT_STRENGTH)
    doc.extensionsUsed = sorted(used) if used else []

    if lighting_states is not None:
        extras = dict(doc.extras or {})
        extras[LIGHTING_STATES_KEY] = _check_states(lighting_states, "lighting_states")
        doc.extras = extras

    text = doc.gltf_to_json(separators=(",", ":"), indent=None)
    is_glb = src.suffix.lower() == ".glb"
    if is_glb:
        data = _glb_bytes(text, doc.binary_blob())
    else:
        data = text.encode("utf-8")
    _atomic_write(dst, data)
    log.info("wrote %s (%d lights) from %s", dst, len(scene.lights), src)
    return dst


# -- the background re-solve -------------------------------------------------------------------------
@dataclass
class RelightResult:
    """One published step of a :class:`Relighter`.

    solution, scene : the solution and the scene it lights (None and "error" on failure)
    step, steps : this step (1-based) of the effort schedule; ``final`` when step == steps
    version : the edit it answers (``submit``'s version)
    seconds : time of this step; total_seconds : since the edit was taken up
    mode : "resolve" (continued from the previous solution), "mesh" or "solve"
    """

    solution: Any
    scene: Any
    step: int
    steps: int
    version: int
    seconds: float = 0.0
    total_seconds: float = 0.0
    mode: str = "resolve"
    error: str | None = None

    @property
    def final(self) -> bool:
        return self.step == self.steps and self.error is None


class Relighter(LatestWorker):
    """Re-solves on a worker thread as lights change; the UI polls the newest improvement.

    solution, scene : the converged solution on screen and the scene it was solved for
    options : the solve options (default: the solution's own)
    schedule : coarser steps solved before the final one, as multiples of the final
      convergence (capped at 0.5); each step starts again from the last converged solution
      with more effort and is published as it arrives (the first after a fraction of the
      final time). The default (8, 2.5) with convergence 0.05 runs 0.4, 0.125, then 0.05.

    ``submit(scene)`` asks for the lights of ``scene`` (cancels the step in progress, except a
    first, coarse step, which finishes so that a continuous drag still shows progress);
    ``submit(scene, remesh=True)`` solves afresh (new adaptive mesh) instead. ``poll()``
    returns the newest result not yet returned.
    """

    def __init__(self, solution, scene, options=None, schedule=(8.0, 2.5), name: str = "iat-relight"):
        from iat.radiosity import SolveOptions

        self.base = solution
        self.base_scene = scene
        if options is None:
            try:
                options = SolveOptions.from_dict(solution.options)
            except Exception:  # an old or hand-made solution
                options = SolveOptions(max_depth=int(solution.max_depth))
        self.options = options
        self.schedule = tuple(float(c) for c in schedule)
        self._version = 0
        self._hold = False  # the step under way finishes even when a newer edit arrives
        super().__init__(name)

    @property
    def steps_done(self) -> int:
        """Steps published so far."""
        return self.published

    # -- UI side ---------------------------------------------------------------------------------
    def submit(self, scene, version: int | None = None, remesh: bool = False) -> None:
        with self._cv:
            self._version = self._version + 1 if version is None else int(version)
            self._request((scene, self._version, bool(remesh)))

    # -- worker ----------------------------------------------------------------------------------
    def _progress(self, fraction, message) -> bool:
        # the first (coarse) step always finishes, so a light dragged without pause still
        # shows a new solution every step's time; later steps give way to a newer edit
        if self._hold:
            with self._cv:
                return not self._stop
        return not self._superseded()

    def _work(self, request) -> None:
        from iat.radiosity import resolve, solve

        scene, version, remesh = request
        t_job = time.perf_counter()
        self._hold = False
        progress = self._progress
        try:
            final_conv = float(self.options.convergence)
            if remesh or not lights_only_changed(self.base_scene, scene):
                plan = [("solve", final_conv)]
            else:
                coarse = sorted({min(0.5, final_conv * m) for m in self.schedule}, reverse=True)
                plan = [("resolve", c) for c in coarse if c > final_conv] + [("resolve", final_conv)]
            for k, (how, conv) in enumerate(plan, 1):
                self._hold = k == 1 and len(plan) > 1
                if k > 1 and self._superseded():
                    break
                opts = dataclasses.replace(self.options, convergence=conv)
                t0 = time.perf_counter()
                if how == "solve":
                    sol = solve(scene, opts, progress)
                else:
                    try:
                        sol = resolve(self.base, scene, opts, progress)
                    except IATError:
                        raise
                    except Exception:  # a solver bug: solve afresh on the mesh, slower but right
                        log.warning("resolve failed, solving on the mesh instead", exc_info=True)
                        sol = solve(scene, opts, progress, mesh=self.base)
                if sol.stats.get("cancelled"):
                    break
                now = time.perf_counter()
                r = RelightResult(
                    sol,
                    scene,
                    k,
                    len(plan),
                    version,
                    now - t0,
                    now - t_job,
                    str(sol.stats.get("mode", how)),
                )
                if k == len(plan):
                    self.base, self.base_scene = sol, scene
                self._publish(r)
        except Exception as e:  # reported to the UI; the last good solution stays
            log.debug("relight failed:\n%s", traceback.format_exc())
            msg = str(e) if isinstance(e, IATError) else f"{type(e).__name__}: {e}"
            self._publish(RelightResult(None, scene, 0, 0, version, error=msg))
