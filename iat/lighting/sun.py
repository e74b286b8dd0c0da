"""The sun over a day: where it stands, which way its light travels, how bright it is.

- :func:`solar_position` -- azimuth and elevation of the sun for a place and a moment, by the
  NOAA Global Monitoring Laboratory's solar-position formulas (the "Solar Calculator" and its
  ``NOAA_Solar_Calculations_day.xls`` spreadsheet, after Meeus, *Astronomical Algorithms*), with
  NOAA's approximate atmospheric refraction. NOAA states the method is accurate to about
  0.0167 degrees (1 arc minute) for the years 1800-2100, refraction aside.
- :func:`sun_direction` / :func:`light_direction` -- that position as a unit vector in scene
  coordinates (towards the sun / the way the light travels), given the scene's north and up.
- :func:`sun_light` -- an :class:`iat.io.scene.Light` of kind ``"directional"`` for it, with the
  clear-sky direct normal irradiance of :func:`clear_sky_dni` (Meinel, with Kasten-Young air mass)
  and optionally the reddening of low sun (:func:`sun_color`).
- :func:`day_times` and :func:`sun_states` -- a day's clock times, and the named lighting states
  (one per time) the day slider steps through.

Conventions: azimuth in degrees clockwise from geographic north (east 90, south 180, west 270);
elevation in degrees above the horizon, refraction-corrected unless ``refraction=False``;
latitude in degrees north (south negative), longitude in degrees east (west negative). Scene
coordinates are right-handed; by default Y is up and north is -Z, so east is +X.
"""

from __future__ import annotations

import datetime
import re
import zoneinfo
from collections.abc import Iterable, Sequence

import numpy as np

from iat.errors import OptionError
from iat.io.scene import Light

#: the J2000.0 epoch (2000-01-01 12:00 UT, Julian day 2451545.0)
J2000 = datetime.datetime(2000, 1, 1, 12, 0, 0, tzinfo=datetime.UTC)

#: Meinel & Meinel (1976) clear-sky model constants: DNI = S * A ** (AM ** P), W/m²
MEINEL_SOLAR_CONSTANT = 1353.0
MEINEL_TRANSMITTANCE = 0.7
MEINEL_EXPONENT = 0.678

#: effective wavelengths (micrometres) of linear R, G, B for the Rayleigh tint of :func:`sun_color`
RGB_WAVELENGTHS_UM = (0.65, 0.55, 0.45)


# --------------------------------------------------------------------------- solar position


def _utc_seconds_since_j2000(when) -> tuple[np.ndarray, bool]:
    """(seconds since J2000 as float64 array, whether ``when`` was one datetime)."""
    scalar = isinstance(when, datetime.datetime)
    items = [when] if scalar else list(np.asarray(when, dtype=object).ravel())
    out = np.empty(len(items))
    for i, t in enumerate(items):
        if not isinstance(t, datetime.datetime):
            raise OptionError(f"solar_position needs datetime.datetime values, got {type(t).__name__}")
        if t.tzinfo is None or t.tzinfo.utcoffset(t) is None:
            raise OptionError(
                f"solar_position needs a timezone-aware datetime, got naive {t.isoformat()} "
                "(give it a tzinfo, e.g. datetime.timezone.utc)"
            )
        out[i] = (t - J2000).total_seconds()
    if not scalar:
        out = out.reshape(np.shape(np.asarray(when, dtype=object)))
    return out, scalar


def _check_place(latitude_deg: float, longitude_deg: float) -> tuple[float, float]:
    lat, lon = float(latitude_deg), float(longitude_deg)
    if not -90.0 <= lat <= 90.0:  # also rejects NaN
        raise OptionError(f"latitude must be in [-90, 90] degrees, got {latitude_deg}")
    if not -180.0 <= lon <= 180.0:
        raise OptionError(f"longitude must be in [-180, 180] degrees, got {longitude_deg}")
    return lat, lon


