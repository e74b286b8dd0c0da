"""Sky radiance models for daylight: what a :class:`iat.io.scene.Sky` sends from each direction.

Conventions (the world of :mod:`iat.io.scene`: Y-up, right-handed):

- A direction ``d`` (unit (3,) vector) points from the scene out to the sky; its zenith angle is
  ``theta = acos(d_y)``. Below the horizon (``d_y < 0``) every kind sends ``sky.ground``; the
  horizon itself (``d_y == 0``) is sky.
- Radiance is linear RGB in W/(m² sr) per unit colour, as ``sky.radiance`` is.
- **Equirectangular images** (``Sky.image``, :func:`sky_equirect`) follow Mitsuba 3's ``envmap``
  emitter exactly (``src/emitters/envmap.cpp`` of Mitsuba 3.9, checked by rendering in
  ``tests/test_sky.py``), with the identity ``to_world``, so a Y-up world needs no transform:

    ``u = atan2(d_x, -d_z) / (2 pi)`` wrapped into ``[0, 1)``,  ``v = acos(d_y) / pi``;
    column ``x = u w - 0.5`` (periodic), row ``y = v (h - 1)`` (clamped), bilinear;

  i.e. pixel (row ``j``, column ``i``) of an (h, w) image is the radiance from
  ``theta = pi j / (h - 1)``, ``phi = 2 pi (i + 0.5) / w``,
  ``d = (sin phi sin theta, cos theta, -cos phi sin theta)``: row 0 is the zenith (+Y), row
  ``h - 1`` the nadir, and ``u = 0, 0.25, 0.5, 0.75`` look towards -Z, +X, +Z, -X (the image's
  left edge is -Z, its middle +Z). Rows sit on the poles (``h - 1`` intervals), columns at
  half-pixel centres.
- ``sky.rotation`` (radians) turns the image about +Y, right-handed: the image's direction
  ``d_img`` appears in the world at ``R_y(rotation) d_img``, where
  ``R_y(a) = [[cos a, 0, sin a], [0, 1, 0], [-sin a, 0, cos a]]`` (Mitsuba's
  ``ScalarTransform4f().rotate([0, 1, 0], degrees(a))``), so a positive rotation carries -Z
  towards -X.

The gathers of the solver call :func:`sky_radiance` on directions drawn by
:func:`cosine_directions`; :func:`sky_irradiance` is the numerical check of both, and
:func:`mitsuba_emitter` gives the same sky to a Mitsuba reference.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from numba import njit

from iat.errors import LoadError
from iat.io.scene import Sky
from iat.radiosity.sampling import concentric_disk, disk_to_hemisphere

SKY_KINDS = ("uniform", "cie_overcast", "preetham", "hdr")
#: file extensions :func:`load_hdr` reads (Radiance RGBE, OpenEXR, portable float map)
HDR_EXTENSIONS = (".hdr", ".pic", ".exr", ".pfm")

# ---------------------------------------------------------------------------------------------
# Preetham, Shirley & Smits, "A Practical Analytic Model for Daylight", SIGGRAPH 1999,
# Appendix A.2: Perez coefficients (A..E) linear in the turbidity T, per quantity Y, x, y.
# Rows: (slope, intercept) for A, B, C, D, E. The paper's printed four-digit values; Mitsuba 0.x
# (mitsuba-renderer/mitsuba, src/luminaires/sky.cpp, ported from the authors' code) uses the
# same numbers with five digits (e.g. Y: A = 0.17872 T - 1.46303), which agree to < 0.1 %.
_PEREZ_Y = np.array(
    [[0.1787, -1.4630], [-0.3554, 0.4275], [-0.0227, 5.3251], [0.1206, -2.5771], [-0.0670, 0.3703]]
)
_PEREZ_X = np.array(
    [[-0.0193, -0.2592], [-0.0665, 0.0008], [-0.0004, 0.2125], [-0.0641, -0.8989], [-0.0033, 0.0452]]
)
_PEREZ_YC = np.array(
    [[-0.0167, -0.2608], [-0.0950, 0.0092], [-0.0079, 0.2102], [-0.0441, -1.6537], [-0.0109, 0.0529]]
)
# zenith chromaticity: x_z = [T^2, T, 1] M [theta_s^3, theta_s^2, theta_s, 1]^T (same appendix)
_ZENITH_X = np.array(
    [
        [0.00166, -0.00375, 0.00209, 0.0],
        [-0.02903, 0.06377, -0.03202, 0.00394],
        [0.11693, -0.21196, 0.06052, 0.25886],
    ]
)
_ZENITH_Y = np.array(
    [
        [0.00275, -0.00610, 0.00317, 0.0],
        [-0.04214, 0.08970, -0.04153, 0.00516],
        [0.15346, -0.26756, 0.06670, 0.26688],
    ]
)
#: CIE XYZ -> linear sRGB (Rec. 709 primaries, D65 white); its inverse's middle row is
#: :data:`iat.color.LUMINANCE_WEIGHTS`, so the RGB keeps the luminance Y.
XYZ_TO_RGB = np.array(
    [
        [3.2404542, -1.5371385, -0.4985314],
        [-0.9692660, 1.8760108, 0.0415560],
        [0.0556434, -0.2040259, 1.0572252],
    ]
)
# grazing directions are clipped to 0.001 rad above the horizon (as Mitsuba 0.x does): the
# Perez term exp(B / cos theta) is then finite and continuous at the horizon
_GRAZING_COS = math.cos(0.5 * math.pi - 1e-3)


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _check_sky(sky: Sky) -> None:
    if sky.kind not in SKY_KINDS:
        raise ValueError(f"unknown sky kind {sky.kind!r} (one of {', '.join(SKY_KINDS)})")
    if sky.kind == "hdr":
        img = sky.image
        if img is None or np.ndim(img) != 3 or np.shape(img)[2] != 3 or min(np.shape(img)[:2]) < 2:
            shape = None if img is None else np.shape(img)
            raise ValueError(f"an 'hdr' sky needs an (h, w, 3) image with h, w >= 2, got {shape}")


# ---------------------------------------------------------------------------------------------
# radiance


def sky_radiance(sky: Sky, dirs: np.ndarray) -> np.ndarray:
    """Linear RGB radiance arriving from world directions.

    sky : the :class:`~iat.io.scene.Sky`
    dirs : (..., 3) unit vectors from the scene out to the sky (normalised here anyway)
    Returns (..., 3) float64 radiance, W/(m² sr): ``sky.ground`` where ``d_y < 0``, else
    - "uniform": ``sky.radiance``;
    - "cie_overcast": CIE standard overcast sky (Moon & Spencer 1942),
      ``radiance (1 + 2 cos theta) / 3`` (``radiance`` at the zenith, a third of it at the horizon);
    - "preetham": :func:`preetham_rgb` (zenith luminance 1) times ``radiance`` per channel;
    - "hdr": ``sky.image`` looked up bilinearly (module docstring: Mitsuba's envmap mapping, turned
      by ``sky.rotation`` about +Y) times ``radiance``.
    """
    _check_sky(sky)
    if sky.kind == "uniform":  # no direction needed beyond its side of the horizon
        below = (np.asarray(dirs)[..., 1] < 0.0)[..., None]
        return np.where(below, sky.ground, sky.radiance)
    d = _unit(dirs)
    shape = d.shape
    d = d.reshape(-1, 3)
    out = np.empty((len(d), 3))
    below = d[:, 1] < 0.0
    out[below] = sky.ground
    up = ~below
    du = d[up]
    if sky.kind == "cie_overcast":
        val = ((1.0 + 2.0 * np.clip(du[:, 1], 0.0, 1.0)) / 3.0)[:, None] * sky.radiance
    elif sky.kind == "preetham":
        val = preetham_rgb(du, sky.sun_direction, sky.turbidity) * sky.radiance
    else:
        val = equirect_lookup(sky.image, rotate_y(du, -sky.rotation)) * sky.radiance
    out[up] = val
    return out.reshape(shape)


#: grid points a side of the table the solver's sky gathers look a Preetham sky up in
#: (:class:`SkyTable`; 2 / 512 in the equal-area map: about a third of a degree)
SKY_TABLE_SIDE = 513


class SkyTable:
    """A sky as the solver's gathers read it: :meth:`radiance` is :func:`sky_radiance`, but for a
    Preetham sky bilinear in a table of it over the disc of the directions above the horizon
    (Lambert's equal-area map, ``(d_x, d_z) / sqrt(1 + d_y)``: as fine at the horizon as at the
    zenith; :data:`SKY_TABLE_SIDE` points a side; exact below the horizon), a sixth of the cost of
    its exponentials a direction."""

    def __init__(self, sky: Sky):
        _check_sky(sky)
        self.sky = sky
        self.table = None
        if sky.kind == "preetham":
            t = np.linspace(-1.0, 1.0, SKY_TABLE_SIDE)
            x, z = np.meshgrid(t, t, indexing="ij")
            rim = np.minimum(1.0, 1.0 / np.maximum(np.hypot(x, z), 1e-300))  # outside the disc: its rim
            x, z = x * rim, z * rim
            y = np.maximum(1.0 - x * x - z * z, 0.0)
            d = np.stack([x * np.sqrt(1.0 + y), y, z * np.sqrt(1.0 + y)], axis=-1)
            self.table = np.ascontiguousarray(sky_radiance(sky, d.reshape(-1, 3)).reshape(*x.shape, 3))

    def radiance(self, dirs: np.ndarray) -> np.ndarray:
        """(n, 3) float64 radiance, W/(m² sr), arriving from the unit directions ``dirs`` (n, 3)."""
        if self.table is None:
            return sky_radiance(self.sky, dirs)
        out = np.empty((len(dirs), 3))
        _table_radiance(self.table, self.sky.ground, np.ascontiguousarray(dirs, dtype=np.float64), out)
        return out

    def light(self, dirs: np.ndarray, free: np.ndarray) -> np.ndarray:
        """(..., 3) :meth:`radiance` along the unit directions ``dirs`` (..., 3) where ``free`` (...)
        is not 0 (some of the light gets in), else 0: the same values, the others not looked up. A
        uniform, tabled or CIE overcast sky in one compiled pass (:func:`seen_light`), without
        gathering the seen directions."""
        args = self.kernel_args()
        if args is None:
            out = np.zeros(dirs.shape)
            seen = free != 0
            out[seen] = self.radiance(dirs[seen])
            return out
        out = np.empty(dirs.shape)
        d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
        f = np.ascontiguousarray(free).reshape(-1)
        seen_light(*args, d, f, len(f), out.reshape(-1, 3))
        return out

    def kernel_args(self) -> tuple | None:
        """What :func:`seen_light` takes to look this sky up in a kernel: ``(kind, table, up,
        ground)`` (:data:`LIGHT_UNIFORM`, :data:`LIGHT_TABLE` or :data:`LIGHT_CIE`; the table, or a
        (2, 2, 3) placeholder; ``sky.radiance`` and ``sky.ground`` (3,) float64); None for an
        image (HDR) sky."""
        kinds = {"uniform": LIGHT_UNIFORM, "preetham": LIGHT_TABLE, "cie_overcast": LIGHT_CIE}
        if self.sky.kind not in kinds:
            return None
        table = self.table if self.table is not None else np.zeros((2, 2, 3))
        up, ground = (np.asarray(x, dtype=np.float64) for x in (self.sky.radiance, self.sky.ground))
        return kinds[self.sky.kind], table, up, ground


#: the kinds of sky :func:`seen_light` looks up
LIGHT_UNIFORM, LIGHT_TABLE, LIGHT_CIE = 0, 1, 2


@njit(cache=True, nogil=True, error_model="numpy")
def _table_radiance(table, ground, dirs, out):
    """:meth:`SkyTable.radiance`: bilinear in ``table`` (m, m, 3) over ``(d_x, d_z) / sqrt(1 + d_y)``
    in [-1, 1]^2."""
    for i in range(dirs.shape[0]):
        _table_one(table, ground, dirs, i, out)


@njit(cache=True, nogil=True, error_model="numpy")
def seen_light(kind, table, up, ground, dirs, free, n, out):
    """:meth:`SkyTable.light` of the first n directions into ``out[:n]`` (3,) each: the sky's
    radiance along ``dirs[i]`` (:func:`_light_one`) where ``free[i]`` is not 0, else 0. kind, table,
    up, ground: :meth:`SkyTable.kernel_args`. The sky's kernel (:mod:`.sky_traced`) calls it too."""
    for i in range(n):
        if free[i] != 0:
            _light_one(kind, table, up, ground, dirs, i, out)
        else:
            out[i, 0] = out[i, 1] = out[i, 2] = 0.0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _light_one(kind, table, up, ground, dirs, i, out):
    """The radiance from direction i of ``dirs`` (n, 3) into ``out[i]`` (3,), :func:`sky_radiance`'s
    arithmetic: ``ground`` (3,) below the horizon; above it ``up`` (3,) for :data:`LIGHT_UNIFORM`,
    bilinear in ``table`` (:func:`_table_one`) for :data:`LIGHT_TABLE`, the CIE overcast sky of
    zenith ``up`` for :data:`LIGHT_CIE`."""
    if kind == LIGHT_TABLE:
        _table_one(table, ground, dirs, i, out)
        return
    y = dirs[i, 1]
    if kind == LIGHT_CIE:  # the unit direction's y, as numpy's norm sums it
        n = math.sqrt(dirs[i, 0] * dirs[i, 0] + dirs[i, 1] * dirs[i, 1] + dirs[i, 2] * dirs[i, 2])
        y = y / max(n, 1e-300)
    if y < 0.0:
        for c in range(3):
            out[i, c] = ground[c]
    elif kind == LIGHT_CIE:
        f = (1.0 + 2.0 * min(max(y, 0.0), 1.0)) / 3.0
        for c in range(3):
            out[i, c] = f * up[c]
    else:
        for c in range(3):
            out[i, c] = up[c]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _table_one(table, ground, dirs, i, out):
    """Direction i of :func:`_table_radiance`."""
    cells = table.shape[0] - 1
    if dirs[i, 1] < 0.0:
        for c in range(3):
            out[i, c] = ground[c]
        return
    s = 1.0 / math.sqrt(1.0 + dirs[i, 1])
    u = (dirs[i, 0] * s + 1.0) * 0.5 * cells
    v = (dirs[i, 2] * s + 1.0) * 0.5 * cells
    a = min(max(int(u), 0), cells - 1)
    b = min(max(int(v), 0), cells - 1)
    fu = min(max(u - a, 0.0), 1.0)
    fv = min(max(v - b, 0.0), 1.0)
    for c in range(3):
        lo = table[a, b, c] + fv * (table[a, b + 1, c] - table[a, b, c])
        hi = table[a + 1, b, c] + fv * (table[a + 1, b + 1, c] - table[a + 1, b, c])
        out[i, c] = lo + fu * (hi - lo)


