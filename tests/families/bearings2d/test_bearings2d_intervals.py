"""The central intervals of range, course and speed an answer states (``status.INTERVAL_COLUMNS``,
``mixture_tails.quantity_intervals``): their quantiles against root finding (scipy) and a
mixture's against Monte Carlo of its exact range, course and speed; a single Gaussian's
against its one-sigma errors; ``calibration.interval_z`` against its definition; and on
targets drawn from ``lm``'s own model, the truth inside them at their nominal rates both
ways, where the one-sigma errors of the same answers are too wide at 1 sd."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq
from scipy.stats import norm

import tma
from tma.families.bearings2d.calibration import WITHIN_TARGETS, interval_z, track_calibration
from tma.families.bearings2d.mixture_tails import (
    INTERVAL_LEVELS,
    _mixture_quantile,
    gaussian_intervals,
    quantity_intervals,
)
from tma.families.bearings2d.status import kinematics_now

LEVELS = np.array(INTERVAL_LEVELS)


def test_the_levels_are_what_one_and_two_sd_of_a_gaussian_hold():
    np.testing.assert_allclose(LEVELS, norm.cdf([-2.0, -1.0, 1.0, 2.0]), rtol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0.01, 1.0), st.floats(-50.0, 50.0), st.floats(-4.0, 3.0)),
                min_size=1, max_size=12),
       st.sampled_from(INTERVAL_LEVELS))
def test_a_mixtures_quantile_is_the_root_of_its_distribution_function(parts, p):
    """``_mixture_quantile`` against scipy's root finder on the mixture's CDF, for weights,
    means and sds (1e-4 to 20) of any spread, overlapping or far apart."""
    w, mu, log_sd = (np.array(v) for v in zip(*parts, strict=True))
    w, sd = w / w.sum(), np.exp(log_sd)
    x = _mixture_quantile(w, mu, sd, w.size, p)
    ref = brentq(lambda v: float(np.sum(w * norm.cdf((v - mu) / sd))) - p, -1e4, 1e4,
                 xtol=1e-12)
    assert x == pytest.approx(ref, abs=1e-7 * (1.0 + np.ptp(mu) + sd.max()))


def _quantities(states, now):
    """Exact range (m), course (deg, unwrapped about ``course0``) and speed of ``states``."""
    dx, dy = states[:, 0] - now[0], states[:, 1] - now[1]
    return np.hypot(dx, dy), np.degrees(np.arctan2(states[:, 2], states[:, 3])), np.hypot(
        states[:, 2], states[:, 3])


def _draws(weights, means, covs, n, seed=0):
    rng = np.random.default_rng(seed)
    which = rng.choice(len(weights), size=n, p=weights / weights.sum())
    out = np.empty((n, 4))
    for c in range(len(weights)):
        rows = which == c
        out[rows] = rng.multivariate_normal(means[c], covs[c], size=rows.sum())
    return out


@pytest.mark.parametrize("course_deg", [60.0, 359.0])
def test_a_mixtures_intervals_hold_what_they_say(course_deg):
    """A target 20 km away: a core (range known to 3 %, course to 1 deg) and, at 12 %, a
    manoeuvre that may have turned it 40 deg and slowed it, 25 % farther: the intervals
    against the quantiles of 400,000 draws of the mixture's exact range, course and speed
    (each component's quantities are Gaussian to first order: within 2 % of the 2-sd
    interval's width), and across north (course 359 deg) the same."""
    now = np.array([1000.0, -500.0])

    def state(r, bearing_deg, speed, course):
        b, c = math.radians(bearing_deg), math.radians(course)
        return [now[0] + r * math.sin(b), now[1] + r * math.cos(b), speed * math.sin(c),
                speed * math.cos(c)]

    means = np.array([state(20e3, 30.0, 6.0, course_deg),
                      state(25e3, 30.0, 4.0, course_deg + 40.0)])
    covs = np.array([np.diag([350.0, 350.0, 0.06, 0.06]) ** 2 * [1, 1, 1, 1],
                     np.diag([1200.0, 1200.0, 0.5, 0.5]) ** 2 * [1, 1, 1, 1]])
    weights = np.array([0.88, 0.12])
    s2 = 1e-5  # (covariances in units of the noise variance, as the kernel's)
    out = np.empty((3, 4))
    quantity_intervals(weights, means, covs / s2, 2, s2, now[0], now[1], LEVELS, out)
    draws = _draws(weights, means, covs, 400_000)
    rng_m, course, speed = _quantities(draws, now)
    course0 = math.degrees(math.atan2(*(weights @ means)[2:]))
    course = course0 + (course - course0 + 180.0) % 360.0 - 180.0
    for a, values in enumerate((rng_m, course, speed)):
        ref = np.quantile(values, LEVELS)
        ours = np.degrees(out[a]) if a == 1 else out[a]
        np.testing.assert_allclose(ours, ref, atol=0.02 * (ref[3] - ref[0]))
    # heavy-tailed: the 2-sd interval is wider than twice the 1-sd one on the tail's side
    assert out[1, 3] - out[1, 2] > 2.0 * (out[1, 2] - out[1, 1])


def test_a_single_gaussians_intervals_are_its_one_sigma_errors():
    """Course and speed +- 1 and 2 sd of the errors ``kinematics_now`` states; range r
    exp(+-k sd / r); NaN where the covariance is not finite."""
    rng = np.random.default_rng(3)
    n = 50
    theta = np.column_stack([rng.uniform(-3e4, 3e4, (n, 2)), rng.uniform(-8.0, 8.0, (n, 2))])
    A = rng.normal(size=(n, 4, 4)) * [30.0, 30.0, 0.05, 0.05]
    cov = A @ np.swapaxes(A, 1, 2)
    t_now, own_x, own_y = np.full(n, 600.0), rng.uniform(-1e3, 1e3, n), np.zeros(n)
    (rng_m, _, course, speed), G = kinematics_now(theta, t_now, own_x, own_y)
    sd = np.sqrt(np.einsum("nij,njk,nik->ni", G, cov, G))
    M = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    M[:, 0, 2] = M[:, 1, 3] = t_now
    cov[0] = np.nan
    out = np.empty((n, 3, 4))
    gaussian_intervals(np.einsum("nij,nj->ni", M, theta), M @ cov @ np.swapaxes(M, 1, 2),
                       own_x, own_y, LEVELS, out)
    k = np.array([-2.0, -1.0, 1.0, 2.0])
    assert np.isnan(out[0]).all()
    np.testing.assert_allclose(out[1:, 0], rng_m[1:, None] * np.exp(
        k * (sd[1:, 0] / rng_m[1:])[:, None]), rtol=1e-7)
    turned = out[1:, 1] - (course[1:, None] + k * sd[1:, 2:3])  # (the same course a turn on)
    np.testing.assert_allclose((turned + np.pi) % (2 * np.pi) - np.pi, 0.0, atol=1e-7)
    np.testing.assert_allclose(out[1:, 2], speed[1:, None] + k * sd[1:, 3:4], rtol=1e-7)


@settings(max_examples=80, deadline=None)
@given(st.floats(0.0, 359.9), st.floats(0.1, 60.0), st.floats(-6.0, 6.0),
       st.floats(0.2, 3.0), st.floats(0.2, 3.0))
def test_the_interval_z_reads_errors_in_units_of_the_intervals(course, sd, z, stretch_lo,
                                                                stretch_hi):
    """Of a Gaussian answer (its estimate +- 1 and 2 sd): z itself, across north too; of
    intervals stretched below and above the estimate: -+1 and -+2 at their ends, and its
    sign that of the error (estimate - truth)."""
    assume(abs(z * sd) < 179.0 and 4 * sd < 359.0)  # (an error of half a turn has no sign)
    ends = [(course + k * sd) % 360.0 for k in (-2.0, -1.0, 1.0, 2.0)]
    error = (z * sd + 180.0) % 360.0 - 180.0
    assert interval_z(course, error, *ends, circular=True) == pytest.approx(z, abs=1e-6)
    lo2, lo1 = 100.0 - 2 * stretch_lo, 100.0 - stretch_lo
    hi1, hi2 = 100.0 + stretch_hi, 100.0 + 2 * stretch_hi + 1.0
    for truth, expected in ((lo1, 1.0), (lo2, 2.0), (hi1, -1.0), (hi2, -2.0),
                            ((lo1 + hi1) / 2, 0.0), (lo2 - (lo1 - lo2), 3.0)):
        assert interval_z(100.0, 100.0 - truth, lo2, lo1, hi1, hi2) == pytest.approx(
            expected, abs=1e-9), truth


@pytest.fixture(scope="module")
def own_model():
    """``lm`` on 800 targets drawn from its own model (bursts, 3 manoeuvres an hour)."""
    ds = tma.simulate("bearings2d", n_tracks=800, sigma_deg=0.5, seed=7, shard_size=800,
                      target={"manoeuvres": {"rate_per_h": 3.0, "shape": "burst"}})
    result = tma.estimate(ds)
    return track_calibration(result.tma.estimates, ds.truth)


def test_on_its_own_model_the_intervals_hold_the_truth_at_their_rates(own_model):
    """The ok answers' truth inside each quantity's 1-sd interval on 60-76 % and inside its
    2-sd interval on at least 90 %, where the same answers' +- 1 sd holds it on more than
    76 % for course and speed (the sd is the heavy-tailed mixture's, wider than its core)."""
    ok = own_model[own_model.status == "ok"]
    assert len(ok) >= 350
    lo, hi = WITHIN_TARGETS[1]
    for q in ("range", "course", "speed"):
        known = np.isfinite(ok[f"{q}_z"].to_numpy())  # (a truth and an sd)
        inside = np.abs(ok[f"{q}_iz"].to_numpy()[known])
        assert known.sum() >= 350 and np.isfinite(inside).all(), q
        assert lo <= np.mean(inside <= 1) <= hi, (q, np.mean(inside <= 1))
        assert np.mean(inside <= 2) >= 0.90, (q, np.mean(inside <= 2))
    for q in ("course", "speed"):
        assert np.mean(np.abs(ok[f"{q}_z"]) <= 1) > hi, q


def test_on_its_own_model_the_median_error_reads_as_honest_only_in_the_intervals(own_model):
    """Issue 36, item 5's reading, where the model is right by construction: the median over
    the ok answers of the largest |z| of range, course and speed lies in 1.0-1.6 (honest
    errors: about 1.2) in units of the intervals, and far below it in units of the sd, which
    a mixture's tails widen beyond its core (the real pairs' 0.35-0.71 are no proof of a
    prior too rich)."""
    ok = own_model[own_model.status == "ok"]
    z = np.abs(ok[["range_z", "course_z", "speed_z"]].to_numpy())
    iz = np.abs(ok[["range_iz", "course_iz", "speed_iz"]].to_numpy())
    known = np.isfinite(z).all(axis=1)
    by_sd, by_interval = np.median(z[known].max(axis=1)), np.median(iz[known].max(axis=1))
    assert by_sd < 0.75 and 0.95 <= by_interval <= 1.6, (by_sd, by_interval)
