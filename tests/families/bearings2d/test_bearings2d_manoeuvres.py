"""Manoeuvring targets (issue 20, items 2, 3 and 5): flagged by the trend test, re-solved
on their last leg by ``last_leg``; estimators that cannot give honest errors say so."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from tma.families import build_estimator
from tma.families.bearings2d.marquardt import STOP_MAX_ITER
from tma.families.bearings2d.metrics import NEES_95, track_metrics
from tma.families.bearings2d.scenario import (
    Config,
    LegConfig,
    ObserverConfig,
    PopulationConfig,
    simulate_shard,
)
from tma.families.bearings2d.target_motion import ManoeuvreConfig, TargetConfig
from tma.families.bearings2d.track_report import track_report

# close targets (5-12 km) turning 60-120 deg in the first half, own-ship zig-zagging
# throughout: the manoeuvres show in the bearings and the last legs are observable
ZIGZAG = ObserverConfig(legs=[
    LegConfig(course_deg=0.0, duration_s=150.0),
    *[LegConfig(course_deg=c, duration_s=150.0) for c in (60.0, 300.0) * 5]])


def _manoeuvring(n=300, prob=1.0, seed=21, observer=ZIGZAG, sigma=0.5, accel_psd=0.0):
    target = TargetConfig(accel_psd_m2_s3=accel_psd, declared=accel_psd == 0,
                          manoeuvres=ManoeuvreConfig(
        prob=prob, start_frac=0.2, end_frac=0.45, course_change_min_deg=60.0,
        course_change_max_deg=120.0, turn_rate_min_deg_s=0.5, turn_rate_max_deg_s=1.0))
    cfg = Config(n_tracks=n, shard_size=n, sigma_deg=sigma, seed=seed, observer=observer,
                 population=PopulationConfig(distance_min_m=5000.0, distance_max_m=12000.0),
                 target=target)
    log, truth = simulate_shard(cfg, 0)
    return log, truth.to_pandas()


def _estimate(log, name, **params):
    out = build_estimator({"name": name, **params}).estimate(log)
    return pd.DataFrame({"track_id": log.track_id,
                         **{k: v for k, v in out.items() if np.ndim(v) == 1}})


def test_manoeuvres_are_found_and_without_them_in_the_prior_flagged():
    """Plain turns on a recording: lm's prior holds manoeuvres, so it finds them (its
    posterior probability of a manoeuvre > 0.5) and its answer follows the last leg; assuming
    none (``manoeuvre_rate_per_h=0``), the trend test flags them, and the note says so."""
    log, truth = _manoeuvring()
    est = _estimate(log, "lm")
    # (a recording's answer rests on its last 20 minutes, manoeuvre_prior.window_s: of this
    # 27.5-minute log; a turn begun before them is no part of it)
    within = truth.manoeuvre_start_s.to_numpy() >= est.leg_start_s.to_numpy()
    assert 0.3 <= within.mean() < 1.0 and (est.leg_start_s > 0).all()
    assert np.mean(est.p_manoeuvre[within] > 0.5) >= 0.9, est.p_manoeuvre.describe()
    # (the trend test still flags a fifth: a turn is an arc, the manoeuvre model's burst of
    # white noise bends less sharply, and at 5-12 km and 0.5 deg the residuals show it)
    assert np.mean(est.status == "manoeuvring") <= 0.3, est.status.value_counts()
    est = _estimate(log, "lm", manoeuvre_rate_per_h=0.0)
    assert "p_manoeuvre" not in est
    assert np.mean(est.status == "manoeuvring") >= 0.9, est.status.value_counts()
    assert (est.loc[est.status == "manoeuvring", "motion_p_value"] < 1e-3).all()
    notes = track_report(est).query("status == 'manoeuvring'")["note"]
    assert notes.str.contains("trend test p = ").all() and notes.str.contains("last_leg").all()


def test_the_last_leg_is_found():
    """Assuming no manoeuvres, ``last_leg`` seeks the leg of every track the trend test flags
    (with manoeuvres in its prior, only where the mixture fails it: below)."""
    log, truth = _manoeuvring(n=150)
    est = _estimate(log, "last_leg", manoeuvre_rate_per_h=0.0)
    found = est.n_rounds > 0
    assert found.mean() >= 0.9
    # the leg starts after the manoeuvre began, and at most a few minutes after it ended
    start = est.loc[found, "leg_start_s"].to_numpy()
    began = truth.loc[found, "manoeuvre_start_s"].to_numpy()
    ended = truth.loc[found, "manoeuvre_end_s"].to_numpy()
    assert np.mean((start >= began) & (start <= ended + 300)) >= 0.9
    assert (est.loc[found, "n_bearings"] < log.t_s.size).all()  # the leg's bearings only


def test_the_last_legs_errors_are_honest():
    """Ships that turn and wander (q = 1e-3, the wander ``last_leg`` assumes of a recording),
    ``last_leg`` assuming that wander and no manoeuvres: its ok tracks' errors cover the
    truth at 0.905 (548 ok of 600; 0.915 with another seed), a little under the nominal 0.95
    (the change time's own uncertainty is not in them) and within issue 20's 90-97 %; errors
    twice too large would give ~1.0. With a recording's manoeuvres in its prior (the
    default, ten an hour: far more than these targets make) they are wider, and cover it
    more often."""
    log, truth = _manoeuvring(n=300, accel_psd=1e-3)
    for params, low, high in (({"manoeuvre_rate_per_h": 0.0}, 0.88, 0.97), ({}, 0.95, 1.0)):
        est = _estimate(log, "last_leg", **params)
        m = track_metrics(est, truth)
        ok = m.status == "ok"
        assert ok.mean() >= 0.75, (params, est.status.value_counts())
        assert low <= np.mean(m.nees[ok] <= NEES_95) <= high, params


def test_a_last_leg_without_own_ship_manoeuvre_is_unobservable():
    """Own-ship zig-zags until 600 s, then holds its course: a target that manoeuvres
    after that has a last leg whose range the bearings cannot give."""
    straight_after = ObserverConfig(legs=[
        LegConfig(course_deg=0.0, duration_s=150.0),
        *[LegConfig(course_deg=c, duration_s=150.0) for c in (60.0, 300.0, 60.0)],
        LegConfig(course_deg=0.0, duration_s=600.0)])
    target = TargetConfig(manoeuvres=ManoeuvreConfig(
        prob=1.0, start_frac=0.6, end_frac=0.65, course_change_min_deg=80.0,
        course_change_max_deg=120.0, turn_rate_min_deg_s=1.0, turn_rate_max_deg_s=2.0))
    cfg = Config(n_tracks=100, shard_size=100, sigma_deg=0.5, seed=3, observer=straight_after,
                 population=PopulationConfig(distance_min_m=5000.0, distance_max_m=10000.0),
                 target=target)
    log, _ = simulate_shard(cfg, 0)
    est = _estimate(log, "last_leg", manoeuvre_rate_per_h=0.0)
    found = est.n_rounds > 0
    assert found.mean() >= 0.8
    assert np.mean(est.loc[found, "status"] == "unobservable") >= 0.9


def test_with_manoeuvres_in_the_prior_a_leg_is_sought_only_where_the_mixture_fails():
    """The mixture already averages over when the target turned: ``last_leg`` with a
    recording's manoeuvres in its prior seeks a leg on few of these turning targets (all of
    them without: ``test_the_last_leg_is_found``), and elsewhere its answer is ``lm``'s."""
    log, _ = _manoeuvring(n=100)
    lm, leg = _estimate(log, "lm"), _estimate(log, "last_leg")
    sought = leg.n_rounds > 0
    assert sought.mean() <= 0.3
    for column in ("x0_m", "range_sd_m", "status", "leg_start_s", "p_manoeuvre"):
        np.testing.assert_array_equal(lm.loc[~sought, column], leg.loc[~sought, column])


