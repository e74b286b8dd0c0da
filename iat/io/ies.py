"""IES LM-63 photometric files (LM-63-1995/2002): a luminaire's candela distribution.

:func:`read_ies` parses a file (``TILT=NONE`` or ``INCLUDE``; photometric type C, the one
architectural luminaires use) into a :class:`Photometry`: vertical angles (0 = nadir), horizontal
angles (C planes), candela ``(n_h, n_v)`` times the multiplier and ballast factor.
:meth:`Photometry.relative` gives the distribution over its peak for directions leaving the light:
a light holding one (``Light.ies``) has ``Light.intensity`` as its peak (W/sr per unit colour) and
shines ``intensity x relative`` along each direction, in the direct pass and when its receivers
shoot (:meth:`iat.radiosity.direct.DirectLight.light_kernel`). Its nadir is ``Light.direction``;
C = 0 lies along :func:`c_zero` of it. Horizontal symmetry as the file gives it: one angle
(axially symmetric), 0-90 (quadrants), 0-180 (bilateral), 0-360 (none).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iat.errors import LoadError


@dataclass(frozen=True, eq=False)
class Photometry:
    """vertical : (n_v,) degrees from nadir, increasing; horizontal : (n_h,) degrees, increasing;
    candela : (n_h, n_v) float64; lumens : the file's rated lumens (all lamps; -1: absolute);
    name : the file's name"""

    vertical: np.ndarray
    horizontal: np.ndarray
    candela: np.ndarray
    lumens: float = -1.0
    name: str = ""

    @property
    def peak(self) -> float:
        """The largest candela of the distribution."""
        return float(self.candela.max())

    def digest(self) -> bytes:
        h = hashlib.sha1()
        for a in (self.vertical, self.horizontal, self.candela):
            h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
        return h.digest()

    def candela_at(self, gamma_deg, c_deg) -> np.ndarray:
        """(...) candela at vertical angles ``gamma_deg`` (from nadir) and C angles ``c_deg``, bilinear
        in the table; 0 outside its vertical range."""
        g = np.asarray(gamma_deg, dtype=np.float64)
        c = np.mod(np.asarray(c_deg, dtype=np.float64), 360.0)
        last = float(self.horizontal[-1])
        if len(self.horizontal) == 1:
            c = np.zeros_like(c)
        elif last <= 90.0 + 1e-9:  # quadrant symmetry
            c = np.mod(c, 180.0)
            c = np.where(c > 90.0, 180.0 - c, c)
        elif last <= 180.0 + 1e-9:  # bilateral symmetry
            c = np.where(c > 180.0, 360.0 - c, c)
        v, h, cd = self.vertical, self.horizontal, self.candela
        gi = np.clip(np.searchsorted(v, g, side="right") - 1, 0, max(len(v) - 2, 0))
        if len(v) > 1:
            gt = np.clip((g - v[gi]) / (v[gi + 1] - v[gi]), 0.0, 1.0)
        else:
            gt = np.zeros_like(g)
        gj = np.minimum(gi + 1, len(v) - 1)
        if len(h) > 1:
            ci = np.clip(np.searchsorted(h, c, side="right") - 1, 0, len(h) - 2)
            ct = np.clip((c - h[ci]) / (h[ci + 1] - h[ci]), 0.0, 1.0)
            cj = ci + 1
        else:
            ci = cj = np.zeros_like(gi)
            ct = np.zeros_like(g)
        lo = cd[ci, gi] * (1 - gt) + cd[ci, gj] * gt
        hi = cd[cj, gi] * (1 - gt) + cd[cj, gj] * gt
        out = lo * (1 - ct) + hi * ct
        inside = (g >= v[0] - 1e-9) & (g <= v[-1] + 1e-9)
        return np.where(inside, out, 0.0)

    def solid_angle(self) -> float:
        """Steradians of the peak that give the flux: ``integral relative dw`` (lumens = peak x
        this), over 16 384 directions of a Fibonacci sphere."""
        k = np.arange(16384) + 0.5
        z = 1.0 - 2.0 * k / 16384
        phi = np.pi * (1.0 + 5.0**0.5) * k
        r = np.sqrt(1.0 - z * z)
        d = np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1)
        return float(4.0 * np.pi * self.relative(d, (0.0, -1.0, 0.0)).mean())

    def relative(self, dirs, nadir) -> np.ndarray:
        """(n,) the distribution over its peak along unit directions ``dirs`` (n, 3) leaving the light,
        whose nadir (vertical angle 0) is the unit vector ``nadir`` (3,)."""
        d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        a = np.asarray(nadir, dtype=np.float64).reshape(3)
        a = a / max(float(np.linalg.norm(a)), 1e-300)
        t1 = c_zero(a)
        t2 = np.cross(a, t1)
        gamma = np.degrees(np.arccos(np.clip(d @ a, -1.0, 1.0)))
        c = np.degrees(np.arctan2(d @ t2, d @ t1))
        peak = self.peak
        return self.candela_at(gamma, c) / peak if peak > 0 else np.zeros(len(d))


