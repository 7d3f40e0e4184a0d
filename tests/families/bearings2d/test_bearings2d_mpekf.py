"""``mpekf``: the modified-polar transition against a Cartesian propagation of the target and
own-ship, its Jacobians against finite differences, noiseless convergence, NEES consistency
over Monte Carlo on a benign geometry, and the innovation gate against outliers."""

import dataclasses

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from tests.families.bearings2d.test_bearings2d_configs import SHARED, check_bearings, configs
from tests.test_estimator_configs import FUZZ
from tma.errors import InputError
from tma.families import build_estimator
from tma.families.bearings2d import metrics
from tma.families.bearings2d.estimators.mpekf import (
    mpc_from_relative,
    mpc_transition,
    reference_velocity,
    theta_from_mpc,
)
from tma.families.bearings2d.scenario import (
    Config,
    OutlierConfig,
    PopulationConfig,
    observer_path,
    simulate_shard,
)

THETA = list(metrics.THETA)
SCALE = np.array([1e-4, 1e-4, 1.0, 1e-4])  # typical size of each MPC component


def _fixed_target(n, sigma, distance, course=120.0, speed=8.0, seed=11, prob=0.0):
    pop = PopulationConfig(distance_min_m=distance, distance_max_m=distance,
                           course_min_deg=course, course_max_deg=course,
                           speed_min_m_s=speed, speed_max_m_s=speed)
    cfg = Config(n_tracks=n, shard_size=n, sigma_deg=sigma, seed=seed, population=pop,
                 outliers=OutlierConfig(prob=prob))
    log, truth = simulate_shard(cfg, 0)
    return log, truth.to_pandas()


def _relative(theta, t, ox, oy, u):
    """Relative position and velocity (target minus own-ship reference) at every epoch."""
    d = np.stack([theta[:, 0, None] + theta[:, 2, None] * t - ox,
                  theta[:, 1, None] + theta[:, 3, None] * t - oy], axis=-1)
    w = theta[:, None, 2:] - u[None]
    return d, w


def test_transition_follows_the_cartesian_motion_through_every_turn():
    """From the true MPC state at t = 0, 600 steps of the transition over the default own-ship
    path (two turns) match the MPC state of the Cartesian truth at every epoch."""
    cfg = Config(n_tracks=50, shard_size=50, seed=2)
    log, truth = simulate_shard(cfg, 0)
    theta = truth.to_pandas()[THETA].to_numpy()
    t, ox, oy = log.t_s, log.own_x_m, log.own_y_m
    u = reference_velocity(t, ox, oy)
    d, w = _relative(theta, t, ox, oy, u)
    y = mpc_from_relative(d[:, 0], w[:, 0])
    worst = 0.0
    for k in range(1, t.size):
        y, _ = mpc_transition(y, t[k] - t[k - 1], u[k - 1] - u[k])
        expected = mpc_from_relative(d[:, k], w[:, k])
        worst = max(worst, np.max(np.abs(y - expected) / SCALE))
    assert worst < 1e-9, worst
    # the reference velocity is the own-ship's true speed (5 m/s) to within the chord effect
    assert np.allclose(np.hypot(u[:, 0], u[:, 1]), 5.0, rtol=1e-4)
    assert observer_path(cfg).duration_s == pytest.approx(t[-1])


def _finite_difference(fn, y, scale, eps=1e-6):
    D = np.empty((y.shape[0], 4, 4))
    for j in range(4):
        h = eps * scale[j]
        up, down = y.copy(), y.copy()
        up[:, j] += h
        down[:, j] -= h
        D[:, :, j] = (fn(up) - fn(down)) / (2 * h)
    return D


def test_jacobians_match_finite_differences():
    rng = np.random.default_rng(1)
    d = rng.uniform(-2e4, 2e4, (20, 2))
    w = rng.uniform(-15, 15, (20, 2))
    y = mpc_from_relative(d, w)
    du, T = np.array([4.0, -3.0]), 2.0
    _, F = mpc_transition(y, T, du)
    F_fd = _finite_difference(lambda v: mpc_transition(v, T, du)[0], y, SCALE)
    np.testing.assert_allclose(F * SCALE[None, None, :] / SCALE[None, :, None],
                               F_fd * SCALE[None, None, :] / SCALE[None, :, None], atol=1e-7)
    t, own, u = np.full(20, 600.0), rng.uniform(-1e3, 1e3, (20, 2)), rng.uniform(-5, 5, (20, 2))
    theta, G = theta_from_mpc(y, t, own, u)
    # the conversion inverts mpc_from_relative: theta's position now is own + d, velocity u + w
    np.testing.assert_allclose(theta[:, :2] + theta[:, 2:] * t[:, None], own + d, rtol=1e-12)
    np.testing.assert_allclose(theta[:, 2:], u + w, rtol=1e-12)
    G_fd = _finite_difference(lambda v: theta_from_mpc(v, t, own, u)[0], y, SCALE)
    np.testing.assert_allclose(G * SCALE, G_fd * SCALE, rtol=1e-6, atol=1e-6)