def test_a_steady_target_is_one_leg():
    log, _ = _manoeuvring(n=100, prob=0.0, seed=5)
    lm, leg = _estimate(log, "lm"), _estimate(log, "last_leg")
    steady = leg.n_rounds == 0
    assert steady.mean() >= 0.98
    for column in ("x0_m", "range_sd_m", "status", "leg_start_s"):
        np.testing.assert_array_equal(lm.loc[steady, column], leg.loc[steady, column])
    assert (leg.leg_start_s == 0).all()


@pytest.mark.parametrize("name", ["iv", "mpekf"])
def test_constant_velocity_estimators_are_approximate_where_targets_may_wander(name):
    """On a log that declares no motion (a recording) iv and mpekf cannot include the
    target's own motion in their errors: never ok, approximate (or flagged)."""
    log, _ = _manoeuvring(n=100, prob=0.0, seed=6)
    log.accel_psd_m2_s3 = None
    est = _estimate(log, name)
    assert (est.status != "ok").all()
    assert np.mean(est.status == "approximate") >= 0.9
    log.accel_psd_m2_s3 = 0.0  # declared constant velocity: their errors are honest again
    assert np.mean(_estimate(log, name).status == "ok") >= 0.95


def test_nbearings_is_never_ok():
    log, _ = _manoeuvring(n=100, prob=0.0, seed=7, sigma=0.1)
    log.accel_psd_m2_s3 = 0.0
    est = _estimate(log, "nbearings")
    assert "ok" not in set(est.status)
    assert np.mean(est.status == "approximate") >= 0.5


