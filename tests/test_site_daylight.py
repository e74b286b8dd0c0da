"""Issue 38: daylight by default at the model's own place (IfcSite, TrueNorth), the same flags on
every command (iat/io/site.py, iat/lighting/daylight_default.py, iat/cli/daylight.py)."""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import numpy as np
import pytest

from iat.cli.commands import main
from iat.errors import OptionError
from iat.io.scene import Light, Material, Scene
from iat.io.site import compound_angle, north_angle, north_vector, read_ifc_site
from iat.lighting.daylight_default import (
    DEFAULT_PLACE,
    DaylightRequest,
    apply_daylight,
    coming_equinox,
    parse_sun_text,
    site_daylight,
    zone_hours,
)
from iat.lighting.sun import day_times, solar_position
from tests.support.site_ifc import (
    LAT,
    LON,
    NORTH_DEG,
    angle_deg,
    expected_to_sun,
    site_ifc,
)

REAL = Path(__file__).resolve().parents[2] / "shared" / "real-models"
MADRID = REAL / "revit2021-madrid-house.ifc"
OPEN_HOUSE = REAL / "ifcopenshell-open-house-ifc4.ifc"


def plain_scene(path: str = "") -> Scene:
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 0, -1], [0, 0, -1]], float)
    return Scene(v, [[0, 1, 2, 3]], [0], [Material(name="floor")], path=path)


# -- reading the site ---------------------------------------------------------------------------
def test_compound_angles_as_the_files_write_them():
    assert compound_angle((40, 25, 13, 9643)) == pytest.approx(40.420280456, abs=1e-9)  # Madrid (Revit)
    assert compound_angle((-3, -42, -20, -772056)) == pytest.approx(-3.705770016, abs=1e-9)
    assert compound_angle((53, 23, 0)) == pytest.approx(53.383333333, abs=1e-9)  # three parts
    assert compound_angle((-3, 42, 20)) == pytest.approx(-(3 + 42 / 60 + 20 / 3600))  # sign on degrees only
    assert compound_angle(None) is None and compound_angle((1, 2)) is None


def test_north_vector_and_angle_are_inverse():
    assert north_vector(0.0) == pytest.approx([0.0, 0.0, -1.0])
    assert north_vector(90.0) == pytest.approx([-1.0, 0.0, 0.0])  # anticlockwise seen from above
    for a in (-150.0, -30.0, 0.0, 30.0, 179.0):
        assert north_angle(north_vector(a)) == pytest.approx(a)


def test_the_real_files_sites():
    pytest.importorskip("ifcopenshell")
    madrid = read_ifc_site(MADRID)
    assert madrid.latitude == pytest.approx(40.4203, abs=1e-4)
    assert madrid.longitude == pytest.approx(-3.7058, abs=1e-4)
    assert madrid.true_north_deg == pytest.approx(0.0, abs=1e-9)
    assert madrid.source == "IfcSite #148 'Default'"
    nowhere = read_ifc_site(OPEN_HOUSE)
    assert not nowhere.has_location and nowhere.source == "IfcSite #24 (no RefLatitude/RefLongitude)"
    d = site_daylight(path=OPEN_HOUSE)
    assert (d.latitude, d.longitude) == DEFAULT_PLACE[:2]
    assert d.place == "default place, Paris: IfcSite #24 (no RefLatitude/RefLongitude): no location"


def test_defaults_date_zone_and_sun_text():
    assert coming_equinox(datetime.date(2026, 12, 6)) == datetime.date(2027, 3, 20)
    assert coming_equinox(datetime.date(2026, 3, 20)) == datetime.date(2026, 3, 20)
    assert coming_equinox(datetime.date(2026, 3, 21)) == datetime.date(2026, 9, 22)
    assert zone_hours(-3.71) == 0.0 and zone_hours(-105.27) == -7.0 and zone_hours(139.7) == 9.0
    assert parse_sun_text("off") == {"sun_on": False}
    assert parse_sun_text("15:30") == {"hour": 15.5}
    f = parse_sun_text("2026-06-21T15:00,Europe/Madrid")
    assert f == {"date": datetime.date(2026, 6, 21), "hour": 15.0, "tz_hours": 2.0}
    f = parse_sun_text("40.4,-3.7,2026-06-21T15:00")
    assert (f["latitude"], f["longitude"], f["tz_hours"], f["hour"]) == (40.4, -3.7, 0.0, 15.0)
    with pytest.raises(
        OptionError, match=r"^--sun must be \[LAT,LON,\]YYYY-MM-DDTHH:MM\[,TZ\], HH:MM or off, got 'noon'$"
    ):
        parse_sun_text("noon")


