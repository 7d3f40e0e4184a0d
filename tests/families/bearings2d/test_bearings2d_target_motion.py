"""Targets that move like ships (``target_motion.py``): manoeuvre paths against the exact
arcs of ``tma.maths.path``, wander against its covariance (Monte Carlo), the truth at the last
bearing, reproducibility and common random numbers."""

import dataclasses

import numpy as np
import pytest

from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.families.bearings2d.target_motion import (
    ManoeuvreConfig,
    TargetConfig,
    burst_deviations,
    course_speed,
    manoeuvre_plan,
    target_paths,
    wander,
)
from tma.maths.angles import bearing_from_north
from tma.maths.path import LegPath


class _Fixed:
    """A generator whose draws make one turn of ``angle`` deg at ``rate`` deg/s starting at
    ``start`` (fraction of the observation), speed unchanged."""

    def __init__(self, start, angle, rate):
        self.values = iter([np.array([0.0]), np.array([[start]]), np.array([[abs(angle)]]),
                            np.array([[1.0 if angle > 0 else 0.0]]), np.array([[rate]]),
                            np.array([[1.0]])])

    def random(self, *_):
        return next(self.values)

    def uniform(self, low, high, size):
        return next(self.values)


def test_a_turn_follows_the_exact_arc():
    """A 90 deg right turn at 0.5 deg/s after 300 s, at 8 m/s from course 45 deg: every
    position within 5 mm of the closed-form path (straight, arc, straight)."""
    t = np.arange(0.0, 1201.0, 2.0)
    cfg = TargetConfig(manoeuvres=ManoeuvreConfig(prob=1.0))
    rng = _Fixed(start=0.25, angle=90.0, rate=0.5)
    start = np.array([100.0]), np.array([-200.0])
    x, y, v_end, last = target_paths(cfg, *start, np.deg2rad([45.0]), np.array([8.0]), t,
                                     rng, np.random.default_rng(0))
    exact = LegPath(100.0, -200.0, 8.0, [
        {"course_deg": 45.0, "duration_s": 300.0},
        {"turn_to_deg": 135.0, "rate_deg_s": 0.5, "direction": "right"},
        {"duration_s": 1200.0 - 480.0}])
    ex, ey = exact.position(t)
    assert np.max(np.hypot(x[0] - ex, y[0] - ey)) < 5e-3
    np.testing.assert_allclose(v_end[0], 8.0 * np.array([np.sin(np.deg2rad(135.0)),
                                                         np.cos(np.deg2rad(135.0))]))
    assert last["manoeuvre_start_s"][0] == pytest.approx(300.0)
    assert last["manoeuvre_end_s"][0] == pytest.approx(480.0)
    assert last["course_change_deg"][0] == pytest.approx(90.0)


def test_manoeuvre_plans_turn_and_change_speed_in_order():
    cfg = ManoeuvreConfig(prob=1.0, count=3, speed_change_rel=0.3, accel_m_s2=0.05)
    speed0 = np.full(500, 10.0)
    plan = manoeuvre_plan(cfg, 1200.0, speed0, np.random.default_rng(5))
    ends = plan["start"] + np.maximum(plan["turn_s"], plan["dv_s"])
    assert (plan["start"][1:] >= ends[:-1] - 1e-9).all()  # one after the other
    turns = np.rad2deg(np.abs(plan["turn"]))
    assert ((turns >= 20) & (turns <= 120)).all()
    course, speed = course_speed(plan, np.zeros(500), speed0, np.array([1e6]))
    np.testing.assert_allclose(np.rad2deg(course[:, 0]), np.rad2deg(plan["turn"].sum(0)))
    assert ((speed > 10 * 0.7**3 - 1e-9) & (speed < 10 * 1.3**3 + 1e-9)).all()


def test_wander_has_the_covariance_of_white_acceleration():
    q, t = 2e-3, np.arange(0.0, 601.0, 5.0)
    px, py, vx, vy = wander(q, t, 20000, np.random.default_rng(1))
    T = t[-1]
    expected = q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
    for p, v in ((px, vx), (py, vy)):
        cov = np.cov(np.vstack([p[:, -1], v[:, -1]]))
        np.testing.assert_allclose(cov, expected, rtol=0.05)
    assert (px[:, 0] == 0).all() and (vy[:, 0] == 0).all()


def _sim(sigma=0.0, **target):
    return simulate_shard(Config(n_tracks=300, shard_size=300, sigma_deg=sigma, seed=4,
                                 target=TargetConfig(**target)), 0)


