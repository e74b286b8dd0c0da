"""The record of a solve's light sources (``stats['sources']``), which :func:`iat.radiosity.resolving.resolve`
compares with a scene's to find what changed."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from iat.io.ies import Photometry

#: the array fields of an IES record
_IES_ARRAYS = ("vertical", "horizontal", "candela")


def daylit(scene) -> bool:
    """``scene`` has a sky or a directional light (a sun)."""
    return getattr(scene, "sky", None) is not None or any(lt.kind == "directional" for lt in scene.lights)


def sources_record(ctx) -> dict:
    """JSON-able description of the light sources of a solve on ``ctx`` (a
    :class:`iat.radiosity.context.Context`): its point / spot lights and its emitting patches
    (``[patch, r, g, b]``, emitted radiance), whether a sun or a sky lit it (``daylight``), its suns
    (:func:`sun_record`) and its sky (:meth:`iat.io.scene.Sky.spec`, None without one or for an HDR
    image): what a scene reloaded from the model lacks when ``--sun`` / ``--sky`` gave them."""
    return {
        "lights": [light_record(lt) for lt in ctx.light.lights],
        "emitters": [[int(p), *(float(x) for x in ctx.patches.emission[p])] for p in ctx.patches.emitters],
        "daylight": bool(ctx.light.suns or ctx.light.sky is not None),
        "suns": [sun_record(lt) for lt in ctx.light.suns],
        "sky": ctx.light.sky.spec() if ctx.light.sky is not None else None,
    }


def sun_record(lt) -> dict:
    """JSON-able description of a directional light (direction its light travels, W/m² per colour)."""
    return {
        "name": str(lt.name),
        "direction": [float(x) for x in lt.direction],
        "radiant_intensity": [float(x) for x in lt.radiant_intensity],
        "angular_diameter": float(lt.angular_diameter),
    }


def light_record(lt) -> dict:
    """JSON-able description of one point / spot light (positions in scene units, cones in radians,
    its IES distribution's angles in degrees and candela, or None)."""
    ies = getattr(lt, "ies", None)
    return {
        "kind": lt.kind,
        "position": [float(x) for x in lt.position],
        "direction": [float(x) for x in lt.direction],
        "radiant_intensity": [float(x) for x in lt.radiant_intensity],
        "inner_cone": float(lt.inner_cone),
        "outer_cone": float(lt.outer_cone),
        "ies": None
        if ies is None
        else {
            "vertical": np.asarray(ies.vertical, dtype=np.float64).tolist(),
            "horizontal": np.asarray(ies.horizontal, dtype=np.float64).tolist(),
            "candela": np.asarray(ies.candela, dtype=np.float64).tolist(),
            "lumens": float(ies.lumens),
            "name": str(ies.name),
        },
    }


def light_from_record(d: dict):
    """A light-like object (what :meth:`DirectLight.light_irradiance` reads) from :func:`light_record`."""
    return SimpleNamespace(
        kind=d["kind"],
        position=np.asarray(d["position"], dtype=np.float64),
        direction=np.asarray(d["direction"], dtype=np.float64),
        radiant_intensity=np.asarray(d["radiant_intensity"], dtype=np.float64),
        inner_cone=float(d["inner_cone"]),
        outer_cone=float(d["outer_cone"]),
        ies=None
        if d.get("ies") is None
        else Photometry(**{k: np.asarray(v) if k in _IES_ARRAYS else v for k, v in d["ies"].items()}),
    )


def light_signature(lt) -> tuple:
    """Kind, position, direction, cones, IES distribution, and last the intensity of a light (for
    matching)."""
    ies = getattr(lt, "ies", None)
    return (
        lt.kind,
        None if ies is None else ies.digest(),
        tuple(np.round(np.asarray(lt.position, dtype=np.float64), 12)),
        tuple(np.round(np.asarray(lt.direction, dtype=np.float64), 12)),
        round(float(lt.inner_cone), 12),
        round(float(lt.outer_cone), 12),
        tuple(np.round(np.asarray(lt.radiant_intensity, dtype=np.float64), 12)),
    )
