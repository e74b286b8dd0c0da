"""Issue 38: the sun study, a day's hours at the model's place solved as lighting states on one mesh
(iat/lighting/sun_study.py, ``iat solve MODEL --sun-study DATE --hours H-H``)."""

from __future__ import annotations

import datetime

import numpy as np
import pytest

from iat.cli.commands import main
from iat.errors import OptionError
from iat.lighting.daylight_default import Daylight, DaylightRequest
from iat.lighting.sun import day_times, solar_position
from iat.lighting.sun_study import daylight_state, hour_name, parse_hours, study_daylight, sun_study_states
from tests.support.site_ifc import LAT, LON, NORTH_DEG, TZ_HOURS, angle_deg, expected_to_sun, site_ifc


def test_hours():
    assert parse_hours("8-18") == [float(h) for h in range(8, 19)]
    assert parse_hours("8-18/5") == [8.0, 13.0, 18.0]
    assert parse_hours("9,12,15") == [9.0, 12.0, 15.0]
    assert parse_hours("8:30-10:30") == [8.5, 9.5, 10.5]
    assert hour_name(8.0) == "08h00" and hour_name(17.5) == "17h30"
    for bad in ("18-8", "9", "noon", "9,9", "8-25"):
        with pytest.raises(OptionError, match=r"^--hours must be H-H\[/STEP\] or H,H,\.\.\."):
            parse_hours(bad)


def test_states_carry_noaas_sun_and_a_sky_towards_it():
    d = Daylight(LAT, LON, datetime.date(2026, 6, 21), north_deg=NORTH_DEG)
    states = sun_study_states(d, "2026-06-21", [6.0, 9.0, 17.0, 21.0])
    assert list(states) == ["06h00", "09h00", "17h00", "21h00"]
    assert [st["time"] for st in states.values()] == pytest.approx([0.0, 0.2, 11 / 15, 1.0])
    for name, st in states.items():
        when = day_times("2026-06-21", [st["label"]], TZ_HOURS)[0]
        az, el = solar_position(LAT, LON, when)
        assert (st["azimuth"], st["elevation"]) == pytest.approx((az, el), abs=1e-9)
        if el > 0:
            assert angle_deg(-np.asarray(st["sun"]["direction"]), expected_to_sun(LAT, LON, when, 30.0)) < 0.1
            assert st["sun"]["intensity"] > 100 and st["sky"]["kind"] == "preetham"
            assert np.asarray(st["sky"]["sun_direction"]) @ -np.asarray(
                st["sun"]["direction"]
            ) == pytest.approx(1)
        else:  # 21:00 in June at Boulder: set; the state takes the sun and the sky out
            assert name == "21h00" and st["sun"]["intensity"] == 0.0 and st["sky"] is None
    off = daylight_state(d.with_changes(sun_on=False, sky_model="overcast"))
    assert off["sun"]["intensity"] == 0.0 and off["sky"]["kind"] == "cie_overcast"


def test_a_study_takes_no_sun_moment():
    from tests.test_site_daylight import plain_scene

    with pytest.raises(
        OptionError, match="^--sun-study takes the sun through the hours: give --hours, not --sun$"
    ):
        study_daylight(plain_scene(), DaylightRequest(sun="12:00"), "2026-06-21")
    d = study_daylight(plain_scene(), DaylightRequest(sky="overcast"), "2026-06-21")
    assert d.sky_model == "overcast" and d.date == datetime.date(2026, 6, 21) and d.sun_on


def test_cli_sun_study_solves_the_hours_on_one_mesh(tmp_path, capsys):
    """``iat solve site.ifc --sun-study 2026-06-21 --hours 9-17/4``: three solutions on one mesh,
    each recording the sun of its hour (NOAA at the IfcSite's place, turned by TrueNorth, to 0.1
    degree) and its key time; read back as a set, blended by the time-of-day slider's rule."""
    pytest.importorskip("ifcopenshell")
    from iat.lighting.solution_set import load_set

    model = site_ifc(tmp_path)
    out = tmp_path / "study.npz"
    argv = ["solve", str(model), "-o", str(out), "--max-depth", "2", "--states-mesh", "first"]
    rc = main([*argv, "--sun-study", "2026-06-21", "--hours", "9-17/4", "--json"])
    assert rc == 0
    err = capsys.readouterr().err
    assert (
        f"iat solve: {model}: sun study at 40.02 N, 105.27 W (IfcSite #10 'site'), true north +30.0 deg:"
        " 3 hours, 2026-06-21 09:00 UTC-7 to 17:00 UTC-7; clear sky (Preetham, turbidity 3," in err
    )
    files = [tmp_path / f"study-{h}.npz" for h in ("09h00", "13h00", "17h00")]
    sset = load_set(files)
    assert sset.names == ["09h00", "13h00", "17h00"]
    assert sset.times.tolist() == [0.0, 0.5, 1.0]
    for name, sol in zip(sset.names, sset.solutions, strict=True):
        (sun,) = sol.stats["sources"]["suns"]
        when = day_times("2026-06-21", [name.replace("h", ":")], TZ_HOURS)[0]
        assert angle_deg(-np.asarray(sun["direction"]), expected_to_sun(LAT, LON, when, NORTH_DEG)) < 0.1
        assert sol.stats["sources"]["sky"]["kind"] == "preetham"
        assert float(sol.vert_radiance.max()) > 0
    assert sset.weights(0.25) == (0, 1, 0.5)  # 11:00: half way between 09h00 and 13h00
    assert main([*argv, "--sun-study", "2026-06-21", "--sun", "12:00"]) == 2
    assert "--sun-study takes the sun through the hours" in capsys.readouterr().err
