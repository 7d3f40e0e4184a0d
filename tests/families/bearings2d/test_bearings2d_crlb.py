"""The Cramer-Rao bound of ``metrics``: the Fisher information against finite differences of
the bearing model, the delta-method mapping against finite differences of the kinematics,
and a Monte Carlo check that the ML (lm) spread reaches the bound on a benign geometry."""

import numpy as np
import pandas as pd
import pytest

from tma.families import build_estimator
from tma.families.bearings2d import metrics
from tma.families.bearings2d.model import predicted_bearings
from tma.families.bearings2d.scenario import (
    Config,
    LegConfig,
    ObserverConfig,
    PopulationConfig,
    simulate_shard,
)
from tma.families.bearings2d.status import kinematics_now

THETA = list(metrics.THETA)


def _fixed_target(n, sigma, distance=15000.0, course=120.0, speed=8.0, seed=5, **kw):
    """n noise draws of one target (the population reduced to a point)."""
    pop = PopulationConfig(distance_min_m=distance, distance_max_m=distance,
                           course_min_deg=course, course_max_deg=course,
                           speed_min_m_s=speed, speed_max_m_s=speed)
    cfg = Config(n_tracks=n, shard_size=n, sigma_deg=sigma, seed=seed, population=pop, **kw)
    log, truth = simulate_shard(cfg, 0)
    return log, truth.to_pandas()


def _numerical_jacobian(theta, t, ox, oy):
    """Central differences of the predicted bearings, (n, K, 4)."""
    J = np.empty((theta.shape[0], t.size, 4))
    for j in range(4):
        h = 1e-6 * np.maximum(np.abs(theta[:, j]), 1.0)
        up, down = theta.copy(), theta.copy()
        up[:, j] += h
        down[:, j] -= h
        diff = predicted_bearings(up, t, ox, oy) - predicted_bearings(down, t, ox, oy)
        J[:, :, j] = (diff + np.pi) % (2 * np.pi) - np.pi
        J[:, :, j] /= 2 * h[:, None]
    return J


def test_fisher_information_matches_finite_differences():
    log, truth = simulate_shard(Config(n_tracks=20, shard_size=20, sigma_deg=0.5, seed=9), 0)
    theta = truth.to_pandas()[THETA].to_numpy()
    t, ox, oy = log.t_s, log.own_x_m, log.own_y_m
    valid = np.ones(log.bearing_deg.shape, dtype=bool)
    valid[3, :200] = False  # a contact seen late: its missing bearings carry no information
    info = metrics.fisher_information(theta, t, ox, oy, valid, 0.5)
    J = _numerical_jacobian(theta, t, ox, oy) * valid[..., None]
    reference = np.einsum("nki,nkj->nij", J, J) / np.deg2rad(0.5) ** 2
    scale = np.sqrt(np.einsum("nii->ni", reference))
    np.testing.assert_allclose(info / (scale[:, :, None] * scale[:, None, :]),
                               reference / (scale[:, :, None] * scale[:, None, :]),
                               atol=1e-6)
    # the bound is its inverse
    bound = metrics.crlb_theta(theta, t, ox, oy, valid, 0.5)
    np.testing.assert_allclose(np.einsum("nij,njk->nik", bound, info),
                               np.broadcast_to(np.eye(4), bound.shape), atol=1e-8)


def test_bound_now_is_the_delta_method_of_the_theta_bound():
    log, truth = _fixed_target(3, 0.3)
    theta = truth[THETA].to_numpy()
    bound = metrics.crlb_now(log, truth)
    C = metrics.crlb_theta(theta, log.t_s, log.own_x_m, log.own_y_m, None, 0.3)
    k = log.t_s.size - 1
    # G by central differences of (range, bearing, course, speed) at the last bearing
    G = np.empty((3, 4, 4))
    for j in range(4):
        h = 1e-4 * max(np.abs(theta[:, j]).max(), 1.0)
        up, down = theta.copy(), theta.copy()
        up[:, j] += h
        down[:, j] -= h
        at = (np.full(3, log.t_s[k]), np.full(3, log.own_x_m[k]), np.full(3, log.own_y_m[k]))
        G[:, :, j] = (np.array(kinematics_now(up, *at)[0])
                      - np.array(kinematics_now(down, *at)[0])).T / (2 * h)
    sd = np.sqrt(np.einsum("nij,njk,nik->ni", G, C, G))
    got = bound[["crlb_range_m", "crlb_bearing_deg", "crlb_course_deg",
                 "crlb_speed_m_s"]].to_numpy()
    np.testing.assert_allclose(got, sd * np.array([1, 180 / np.pi, 180 / np.pi, 1]), rtol=1e-5)


