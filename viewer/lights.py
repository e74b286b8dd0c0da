"""Lights of the Lighting panel: where a new one goes (:func:`new_light_position`) and how bright it
is (:func:`new_light_intensity`), of the order of the scene's own lighting; a point or spot light's
IES LM-63 distribution (:func:`load_ies`, :func:`ies_controls`)."""

from __future__ import annotations

import math

import numpy as np

from iat.errors import IATError
from iat.io.ies import read_ies
from iat.measure.photometry import intensity_from_candela, light_candela, light_lumens

#: the point and spot lights whose intensities a new light takes after (a sun is not a lamp)
LAMP_KINDS = ("point", "spot")


def new_light_intensity(scene) -> float:
    """Radiant intensity (W/sr) for a light added to ``scene``: the median of its point and spot
    lights' intensities; with none, the emitters' power spread over a sphere (``sum(pi L A) / 4 pi``,
    L the emitted radiance's largest channel, A the emitting area: a lamp as bright as all the
    emissive surfaces together); with neither, ``diagonal**2 / 100`` (a lamp that lights a room the
    size of the bounds dimly, a tenth of the light editor's default in distance)."""
    lit = [float(lt.intensity) for lt in scene.lights if lt.kind in LAMP_KINDS and lt.intensity > 0]
    if lit:
        return float(np.median(lit))
    if len(scene.materials) and scene.n_patches:
        emission = np.array([float(np.max(m.emission)) for m in scene.materials])[scene.patch_material]
        power = float(np.sum(math.pi * emission * np.asarray(scene.patch_area, dtype=np.float64)))
        if math.isfinite(power) and power > 0:
            return power / (4.0 * math.pi)
    lo, hi = scene.bounds
    d = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
    return d * d / 100.0 if math.isfinite(d) and d > 0 else 1.0


def new_light_position(scene, camera):
    """Where a new light goes: in front of ``camera`` (one fifth of the model's size), inside the
    model's bounds (5 % in from each side); None without a camera."""
    if camera is None:
        return None
    lo, hi = scene.bounds
    p = np.asarray(camera.eye) + np.asarray(camera.forward) * 0.2 * float(np.linalg.norm(hi - lo))
    m = 0.05 * (hi - lo)
    return np.clip(p, lo + m, hi - m)


def load_ies(editor, index: int, path) -> str:
    """Give light ``index`` of ``editor`` (a :class:`~iat.lighting.editor.LightEditor`) the IES
    distribution of the file ``path``: its ``ies``, and its intensity the file's peak candela in the
    light's colour (the one conversion, as a glTF light naming its file in ``extras.ies`` gets).
    Returns the status line; a bad file or a black light raises :class:`~iat.errors.IATError` (one
    line naming the file) and leaves the light as it was."""
    photometry = read_ies(path)
    lt = editor.lights[index]
    try:
        intensity = intensity_from_candela(photometry.peak, lt.color)
    except ValueError as e:
        raise IATError(f"cannot give it an IES distribution: {e}", path) from None
    editor.edit(index, ies=photometry, intensity=intensity)
    lt = editor.lights[index]
    return f"{lt.name}: IES {photometry.name}, {light_candela(lt):.0f} cd peak, {light_lumens(lt):.0f} lm"


def ies_controls(state, editor, index: int) -> None:
    """The selected point or spot light's IES row of the Lighting panel: a path field, "Load IES"
    (the re-solve follows, as for any edit; a bad file is an error line, the light unchanged), and
    with a distribution loaded its name, peak and flux and "No IES"."""
    from imgui_bundle import hello_imgui, imgui

    fields = state.requests.file_fields
    fields.setdefault("ies", "")
    imgui.set_next_item_width(-hello_imgui.em_size(6.0))
    _, fields["ies"] = imgui.input_text("IES file", fields["ies"])
    if imgui.button("Load IES") and fields["ies"].strip():
        try:
            state.messages.set_status(load_ies(editor, index, fields["ies"].strip()))
        except IATError as e:
            state.messages.set_error(str(e))
    lt = editor.lights[index]
    if lt.ies is not None:
        imgui.same_line()
        if imgui.button("No IES"):
            editor.edit(index, ies=None)
        else:
            imgui.text(f"{lt.ies.name}: {light_candela(lt):.0f} cd peak, {light_lumens(lt):.0f} lm")
