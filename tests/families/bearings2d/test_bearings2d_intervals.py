"""The central intervals of range, course and speed an answer states (``status.INTERVAL_COLUMNS``,
``mixture_tails.quantity_intervals``): their quantiles against root finding (scipy) and a
mixture's against Monte Carlo of its exact range, course and speed; a single Gaussian's
against its one-sigma errors; ``calibration.interval_z`` against its definition; and on
targets drawn from ``lm``'s own model, the truth inside them at their nominal rates both
ways, pooled, where the answer says a manoeuvre is unlikely and within 30 km (not yet where
it is sure one was made: a strict xfail), where the one-sigma errors of the same answers are
too wide at 1 sd."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq
from scipy.stats import norm

from tests.families.bearings2d.real_motion import TWO_SIDED
from tests.families.bearings2d.test_bearings2d_manoeuvre_model import _mixture_draws
from tma.families.bearings2d.calibration import (
    WITHIN_TARGETS,
    cell_row,
    cells,
    interval_z,
    outside_targets,
    track_calibration,
    widened_intervals,
)
from tma.families.bearings2d.mixture_tails import (
    INTERVAL_LEVELS,
    _mixture_quantile,
    quantity_intervals,
)
from tma.families.bearings2d.status import INTERVAL_COLUMNS, interval_columns

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
    # a component that does not determine the quantity: no quantile at all
    assert np.isnan(_mixture_quantile(np.append(w, 0.0), np.append(mu, 0.0),
                                      np.append(sd, np.nan), w.size + 1, p))


def _quantities(states, now):
    """Exact range (m) from ``now``, course (deg, in (-180, 180]) and speed of ``states``."""
    dx, dy = states[:, 0] - now[0], states[:, 1] - now[1]
    return np.hypot(dx, dy), np.degrees(np.arctan2(states[:, 2], states[:, 3])), np.hypot(
        states[:, 2], states[:, 3])


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
    covs = np.array([np.diag([350.0, 350.0, 0.06, 0.06]) ** 2,
                     np.diag([1200.0, 1200.0, 0.5, 0.5]) ** 2])
    weights = np.array([0.88, 0.12])
    s2 = 1e-5  # (covariances in units of the noise variance, as the kernel's)
    out = np.empty((3, 4))
    quantity_intervals(weights, means, covs / s2, 2, s2, now[0], now[1], LEVELS, out)
    draws = _mixture_draws(weights, means, covs, 400_000)
    rng_m, course, speed = _quantities(draws, now)
    course0 = math.degrees(math.atan2(*(weights @ means)[2:]))
    course = course0 + (course - course0 + 180.0) % 360.0 - 180.0
    # (the first-order statement of each component: range and course within 0.5 % of the
    # 2-sd interval's width, speed, curved most, within 2 %; measured 0.1 and 1.1-1.4 %)
    for a, (values, tol) in enumerate(((rng_m, 0.005), (course, 0.005), (speed, 0.02))):
        ref = np.quantile(values, LEVELS)
        ours = np.degrees(out[a]) if a == 1 else out[a]
        np.testing.assert_allclose(ours, ref, atol=tol * (ref[3] - ref[0]))
    # heavy-tailed: on the tail's side the 2-sd end lies farther beyond the 1-sd end than
    # the whole 1-sd interval is wide, twice over
    assert out[1, 3] - out[1, 2] > 2.0 * (out[1, 2] - out[1, 1])


def test_one_components_intervals_are_the_closed_form_a_single_answer_states():
    """``quantity_intervals`` of one component, stated by ``status.interval_columns``,
    against its closed form from the sd the component's gradient gives: course and speed +-
    1 and 2 sd, range r exp(+-k sd / r) (both within the plausible targets'); a component at
    rest leaves course and speed NaN (the closed form then stands in), one with a NaN
    covariance everything."""
    rng = np.random.default_rng(3)
    for _ in range(40):
        r, bearing = rng.uniform(500.0, 5e4), rng.uniform(-np.pi, np.pi)
        speed, course = rng.uniform(0.5, 15.0), rng.uniform(-np.pi, np.pi)
        now = np.array([rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3)])
        state = np.array([now[0] + r * np.sin(bearing), now[1] + r * np.cos(bearing),
                          speed * np.sin(course), speed * np.cos(course)])
        A = rng.normal(size=(4, 4)) * [0.05 * r, 0.05 * r, 0.3 * speed, 0.3 * speed]
        cov = A @ A.T
        out = np.empty((3, 4))
        quantity_intervals(np.ones(1), state[None], cov[None] / 4.0, 1, 4.0, now[0], now[1],
                           LEVELS, out)
        assert np.isfinite(out).all()  # (else interval_columns would fall back to its own)
        g_r = (state[:2] - now) / r
        g_c = np.array([state[3], -state[2]]) / speed**2
        g_s = state[2:] / speed
        sd = np.sqrt([g_r @ cov[:2, :2] @ g_r, g_c @ cov[2:, 2:] @ g_c, g_s @ cov[2:, 2:] @ g_s])
        closed = interval_columns(np.array([[r, course, speed]]), sd[None])
        ours = interval_columns(np.array([[r, course, speed]]), sd[None], out[None])
        for q, names in INTERVAL_COLUMNS.items():
            for c in names:
                np.testing.assert_allclose(ours[c], closed[c], rtol=1e-7, atol=1e-6, err_msg=q)
    rest = state.copy()
    rest[2:] = 0.0
    quantity_intervals(np.ones(1), rest[None], cov[None], 1, 1.0, now[0], now[1], LEVELS, out)
    assert np.isfinite(out[0]).all() and np.isnan(out[1:]).all()
    quantity_intervals(np.ones(1), state[None], np.full((1, 4, 4), np.nan), 1, 1.0, now[0],
                       now[1], LEVELS, out)
    assert np.isnan(out).all()


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
    assert interval_z(course, error, *ends, scale="circular") == pytest.approx(z, abs=1e-6)
    lo2, lo1 = 100.0 - 2 * stretch_lo, 100.0 - stretch_lo
    hi1, hi2 = 100.0 + stretch_hi, 100.0 + 2 * stretch_hi + 1.0
    for truth, expected in ((lo1, 1.0), (lo2, 2.0), (hi1, -1.0), (hi2, -2.0),
                            ((lo1 + hi1) / 2, 0.0), (lo2 - (lo1 - lo2), 3.0)):
        assert interval_z(100.0, 100.0 - truth, lo2, lo1, hi1, hi2) == pytest.approx(
            expected, abs=1e-9), truth


def test_the_interval_z_on_a_circle_and_in_logarithms():
    """Course: an asymmetric 2-sd arc reaching more than half a turn from the 1-sd middle
    (160 clockwise to 100 deg, the 1-sd 350-10) reads a truth inside it as inside (170 deg:
    1.95), one outside beyond its nearer end; a 2-sd interval of a whole turn (blank) holds
    every course: outside the 1-sd interval, 1.5 on the side nearer. Range: in its
    logarithm, so a single answer's r exp(+-k sd / r) reads log(estimate / truth) over
    sd / r."""
    ends = (160.0, 350.0, 10.0, 100.0)
    assert interval_z(0.0, -170.0, *ends, scale="circular") == pytest.approx(1 + 180 / 190)
    assert interval_z(0.0, 0.0, *ends, scale="circular") == pytest.approx(0.0)
    assert interval_z(0.0, -120.0, *ends, scale="circular") == pytest.approx(-2 - 20 / 90)
    assert interval_z(0.0, 80.0, *ends, scale="circular") == pytest.approx(1 + 70 / 190)
    assert interval_z(0.0, -110.0, *ends, scale="circular") == pytest.approx(-2 - 10 / 90)
    assert interval_z(0.0, -150.0, *ends, scale="circular") == pytest.approx(2 + 10 / 190)
    whole = (np.nan, 350.0, 10.0, np.nan)
    assert interval_z(0.0, -5.0, *whole, scale="circular") == pytest.approx(-0.5)
    assert interval_z(0.0, -40.0, *whole, scale="circular") == -1.5
    assert interval_z(0.0, 170.0, *whole, scale="circular") == 1.5
    r, sd, truth = 20e3, 3e3, 24e3
    ends = r * np.exp(np.array([-2.0, -1.0, 1.0, 2.0]) * sd / r)
    assert interval_z(r, r - truth, *ends, scale="log") == pytest.approx(
        math.log(r / truth) / (sd / r))


@pytest.fixture(scope="module")
def own_model(own_model_runs):
    """``lm`` on 1,000 targets drawn from its own model (bursts, 3 manoeuvres an hour): per
    track ``calibration.track_calibration``."""
    ds, result = own_model_runs["burst"]
    return track_calibration(result.tma.estimates, ds.truth)


def _outside(own_model, group, cell):
    """A cell's figures of the intervals outside their targets (``outside_targets``). A cell
    of too few ok answers to grade, or whose ok answers do not all state their intervals,
    is an error, not a finding (not an AssertionError, which a strict xfail would take)."""
    (mask,) = [m for g, c, m in cells(own_model) if (g, c) == (group, cell)]
    row = cell_row(own_model, mask)
    ok = mask & (own_model.status == "ok").to_numpy()
    stated = np.isfinite(own_model.loc[ok, ["range_iz", "course_iz", "speed_iz"]]).all(axis=1)
    if not row["graded"] or stated.mean() < 0.99:
        raise RuntimeError(f"{group} {cell}: {row['n_ok']} ok, {stated.mean():.1%} stating "
                           "their intervals")
    return row, [o for o in outside_targets(row) if "interval" in o]


@pytest.mark.parametrize("group, cell", [("all", "all"), ("p_manoeuvre", "<0.5"),
                                         ("range_km", "<15"), ("range_km", "15-30")])
def test_on_its_own_model_the_intervals_hold_the_truth_at_their_rates(own_model, group,
                                                                      cell):
    """Two-sided, per quantity: the ok answers' truth inside each quantity's 1-sd interval on
    60-76 % and inside its 2-sd interval on 92-98 %, pooled, where the answer says a
    manoeuvre is unlikely and where the target is within 30 km (graded cells of at least 100
    ok answers; the cells by manoeuvres made are not what a posterior promises: those that
    made none hold more, docs/manoeuvres.md); pooled, the same answers' +- 1 sd holds course
    and speed on more than 76 % (the sd is the heavy-tailed mixture's, wider than its
    core)."""
    row, outside = _outside(own_model, group, cell)
    assert not outside, outside
    if group == "all":
        assert all(row[f"{q}_within_1sd"] > WITHIN_TARGETS[1][1] for q in ("course", "speed"))


NARROW = ("its intervals too narrow (the components' overconfidence after manoeuvres and "
          "the weights of which manoeuvres: docs/manoeuvres.md)")


@pytest.mark.parametrize("group, cell", [
    pytest.param(group, cell, marks=pytest.mark.xfail(strict=True, raises=AssertionError,
                                                       reason=f"{why}: {NARROW}"))
    for group, cell, why in (("p_manoeuvre", ">0.99", "a manoeuvre surely made"),
                             ("range_km", ">30", "beyond 30 km"))])
def test_on_its_own_model_the_intervals_hold_where_a_manoeuvre_was_surely_made(own_model,
                                                                             group, cell):
    """The same where ``p_manoeuvre`` > 0.99, and beyond 30 km: not yet, each cell on its
    own."""
    _, outside = _outside(own_model, group, cell)
    assert not outside, outside


def test_on_its_own_model_the_median_error_reads_as_honest_only_in_the_intervals(own_model):
    """Issue 36, item 5's reading, where the model is right by construction: the median over
    the ok answers of the largest |z| of range, course and speed lies in the real-motion
    checks' band (``real_motion.TWO_SIDED``, the issue's 1.0-1.6 scaled to 1.02, what 2,000
    such targets give; these 1,000: 1.03) in units of the intervals, and far below it in
    units of the sd, which a mixture's tails widen beyond its core (so the real pairs'
    0.35-0.71 in units of the sd are no proof of a prior too rich)."""
    ok = own_model[own_model.status == "ok"]
    z = np.abs(ok[["range_z", "course_z", "speed_z"]].to_numpy())
    iz = np.abs(ok[["range_iz", "course_iz", "speed_iz"]].to_numpy())
    known = np.isfinite(z).all(axis=1)
    assert known.sum() >= 350 and np.isfinite(iz[known]).all()
    by_sd, by_interval = np.median(z[known].max(axis=1)), np.median(iz[known].max(axis=1))
    lo, hi = TWO_SIDED["median_max_iz"]
    assert by_sd < lo and lo <= by_interval <= hi, (by_sd, by_interval)


def test_intervals_stay_within_the_plausible_targets():
    """An undetermined range (an unobservable track's: here an sd 15 times the range, and
    one equal to it) or speed states no end beyond the ranges and speeds of plausible targets
    (10 m to 2,000 km, 0 to 343 m/s: ``status.not_an_answer``'s): an unobservable track's
    2347 +- 1807 m once read [1e-6 m, 1.9e9 m]."""
    from tma.families.bearings2d.status import MAX_RANGE_M, MAX_SPEED_M_S, MIN_RANGE_M

    now = np.array([[2347.0, 0.5, 3.0], [5e4, 0.5, 300.0]])
    sd = np.array([[1807.0 * 20, 0.1, 5.0], [5e4, 0.1, 40.0]])
    columns = interval_columns(now, sd)
    ranges = np.column_stack([columns[c] for c in INTERVAL_COLUMNS["range"]])
    speeds = np.column_stack([columns[c] for c in INTERVAL_COLUMNS["speed"]])
    assert ranges.min() == MIN_RANGE_M and ranges.max() == MAX_RANGE_M
    assert speeds.min() == 0.0 and speeds.max() == MAX_SPEED_M_S
    assert np.all(np.diff(ranges, axis=1) >= 0) and np.all(np.diff(speeds, axis=1) >= 0)


@pytest.mark.parametrize("scale, estimate, sd", [("linear", 6.0, 0.8), ("circular", 355.0, 4.0),
                                                 ("log", 2e4, 1.5e3)])
def test_a_truths_own_error_widens_the_intervals_as_it_widens_the_sd(scale, estimate, sd):
    """A sparse AIS's truth error (sd ``extra``) folded into a single answer's intervals: the
    interval z is then the error over hypot(sd, extra), as the sd's z is (range: in its
    logarithm, extra over the range); none added, the intervals unchanged; an arc grown to a
    whole turn is blank (the 2-sd one alone, or both)."""
    k = np.array([-2.0, -1.0, 1.0, 2.0])
    if scale == "log":
        ends = estimate * np.exp(k * sd / estimate)
    else:
        ends = (estimate + k * sd) % 360.0 if scale == "circular" else estimate + k * sd
    np.testing.assert_allclose(widened_intervals(*ends, 0.0, scale), ends)
    extra, error = 0.5 * sd, 1.3 * sd
    z = interval_z(estimate, error, *widened_intervals(*ends, extra, scale), scale=scale)
    expected = (math.log(estimate / (estimate - error)) / (math.hypot(sd, extra) / estimate)
                if scale == "log" else error / math.hypot(sd, extra))
    assert z == pytest.approx(expected, rel=1e-9)
    if scale == "circular":  # (2 x 2 x 100 deg: the 2-sd arc; 2 x 200: the 1-sd one too)
        lo2, lo1, hi1, hi2 = widened_intervals(*ends, 100.0, scale)
        assert np.isnan([lo2, hi2]).all() and np.isfinite([lo1, hi1]).all()
        assert np.isnan(widened_intervals(*ends, 200.0, scale)).all()