def test_noiseless_bearings_converge_to_the_truth():
    log, truth = simulate_shard(Config(n_tracks=300, shard_size=300, sigma_deg=0.0, seed=8), 0)
    out = build_estimator({"name": "mpekf"}).estimate(log)
    err = _theta(out) - truth.to_pandas()[THETA].to_numpy()
    distance = truth["distance0_m"].to_numpy()
    assert np.max(np.hypot(err[:, 0], err[:, 1]) / distance) < 1e-4
    assert np.max(np.hypot(err[:, 2], err[:, 3])) < 0.01  # m/s
    assert (out["status"] == "ok").all()


def _theta(out):
    return np.column_stack([out[c] for c in THETA])


def test_nees_is_consistent_on_a_benign_geometry():
    """500 noise draws of a target 10 km away at sigma 0.1 deg: the filter's normalised error
    (theta_hat - theta)^T P^-1 (theta_hat - theta) at the last bearing averages within the 99 %
    band of chi-square(4 * 500) / 500, and about 95 % of the draws lie below the chi-square(4)
    95 % point."""
    n = 500
    log, truth = _fixed_target(n, 0.1, 10000.0)
    out = build_estimator({"name": "mpekf"}).estimate(log)
    est = pd.DataFrame({k: v for k, v in out.items() if np.ndim(v) == 1})
    est["track_id"] = log.track_id
    nees = metrics.track_metrics(est, truth)["nees"].to_numpy()
    lo, hi = chi2.ppf([0.005, 0.995], 4 * n) / n
    assert lo < nees.mean() < hi, (nees.mean(), lo, hi)
    share = np.mean(nees <= metrics.NEES_95)
    assert 0.92 < share < 0.98, share
    # the covariance the output carries is the filter's: the one-sigma range error agrees with
    # the spread of the range errors
    err = metrics.errors_now(est, truth)["range_err_m"]
    assert np.median(out["range_sd_m"]) == pytest.approx(err.std(), rel=0.1)


def test_the_gate_keeps_the_filter_on_track_among_outliers():
    """10 % of the bearings replaced by uniform draws: without a gate the filter is lost,
    with a 4-sd gate its errors stay those of clean data and it skips about the outliers."""
    clean, truth = _fixed_target(200, 0.3, 15000.0)
    dirty, _ = _fixed_target(200, 0.3, 15000.0, prob=0.1)
    replaced = (dirty.bearing_deg != clean.bearing_deg).sum(axis=1)

    def range_error(log, **config):
        out = build_estimator({"name": "mpekf", **config}).estimate(log)
        est = pd.DataFrame({k: v for k, v in out.items() if np.ndim(v) == 1})
        est["track_id"] = log.track_id
        return metrics.errors_now(est, truth)["range_err_m"].to_numpy(), out

    reference, _ = range_error(clean)
    plain, _ = range_error(dirty)
    gated, out = range_error(dirty, gate_sigmas=4.0)
    rms = {k: np.sqrt(np.nanmean(v**2)) for k, v in
           [("clean", reference), ("plain", plain), ("gated", gated)]}
    assert rms["gated"] < 1.3 * rms["clean"], rms
    assert rms["plain"] > 10 * rms["clean"] or np.isnan(plain).mean() > 0.1, rms
    # about every outlier is gated (those within 4 sd of the truth pass, harmlessly), and few
    # good bearings (a restart after an outlier first bearing skips 5)
    print(out["n_gated"].sum() / replaced.sum())
    assert 0.95 * replaced.sum() < out["n_gated"].sum() < 1.1 * replaced.sum()


def test_a_log_without_noise_needs_sigma():
    log, _ = _fixed_target(3, 0.5, 15000.0)
    unknown = dataclasses.replace(log, sigma_deg=None)
    with pytest.raises(InputError, match="sigma_deg"):
        build_estimator({"name": "mpekf"}).estimate(unknown)
    given_sigma = build_estimator({"name": "mpekf", "sigma_deg": 0.5}).estimate(unknown)
    declared = build_estimator({"name": "mpekf"}).estimate(log)
    np.testing.assert_array_equal(_theta(given_sigma), _theta(declared))


MPEKF = {"initial_range_m": st.floats(1.0, 1e8), "initial_range_sd_m": st.floats(1.0, 1e8),
         "initial_speed_sd_m_s": st.floats(1e-3, 1e3),
         "sigma_deg": st.one_of(st.none(), st.floats(0.0, 45.0)),
         "min_sigma_deg": st.floats(1e-6, 10.0),
         "gate_sigmas": st.one_of(st.none(), st.floats(0.1, 100.0)),
         "gate_reset": st.integers(0, 50)}


@settings(FUZZ, max_examples=60)
@given(configs("mpekf", {**SHARED, **MPEKF}))
def test_mpekf_config_is_refused_or_every_track_is_finite_or_flagged(node):
    check_bearings(node)
