"""Daylight by default: the sun and a clear sky at the model's own place when it brings no light.

A model with no light source (no lamp, no sky, no emissive material: every IFC file, most CAD
exports) would solve black. :func:`apply_daylight` gives it instead

- **the place**: an IFC file's site (:func:`iat.io.site.read_ifc_site`: ``IfcSite`` RefLatitude /
  RefLongitude, TrueNorth), else :data:`DEFAULT_PLACE` (a glTF, OBJ or other format, or an IFC
  site without a location);
- **the moment**: :data:`DEFAULT_HOUR` (10:00) on the coming equinox (:func:`coming_equinox`: 20
  March or 22 September, the first on or after today), clock time in the zone of the longitude
  (:func:`zone_hours`: ``round(longitude / 15)`` hours from UTC; IFC files give no time zone);
- **the sun**: NOAA's position there and then (:func:`iat.lighting.sun.solar_position`), turned by
  true north, with Meinel's clear-sky direct normal irradiance (:func:`iat.lighting.sun.clear_sky_dni`);
- **the sky**: Preetham's clear sky (turbidity :data:`DEFAULT_TURBIDITY`) towards that sun, scaled so
  that it sends the clear sky's diffuse horizontal irradiance (:func:`clear_sky_diffuse`:
  Haurwitz's global irradiance less the direct part), times ``sky_scale``;

and says so in one line (:meth:`Daylight.summary`). The command line's ``--sun``, ``--sky``,
``--north``, ``--sky-scale`` and ``--no-daylight`` (:class:`DaylightRequest`) change it, the same
way in ``iat solve``, ``bake``, ``render``, ``view`` and ``batch``; the viewer's Sun & sky panel
edits a :class:`Daylight`.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iat.errors import OptionError
from iat.io.scene import Light, Scene, Sky
from iat.io.site import north_angle, north_vector, read_ifc_site
from iat.lighting.sun import clear_sky_dni, day_times, solar_position, sun_direction, sun_light

#: where a model with no site stands: (latitude, longitude, name)
DEFAULT_PLACE = (48.85, 2.35, "Paris")
#: the clock hour of the default daylight (in the longitude's zone)
DEFAULT_HOUR = 10.0
#: the default clear sky's turbidity (Preetham: 2 very clear ... 10 hazy)
DEFAULT_TURBIDITY = 3.0
#: the equinoxes the default date is taken from: (month, day)
EQUINOXES = ((3, 20), (9, 22))
#: Haurwitz (1945) clear-sky global horizontal irradiance: 1098 cos z exp(-0.057 / cos z) W/m²
HAURWITZ = (1098.0, 0.057)
#: an overcast sky's horizontal irradiance as a fraction of the clear sky's global one
OVERCAST_FRACTION = 0.3
#: the sky models the panel and ``--sky`` offer beside the file-format ones
SKY_MODELS = ("clear", "overcast", "uniform", "none")
#: how a user changes the default (the end of the one line)
HOW_TO_CHANGE = "change with --sun [LAT,LON,]YYYY-MM-DDTHH:MM[,TZ], --sky KIND or --no-daylight"


# --------------------------------------------------------------------------- defaults


def coming_equinox(today: datetime.date | None = None) -> datetime.date:
    """The first of 20 March and 22 September on or after ``today`` (default: today's date)."""
    today = today or datetime.date.today()
    for year in (today.year, today.year + 1):
        for month, day in EQUINOXES:
            d = datetime.date(year, month, day)
            if d >= today:
                return d
    raise AssertionError("unreachable")


def zone_hours(longitude: float) -> float:
    """The time zone of a longitude when a file gives none: ``round(longitude / 15)`` hours from
    UTC, in [-12, 12] (Madrid, 3.71 W: UTC+0; the civil zones of many countries differ)."""
    return float(min(max(round(float(longitude) / 15.0), -12), 12))


def clear_sky_global(elevation_deg: float) -> float:
    """Haurwitz's clear-sky global horizontal irradiance, W/m², at an elevation in degrees (0 at or
    below the horizon)."""
    s = math.sin(math.radians(float(elevation_deg)))
    if s <= 0.0:
        return 0.0
    a, b = HAURWITZ
    return a * s * math.exp(-b / s)


def clear_sky_diffuse(elevation_deg: float) -> float:
    """The clear sky's diffuse horizontal irradiance, W/m²: :func:`clear_sky_global` less the direct
    part (:func:`iat.lighting.sun.clear_sky_dni` times sin of the elevation), at least 10 % of the
    global (about 90 W/m² with the sun at 35 degrees, 100 at 60)."""
    g = clear_sky_global(elevation_deg)
    direct = float(clear_sky_dni(elevation_deg)) * math.sin(math.radians(float(elevation_deg)))
    return max(g - direct, 0.1 * g)


def _sky_unit_irradiance(sky: Sky) -> float:
    """Horizontal irradiance (green channel) of ``sky`` at radiance scale 1."""
    from iat.radiosity.sky import sky_irradiance

    unit = dataclasses.replace(sky, radiance=np.ones(3))
    return float(sky_irradiance(unit, n=128)[1])


# --------------------------------------------------------------------------- one setting


@dataclass
class Daylight:
    """The sun and sky of a place at a moment (what the default chooses and the panel edits).

    latitude, longitude : degrees north / east (west negative)
    date : the day; hour : clock hours in [0, 24] in the zone ``tz_hours`` (None: :func:`zone_hours`)
    north_deg : true north, degrees from the scene's -Z, anticlockwise seen from above (an IFC's
      TrueNorth; :func:`iat.io.site.north_vector`)
    sun_on : the sun is there (its light is 0 below the horizon anyway)
    sky_model : "clear" (Preetham of ``turbidity`` at the clear sky's diffuse irradiance), "overcast"
      (CIE overcast at :data:`OVERCAST_FRACTION` of the clear sky's global irradiance), "uniform" (one
      radiance everywhere, at the clear sky's diffuse irradiance), "none"
    sky_scale : the sky's brightness factor (1: the model's own figure)
    custom_sky : a sky given as such (``--sky uniform:...``, ``preetham:T``, ``hdr:FILE``): replaces
      ``sky_model``; a "preetham" one is turned towards the sun
    place : where the place came from, for the one line ("IfcSite #148 'Default'", "default place")
    """

    latitude: float
    longitude: float
    date: datetime.date
    hour: float = DEFAULT_HOUR
    tz_hours: float | None = None
    north_deg: float = 0.0
    sun_on: bool = True
    sky_model: str = "clear"
    turbidity: float = DEFAULT_TURBIDITY
    sky_scale: float = 1.0
    custom_sky: Sky | None = field(default=None, compare=False)
    place: str = ""

    def __post_init__(self):
        if not -90.0 <= float(self.latitude) <= 90.0:
            raise OptionError(f"latitude must be in [-90, 90] degrees, got {self.latitude}")
        if not -180.0 <= float(self.longitude) <= 180.0:
            raise OptionError(f"longitude must be in [-180, 180] degrees, got {self.longitude}")
        if not 0.0 <= float(self.hour) <= 24.0:
            raise OptionError(f"hour must be in [0, 24], got {self.hour}")
        if self.sky_model not in SKY_MODELS:
            raise OptionError(f"sky model must be one of {', '.join(SKY_MODELS)}, got {self.sky_model!r}")
        if not 1.0 <= float(self.turbidity) <= 20.0:
            raise OptionError(f"turbidity must be in [1, 20], got {self.turbidity:g}")
        if not (math.isfinite(self.sky_scale) and self.sky_scale >= 0):
            raise OptionError(f"sky scale must be a number >= 0, got {self.sky_scale!r}")

    # -- where and when
    @property
    def tz(self) -> float:
        """Hours from UTC of the clock ``hour`` is read on."""
        return zone_hours(self.longitude) if self.tz_hours is None else float(self.tz_hours)

    def when(self) -> datetime.datetime:
        return day_times(self.date, [float(self.hour)], self.tz)[0]

    def position(self) -> tuple[float, float]:
        """The sun's (azimuth, elevation) in degrees (NOAA, refraction-corrected)."""
        return solar_position(self.latitude, self.longitude, self.when())

    def north(self) -> np.ndarray:
        return north_vector(self.north_deg)

    def to_sun(self) -> np.ndarray:
        """(3,) unit vector from the scene towards the sun, true north applied."""
        az, el = self.position()
        return sun_direction(az, el, north=self.north())

    def illuminance(self) -> float:
        """The sun's W/m² on a surface facing it: the clear-sky DNI, 0 when off or down."""
        _, el = self.position()
        return float(clear_sky_dni(el)) if self.sun_on and el > 0 else 0.0

    # -- the lights
    def sun(self) -> Light | None:
        """The directional light ``sun``, or None (off, or below the horizon)."""
        power = self.illuminance()
        if power <= 0:
            return None
        return sun_light(self.to_sun(), illuminance=power, name="sun")

    def sky(self) -> Sky | None:
        """The sky around the model, or None."""
        to_sun = self.to_sun()
        if self.custom_sky is not None:
            sky = dataclasses.replace(self.custom_sky)
            if sky.kind == "preetham":
                sky.sun_direction = to_sun
            return sky
        if self.sky_model == "none" or self.sky_scale <= 0:
            return None
        _, el = self.position()
        if self.sky_model == "clear":
            sky = Sky(
                kind="preetham", turbidity=float(self.turbidity), sun_direction=to_sun, name="clear sky"
            )
            target = clear_sky_diffuse(el)
        elif self.sky_model == "uniform":
            sky = Sky(kind="uniform", name="uniform sky")
            target = clear_sky_diffuse(el)
        else:
            sky = Sky(kind="cie_overcast", name="overcast sky")
            target = OVERCAST_FRACTION * clear_sky_global(el)
        if target <= 0:
            return None
        sky.radiance = np.full(3, self.sky_scale * target / _sky_unit_irradiance(sky))
        return sky

    def apply(self, scene: Scene) -> Scene:
        """Put this sun (replacing the scene's directional lights) and sky into ``scene``, in place;
        returns it."""
        sun = self.sun()
        scene.lights = [lt for lt in scene.lights if lt.kind != "directional"] + ([sun] if sun else [])
        scene.sky = self.sky()
        return scene

    # -- words
    def clock_text(self) -> str:
        h = int(round(float(self.hour) * 60))
        tz = self.tz
        sign = "+" if tz >= 0 else "-"
        zone = f"UTC{sign}{abs(tz):g}"
        return f"{self.date.isoformat()} {h // 60:02d}:{h % 60:02d} {zone}"

    def place_text(self) -> str:
        lat, lon = float(self.latitude), float(self.longitude)
        text = f"{abs(lat):.2f} {'N' if lat >= 0 else 'S'}, {abs(lon):.2f} {'E' if lon >= 0 else 'W'}"
        return f"{text} ({self.place})" if self.place else text

    def sky_text(self) -> str:
        sky = self.sky()
        if sky is None:
            return "no sky"
        if self.custom_sky is not None:
            return f"{sky.kind} sky"
        _, el = self.position()
        if self.sky_model == "clear":
            e = self.sky_scale * clear_sky_diffuse(el)
            return f"clear sky (Preetham, turbidity {self.turbidity:g}, {e:.0f} W/m² diffuse)"
        if self.sky_model == "uniform":
            return f"uniform sky ({self.sky_scale * clear_sky_diffuse(el):.0f} W/m² diffuse)"
        e = self.sky_scale * OVERCAST_FRACTION * clear_sky_global(el)
        return f"overcast sky (CIE, {e:.0f} W/m² diffuse)"

    def sun_text(self) -> str:
        az, el = self.position()
        if not self.sun_on:
            return f"sun off (azimuth {az:.1f} deg, elevation {el:.1f} deg)"
        if el <= 0:
            return f"sun below the horizon (elevation {el:.1f} deg)"
        return f"sun at azimuth {az:.1f} deg, elevation {el:.1f} deg, {self.illuminance():.0f} W/m²"

    def summary(self) -> str:
        """One line: where, when, the sun, the sky."""
        north = f", true north {self.north_deg:+.1f} deg" if abs(self.north_deg) > 1e-9 else ""
        return f"{self.place_text()}{north}, {self.clock_text()}: {self.sun_text()}; {self.sky_text()}"

    def to_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("latitude", "longitude", "hour", "tz_hours", "north_deg")}
        d.update(
            date=self.date.isoformat(),
            sun_on=self.sun_on,
            sky_model=self.sky_model,
            turbidity=self.turbidity,
            sky_scale=self.sky_scale,
            place=self.place,
            custom_sky=None if self.custom_sky is None else self.custom_sky.kind,
        )
        return d

    def key(self) -> str:
        """A short text naming this setting (a cache file's suffix)."""
        import hashlib
        import json

        spec = self.to_dict()
        if self.custom_sky is not None:
            spec["custom_sky"] = self.custom_sky.spec() or "hdr"
        return hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()[:12]

    def with_changes(self, **changes) -> Daylight:
        return dataclasses.replace(self, **changes)


