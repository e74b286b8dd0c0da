"""What both benchmark tools (:mod:`iat.tools.bench`, :mod:`iat.tools.chart`) report with: JSON-able
values, a bake's policy and memory report, and PSNR from a normalised mean squared error."""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

#: PSNR reported for identical images, in dB (JSON has no infinity)
PSNR_IDENTICAL = 200.0


def psnr_from(normalised_mse: float) -> float:
    """PSNR in dB of a mean squared error over the squared peak, capped at :data:`PSNR_IDENTICAL`."""
    if normalised_mse <= 0.0:
        return PSNR_IDENTICAL
    return min(PSNR_IDENTICAL, float(-10.0 * math.log10(normalised_mse)))


def jsonable(o):
    """``o`` with numpy arrays and scalars as lists and numbers, paths as strings, dict keys as
    strings and non-finite floats as None (what ``json.dumps`` writes as strict JSON)."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return jsonable(o.tolist())
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, Path):
        return str(o)
    return o


def policy_dict(policy) -> dict:
    """The fields of a bake policy (its ``to_dict``, a dataclass, or any object with attributes) as a dict."""
    if hasattr(policy, "to_dict"):
        return policy.to_dict()
    try:
        return asdict(policy)
    except TypeError:
        return dict(vars(policy))


def memory_report(baked) -> dict:
    """A baked model's memory report (``baked.memory``) as a dict."""
    mem = baked.memory
    return mem.to_dict() if hasattr(mem, "to_dict") else dict(vars(mem))


def texture_bytes(mem: dict) -> int:
    """Texture bytes of a :func:`memory_report`; KeyError if it has none."""
    for k in ("texture_bytes", "gpu_texture_bytes", "texture"):
        if k in mem:
            return int(mem[k])
    if "texture_mb" in mem:
        return int(round(float(mem["texture_mb"]) * 2**20))
    raise KeyError(f"memory report has no texture bytes: {sorted(mem)}")
