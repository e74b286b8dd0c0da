"""Light edits: change lights and emission without touching the geometry.

Everything here works on :class:`~iat.io.scene.Scene` objects and never changes one
in place: an edit returns a new Scene that shares the geometry arrays (vertices,
patches, UVs, detail textures) and owns copies of its lights and materials, so a
background solve can keep the scene it started from while the user edits on.

Edits: :func:`edit_light`, :func:`add_light`, :func:`delete_light`, :func:`set_emission`;
:func:`copy_light` / :func:`checked_light` copy and validate one light;
:func:`lights_only_changed` tells whether a re-solve may continue from an old solution.
:class:`iat.lighting.editor.LightEditor` keeps a sequence of edits.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from iat.errors import OptionError
from iat.io.scene import Light, Material, Scene

#: the light kinds the solver takes (directional lights are not supported)
LIGHT_KINDS = ("point", "spot", "directional")


def copy_light(lt: Light, **changes) -> Light:
    """A checked copy of ``lt`` with ``changes`` (Light fields) applied; see :func:`checked_light`."""
    kw = {
        "kind": lt.kind,
        "position": np.array(lt.position, dtype=np.float64),
        "direction": np.array(lt.direction, dtype=np.float64),
        "color": np.array(lt.color, dtype=np.float64),
        "intensity": float(lt.intensity),
        "inner_cone": float(lt.inner_cone),
        "outer_cone": float(lt.outer_cone),
        "name": lt.name,
        "angular_diameter": float(getattr(lt, "angular_diameter", Light().angular_diameter)),
        "ies": lt.ies,
    }
    kw.update(changes)
    return checked_light(Light(**kw))


def copy_material(m: Material, **changes) -> Material:
    """A copy of ``m`` (own albedo and emission arrays, shared detail texture) with ``changes``."""
    kw = {
        "name": m.name,
        "albedo": np.array(m.albedo),
        "emission": np.array(m.emission),
        "detail": m.detail,
        "transmission": float(m.transmission),
    }
    kw.update(changes)
    return Material(**kw)


def checked_light(lt: Light) -> Light:
    """``lt`` with its direction normalised; OptionError for a bad kind, vector, intensity or cone."""
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
    lights = [copy_light(lt) for lt in scene.lights] if lights is None else list(lights)
    materials = [copy_material(m) for m in scene.materials] if materials is None else list(materials)
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


def light_index(scene: Scene, index: int | str) -> int:
    """Position of light ``index`` (a name, or a position) in ``scene.lights``; OptionError if none."""
    return _named_index([lt.name for lt in scene.lights], index, "light")


def _material_index(scene: Scene, material: int | str) -> int:
    return _named_index([m.name for m in scene.materials], material, "material")


def edit_light(scene: Scene, index: int | str, **changes) -> Scene:
    """A new Scene with light ``index`` (or name) changed: any of ``position``, ``direction``,
    ``color``, ``intensity``, ``inner_cone``, ``outer_cone``, ``kind``, ``name``, ``ies`` (an
    :class:`~iat.io.ies.Photometry` or None).
    Raises :class:`~iat.errors.OptionError` on an unknown field or a bad value."""
    i = light_index(scene, index)
    allowed = {
        *("position", "direction", "color", "intensity", "inner_cone", "outer_cone", "kind", "name", "ies")
    }
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
    lights = [copy_light(lt) for lt in scene.lights]
    lights[i] = copy_light(scene.lights[i], **conv)
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
    lt = checked_light(
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
    return copy_lighting(scene, lights=[copy_light(x) for x in scene.lights] + [lt])


def delete_light(scene: Scene, index: int | str) -> Scene:
    """A new Scene without light ``index`` (or name); later lights move down by one."""
    i = light_index(scene, index)
    return copy_lighting(scene, lights=[copy_light(lt) for k, lt in enumerate(scene.lights) if k != i])


def set_emission(scene: Scene, material: int | str, emission) -> Scene:
    """A new Scene whose material ``material`` (index or name) emits ``emission``: (3,) linear
    RGB radiance, or a number (grey)."""
    i = _material_index(scene, material)
    e = np.broadcast_to(np.asarray(emission, dtype=np.float64), (3,)).copy()
    if not np.isfinite(e).all() or (e < 0).any():
        raise OptionError(
            f"emission of {scene.materials[i].name!r} must be finite and >= 0, got {e.tolist()}"
        )
    mats = [copy_material(m) for m in scene.materials]
    mats[i] = copy_material(scene.materials[i], emission=e)
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