def site_daylight(scene: Scene | None = None, path: str | Path | None = None, today=None) -> Daylight:
    """The default :class:`Daylight` of a model: its IFC site's place and north, else
    :data:`DEFAULT_PLACE` (north -Z); the coming equinox at :data:`DEFAULT_HOUR`."""
    path = path if path is not None else (scene.path if scene is not None else "")
    site = read_ifc_site(path) if path else None
    date = coming_equinox(today)
    if site is not None and site.has_location:
        return Daylight(site.latitude, site.longitude, date, north_deg=site.true_north_deg, place=site.source)
    lat, lon, name = DEFAULT_PLACE
    why = "the file gives no site" if site is None else f"{site.source}: no location"
    north = site.true_north_deg if site is not None else 0.0
    return Daylight(lat, lon, date, north_deg=north, place=f"default place, {name}: {why}")


# --------------------------------------------------------------------------- the flags


@dataclass(frozen=True)
class DaylightRequest:
    """What ``--sun``, ``--sky``, ``--sky-scale``, ``--north`` and ``--no-daylight`` asked for (text as
    given; :func:`apply_daylight` reads it). Picklable and JSON-ready (``iat batch`` ships it)."""

    sun: str | None = None
    sky: str | None = None
    sky_scale: float = 1.0
    north: str | None = None
    enabled: bool = True

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @property
    def explicit(self) -> bool:
        return bool(self.sun or self.sky)