def cie_overcast_irradiance(zenith_radiance) -> np.ndarray:
    """(3,) the exact irradiance on an unoccluded horizontal plane under a CIE overcast sky of
    zenith radiance ``zenith_radiance`` (3,): ``7 pi L_z / 9``."""
    return 7.0 * np.pi / 9.0 * np.asarray(zenith_radiance, dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# Preetham clear sky


def _perez(coef: np.ndarray, cos_theta: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    a, b, c, d, e = coef
    return (1.0 + a * np.exp(b / cos_theta)) * (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2)


def _coefficients(table: np.ndarray, turbidity: float) -> np.ndarray:
    return table[:, 0] * turbidity + table[:, 1]


def preetham_zenith(turbidity: float, sun_theta: float) -> tuple[float, float, float]:
    """The zenith of Preetham's clear sky (the paper's Appendix A.2).

    turbidity : T (the model was fitted for 2 ... 10)
    sun_theta : the sun's zenith angle, radians (clipped to [0, pi/2])
    Returns (Y_z in kcd/m², x_z, y_z): ``chi = (4/9 - T/120)(pi - 2 theta_s)``,
    ``Y_z = (4.0453 T - 4.9710) tan chi - 0.2155 T + 2.4192``, and the chromaticities from the
    cubic-in-theta_s, quadratic-in-T polynomials.
    """
    t = float(turbidity)
    ts = min(max(float(sun_theta), 0.0), 0.5 * math.pi)
    chi = (4.0 / 9.0 - t / 120.0) * (math.pi - 2.0 * ts)
    yz = (4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192
    tv = np.array([t * t, t, 1.0])
    sv = np.array([ts**3, ts**2, ts, 1.0])
    return yz, float(tv @ _ZENITH_X @ sv), float(tv @ _ZENITH_Y @ sv)


def preetham_xyY(dirs: np.ndarray, sun_direction: np.ndarray, turbidity: float) -> np.ndarray:
    """Preetham's clear sky in CIE xyY, luminance relative to the zenith.

    dirs : (n, 3) unit directions with ``d_y >= 0`` (grazing ones are clipped to 0.001 rad above
      the horizon)
    sun_direction : (3,) towards the sun; a sun below the horizon is taken at the horizon (the
      model does not cover twilight)
    turbidity : T
    Returns (n, 3) float64 columns (x, y, Y / Y_z): ``q = q_z F_q(theta, gamma) / F_q(0, theta_s)``
    with Perez's ``F(theta, gamma) = (1 + A e^{B / cos theta})(1 + C e^{D gamma} + E cos² gamma)``,
    gamma the angle to the sun. The sun's disc itself is not part of the model.
    """
    d = _unit(dirs).reshape(-1, 3)
    s = _unit(sun_direction).reshape(3)
    if s[1] < 0.0:  # sun below the horizon: at the horizon, same azimuth
        hz = np.array([s[0], 0.0, s[2]])
        s = _unit(hz) if np.linalg.norm(hz) > 1e-12 else np.array([1.0, 0.0, 0.0])
    ts = math.acos(min(max(float(s[1]), 0.0), 1.0))
    cos_t = np.maximum(d[:, 1], _GRAZING_COS)
    gamma = np.arccos(np.clip(d @ s, -1.0, 1.0))
    t = float(turbidity)
    _yz, xz, yzc = preetham_zenith(t, ts)
    out = np.empty((len(d), 3))
    for k, (table, zenith) in enumerate(((_PEREZ_X, xz), (_PEREZ_YC, yzc), (_PEREZ_Y, 1.0))):
        c = _coefficients(table, t)
        ref = _perez(c, np.ones(1), np.array([ts]))[0]
        out[:, k] = zenith * _perez(c, cos_t, gamma) / ref
    return out


def xyY_to_rgb(xyY: np.ndarray) -> np.ndarray:
    """(n, 3) CIE xyY -> (n, 3) linear sRGB (Rec. 709, D65), negatives (out of gamut) clamped to 0."""
    x, y, Y = xyY[:, 0], xyY[:, 1], xyY[:, 2]
    ys = Y / np.maximum(y, 1e-12)
    xyz = np.stack([x * ys, Y, np.maximum(1.0 - x - y, 0.0) * ys], axis=1)
    return np.maximum(xyz @ XYZ_TO_RGB.T, 0.0)


def preetham_rgb(dirs: np.ndarray, sun_direction: np.ndarray, turbidity: float) -> np.ndarray:
    """(n, 3) float64 linear RGB of Preetham's clear sky normalised to luminance 1 at the zenith
    (the paper's kcd/m² divided by the zenith luminance :func:`preetham_zenith`); dirs as in
    :func:`preetham_xyY`."""
    return xyY_to_rgb(preetham_xyY(dirs, sun_direction, turbidity))


# ---------------------------------------------------------------------------------------------
# equirectangular images (Mitsuba 3 envmap convention, module docstring)


def rotate_y(dirs: np.ndarray, angle: float) -> np.ndarray:
    """(..., 3) directions turned by ``angle`` radians about +Y (right-handed, ``R_y`` above)."""
    c, s = math.cos(angle), math.sin(angle)
    d = np.asarray(dirs, dtype=np.float64)
    out = d.copy()
    out[..., 0] = c * d[..., 0] + s * d[..., 2]
    out[..., 2] = -s * d[..., 0] + c * d[..., 2]
    return out


def direction_to_equirect(dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Texture coordinates of directions (..., 3) (image frame): u in [0, 1) (azimuth,
    ``atan2(d_x, -d_z) / 2 pi``), v in [0, 1] (``acos(d_y) / pi``, 0 at the zenith)."""
    d = _unit(dirs)
    u = np.arctan2(d[..., 0], -d[..., 2]) / (2.0 * np.pi)
    u = u - np.floor(u)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u, v


def equirect_directions(height: int, width: int) -> np.ndarray:
    """(height, width, 3) float64 unit directions (image frame) of the pixels of an equirectangular
    image: row j at ``theta = pi j / (height - 1)``, column i at ``phi = 2 pi (i + 0.5) / width``,
    ``d = (sin phi sin theta, cos theta, -cos phi sin theta)``."""
    theta = np.pi * np.arange(height) / max(height - 1, 1)
    phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    sp, cp = np.sin(phi)[None, :], np.cos(phi)[None, :]
    return np.stack(np.broadcast_arrays(sp * st, ct, -cp * st), axis=-1)


def equirect_lookup(image: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(n, 3) float64 bilinear lookup of an (h, w, 3) equirectangular image at directions (n, 3)
    in the image's frame, exactly as Mitsuba 3's envmap evaluates it (columns periodic, rows
    clamped; module docstring)."""
    img = np.asarray(image)
    h, w = img.shape[:2]
    u, v = direction_to_equirect(dirs)
    x = u * w - 0.5
    x0 = np.floor(x)
    fx = x - x0
    i0 = x0.astype(np.int64) % w
    i1 = (i0 + 1) % w
    y = np.clip(v * (h - 1), 0.0, h - 1)
    j0 = np.minimum(y.astype(np.int64), h - 2)
    fy = (y - j0)[:, None]
    j1 = j0 + 1
    fx = fx[:, None]
    top = img[j0, i0] * (1.0 - fx) + img[j0, i1] * fx
    bot = img[j1, i0] * (1.0 - fx) + img[j1, i1] * fx
    return (top * (1.0 - fy) + bot * fy).astype(np.float64)


def sky_equirect(sky: Sky, width: int = 256) -> np.ndarray:
    """The sky rendered into an equirectangular image in Mitsuba's envmap convention.

    width : columns (>= 6); the image has ``width // 2`` rows
    Returns (width // 2, width, 3) float32: pixel (j, i) is :func:`sky_radiance` of the direction
    :func:`equirect_directions` gives it (ground included; ``rotation`` applied), so
    ``{"type": "envmap", "bitmap": mi.Bitmap(img)}`` with no ``to_world`` is this sky in a Y-up
    Mitsuba scene, up to the bilinear blur of one row (pi / (h - 1)) across the horizon.
    """
    width = int(width)
    if width < 6:
        raise ValueError(f"sky_equirect needs width >= 6 (Mitsuba's envmap takes >= 2 x 3), got {width}")
    h = width // 2
    dirs = equirect_directions(h, width)
    return sky_radiance(sky, dirs.reshape(-1, 3)).reshape(h, width, 3).astype(np.float32)


def mitsuba_emitter(sky: Sky, width: int | None = None) -> dict:
    """The sky as a Mitsuba 3 emitter dict (for ``mi.load_dict``; the caller has set a variant).

    A sky of one radiance everywhere ("uniform" with ``ground == radiance``) is a ``constant``
    emitter; any other (including "uniform" over a different ground, which ``constant`` cannot
    express) is an ``envmap`` of :func:`sky_equirect` passed as an in-memory ``mi.Bitmap``, with the
    identity ``to_world`` (Mitsuba's envmap is Y-up already). ``width`` of that image: the image's
    own for "hdr", else 512 (0.7° per pixel), unless given.
    """
    import mitsuba as mi

    _check_sky(sky)
    if sky.kind == "uniform" and np.array_equal(sky.ground, sky.radiance):
        return {"type": "constant", "radiance": {"type": "rgb", "value": [float(x) for x in sky.radiance]}}
    if width is None:
        width = max(int(np.shape(sky.image)[1]), 6) if sky.kind == "hdr" else 512
    return {"type": "envmap", "bitmap": mi.Bitmap(sky_equirect(sky, width))}


# ---------------------------------------------------------------------------------------------
# files


def load_hdr(path: str | Path) -> np.ndarray:
    """Read an equirectangular high-dynamic-range image.

    path : a Radiance RGBE ``.hdr`` / ``.pic``, an OpenEXR ``.exr`` or a ``.pfm`` file
    Returns (h, w, 3) float32 linear radiance, row 0 at the top of the file.
    Raises :class:`iat.errors.LoadError` (one line, naming the file) when the file is missing,
    unreadable, of another format, or when the reader (``opencv-python-headless``) is not installed.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in HDR_EXTENSIONS:
        raise LoadError(f"not a high-dynamic-range image (expected {', '.join(HDR_EXTENSIONS)})", p)
    if not p.is_file():
        raise LoadError("no such file", p)
    # OpenCV decodes OpenEXR only when asked to, through a variable it reads at its first .exr
    os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
    try:
        import cv2
    except ImportError:
        raise LoadError(
            f"reading {ext} needs the opencv-python-headless package (pip install opencv-python-headless)",
            p,
        ) from None
    try:
        data = np.fromfile(p, dtype=np.uint8)
        img = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR) if data.size else None
    except (OSError, cv2.error) as e:
        if "OpenEXR" in str(e):
            raise LoadError(
                "OpenCV's OpenEXR codec is disabled (set OPENCV_IO_ENABLE_OPENEXR=1 before the first .exr)", p
            ) from None
        msg = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise LoadError(f"cannot read the image ({msg[:200]})", p) from None
    if img is None:
        raise LoadError(f"cannot decode the file as a {ext} image (damaged or another format)", p)
    if img.dtype != np.float32 or img.ndim != 3 or img.shape[2] < 3:
        raise LoadError(f"not a floating-point RGB image (decoded as {img.dtype} {img.shape})", p)
    rgb = np.ascontiguousarray(img[..., 2::-1], dtype=np.float32)  # OpenCV's BGR -> RGB
    if not np.all(np.isfinite(rgb)):
        raise LoadError("the image holds NaN or infinite values", p)
    return rgb


# ---------------------------------------------------------------------------------------------
# integration and sampling


def sky_irradiance(sky: Sky, normal=(0.0, 1.0, 0.0), n: int = 256) -> np.ndarray:
    """(3,) float64 irradiance, W/m², on an unoccluded plane facing ``normal`` (3,), including the
    ground below the horizon: ``E = integral L(d) max(n . d, 0) dω``.

    Midpoint rule on the sphere in (theta, phi): ``n`` rows (rounded up to even, so the horizon is
    a row boundary and the ground's step is integrated exactly), ``2 n`` columns; ``n = 256``
    (131 072 directions) is within 1e-4 of the exact value for the analytic kinds.
    """
    nrm = _unit(normal).reshape(3)
    rows = int(n) + int(n) % 2
    cols = 2 * rows
    theta = (np.arange(rows) + 0.5) * (np.pi / rows)
    phi = (np.arange(cols) + 0.5) * (2.0 * np.pi / cols)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    d = np.stack(np.broadcast_arrays(np.sin(phi)[None, :] * st, ct, -np.cos(phi)[None, :] * st), axis=-1)
    d = d.reshape(-1, 3)
    w = np.maximum(d @ nrm, 0.0) * np.repeat(st[:, 0], cols) * (np.pi / rows) * (2.0 * np.pi / cols)
    keep = w > 0.0
    return w[keep] @ sky_radiance(sky, d[keep])


def tangent_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic orthonormal tangents (t, b), each (n, 3), with ``t x b = normal`` for unit
    normals (n, 3) (Duff et al., "Building an orthonormal basis, revisited", JCGT 2017: continuous
    except across ``n_z = 0`` with ``n_z < 0``)."""
    nrm = _unit(normals).reshape(-1, 3)
    x, y, z = nrm[:, 0], nrm[:, 1], nrm[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    bt = np.stack([b, sign + y * y * a, -y], axis=1)
    return t, bt


def cosine_directions(normals: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions on the hemispheres around normals.

    normals : (n, 3) unit normals
    u, v : (n, S) uniform numbers in [0, 1) (e.g. :func:`iat.radiosity.sampling.hash_uniform`)
    Returns (n, S, 3) float64 unit directions, density ``cos / pi`` per steradian: the
    Shirley-Chiu concentric disc (:func:`iat.radiosity.sampling.concentric_disk`) lifted to the
    hemisphere (Malley), in the frame :func:`tangent_frame`. With it the irradiance estimate of
    S samples is ``pi * mean(L(d))``.
    """
    t, b = tangent_frame(normals)
    nrm = _unit(normals).reshape(-1, 3)
    dx, dy = concentric_disk(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    return _unit(disk_to_hemisphere(dx, dy, t, b, nrm))