@pytest.mark.parametrize("sigma", [0.1, 0.5, 1.0])
def test_mpekf_errors_are_consistent(sigma):
    """Its covariance (the batch one plus its distance from the batch optimum): 93-97 % of
    ok tracks within the chi-square(4) 95 % point (the filter's own: 72-87 %)."""
    cfg = Config(n_tracks=1500, shard_size=1500, sigma_deg=sigma, seed=31)
    log, truth = simulate_shard(cfg, 0)
    m = track_metrics(_estimate(log, "mpekf"), truth.to_pandas())
    ok = m.status == "ok"
    assert ok.mean() >= 0.98
    assert 0.93 <= np.mean(m.nees[ok] <= NEES_95) <= 0.97


def test_motion_test_modes():
    log, _ = _manoeuvring(n=60, prob=1.0, seed=8)
    log.accel_psd_m2_s3 = 0.0  # declared (wrongly) constant velocity: auto does not test
    assert np.isnan(_estimate(log, "lm")["motion_p_value"]).all()
    assert (_estimate(log, "lm", motion_test="on")["status"] == "manoeuvring").mean() > 0.8
    log.accel_psd_m2_s3 = None
    assert np.isnan(_estimate(log, "lm", motion_test="off")["motion_p_value"]).all()
    assert np.isfinite(_estimate(log, "lm")["motion_p_value"]).all()


def test_the_manoeuvre_prior_options():
    """Every part of the manoeuvres' prior is an option (to fit it on one recording and test
    it on another): a recording's prior is real-ship motion, a simulation's its declared one,
    each part replaced where set; the rate and q, not the size or durations, are scaled by
    ``motion_prior_scale``; and the answer follows the prior it is given."""
    from tma.families.bearings2d.manoeuvre_prior import (
        RECORDED_DURATIONS_S,
        RECORDED_DV_M_S,
        RECORDED_RATE_PER_H,
        ManoeuvrePrior,
    )
    from tma.families.bearings2d.ncv import RECORDED_ACCEL_PSD
    log, _ = _manoeuvring(n=20)
    recording = dataclasses.replace(log, accel_psd_m2_s3=None, manoeuvres=None)
    declared = dataclasses.replace(log, accel_psd_m2_s3=0.0,
                                   manoeuvres=ManoeuvrePrior(3.0, 2.0, (60.0, 90.0)))
    lm = build_estimator({"name": "lm"})
    assert lm.motion(recording).accel_psd_m2_s3 == RECORDED_ACCEL_PSD
    assert lm.motion(recording).manoeuvres == ManoeuvrePrior(
        RECORDED_RATE_PER_H, RECORDED_DV_M_S, RECORDED_DURATIONS_S)
    assert lm.motion(declared).manoeuvres == ManoeuvrePrior(3.0, 2.0, (60.0, 90.0))
    set_ = build_estimator({"name": "lm", "accel_psd_m2_s3": 2e-4, "manoeuvre_rate_per_h": 7.0,
                            "manoeuvre_dv_m_s": 3.5, "manoeuvre_durations_s": [50, 150],
                            "motion_prior_scale": 0.5})
    for which in (recording, declared):
        motion = set_.motion(which)
        assert motion.accel_psd_m2_s3 == pytest.approx(1e-4)
        assert motion.manoeuvres == ManoeuvrePrior(3.5, 3.5, (50.0, 150.0))
    # only the size set: the rest as the log declares; none declared: no manoeuvres
    sized = build_estimator({"name": "lm", "manoeuvre_dv_m_s": 1.0})
    assert sized.motion(declared).manoeuvres == ManoeuvrePrior(3.0, 1.0, (60.0, 90.0))
    assert sized.motion(dataclasses.replace(declared, manoeuvres=None)).manoeuvres is None
    # the answer follows the prior: the recorded one given as options is the default's
    # answer, another size or other durations another answer
    as_set = build_estimator({"name": "lm", "manoeuvre_dv_m_s": RECORDED_DV_M_S,
                              "manoeuvre_durations_s": list(RECORDED_DURATIONS_S)})
    a = lm.estimate(recording)
    np.testing.assert_array_equal(a["range_sd_m"], as_set.estimate(recording)["range_sd_m"])
    for other in ({"manoeuvre_dv_m_s": 2 * RECORDED_DV_M_S},
                  {"manoeuvre_durations_s": [30.0, 600.0]}):
        b = build_estimator({"name": "lm", **other}).estimate(recording)
        both = np.isfinite(a["range_sd_m"]) & np.isfinite(b["range_sd_m"])
        assert both.sum() >= 10, other
        assert np.median(np.abs(b["range_sd_m"][both] / a["range_sd_m"][both] - 1)) > 0.01, other