SUN_FORMS = "--sun must be [LAT,LON,]YYYY-MM-DDTHH:MM[,TZ], HH:MM or off"
_TIME_ONLY = re.compile(r"^\d{1,2}:\d{2}$")


def parse_sun_text(text: str) -> dict:
    """``--sun``: ``LAT,LON,YYYY-MM-DDTHH:MM[,TZ]``, ``YYYY-MM-DDTHH:MM[,TZ]`` (at the model's place),
    ``HH:MM`` (on the default date) or ``off`` -> the :class:`Daylight` fields it sets. TZ: hours
    from UTC or an IANA zone name (then converted at that date); default: UTC for a place given, the
    longitude's zone otherwise."""
    t = text.strip()
    if t.lower() == "off":
        return {"sun_on": False}
    if _TIME_ONLY.match(t):
        hours = day_times("2000-01-01", [t], 0.0)[0]
        return {"hour": hours.hour + hours.minute / 60.0}
    parts = [p.strip() for p in t.split(",")]
    out: dict = {}
    if len(parts) in (3, 4):
        try:
            out["latitude"], out["longitude"] = float(parts[0]), float(parts[1])
        except ValueError:
            raise OptionError(
                f"--sun must be [LAT,LON,]YYYY-MM-DDTHH:MM[,TZ], HH:MM or off, got {text!r}"
            ) from None
        out["tz_hours"] = 0.0
        out["place"] = "--sun"
        parts = parts[2:]
    if len(parts) not in (1, 2) or "T" not in parts[0]:
        raise OptionError(f"{SUN_FORMS}, got {text!r}")
    date, _, clock = parts[0].partition("T")
    tz: str | float | None = parts[1] if len(parts) == 2 else out.get("tz_hours")
    try:
        tz = float(tz) if tz is not None else None
    except ValueError:
        pass
    when = day_times(date, [clock or "12:00"], 0.0 if tz is None else tz)[0]
    out["date"] = when.date()
    out["hour"] = when.hour + when.minute / 60.0 + when.second / 3600.0
    if tz is not None:
        off = when.utcoffset()
        out["tz_hours"] = off.total_seconds() / 3600.0
    return out


