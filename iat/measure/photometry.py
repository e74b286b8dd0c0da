"""Photometric units: one conversion from the solver's radiometric values to lux, cd/m², lm, cd.

The solver works in radiometric units per unit of linear RGB colour (W/sr for point and spot lights,
W/m² for a sun, W/(m² sr) for radiance and the sky). Every photometric figure IAT prints or draws
comes from those by **one** conversion (``docs/photometry.md``)::

    photometric = LUMINOUS_EFFICACY x (LUMINANCE_WEIGHTS . rgb)        LUMINOUS_EFFICACY = 179 lm/W

179 lm/W is RADIANCE's ``WHTEFFICACY``: the luminous efficacy of equal-energy white light over the
visible band (683 lm/W at 555 nm times the mean of V(lambda) from 380 to 780 nm). It is chosen over
683 lm/W because our RGB values are broadband, not monochromatic green: 683 would make a white
(1, 1, 1) W/m² read 683 lux, the efficacy of a 555 nm laser, while 179 makes it read what RADIANCE's
``rtrace -I`` users get from ``179 x (0.265 R + 0.670 G + 0.065 B)``, so figures can be compared
with RADIANCE's. The weights are our linear Rec. 709 luminance (:data:`iat.color.LUMINANCE_WEIGHTS`),
RADIANCE's are those of its own primaries. Ratios (daylight factor, uniformity) do not depend on the
constant. The daylight model's W/m² (Meinel's sun, Haurwitz's sky) are broadband solar, whose real
efficacy is about 105 lm/W (sun) to 125 lm/W (overcast sky): read with 179 lm/W their lux are about
1.5-1.7 x those of a daylight meter, and only the daylight factor is free of that.

Lights given photometrically: :func:`intensity_from_candela`, :func:`intensity_from_lumens` give the
radiometric ``Light.intensity`` (per unit colour) that yields that many candela or lumens.
glTF files are read as before (their candela taken as W/sr per unit colour): such a light of
``intensity`` I shows ``179 I Y(colour)`` cd.
"""

from __future__ import annotations

import math

import numpy as np

from iat.color import LUMINANCE_WEIGHTS, LUMINOUS_EFFICACY
from iat.geometry import quadtree as qt

#: albedo at or below which a surface's irradiance cannot be read from its radiance (NaN there)
ALBEDO_FLOOR = 1e-4


def photometric(rgb) -> np.ndarray:
    """(...) float64 ``LUMINOUS_EFFICACY x luminance`` of radiometric linear RGB values (..., 3):
    irradiance W/m² -> illuminance lux, radiance W/(m² sr) -> luminance cd/m², W/sr -> cd, W -> lm."""
    return LUMINOUS_EFFICACY * (np.asarray(rgb, dtype=np.float64)[..., :3] @ LUMINANCE_WEIGHTS)


def illuminance(irradiance) -> np.ndarray:
    """(...) lux of irradiance (..., 3) W/m² per unit colour."""
    return photometric(irradiance)


def luminance(radiance) -> np.ndarray:
    """(...) cd/m² of radiance (..., 3) W/(m² sr) per unit colour."""
    return photometric(radiance)


def _colour_luminance(color) -> float:
    y = float(np.asarray(color, dtype=np.float64).reshape(3) @ LUMINANCE_WEIGHTS)
    if not y > 0:
        raise ValueError(f"a light's colour must have a positive luminance, got {np.ravel(color).tolist()}")
    return y


def intensity_from_candela(candela: float, color=(1.0, 1.0, 1.0)) -> float:
    """``Light.intensity`` (W/sr per unit colour) of a point or spot light of ``candela`` cd (on its
    axis) in ``color``."""
    return float(candela) / (LUMINOUS_EFFICACY * _colour_luminance(color))


def cone_solid_angle(kind: str, outer_cone: float = math.pi / 4) -> float:
    """Steradians a light's flux is spread over: 4 pi for a point light, the outer cone's
    ``2 pi (1 - cos outer)`` for a spot (as the solver's ``light_power`` counts it)."""
    if kind == "point":
        return 4.0 * math.pi
    if kind == "spot":
        return 2.0 * math.pi * (1.0 - math.cos(float(outer_cone)))
    raise ValueError(f"lumens apply to point and spot lights, not {kind!r}")


def intensity_from_lumens(
    lumens: float, kind: str = "point", outer_cone: float = math.pi / 4, color=(1, 1, 1)
):
    """``Light.intensity`` (W/sr per unit colour) of a point or spot light emitting ``lumens`` lm:
    ``lumens / solid angle`` cd (:func:`cone_solid_angle`; a spot's whole flux inside its outer cone,
    its edge fall-off ignored), then :func:`intensity_from_candela`."""
    return intensity_from_candela(float(lumens) / cone_solid_angle(kind, outer_cone), color)