def test_ml_reaches_the_bound_on_a_benign_geometry():
    """2000 noise draws of one target 15 km away at sigma 0.1 deg: the spread of lm's range,
    course and speed at the last bearing is within 15 % of the bound (the sampling error of a
    variance over 2000 draws is about 3 %)."""
    log, truth = _fixed_target(2000, 0.1)
    out = build_estimator({"name": "lm"}).estimate(log)
    est = pd.DataFrame({k: v for k, v in out.items() if np.ndim(v) == 1})
    est["track_id"] = log.track_id
    err = metrics.errors_now(est, truth)
    bound = metrics.crlb_now(log, truth).iloc[0]
    for error, limit in [("range_err_m", "crlb_range_m"), ("course_err_deg", "crlb_course_deg"),
                         ("speed_err_m_s", "crlb_speed_m_s")]:
        ratio = err[error].var() / bound[limit] ** 2
        assert abs(ratio - 1) < 0.15, (error, ratio)
    row = metrics.efficiency_row(err, metrics.crlb_now(log, truth))
    assert 0.85 < row["efficiency_range"] < 1.15
    # the N-bearings estimate, biased by its first bearing, is far from efficient
    nb = build_estimator({"name": "nbearings"}).estimate(log)
    est_nb = pd.DataFrame({k: v for k, v in nb.items() if np.ndim(v) == 1})
    est_nb["track_id"] = log.track_id
    row_nb = metrics.efficiency_row(metrics.errors_now(est_nb, truth),
                                    metrics.crlb_now(log, truth))
    assert row_nb["efficiency_range"] < 0.2


def test_efficiency_row_by_hand():
    errors = pd.DataFrame({"track_id": [1, 2, 3, 4], "range_err_m": [3.0, -4.0, 0.0, np.nan],
                           "course_err_deg": [1.0, 1.0, 1.0, 1.0],
                           "speed_err_m_s": [0.0, 0.0, 2.0, 0.0], "bearing_err_deg": 0.0})
    bounds = pd.DataFrame({"track_id": [4, 3, 2, 1], "crlb_range_m": [9.0, 1.0, 2.0, 2.0],
                           "crlb_course_deg": [0.5, 0.5, 0.5, 0.5],
                           "crlb_speed_m_s": [1.0, 1.0, 1.0, np.inf]})
    row = metrics.efficiency_row(errors, bounds)
    assert row["n_failed"] == 1  # track 4: no finite estimate
    # tracks 2 and 3 only (track 1 has an infinite bound): range errors -4, 0; bounds 2, 1
    assert row["rmse_range"] == pytest.approx(np.sqrt(8.0))
    assert row["crlb_range"] == pytest.approx(np.sqrt(2.5))
    assert row["efficiency_range"] == pytest.approx(2.5 / 8.0)
    assert row["efficiency_course"] == pytest.approx(0.25)
    assert row["rmse_speed"] == pytest.approx(np.sqrt(2.0))


def test_noiseless_and_unobservable_bounds():
    log, truth = _fixed_target(2, 0.0)
    assert (metrics.crlb_now(log, truth).drop(columns="track_id").to_numpy() == 0).all()
    straight = ObserverConfig(legs=[LegConfig(course_deg=0.0, duration_s=1200.0)])
    log, truth = _fixed_target(2, 0.5, observer=straight)  # no manoeuvre: range unobservable
    bound = metrics.crlb_now(log, truth)
    assert np.isinf(bound["crlb_range_m"]).all()