def parse_north_text(text: str) -> float:
    """``--north X,Y,Z`` (the scene's north) -> degrees from -Z, anticlockwise seen from above."""
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise OptionError(f"--north must be three numbers X,Y,Z, got {text!r}") from None
    if v.shape != (3,) or not np.isfinite(v).all() or math.hypot(v[0], v[2]) <= 1e-9:
        raise OptionError(f"--north must be three finite numbers X,Y,Z, not vertical, got {text!r}")
    return north_angle(v)


def sky_from_text(text: str, scale: float = 1.0) -> tuple[str, float | None, Sky | None]:
    """``--sky``: ``clear[:T]`` and ``overcast`` (brightness from the sun's elevation), ``none``, or one
    of the absolute kinds ``uniform[:R,G,B]``, ``overcast:R,G,B`` (the zenith's radiance),
    ``preetham[:T]`` (zenith luminance ``scale``), ``hdr:FILE``. Returns (sky model, turbidity or
    None, custom Sky or None)."""
    kind, _, arg = text.partition(":")
    if not (np.isfinite(scale) and scale >= 0):
        raise OptionError(f"--sky-scale must be a number >= 0, got {scale!r}")
    if kind == "none" and not arg:
        return "none", None, None
    if kind == "clear" or (kind == "overcast" and not arg):
        if kind == "overcast":
            return "overcast", None, None
        try:
            turbidity = float(arg or DEFAULT_TURBIDITY)
        except ValueError:
            raise OptionError(f"--sky clear: turbidity must be a number, got {arg!r}") from None
        if not 1.0 <= turbidity <= 20.0:
            raise OptionError(f"--sky clear: turbidity must be in [1, 20], got {turbidity:g}")
        return "clear", turbidity, None
    return "none", None, absolute_sky(text, scale)


