"""Where the day cycle's sun stands at the time-of-day slider (issue 16's viewer part): the key
states' sun directions blended as the set blends their light; azimuth and elevation in the
conventions of iat.lighting.sun. No display needed."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from iat.lighting.sun import light_direction, sun_direction


def app_with(states: dict, times):
    from iat.lighting.solution_set import blend_weights
    from viewer.state import AppState

    s = AppState()
    s.lighting.states = states
    # only names, times and weights matter here: the weights are SolutionSet's own rule
    sset = SimpleNamespace(names=list(states), times=np.asarray(times, float))
    sset.weights = lambda t: blend_weights(sset.times, t)
    s.lighting.solution_set, s.lighting.day_cycle = sset, True
    return s


def sun_state(az, el):
    return {"sun": {"direction": light_direction(az, el).tolist(), "intensity": 800.0}}


def test_the_sun_at_the_key_times_and_between():
    from viewer.daylight import angles, sun_at, sun_label

    s = app_with({"morning": sun_state(100, 10), "noon": sun_state(180, 60), "night": {}}, [0.0, 0.5, 1.0])
    for t, (az, el) in ((0.0, (100, 10)), (0.5, (180, 60))):
        s.lighting.day_time = t
        got = angles(sun_at(s))
        assert got == pytest.approx((az, el), abs=1e-6)
    s.lighting.day_time = 0.25  # halfway: the normalised mean of the two directions
    mid = sun_direction(100, 10) + sun_direction(180, 60)
    np.testing.assert_allclose(sun_at(s), mid / np.linalg.norm(mid), atol=1e-9)
    az, el = angles(sun_at(s))
    assert 100 < az < 180 and 10 < el < 60
    assert sun_label(s).startswith("sun: azimuth")
    s.lighting.day_time = 0.75  # towards the night (no sun): the side that has one
    assert angles(sun_at(s)) == pytest.approx((180, 60), abs=1e-6)
    s.lighting.day_cycle = False
    assert sun_at(s) is None and sun_label(s) == ""


def test_angles_follow_the_sun_module():
    from viewer.daylight import angles

    for az, el in ((0, 30), (90, 5), (270, 80), (200, 45)):
        assert angles(sun_direction(az, el)) == pytest.approx((az, el), abs=1e-6)


def test_the_states_own_angles_win_for_a_model_with_another_north():
    """The daylit house's north is +Z: its states' azimuth/elevation (sun_states) are what the
    label shows, not the angles of the direction read against -Z."""
    from iat.lighting.sun import sun_states
    from viewer.daylight import angles, sun_at, sun_label

    states = sun_states(48.85, 2.35, "2026-09-22", ["11:00", "14:00"], "Europe/Paris", north=(0, 0, 1))
    s = app_with(states, [0.0, 1.0])
    s.lighting.day_time = 0.0
    first = states["11:00"]
    assert sun_label(s) == f"sun: azimuth {first['azimuth']:.0f} deg, elevation {first['elevation']:.0f} deg"
    assert abs(angles(sun_at(s))[0] - first["azimuth"]) > 90  # read against -Z it would be wrong
    s.lighting.day_time = 0.5
    az = float(sun_label(s).split()[2])
    assert (
        min(first["azimuth"], states["14:00"]["azimuth"])
        < az
        < max(first["azimuth"], states["14:00"]["azimuth"])
    )