def test_truth_is_the_state_at_the_last_bearing():
    """Noiseless bearings of moving targets: the truth's straight line through the state at
    the last bearing gives exactly the last bearing."""
    log, truth = _sim(accel_psd_m2_s3=1e-3, manoeuvres=ManoeuvreConfig(prob=0.5))
    truth = truth.to_pandas()
    t, k = log.t_s[-1], -1
    bearing = bearing_from_north(truth.x0_m + truth.vx_m_s * t - log.own_x_m[k],
                                 truth.y0_m + truth.vy_m_s * t - log.own_y_m[k])
    np.testing.assert_allclose(np.rad2deg(bearing) % 360, log.bearing_deg[:, k], atol=1e-9)
    assert truth.manoeuvring.mean() == pytest.approx(0.5, abs=0.1)
    assert truth.loc[~truth.manoeuvring, "course_change_deg"].isna().all()
    assert log.accel_psd_m2_s3 is None  # targets that manoeuvre declare no motion model


def test_options_off_leave_the_dataset_as_it_was_and_draws_are_shared():
    base, base_truth = _sim(sigma=0.5)
    declared_off, _ = _sim(sigma=0.5, declared=False)
    np.testing.assert_array_equal(base.bearing_deg, declared_off.bearing_deg)
    assert base.accel_psd_m2_s3 == 0.0 and declared_off.accel_psd_m2_s3 is None
    assert list(base_truth.column_names) == ["track_id", "x0_m", "y0_m", "vx_m_s", "vy_m_s",
                                             "distance0_m", "course_deg", "speed_m_s"]
    # a target's manoeuvre is the same at every share that makes it manoeuvre
    _, half = _sim(manoeuvres=ManoeuvreConfig(prob=0.5))
    _, full = _sim(manoeuvres=ManoeuvreConfig(prob=1.0))
    half, full = half.to_pandas(), full.to_pandas()
    both = half.manoeuvring.to_numpy()
    np.testing.assert_array_equal(half.course_change_deg[both], full.course_change_deg[both])
    again, _ = _sim(sigma=0.5, accel_psd_m2_s3=1e-4)
    twice, _ = _sim(sigma=0.5, accel_psd_m2_s3=1e-4)
    np.testing.assert_array_equal(again.bearing_deg, twice.bearing_deg)


def test_bad_target_options_are_refused():
    from tma.errors import ConfigError

    for target in (TargetConfig(accel_psd_m2_s3=-1.0),
                   TargetConfig(manoeuvres=ManoeuvreConfig(prob=2.0)),
                   TargetConfig(manoeuvres=ManoeuvreConfig(start_frac=0.9, end_frac=0.1)),
                   TargetConfig(manoeuvres=ManoeuvreConfig(turn_rate_min_deg_s=0.0)),
                   TargetConfig(manoeuvres=ManoeuvreConfig(prob=0.5, shape="burst")),
                   TargetConfig(manoeuvres=ManoeuvreConfig(rate_per_h=3.0, shape="arc"))):
        with pytest.raises(ConfigError, match="target"):
            Config(target=target)


def test_the_truth_counts_the_manoeuvres_started_within_the_observation():
    """``n_manoeuvres``: three manoeuvres early in the window all start within it; three from
    99 % of it on (each at least 20 s long: the next starts when one ends) only the first; a
    Poisson process of short manoeuvres (20 deg at 1 deg/s, no speed change: hardly ever
    delayed) counts as Poisson(rate x duration); targets that did not manoeuvre, 0."""
    def truth(**manoeuvres):
        return _sim(manoeuvres=ManoeuvreConfig(**manoeuvres))[1].to_pandas()

    early = truth(prob=0.5, count=3, start_frac=0.1, end_frac=0.3, turn_rate_min_deg_s=1.0,
                  turn_rate_max_deg_s=1.0, course_change_max_deg=30.0, speed_change_rel=0.0)
    np.testing.assert_array_equal(early.n_manoeuvres, np.where(early.manoeuvring, 3, 0))
    late = truth(prob=1.0, count=3, start_frac=0.99, end_frac=0.99)
    assert (late.n_manoeuvres == 1).all()
    log, poisson = _sim(manoeuvres=ManoeuvreConfig(
        rate_per_h=6.0, course_change_min_deg=20.0, course_change_max_deg=20.0,
        turn_rate_min_deg_s=1.0, turn_rate_max_deg_s=1.0, speed_change_rel=0.0))
    counts = poisson.to_pandas().n_manoeuvres.to_numpy()
    mean = 6.0 / 3600.0 * (log.t_s[-1] - log.t_s[0])
    assert abs(counts.mean() - mean) <= 4 * np.sqrt(mean / counts.size)
    assert abs(counts.var() - mean) <= 4 * mean * np.sqrt(2.0 / counts.size) + 0.1
    assert ((counts > 0) == poisson.to_pandas().manoeuvring).all()