def absolute_sky(text: str, scale: float = 1.0) -> Sky:
    """``uniform[:R,G,B]``, ``overcast[:R,G,B]``, ``preetham[:T]``, ``hdr:FILE`` -> :class:`Sky`,
    its radiance (W/(m² sr) per unit colour; 1 when not given) times ``scale``."""
    kind, _, arg = text.partition(":")
    kinds = {"uniform": "uniform", "overcast": "cie_overcast", "preetham": "preetham", "hdr": "hdr"}
    if kind not in kinds:
        raise OptionError(
            "--sky must be clear[:T], overcast[:R,G,B], none, uniform[:R,G,B], preetham[:T] or hdr:FILE,"
            f" got {text!r}"
        )
    if not (np.isfinite(scale) and scale >= 0):
        raise OptionError(f"--sky-scale must be a number >= 0, got {scale!r}")
    if kind == "hdr":
        from iat.radiosity.sky import load_hdr

        if not arg:
            raise OptionError("--sky hdr needs a file: hdr:FILE.hdr")
        return Sky(kind="hdr", image=load_hdr(arg), radiance=np.full(3, scale))
    if kind == "preetham":
        try:
            turbidity = float(arg or 3.0)
        except ValueError:
            raise OptionError(f"--sky preetham: turbidity must be a number, got {arg!r}") from None
        if not 1.0 <= turbidity <= 20.0:
            raise OptionError(f"--sky preetham: turbidity must be in [1, 20], got {turbidity:g}")
        return Sky(kind="preetham", turbidity=turbidity, radiance=np.full(3, scale))
    try:
        x = [float(t) for t in (arg or "1").split(",")]
    except ValueError:
        raise OptionError(f"--sky {kind}: radiance must be R,G,B or one number, got {arg!r}") from None
    if len(x) not in (1, 3) or not np.isfinite(x).all() or min(x) < 0:
        raise OptionError(f"--sky {kind}: radiance must be one or three numbers >= 0, got {arg!r}")
    return Sky(kind=kinds[kind], radiance=np.resize(np.array(x), 3) * scale)