def c_zero(nadir) -> np.ndarray:
    """(3,) the C = 0 direction of a light whose nadir is ``nadir``: world +X projected off it (+Z
    when the nadir is along X)."""
    a = np.asarray(nadir, dtype=np.float64).reshape(3)
    a = a / max(float(np.linalg.norm(a)), 1e-300)
    ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    t = ref - (ref @ a) * a
    return t / np.linalg.norm(t)


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def parse_ies(text: str, name: str = "") -> Photometry:
    """A :class:`Photometry` of an LM-63 file's text; ValueError (one line) when it is not one."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    tilt = next((k for k, ln in enumerate(lines) if ln.strip().upper().startswith("TILT")), None)
    if tilt is None:
        raise ValueError("not an IES LM-63 file (no TILT= line)")
    kind = lines[tilt].split("=", 1)[-1].strip().upper()
    nums = [float(x) for x in _NUMBER.findall(" ".join(lines[tilt + 1 :]))]
    if kind == "INCLUDE":  # lamp-to-luminaire geometry, n pairs of angles and factors
        if len(nums) < 2:
            raise ValueError("TILT=INCLUDE without its table")
        n = int(nums[1])
        nums = nums[2 + 2 * n :]
    elif kind != "NONE":
        raise ValueError(f"TILT={kind}: a tilt file is not read (give TILT=NONE or INCLUDE)")
    if len(nums) < 13:
        raise ValueError("the photometric header is cut short")
    lamps, lumens, mult, n_v, n_h, ptype = nums[:6]
    ballast = nums[10]
    n_v, n_h = int(n_v), int(n_h)
    if int(ptype) != 1:
        raise ValueError(f"photometric type {int(ptype)} (only type C, 1, is read)")
    body = nums[13:]
    if n_v < 1 or n_h < 1 or len(body) < n_v + n_h + n_v * n_h:
        raise ValueError(f"{n_v} vertical x {n_h} horizontal angles announced, {len(body)} numbers follow")
    v = np.array(body[:n_v])
    h = np.array(body[n_v : n_v + n_h])
    cd = np.array(body[n_v + n_h : n_v + n_h + n_v * n_h]).reshape(n_h, n_v) * mult * (ballast or 1.0)
    if np.any(np.diff(v) <= 0) or np.any(np.diff(h) < 0) or not np.isfinite(cd).all() or (cd < 0).any():
        raise ValueError("angles must increase and candela be finite and >= 0")
    return Photometry(v, h, cd, float(lamps * lumens) if lumens > 0 else -1.0, name)


def read_ies(path) -> Photometry:
    """:func:`parse_ies` of a file; LoadError naming it on any fault."""
    path = Path(path)
    try:
        text = path.read_text(encoding="latin-1")
    except OSError as e:
        raise LoadError(f"cannot read IES file: {e.strerror or e}", path) from None
    try:
        return parse_ies(text, path.name)
    except ValueError as e:
        raise LoadError(f"IES file: {e}", path) from None