@pytest.mark.parametrize("hours", [0.5, 6.0])
def test_poisson_manoeuvres_keep_their_rate_on_logs_of_hours(hours):
    """At ten an hour, a run of 30 minutes and one of 6 hours make rate x duration
    manoeuvres per target on average, with a Poisson variance (none cut off: 6 hours expect
    60, twice the slots a short run needs)."""
    n = 4000
    plan = manoeuvre_plan(ManoeuvreConfig(rate_per_h=10.0), hours * 3600.0,
                          np.full(n, 5.0), np.random.default_rng(np.random.SeedSequence(6)))
    count = (plan["turn"] != 0).sum(axis=0)
    mean = 10.0 * hours
    assert abs(count.mean() - mean) < 4 * np.sqrt(mean / n), count.mean()
    assert abs(count.var() / mean - 1) < 0.1, count.var()


def test_a_burst_changes_the_velocity_as_the_estimators_model_says():
    """The estimators' manoeuvre (``manoeuvres.py``): a burst of white acceleration of density
    s^2 / D over D changes the velocity by N(0, s^2) per axis and puts the position, seen from
    after it, N(0, s^2 D^2 / 12) off a sudden change at its centre, uncorrelated: the
    covariance of (position, velocity) at the end of 20,000 draws against that closed form,
    the burst's ends off the bearing grid (steps it covers in part)."""
    s, D, start = 5.0, 120.0, 303.7
    t = np.arange(0.0, 601.0, 10.0)
    n = 20000
    begin = np.full((1, n), start)
    px, py, vx, vy = burst_deviations(t, begin, np.full((1, n), D), s,
                                      np.random.default_rng(3))
    after = t[-1] - (start + D / 2)  # from the burst's centre to the last epoch
    expected = s**2 * np.array([[after**2 + D**2 / 12, after], [after, 1.0]])
    for p, v in ((px, vx), (py, vy)):
        np.testing.assert_allclose(np.cov(np.vstack([p[:, -1], v[:, -1]])), expected,
                                   rtol=0.05)
        assert np.all(v[:, t <= start] == 0) and np.all(p[:, t <= start] == 0)
    # before the burst ends, as far as it went: the velocity change has s^2 (seen / D)
    k = np.searchsorted(t, start + D / 2)
    assert np.var(vx[:, k]) == pytest.approx(s**2 * (t[k] - start) / D, rel=0.05)


def test_burst_manoeuvres_are_the_declared_prior():
    """``shape=burst``: the log declares the prior the targets were drawn from; Poisson
    counts at its rate, each burst one of its durations; a dataset of turns is as before."""
    log, truth = _sim(manoeuvres=ManoeuvreConfig(rate_per_h=6.0, shape="burst"))
    truth = truth.to_pandas()
    prior = log.manoeuvres
    assert prior is not None and prior.rate_per_h == 6.0
    counts = truth.n_manoeuvres.to_numpy()
    mean = 6.0 / 3600.0 * (log.t_s[-1] - log.t_s[0])
    assert abs(counts.mean() - mean) <= 4 * np.sqrt(mean / counts.size)
    made = truth[truth.manoeuvring]
    span = (made.manoeuvre_end_s - made.manoeuvre_start_s).to_numpy()
    assert np.isin(np.round(span, 6), np.round(prior.durations_s, 6)).all()
    assert ((counts > 0) == truth.manoeuvring).all()
    turns, _ = _sim(manoeuvres=ManoeuvreConfig(rate_per_h=6.0))
    assert turns.manoeuvres == prior  # the same declaration, another motion
    assert not np.array_equal(turns.bearing_deg, log.bearing_deg)
    # shape=turn, the default, leaves a dataset and its name (config hash) as they were
    named, _ = _sim(manoeuvres=ManoeuvreConfig(rate_per_h=6.0, shape="turn"))
    np.testing.assert_array_equal(named.bearing_deg, turns.bearing_deg)
    from tma.families import dataset_name
    from tma.families.bearings2d import scenario

    def name(shape):
        return dataset_name(scenario, Config(n_tracks=300, shard_size=300, seed=4, target=
                                             TargetConfig(manoeuvres=ManoeuvreConfig(
                                                 rate_per_h=6.0, shape=shape))))
    assert name("turn") == dataset_name(scenario, Config(
        n_tracks=300, shard_size=300, seed=4,
        target=TargetConfig(manoeuvres=ManoeuvreConfig(rate_per_h=6.0))))
    assert name("burst") != name("turn")


def test_a_burst_of_no_size_changes_nothing():
    """A declared prior of no size (no turns, no speed changes): bursts leave the targets at
    constant velocity (no 0 / 0), as the turns do."""
    still = ManoeuvreConfig(rate_per_h=6.0, course_change_min_deg=0.0,
                            course_change_max_deg=0.0, speed_change_rel=0.0)
    bursts, _ = _sim(manoeuvres=dataclasses.replace(still, shape="burst"))
    turns, _ = _sim(manoeuvres=still)
    assert bursts.manoeuvres.dv_m_s == 0.0
    np.testing.assert_allclose(bursts.bearing_deg, turns.bearing_deg, atol=1e-9)