def request_daylight(scene: Scene, request: DaylightRequest, today=None) -> Daylight | None:
    """The :class:`Daylight` ``request`` gives ``scene``, or None (``--no-daylight``, or a model with
    light sources of its own and neither ``--sun`` nor ``--sky``).

    A model without light sources gets the default (:func:`site_daylight`), changed by the flags
    given. A model with its own lights keeps them and gets only what the flags name: ``--sun`` a
    sun (no sky), ``--sky`` a sky (a ``clear`` or ``preetham`` one towards the model's own sun when
    it has one, else towards the default sun, which it then also gets). OptionError for
    ``--no-daylight`` with ``--sun`` or ``--sky``, and for an explicit sun below the horizon."""
    if not request.enabled:
        if request.explicit:
            raise OptionError("--no-daylight goes with neither --sun nor --sky")
        return None
    own = scene.has_light_sources
    if own and not request.explicit:
        return None
    d = site_daylight(scene, today=today)
    if request.north:
        d.north_deg = parse_north_text(request.north)
    sun_given = request.sun is not None
    if sun_given:
        fields = parse_sun_text(request.sun)
        d = d.with_changes(**fields)
    if request.sky is not None:
        model, turbidity, custom = sky_from_text(request.sky, request.sky_scale)
        d.sky_model, d.custom_sky = model, custom
        if turbidity is not None:
            d.turbidity = turbidity
        if custom is None:
            d.sky_scale = float(request.sky_scale)
    elif own:
        d.sky_model = "none"
    else:
        d.sky_scale = float(request.sky_scale)
    if own and not sun_given:  # the model's own sun, if any, stays; else the default one
        has_sun = any(lt.kind == "directional" for lt in scene.lights)
        d.sun_on = not has_sun and _sky_needs_sun(d)
    if sun_given and d.sun_on:
        az, el = d.position()
        if el <= 0:
            raise OptionError(f"--sun: the sun is below the horizon then (elevation {el:.1f} degrees)")
    return d


def _sky_needs_sun(d: Daylight) -> bool:
    if d.custom_sky is not None:
        return d.custom_sky.kind == "preetham"
    return d.sky_model == "clear"


def apply_daylight(scene: Scene, request: DaylightRequest | None = None, today=None) -> str | None:
    """Give ``scene`` the daylight ``request`` asks for (:func:`request_daylight`), in place. Returns
    the one line to show (what was chosen and how to change it), or None when nothing was added."""
    request = request or DaylightRequest()
    d = request_daylight(scene, request, today=today)
    if d is None:
        return None
    name = scene.path or "model"
    own = scene.has_light_sources
    own_suns = [lt for lt in scene.lights if lt.kind == "directional"]
    if not own or request.sun is not None or (d.sun_on and not own_suns):
        sun = d.sun()
        scene.lights = [lt for lt in scene.lights if lt.kind != "directional"] + ([sun] if sun else [])
    if not own or request.sky is not None:
        scene.sky = d.sky()
        suns = [lt for lt in scene.lights if lt.kind == "directional"]
        if scene.sky is not None and scene.sky.kind == "preetham" and suns:
            scene.sky.sun_direction = -np.asarray(suns[0].direction, dtype=np.float64)
    if not own:
        return f"{name}: no light sources, so daylight: {d.summary()}; {HOW_TO_CHANGE}"
    if own_suns and request.sun is None:
        return f"{name}: daylight: {d.sky_text()} around the model's own sun"
    return f"{name}: daylight: {d.summary()}"
