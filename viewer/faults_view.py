"""The Model faults panel (issue 36): what the loader found wrong with the model, tinted in the 3D view.

**Model faults** (a tab beside View and Model): *Tint faults in the view*, then a checkbox per kind
(:data:`iat.geometry.faults.FAULTS`: inside-out solids turned, open sheets given a back face, faces
cut by a crossing element, faces a dropped repeat coincided with) with its colour and the patches
that carry it, the tint's strength, and ``iat info``'s counts of solids, sheets and elements. The
tint is drawn over the mesh, IAT, split and preview modes (:class:`iat.render.fault_tint.FaultTint`,
an overlay of the renderer); the patches' faults are found once per scene
(:func:`iat.geometry.faults.patch_faults`, on a thread of their own: 0.7 s for the Madrid house's
66 k patches, 2.5 s for the Tekla car wash's 165 k, on a loaded machine), when the panel is first
drawn or the tint turned on; the panel says so meanwhile.

The panel's choices live in a :class:`FaultsView` per app state (:func:`of`); :func:`frame` (the
app's per-frame call) hands them to the tint and draws the view again when they changed.
"""

from __future__ import annotations

import weakref
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from imgui_bundle import ImVec2, ImVec4, imgui

from iat.color import srgb_encode
from iat.geometry.faults import COLORS, FAULTS, LABELS, fault_counts, patch_faults
from iat.render.fault_tint import ALL, ALPHA, FaultTint
from viewer.panels import DIM
from viewer.state import AppState


@dataclass
class FaultsView:
    """The panel's choices and what the tint holds.

    enabled : tint on; shown : bits of the kinds tinted; alpha : the tint's share of a pixel
    scene, bits : the scene whose patches' faults ``bits`` (P,) uint8 are (None: not found yet);
      job : their search
    tint : the renderer's overlay once made; uploaded : the scene it holds; applied : the settings
      it was last given (a change draws the view again)
    """

    enabled: bool = False
    shown: int = ALL
    alpha: float = ALPHA
    scene: Any = None
    bits: np.ndarray | None = None
    job: Future | None = None
    tint: FaultTint | None = None
    uploaded: Any = None
    applied: tuple | None = None

    def find(self, scene) -> np.ndarray | None:
        """The faults of ``scene``'s patches, or None while they are being found (once per scene, on
        the search thread; its error is raised here)."""
        if self.scene is not scene:
            self.scene, self.bits, self.job = scene, None, _SEARCH.submit(patch_faults, scene)
        if self.bits is None and self.job.done():
            self.bits = self.job.result()
        return self.bits


_SEARCH = ThreadPoolExecutor(max_workers=1, thread_name_prefix="faults")


_VIEWS: dict[int, FaultsView] = {}


def of(state: AppState) -> FaultsView:
    """The :class:`FaultsView` of ``state`` (made on first use, dropped with the state)."""
    key = id(state)
    if key not in _VIEWS:
        _VIEWS[key] = FaultsView()
        weakref.finalize(state, _VIEWS.pop, key, None)
    return _VIEWS[key]


def panel(state: AppState) -> None:
    v, scene = of(state), state.model.scene
    if scene is None:
        imgui.text_disabled("no model open")
        return
    if getattr(scene, "faults", None) is None:
        imgui.text_disabled("no record of what the loader found\n(a scene rebuilt from its solution)")
        return
    _, v.enabled = imgui.checkbox("Tint faults in the view", v.enabled)
    bits = v.find(scene)
    if bits is None:
        imgui.text_disabled("finding the patches the faults lie on...")
    counts = fault_counts(bits if bits is not None else np.zeros(0, np.uint8))
    for k, name in enumerate(FAULTS):
        c = srgb_encode(np.asarray(COLORS[name], dtype=np.float64))
        imgui.color_button(f"##{name}", ImVec4(*c, 1.0), imgui.ColorEditFlags_.no_tooltip, ImVec2(14, 14))
        imgui.same_line()
        changed, on = imgui.checkbox(LABELS[name], bool(v.shown >> k & 1))
        if changed:
            v.shown = v.shown | (1 << k) if on else v.shown & ~(1 << k)
        imgui.same_line()
        imgui.text_colored(DIM, f"{counts[name]} patches" if bits is not None else "...")
    changed, a = imgui.slider_float("Tint", float(v.alpha), 0.1, 1.0, "%.2f")
    if changed:
        v.alpha = float(a)
    sd, pc = scene.sides, scene.pierce
    if sd is not None and pc is not None:  # iat info's counts
        imgui.text_colored(
            DIM,
            f"iat info: {sd.inside_out} inside-out solids, {sd.open_sheets} open sheets,\n"
            f"{pc.objects} intersecting elements, {sd.coincident_faces} coincident faces",
        )


def frame(app) -> None:
    """Hand the panel's choices to the renderer's tint (made when first turned on; the scene's
    faulty patches uploaded when it changed) and draw the view again when they changed."""
    if app.renderer is None or app.view3d is None:
        return
    v, scene = of(app.state), app.state.model.scene
    on = v.enabled and scene is not None and getattr(scene, "faults", None) is not None
    if on and v.tint is None:
        v.tint = FaultTint(app.ctx)
        app.renderer.overlays.append(v.tint)
    if v.tint is None:
        return
    if on and v.uploaded is not scene and v.find(scene) is not None:
        v.tint.set_scene(scene, v.bits)
        v.uploaded = scene
    key = (on, v.shown, v.alpha, id(v.uploaded))
    if key != v.applied:
        v.tint.enabled, v.tint.shown, v.tint.alpha = on, v.shown, v.alpha
        v.applied = key
        app.view3d.invalidate()