def light_candela(light) -> float:
    """cd of a point or spot light (its axis), W/sr x colour read with the one conversion."""
    return float(photometric(light.radiant_intensity))


def light_lumens(light) -> float:
    """lm of a point or spot light (:func:`light_candela` x :func:`cone_solid_angle`, or x the
    IES distribution's :meth:`~iat.io.ies.Photometry.solid_angle`)."""
    if getattr(light, "ies", None) is not None:
        return light_candela(light) * light.ies.solid_angle()
    return light_candela(light) * cone_solid_angle(light.kind, light.outer_cone)


def ies_light(photometry, position, direction=(0.0, -1.0, 0.0), color=(1.0, 1.0, 1.0), name: str = ""):
    """A point light of an IES distribution (:func:`iat.io.ies.read_ies`) at ``position``, its nadir
    along ``direction``: ``intensity`` the file's peak candela through the one conversion."""
    from iat.io.scene import Light

    return Light(
        kind="point",
        position=position,
        direction=direction,
        color=color,
        intensity=intensity_from_candela(photometry.peak, color),
        ies=photometry,
        name=name or photometry.name,
    )


def sun_illuminance(light) -> float:
    """lux on a surface facing a directional light (the sun) of ``intensity`` W/m² x colour."""
    return float(photometric(light.radiant_intensity))


def vertex_patch(solution) -> np.ndarray:
    """(V,) int64 the patch of each of a solution's vertices."""
    return qt.decode_key(np.asarray(solution.vert_key, dtype=np.int64), 1 << int(solution.max_depth))[0]


def surface_mean(solution, values, patches=None) -> dict:
    """Area statistics of per-vertex ``values`` (V,) over the solution's drawn triangles (linear over
    each, as drawn), NaN vertices' triangles left out: ``{"mean", "min", "max", "area"}`` (area in
    m²), over the patches ``patches`` ((P,) bool, default all)."""
    d = solution.drawn_mesh()
    v = d.radiance(np.repeat(np.asarray(values, dtype=np.float64).reshape(-1, 1), 3, axis=1))[:, 0]
    tri = np.asarray(d.triangles, dtype=np.int64).reshape(-1, 3)
    if patches is not None:
        tri = tri[np.asarray(patches, dtype=bool)[d.patch[tri[:, 0]]]]
    vt = v[tri]
    keep = np.isfinite(vt).all(axis=1)
    tri, vt = tri[keep], vt[keep]
    p = d.position
    area = 0.5 * np.linalg.norm(np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), axis=1)
    total = float(area.sum())
    if total <= 0:
        return {"mean": float("nan"), "min": float("nan"), "max": float("nan"), "area": 0.0}
    return {
        "mean": float((area * vt.mean(axis=1)).sum() / total),
        "min": float(vt.min()),
        "max": float(vt.max()),
        "area": total,
    }


def vertex_irradiance(solution, patch_emission=None) -> np.ndarray:
    """(V, 3) float64 irradiance W/m² at a solution's vertices: ``pi (L - L_e) / rho`` of a diffuse
    surface (what it reflects divided by its albedo; exact at the vertices, as their radiance is),
    NaN where the albedo of a channel is at or below ``ALBEDO_FLOOR`` (black or glass surfaces keep
    no trace of what they receive).

    patch_emission : (P, 3) emitted radiance per patch (``scene.patch_emission``), or None (none)
    """
    patch = vertex_patch(solution)
    rad = np.asarray(solution.vert_radiance, dtype=np.float64)
    if patch_emission is not None:
        rad = rad - np.asarray(patch_emission, dtype=np.float64).reshape(-1, 3)[patch]
    rho = np.asarray(solution.patch_albedo, dtype=np.float64).reshape(-1, 3)[patch]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(rho > ALBEDO_FLOOR, np.pi * np.maximum(rad, 0.0) / rho, np.nan)
    tau = np.asarray(getattr(solution, "patch_transmission", np.zeros(0)), dtype=np.float64).reshape(-1)
    if len(tau):
        out[tau[patch] > 0] = np.nan
    return out


def vertex_illuminance(solution, patch_emission=None) -> np.ndarray:
    """(V,) lux at a solution's vertices (:func:`vertex_irradiance`; NaN where it is unknown)."""
    return illuminance(vertex_irradiance(solution, patch_emission))


def vertex_luminance(solution) -> np.ndarray:
    """(V,) cd/m² leaving a solution's vertices (emission included)."""
    return luminance(solution.vert_radiance)