def test_an_answer_that_follows_the_motion_is_judged_by_its_own_convergence():
    """With manoeuvres in the prior the answer is the mixture's, which the constant-velocity
    fit only starts: a start stopped at max_iter (one step here; on a log of hours, a target
    that manoeuvred throughout) is no ``not_converged`` answer where the mixture converged,
    and the mixture from that poorer start still answers most tracks."""
    log, _ = _manoeuvring(n=40, seed=5, accel_psd=1e-4)
    full = _estimate(log, "lm")
    one_step = _estimate(log, "lm", max_iter=1)
    assert (one_step.stop_reason == STOP_MAX_ITER).all()  # every start stopped short
    assert not (one_step.status == "not_converged").any(), one_step.status.value_counts()
    ok = (full.status == "ok").to_numpy()  # the same answers where the full start's are ok
    assert ok.sum() >= 20 and (one_step.status[ok] == "ok").all(), one_step.status[ok]
    np.testing.assert_array_less(np.abs(one_step.range_now_m - full.range_now_m)[ok],
                                 0.1 * full.range_sd_m[ok])


def test_last_leg_rests_on_the_span_lm_answers_from():
    """On a log of an hour under a recording's prior (manoeuvres not declared), ``last_leg``
    seeks legs only within the window ``lm``'s answer rests on (``manoeuvres.window_s``): no
    leg starts before it, and where ``lm``'s answer passes the trend test the two agree."""
    import tma
    from tma.families.bearings2d.manoeuvre_prior import RECORDED_MANOEUVRES, window_s

    legs = [{"course_deg": 45.0 if k % 2 == 0 else 135.0, "duration_s": 720.0}
            for k in range(5)]
    ds = tma.simulate("bearings2d", n_tracks=16, sigma_deg=0.5, sample_period_s=10.0, seed=3,
                      population={"distance_min_m": 5000.0, "distance_max_m": 15000.0,
                                  "speed_min_m_s": 3.0, "speed_max_m_s": 6.0},
                      observer={"legs": legs},
                      target={"accel_psd_m2_s3": 1e-3, "manoeuvres": {"rate_per_h": 10.0},
                              "declared": False})
    lm, last_leg = tma.estimate(ds, "lm"), tma.estimate(ds, "last_leg")
    window = window_s(RECORDED_MANOEUVRES)
    assert (last_leg.t_now_s - last_leg.leg_start_s <= window + 1e-6).all(), last_leg.leg_start_s
    assert (lm.t_now_s - lm.leg_start_s <= window + 1e-6).all()
    # an unobservable answer says that only own-ship's motion within its span can help, and
    # shows no course or speed (nor its range determined, its velocity)
    unobservable = lm[lm.status == "unobservable"]
    assert len(unobservable) >= 1, lm.status.value_counts()
    assert unobservable.note.str.contains("the answer rests on the last 20 min of bearings").all()
    assert unobservable.course_deg.isna().all() and unobservable.speed_m_s.isna().all()
    same = (lm.motion_p_value >= 1e-3).to_numpy()  # (estimator.motion_alpha)
    assert same.sum() >= 8, lm.motion_p_value
    for column in ("status", "range_now_m", "bearing_now_deg", "leg_start_s"):
        np.testing.assert_array_equal(last_leg[column].to_numpy()[same],
                                      lm[column].to_numpy()[same], err_msg=column)
