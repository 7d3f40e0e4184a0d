"""The manoeuvre search's reach (issue 36): as many manoeuvres as the bearings show, not a
fixed three; what it leaves out, said; and a log of hours answered from its recent past."""

import math

import numpy as np
import pytest

from tma.families import build_estimator
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.manoeuvre_prior import ManoeuvrePrior, window_s

SIGMA_DEG = 0.5


def _turning_log(turns_s, n=8, duration_s=2400.0, dt=5.0, seed=3, prior=None):
    """Own-ship zig-zagging (a leg of 5 minutes at 6 m/s, 60 deg either side of north); n
    targets 6-9 km away at 6 m/s, each turning by 70 deg (alternately left and right, at 3
    deg/s: sharp turns, which the manoeuvre model's bursts follow; a slow turn's arc is a
    misfit it says, poor_fit) at each time of ``turns_s``; bearings every ``dt`` s with 0.5
    deg noise; the
    manoeuvres' prior declared (``prior``)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s + 1e-9, dt)
    heading = np.where((t // 300) % 2 == 0, math.radians(60), math.radians(-60))
    ox = np.concatenate([[0.0], np.cumsum(6.0 * np.sin(heading[:-1]) * dt)])
    oy = np.concatenate([[0.0], np.cumsum(6.0 * np.cos(heading[:-1]) * dt)])
    bearings, truth = [], []
    for _ in range(n):
        course = np.full(t.size, rng.uniform(0, 2 * math.pi))
        for j, start in enumerate(turns_s):
            sign = 1.0 if j % 2 == 0 else -1.0
            course += sign * np.radians(np.clip(3.0 * (t - start), 0.0, 70.0))
        vx, vy = 6.0 * np.sin(course), 6.0 * np.cos(course)
        a = rng.uniform(0, 2 * math.pi)
        r0 = rng.uniform(6000.0, 9000.0)
        x = r0 * math.sin(a) + np.concatenate([[0.0], np.cumsum(vx[:-1] * dt)])
        y = r0 * math.cos(a) + np.concatenate([[0.0], np.cumsum(vy[:-1] * dt)])
        z = np.degrees(np.arctan2(x - ox, y - oy)) + SIGMA_DEG * rng.standard_normal(t.size)
        bearings.append(z % 360.0)
        truth.append((x[-1], y[-1], vx[-1], vy[-1]))
    log = BearingsLog(t_s=t, own_x_m=ox, own_y_m=oy, track_id=np.arange(n),
                      bearing_deg=np.array(bearings), sigma_deg=SIGMA_DEG,
                      accel_psd_m2_s3=1e-5, manoeuvres=prior)
    return log, np.array(truth)


def test_four_manoeuvres_are_weighed_and_nothing_much_is_left_out():
    """Four turns in the window, more than the three the mixture weighed before: the
    posterior mean number of manoeuvres is about four, and the share of the posterior left
    out is small (how far such answers are to be trusted is the manoeuvre experiment's
    calibration table)."""
    prior = ManoeuvrePrior(4.0, 6.0, (40.0, 70.0, 120.0))
    assert window_s(prior) >= 2400.0
    log, truth = _turning_log((400.0, 900.0, 1400.0, 1900.0), prior=prior)
    out = build_estimator({"name": "lm"}).estimate(log)
    assert np.median(out["n_manoeuvres"]) >= 3.5, out["n_manoeuvres"]
    assert np.median(out["p_omitted"]) < 0.05 and np.all(out["p_omitted"] < 0.5), \
        out["p_omitted"]
    assert np.all(out["p_manoeuvre"] > 0.99)
    assert np.sum(out["status"] == "ok") >= 3, out["status"]


@pytest.mark.parametrize("minutes", [30, 120])
def test_a_log_of_hours_is_answered_from_its_recent_past(minutes):
    """A recording's answer rests on the last ``manoeuvre_prior.window_s`` of it (20
    minutes for the recorded prior's ten manoeuvres an hour), which ``leg_start_s`` says,
    and uses those bearings only; the same estimator assuming no manoeuvres uses them all."""
    log, _ = _turning_log((), n=3, duration_s=60.0 * minutes, dt=10.0)
    log.accel_psd_m2_s3 = None  # a recording: no declared motion
    out = build_estimator({"name": "lm", "initial_bearing_deg": None}).estimate(log)
    start = log.t_s[-1] - 1200.0
    expected = log.t_s[np.searchsorted(log.t_s, start)] if minutes > 20 else log.t_s[0]
    np.testing.assert_allclose(out["leg_start_s"], expected)
    assert np.all(out["n_bearings"] == np.sum(log.t_s >= expected))
    steady = build_estimator({"name": "lm", "initial_bearing_deg": None,
                              "manoeuvre_rate_per_h": 0.0}).estimate(log)
    np.testing.assert_allclose(steady["leg_start_s"], log.t_s[0])
    assert np.all(steady["n_bearings"] == log.t_s.size)
