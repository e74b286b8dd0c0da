"""The viewer's time left (viewer/eta.py): from the rate measured over the recent window, not the
average since the start, and a new stage when the fraction falls."""

from __future__ import annotations

import pytest

from viewer.eta import JobEta, RateEta


def test_time_left_follows_the_recent_rate():
    eta = RateEta(window_s=10.0, min_s=1.0, min_fraction=0.02)
    assert eta.update(0.0, now=0.0) is None  # no guess from nothing
    assert eta.update(0.01, now=0.5) is None
    # a slow first part (0.2 in 20 s), then four times faster (0.04 a second)
    for t in range(1, 21):
        eta.update(0.01 * t, now=float(t))
    for t in range(21, 31):
        left = eta.update(0.2 + 0.04 * (t - 20), now=float(t))
    # at t = 30 the fraction is 0.6: 0.4 left at the last 10 s's rate is 10 s (the average since the
    # start, 0.02 a second, would say 20 s)
    assert left == pytest.approx(10.0, rel=1e-6)
    assert eta.update(1.0, now=31.0) is None  # done


def test_a_falling_fraction_starts_a_new_stage_and_a_new_job_afresh():
    eta = RateEta(window_s=10.0, min_s=1.0, min_fraction=0.02)
    for t in range(0, 11):
        eta.update(0.05 * t, now=float(t))  # the load: 0.5 in 10 s
    assert eta.update(0.0, now=11.0) is None  # the solve starts at 0: no rate yet
    assert eta.update(0.01, now=12.0) is None  # under min_fraction
    assert eta.update(0.1, now=21.0) == pytest.approx(90.0)  # 0.1 in 10 s: 0.9 left at 0.01 / s
    jobs = JobEta()
    a, b = object(), object()
    jobs.update(a, 0.0)
    assert jobs.update(b, 0.5) is None  # another job: measured from scratch
