"""The light editor: the lights of a scene being edited, where each came from in the file, and
each emissive material's strength (a multiplier on its emission as loaded). The viewer's
Lighting panel works through one; :meth:`LightEditor.save` writes the edits back to glTF.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from iat.errors import OptionError
from iat.io.scene import Light, Scene
from iat.lighting.edits import (
    add_light,
    delete_light,
    edit_light,
    emissive_materials,
    light_index,
    set_emission,
)
from iat.lighting.save import save_gltf
from iat.lighting.states import apply_lighting_state


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
        i = light_index(self.scene, index)
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