def refraction_deg(elevation_deg):
    """NOAA's approximate atmospheric refraction, degrees, for a geometric (airless) elevation in
    degrees: the spreadsheet's piecewise formula (after Zimmerman's "Sun-pointing programs",
    standard atmosphere); 0 above 85 degrees. Added to the geometric elevation it gives the
    apparent one. Works on arrays."""
    e = np.asarray(elevation_deg, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.tan(np.radians(e))
        high = 58.1 / t - 0.07 / t**3 + 0.000086 / t**5
        near = 1735.0 + e * (-518.2 + e * (103.4 + e * (-12.79 + e * 0.711)))
        low = -20.772 / t
    arcsec = np.where(e > 85.0, 0.0, np.where(e > 5.0, high, np.where(e > -0.575, near, low)))
    return arcsec / 3600.0


def solar_position(latitude_deg: float, longitude_deg: float, when, refraction: bool = True):
    """The sun's (azimuth_deg, elevation_deg) seen from a place at a moment (NOAA algorithm).

    latitude_deg : degrees north, in [-90, 90]; longitude_deg : degrees east, in [-180, 180]
    when : a timezone-aware :class:`datetime.datetime`, or an array-like of them (any shape)
    refraction : add NOAA's approximate atmospheric refraction (:func:`refraction_deg`) to the
      elevation (the NOAA calculator's "corrected" elevation); False gives the geometric one

    Returns floats for one datetime, else two float64 arrays of ``when``'s shape: azimuth in
    degrees clockwise from geographic north in [0, 360), elevation in degrees above the horizon
    (negative below it; the refraction formula is applied there too, as NOAA does).

    The moment is taken as UT (no delta-T), as in NOAA's calculator. OptionError (one line) for a
    naive datetime or a latitude / longitude out of range.
    """
    lat, lon = _check_place(latitude_deg, longitude_deg)
    seconds, scalar = _utc_seconds_since_j2000(when)
    jc = seconds / 86400.0 / 36525.0  # Julian century

    # the sun's geometric mean longitude and anomaly, the orbit's eccentricity (degrees)
    mean_long = np.mod(280.46646 + jc * (36000.76983 + jc * 0.0003032), 360.0)
    mean_anom = 357.52911 + jc * (35999.05029 - 0.0001537 * jc)
    ecc = 0.016708634 - jc * (0.000042037 + 0.0000001267 * jc)
    m = np.radians(mean_anom)
    centre = (
        np.sin(m) * (1.914602 - jc * (0.004817 + 0.000014 * jc))
        + np.sin(2 * m) * (0.019993 - 0.000101 * jc)
        + np.sin(3 * m) * 0.000289
    )
    true_long = mean_long + centre
    omega = np.radians(125.04 - 1934.136 * jc)
    app_long = true_long - 0.00569 - 0.00478 * np.sin(omega)
    mean_obliq = 23.0 + (26.0 + (21.448 - jc * (46.815 + jc * (0.00059 - jc * 0.001813))) / 60.0) / 60.0
    obliq = mean_obliq + 0.00256 * np.cos(omega)
    decl = np.arcsin(np.sin(np.radians(obliq)) * np.sin(np.radians(app_long)))  # radians

    # equation of time (minutes)
    y = np.tan(np.radians(obliq / 2.0)) ** 2
    l0 = np.radians(mean_long)
    eq_time = 4.0 * np.degrees(
        y * np.sin(2 * l0)
        - 2 * ecc * np.sin(m)
        + 4 * ecc * y * np.sin(m) * np.cos(2 * l0)
        - 0.5 * y * y * np.sin(4 * l0)
        - 1.25 * ecc * ecc * np.sin(2 * m)
    )

    # true solar time (minutes) and hour angle (degrees): UT minutes of the day + EoT + 4 min/deg
    ut_minutes = np.mod(seconds / 60.0 + 720.0, 1440.0)  # J2000 is at noon
    tst = np.mod(ut_minutes + eq_time + 4.0 * lon, 1440.0)
    hour_angle = np.where(tst / 4.0 < 0, tst / 4.0 + 180.0, tst / 4.0 - 180.0)

    phi = np.radians(lat)
    cos_zen = np.sin(phi) * np.sin(decl) + np.cos(phi) * np.cos(decl) * np.cos(np.radians(hour_angle))
    zen = np.arccos(np.clip(cos_zen, -1.0, 1.0))
    elevation = 90.0 - np.degrees(zen)

    denom = np.cos(phi) * np.sin(zen)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_az = (np.sin(phi) * np.cos(zen) - np.sin(decl)) / denom
    az_from_south = np.degrees(np.arccos(np.clip(cos_az, -1.0, 1.0)))
    azimuth = np.where(
        hour_angle > 0, np.mod(az_from_south + 180.0, 360.0), np.mod(540.0 - az_from_south, 360.0)
    )
    # at a pole or with the sun in the zenith the azimuth is undefined: NOAA's calculator says
    # 180 (north of the equator) or 0
    azimuth = np.where(np.abs(denom) > 1e-9, azimuth, 180.0 if lat > 0 else 0.0)
    azimuth = np.mod(azimuth, 360.0)

    if refraction:
        elevation = elevation + refraction_deg(elevation)
    if scalar:
        return float(azimuth.reshape(-1)[0]), float(elevation.reshape(-1)[0])
    return azimuth, elevation


# --------------------------------------------------------------------------- directions


def _frame(north, up) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit (north, east, up) of the scene: north made horizontal (orthogonal to up), east = north x up."""
    u = np.asarray(up, dtype=np.float64).reshape(3)
    n = np.asarray(north, dtype=np.float64).reshape(3)
    if not (np.isfinite(u).all() and np.linalg.norm(u) > 0):
        raise OptionError(f"up must be a non-zero vector, got {u.tolist()}")
    u = u / np.linalg.norm(u)
    n = n - np.dot(n, u) * u
    if not (np.isfinite(n).all() and np.linalg.norm(n) > 1e-9):
        raise OptionError(f"north must be a vector not parallel to up, got {np.asarray(north).tolist()}")
    n = n / np.linalg.norm(n)
    return n, np.cross(n, u), u


def sun_direction(azimuth_deg: float, elevation_deg: float, north=(0.0, 0.0, -1.0), up=(0.0, 1.0, 0.0)):
    """(3,) float64 unit vector from the scene TOWARDS the sun, in scene coordinates.

    azimuth_deg : degrees clockwise from north (seen from above: north towards east)
    elevation_deg : degrees above the horizon
    north : the scene's north (made horizontal against ``up``); default -Z
    up : the scene's up; default +Y. East is north x up (+X for the defaults).
    """
    n, e, u = _frame(north, up)
    az, el = np.radians(float(azimuth_deg)), np.radians(float(elevation_deg))
    d = np.cos(el) * (np.cos(az) * n + np.sin(az) * e) + np.sin(el) * u
    return d / np.linalg.norm(d)


def light_direction(azimuth_deg: float, elevation_deg: float, north=(0.0, 0.0, -1.0), up=(0.0, 1.0, 0.0)):
    """(3,) float64 unit vector the sunlight travels along (from the sun towards the scene): minus
    :func:`sun_direction`; what :attr:`iat.io.scene.Light.direction` holds for a directional light."""
    return -sun_direction(azimuth_deg, elevation_deg, north, up)


# --------------------------------------------------------------------------- intensity, colour


def air_mass(elevation_deg):
    """Kasten & Young (1989) relative optical air mass for an (apparent) elevation in degrees:
    1 / (cos z + 0.50572 (96.07995 - z)^-1.6364), z the zenith angle in degrees; 1 at the zenith,
    about 38 at the horizon. NaN below the horizon. Works on arrays."""
    e = np.asarray(elevation_deg, dtype=np.float64)
    z = 90.0 - e
    with np.errstate(invalid="ignore", divide="ignore"):
        am = 1.0 / (np.cos(np.radians(z)) + 0.50572 * (96.07995 - z) ** -1.6364)
    return np.where(e >= 0.0, am, np.nan)


def clear_sky_dni(elevation_deg):
    """Clear-sky direct normal irradiance, W/m², of the sun at an (apparent) elevation in degrees:
    Meinel & Meinel (1976), DNI = 1353 * 0.7 ** (AM ** 0.678) with the Kasten-Young air mass AM
    (:func:`air_mass`); about 950 W/m² with the sun in the zenith, 910 at 60 degrees, 690 at 15,
    20 at the horizon, and 0 below it. Works on arrays (a float for a scalar)."""
    am = air_mass(elevation_deg)
    with np.errstate(invalid="ignore"):
        dni = MEINEL_SOLAR_CONSTANT * MEINEL_TRANSMITTANCE ** (am**MEINEL_EXPONENT)
    dni = np.where(np.isfinite(dni), dni, 0.0)
    return float(dni) if np.ndim(dni) == 0 else dni


def sun_color(elevation_deg: float) -> np.ndarray:
    """(3,) float64 linear RGB tint of direct sunlight at an (apparent) elevation in degrees: white
    with the sun in the zenith, warmer as its light crosses more air. Rayleigh scattering's extra
    loss beyond one air mass, exp(-tau(lambda) (AM - 1)) with tau = 0.008569 lambda^-4
    (1 + 0.0113 lambda^-2 + 0.00013 lambda^-4) (lambda in micrometres, R/G/B at 0.65/0.55/0.45),
    scaled so the largest channel is 1 (so the tint dims the light a little as it reddens).
    White below the horizon (the light is off there anyway)."""
    am = air_mass(elevation_deg)
    if not np.isfinite(am):
        return np.ones(3)
    lam = np.asarray(RGB_WAVELENGTHS_UM)
    tau = 0.008569 * lam**-4 * (1.0 + 0.0113 * lam**-2 + 0.00013 * lam**-4)
    c = np.exp(-tau * (float(am) - 1.0))
    return c / c.max()


def sun_light(
    direction_to_sun,
    illuminance: float | None = None,
    color=None,
    name: str = "sun",
    warm: bool = False,
    angular_diameter: float | None = None,
    up=(0.0, 1.0, 0.0),
) -> Light:
    """A directional :class:`iat.io.scene.Light` for the sun standing in ``direction_to_sun``.

    direction_to_sun : (3,) vector from the scene towards the sun (:func:`sun_direction`); the
      light's ``direction`` is minus it, normalised
    illuminance : W/m² per unit colour on a surface facing the sun (the light's ``intensity``);
      None: :func:`clear_sky_dni` at the sun's elevation above the plane normal to ``up`` (0 below it)
    color : (3,) linear RGB; None: white, or :func:`sun_color` when ``warm``
    angular_diameter : radians; None: the Light default (0.53 degrees)
    up : the scene's up (default +Y), for the elevation the defaults depend on
    """
    d = np.asarray(direction_to_sun, dtype=np.float64).reshape(3)
    norm = np.linalg.norm(d)
    if not (np.isfinite(d).all() and norm > 0):
        raise OptionError(f"direction_to_sun must be a non-zero vector, got {d.tolist()}")
    d = d / norm
    u = np.asarray(up, dtype=np.float64).reshape(3)
    if not (np.isfinite(u).all() and np.linalg.norm(u) > 0):
        raise OptionError(f"up must be a non-zero vector, got {u.tolist()}")
    elevation = float(np.degrees(np.arcsin(np.clip(np.dot(d, u) / np.linalg.norm(u), -1.0, 1.0))))
    if illuminance is None:
        illuminance = clear_sky_dni(elevation)
    elif not (np.isfinite(illuminance) and illuminance >= 0):
        raise OptionError(f"sun illuminance must be a number >= 0 W/m², got {illuminance}")
    if color is None:
        color = sun_color(elevation) if warm else np.ones(3)
    kw = {} if angular_diameter is None else {"angular_diameter": float(angular_diameter)}
    return Light(kind="directional", direction=-d, color=color, intensity=float(illuminance), name=name, **kw)


# --------------------------------------------------------------------------- a day


def _tzinfo(tz) -> datetime.tzinfo:
    if isinstance(tz, datetime.tzinfo):
        return tz
    if isinstance(tz, bool):
        raise OptionError(f"tz must be a tzinfo, an offset in hours or an IANA zone name, got {tz!r}")
    if isinstance(tz, int | float):
        if not -24.0 < float(tz) < 24.0:
            raise OptionError(f"a UTC offset must be in (-24, 24) hours, got {tz}")
        return datetime.timezone(datetime.timedelta(hours=float(tz)))
    if isinstance(tz, str):
        try:
            return zoneinfo.ZoneInfo(tz)
        except (zoneinfo.ZoneInfoNotFoundError, ValueError):
            raise OptionError(
                f"unknown time zone {tz!r} (give an IANA name such as 'Europe/Paris')"
            ) from None
    raise OptionError(f"tz must be a tzinfo, an offset in hours or an IANA zone name, got {tz!r}")


def _date(date) -> datetime.date:
    if isinstance(date, datetime.datetime):
        return date.date()
    if isinstance(date, datetime.date):
        return date
    if isinstance(date, str):
        try:
            return datetime.date.fromisoformat(date.strip())
        except ValueError:
            raise OptionError(f"date must be 'YYYY-MM-DD', got {date!r}") from None
    raise OptionError(f"date must be a datetime.date or 'YYYY-MM-DD', got {date!r}")


_HHMM = re.compile(r"^\s*(\d{1,2}):(\d{2})(?::(\d{2}))?\s*$")


def _seconds_of_day(t) -> int:
    """A clock time ('HH:MM', 'HH:MM:SS', hours as a number, or a datetime.time) as whole seconds
    after midnight, in [0, 86400]."""
    if isinstance(t, datetime.time):
        return t.hour * 3600 + t.minute * 60 + t.second
    if isinstance(t, str):
        m = _HHMM.match(t)
        if not m:
            raise OptionError(f"a time must be 'HH:MM' or hours as a number, got {t!r}")
        h, mi, s = int(m.group(1)), int(m.group(2)), int(m.group(3) or 0)
        if mi > 59 or s > 59 or h * 3600 + mi * 60 + s > 86400:
            raise OptionError(f"a time must be within 00:00 and 24:00, got {t!r}")
        return h * 3600 + mi * 60 + s
    if isinstance(t, int | float | np.integer | np.floating) and not isinstance(t, bool):
        if not 0.0 <= float(t) <= 24.0:
            raise OptionError(f"a time in hours must be within [0, 24], got {t}")
        return int(round(float(t) * 3600.0))
    raise OptionError(f"a time must be 'HH:MM' or hours as a number, got {t!r}")


def day_times(date, times: Iterable, tz) -> list[datetime.datetime]:
    """Timezone-aware datetimes of a day.

    date : a :class:`datetime.date` (or datetime: its date) or 'YYYY-MM-DD'
    times : clock times in the zone: 'HH:MM' / 'HH:MM:SS' strings, hours as numbers (6.5 is 06:30,
      rounded to the second), or :class:`datetime.time`; 24 / '24:00' is midnight ending the day
    tz : a :class:`datetime.tzinfo`, a fixed offset from UTC in hours (-7 for UTC-7), or an IANA
      zone name ('America/Denver', through :mod:`zoneinfo`, daylight saving included)
    """
    d, zone = _date(date), _tzinfo(tz)
    out = []
    for t in times:
        s = _seconds_of_day(t)
        day = d + datetime.timedelta(days=s // 86400)
        s %= 86400
        out.append(
            datetime.datetime(day.year, day.month, day.day, s // 3600, s // 60 % 60, s % 60, tzinfo=zone)
        )
    return out


def _label(t: datetime.datetime, start: datetime.date) -> str:
    if t.date() != start:  # 24:00
        return "24:00"
    return t.strftime("%H:%M:%S" if t.second else "%H:%M")


def sun_states(
    latitude: float,
    longitude: float,
    date,
    times: Sequence,
    tz,
    north=(0.0, 0.0, -1.0),
    up=(0.0, 1.0, 0.0),
    illuminance: float | None = None,
    warm: bool = False,
    spacing: str = "clock",
) -> dict[str, dict]:
    """Named lighting states, one per clock time, the sun placed for each.

    latitude, longitude : degrees (north, east); date, times, tz : as :func:`day_times`; times must
      increase strictly
    north, up : the scene's north and up (:func:`sun_direction`)
    illuminance : W/m² with the sun up (all times alike); None: :func:`clear_sky_dni` of each elevation
    warm : tint low sun with :func:`sun_color` (else white)
    spacing : how the states' ``time`` (the day slider, in [0, 1]) follows the clock: "clock" in
      proportion to the clock time from the first to the last, "even" evenly spaced in order

    Returns {label: state} in time order, the label 'HH:MM' ('HH:MM:SS' off the minute), each state
    {"time": float in [0, 1], "label": str,
     "sun": {"direction": [x, y, z] (unit, the way the light travels), "intensity": W/m²,
             "color": [r, g, b]},
     "elevation": degrees (refraction-corrected), "azimuth": degrees clockwise from north}
    as plain Python numbers (JSON-ready); a sun at or below the horizon has intensity 0 (its
    direction is still where it is, travelling upwards).
    """
    if spacing not in ("clock", "even"):
        raise OptionError(f"spacing must be 'clock' or 'even', got {spacing!r}")
    times = list(times)
    if not times:
        raise OptionError("sun_states needs at least one time")
    start = _date(date)
    when = day_times(start, times, tz)
    clock = np.array([(t - when[0]).total_seconds() for t in when])
    if len(clock) > 1 and not (np.diff(clock) > 0).all():
        raise OptionError(f"sun_states times must increase strictly, got {[str(t) for t in times]}")
    az, el = solar_position(latitude, longitude, when)
    if len(when) == 1:
        slider = np.zeros(1)
    elif spacing == "even":
        slider = np.linspace(0.0, 1.0, len(when))
    else:
        slider = clock / clock[-1]
    if illuminance is not None and not (np.isfinite(illuminance) and illuminance >= 0):
        raise OptionError(f"sun illuminance must be a number >= 0 W/m², got {illuminance}")
    states: dict[str, dict] = {}
    for t, a, e, s in zip(when, az, el, slider, strict=True):
        label = _label(t, start)
        if label in states:
            raise OptionError(f"sun_states: two times share the label {label}")
        up_now = e > 0.0
        power = (clear_sky_dni(e) if illuminance is None else float(illuminance)) if up_now else 0.0
        color = sun_color(e) if (warm and up_now) else np.ones(3)
        states[label] = {
            "time": float(s),
            "label": label,
            "sun": {
                "direction": [float(v) for v in light_direction(a, e, north, up)],
                "intensity": float(power),
                "color": [float(v) for v in color],
            },
            "elevation": float(e),
            "azimuth": float(a),
        }
    return states