# -- the scene gets the sun ---------------------------------------------------------------------
def test_ifc_site_sun_matches_noaa_rotated_by_true_north(tmp_path):
    """The site's place and true north reach the solve: the sun the solution records is NOAA's
    azimuth and elevation for Boulder at the default moment (10:00 UTC-7 on the coming equinox),
    turned by the 30 degrees of TrueNorth, to 0.1 degree."""
    pytest.importorskip("ifcopenshell")
    model = site_ifc(tmp_path)
    site = read_ifc_site(model)
    assert site.latitude == pytest.approx(LAT, abs=1e-9) and site.longitude == pytest.approx(LON, abs=1e-9)
    assert site.true_north_deg == pytest.approx(NORTH_DEG, abs=1e-6) and site.elevation == 1655.0
    out = tmp_path / "site.npz"
    rc = main(["solve", str(model), "-o", str(out), "--max-depth", "2", "--json"])
    assert rc == 0
    from iat.radiosity.solution import Solution

    sol = Solution.load(out)
    (sun,) = sol.stats["sources"]["suns"]
    when = day_times(coming_equinox(), [10.0], -7.0)[0]
    want = expected_to_sun(LAT, LON, when, NORTH_DEG)
    got = -np.asarray(sun["direction"])
    assert angle_deg(got, want) < 0.1
    assert angle_deg(got, expected_to_sun(LAT, LON, when, 0.0)) > 10.0  # the 30 degrees are there
    assert sol.stats["sources"]["sky"]["kind"] == "preetham"


def test_the_line_says_what_was_chosen(tmp_path, capsys):
    pytest.importorskip("ifcopenshell")
    model = site_ifc(tmp_path)
    scene = plain_scene(str(model))
    today = datetime.date(2026, 12, 6)
    line = apply_daylight(scene, DaylightRequest(), today=today)
    when = day_times("2027-03-20", [10.0], -7.0)[0]
    az, el = solar_position(LAT, LON, when)
    site = read_ifc_site(model)
    assert line.startswith(
        f"{model}: no light sources, so daylight: 40.02 N, 105.27 W ({site.source}), true north +30.0 deg,"
        f" 2027-03-20 10:00 UTC-7: sun at azimuth {az:.1f} deg, elevation {el:.1f} deg, "
    )
    assert line.endswith("; change with --sun [LAT,LON,]YYYY-MM-DDTHH:MM[,TZ], --sky KIND or --no-daylight")
    (sun,) = scene.lights
    assert (
        sun.kind == "directional" and angle_deg(-sun.direction, expected_to_sun(LAT, LON, when, 30.0)) < 0.1
    )
    assert scene.sky.kind == "preetham" and scene.sky.sun_direction @ -sun.direction == pytest.approx(1.0)


def test_a_model_with_no_site_uses_the_default_place_and_says_so(tmp_path):
    obj = tmp_path / "court.obj"
    obj.write_text(
        "v 0 0 0\nv 0 0 4\nv 4 0 4\nv 4 0 0\nv 0 2 0\nv 0 2 4\nv 4 2 4\nv 4 2 0\n"
        "f 1 2 3 4\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\n"
    )
    scene = plain_scene(str(obj))
    line = apply_daylight(scene, DaylightRequest(), today=datetime.date(2026, 12, 6))
    assert line.startswith(
        f"{obj}: no light sources, so daylight: 48.85 N, 2.35 E"
        " (default place, Paris: the file gives no site), 2027-03-20 10:00 UTC+0: sun at azimuth "
    )
    when = day_times("2027-03-20", [10.0], 0.0)[0]
    assert angle_deg(-scene.lights[0].direction, expected_to_sun(48.85, 2.35, when, 0.0)) < 0.1
    # the command line prints it on stderr, and --no-daylight keeps the model black
    import subprocess
    import sys

    iat = [sys.executable, "-m", "iat"]
    r = subprocess.run([*iat, "info", str(obj), "--json"], capture_output=True, text=True)
    assert json.loads(r.stdout)["light_sources"] == "no light sources"
    r = subprocess.run(
        [*iat, "solve", str(obj), "-o", str(tmp_path / "c.npz"), "--max-depth", "2", "--json"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    (said,) = r.stderr.splitlines()
    assert said.startswith(f"iat solve: {obj}: no light sources, so daylight: 48.85 N, 2.35 E (default place")
    stats = json.loads(r.stdout)
    assert stats["received_power"] > 0 and len(stats["sources"]["suns"]) == 1
    r = subprocess.run(
        [*iat, "solve", str(obj), "-o", str(tmp_path / "d.npz"), "--max-depth", "2", "--no-daylight"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0 and r.stderr.splitlines() == [
        f"iat solve: warning: {obj}: no light sources (no lights, no sky, no emissive materials):"
        " the solution is black"
    ]


def test_flags_change_the_default():
    today = datetime.date(2026, 12, 6)
    scene = plain_scene()
    line = apply_daylight(scene, DaylightRequest(sun="2026-06-21T15:00", sky="none"), today=today)
    az, el = solar_position(48.85, 2.35, day_times("2026-06-21", ["15:00"], 0.0)[0])
    assert f"2026-06-21 15:00 UTC+0: sun at azimuth {az:.1f} deg, elevation {el:.1f} deg" in line
    assert scene.sky is None and len(scene.lights) == 1
    scene = plain_scene()
    apply_daylight(scene, DaylightRequest(sun="off", sky="clear:5"), today=today)
    assert scene.lights == [] and scene.sky.kind == "preetham" and scene.sky.turbidity == 5.0
    scene = plain_scene()
    apply_daylight(scene, DaylightRequest(sky="clear", sky_scale=2.0), today=today)
    base = plain_scene()
    apply_daylight(base, DaylightRequest(), today=today)
    assert scene.sky.radiance == pytest.approx(2.0 * base.sky.radiance)
    with pytest.raises(OptionError, match="^--no-daylight goes with neither --sun nor --sky$"):
        apply_daylight(plain_scene(), DaylightRequest(sun="12:00", enabled=False))
    with pytest.raises(OptionError, match=r"^--sun: the sun is below the horizon then \(elevation -"):
        apply_daylight(plain_scene(), DaylightRequest(sun="23:00"), today=today)
    assert apply_daylight(plain_scene(), DaylightRequest(enabled=False)) is None


def test_a_model_with_its_own_lamps_keeps_them():
    scene = plain_scene()
    lamp = Light(kind="point", position=np.array([0.5, 1.0, -0.5]), intensity=5.0, name="lamp")
    scene.lights = [lamp]
    assert apply_daylight(scene, DaylightRequest()) is None
    assert scene.lights == [lamp] and scene.sky is None
    line = apply_daylight(scene, DaylightRequest(sky="uniform:0.5"))
    assert scene.lights == [lamp] and scene.sky.kind == "uniform" and line.startswith("model: daylight: ")


@pytest.mark.slow
def test_the_madrid_house_opens_lit_at_its_site():
    """The real Revit file, loaded with no flags: a sun at 40.42 N, 3.71 W (NOAA, north +Y of the plan)."""
    pytest.importorskip("ifcopenshell")
    from iat.io.load import load_scene

    scene = load_scene(MADRID)
    assert not scene.has_light_sources
    today = datetime.date(2026, 12, 6)
    line = apply_daylight(scene, DaylightRequest(), today=today)
    assert line.startswith(
        f"{MADRID}: no light sources, so daylight: 40.42 N, 3.71 W (IfcSite #148 'Default'),"
    )
    when = day_times("2027-03-20", [10.0], 0.0)[0]
    (sun,) = [lt for lt in scene.lights if lt.kind == "directional"]
    assert angle_deg(-sun.direction, expected_to_sun(40.420280456, -3.705770016, when, 0.0)) < 0.1
    assert sun.intensity > 700 and scene.sky.kind == "preetham"


def test_the_viewer_opens_a_model_without_lights_by_daylight(tmp_path, monkeypatch):
    """The viewer's open job (its real worker thread) gives the model the default daylight, keys its
    cached solution by it, and says so in the status line; --no-daylight leaves it dark."""
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions
    from viewer.daylight import sun_facts
    from viewer.jobs import OpenJob

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    obj = tmp_path / "court.obj"
    obj.write_text(
        "v 0 0 0\nv 0 0 4\nv 4 0 4\nv 4 0 0\nv 0 2 0\nv 0 2 4\nv 4 2 4\nv 4 2 0\n"
        "f 1 2 3 4\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\n"
    )
    opts = SolveOptions(max_depth=2)
    job = OpenJob(obj, opts, BakePolicy(threshold=1))
    assert job.join(300) and job.error is None, job.error
    opened = job.result
    (sun,) = opened.scene.lights
    assert opened.daylight_line.startswith(f"{obj}: no light sources, so daylight: 48.85 N, 2.35 E")
    assert opened.status(0).endswith(opened.daylight_line)
    assert "-daylight-" in Path(list((tmp_path / "cache").glob("*.npz"))[0]).name
    az, el = solar_position(48.85, 2.35, day_times(coming_equinox(), [10.0], 0.0)[0])
    assert sun_facts(sun).startswith(f"azimuth {az:.1f} deg, elevation {el:.1f} deg, ")
    assert float(opened.solution.vert_radiance.max()) > 0
    dark = OpenJob(obj, opts, BakePolicy(threshold=1), daylight=DaylightRequest(enabled=False))
    assert dark.join(300) and dark.error is None
    assert dark.result.scene.lights == [] and dark.result.daylight_line == ""
