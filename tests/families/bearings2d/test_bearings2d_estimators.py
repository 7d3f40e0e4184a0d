"""LM against scipy.optimize.least_squares, N bearings exactness and its linear algebra."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from tma.errors import ConfigError, InputError
from tma.families import build_estimator
from tma.families.bearings2d.estimators.lm import initial_theta
from tma.families.bearings2d.model import bearing_cost, bearing_jacobian, bearing_residuals
from tma.families.bearings2d.scenario import Config, simulate_shard


def _log(n=300, sigma=0.5, seed=7):
    log, truth = simulate_shard(Config(n_tracks=n, shard_size=n, sigma_deg=sigma, seed=seed), 0)
    return log, truth.to_pandas()


def test_lm_reaches_the_same_minimum_as_scipy():
    log, _ = _log()
    lm = build_estimator({"name": "lm"})
    out = lm.estimate(log)
    t, ox, oy = log.t_s, log.own_x_m, log.own_y_m
    measured = np.deg2rad(log.bearing_deg)
    theta0 = initial_theta(lm.config, t, ox, oy, measured, np.zeros(log.n_tracks, int))
    ours = np.column_stack([out[c] for c in ("x0_m", "y0_m", "vx_m_s", "vy_m_s")])
    agree = 0
    for i in range(log.n_tracks):
        m = measured[i:i + 1]

        def fun(th, m=m):
            return -bearing_residuals(th[None], t, ox, oy, m, None)[0]

        def jac(th):
            return bearing_jacobian(th[None], t, ox, oy, None)[0]

        ref = least_squares(fun, theta0[i], jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
        f_ref = 2 * ref.cost
        f_ours = out["cost_rad2"][i]
        same = abs(f_ours - f_ref) <= 1e-6 * f_ref and np.allclose(ours[i], ref.x, rtol=1e-3,
                                                                      atol=1.0)
        agree += same
        # never worse than scipy by more than round-off
        assert f_ours <= f_ref * (1 + 1e-6) or not ref.success
    print(f"{agree} of {log.n_tracks} minima agree")
    assert agree >= 0.97 * log.n_tracks, f"only {agree} of {log.n_tracks} minima agree"
    assert out["converged"].all()


def test_lm_is_a_stationary_point_and_counts_evaluations():
    log, _ = _log(n=100, sigma=0.2)
    out = build_estimator({"name": "lm"}).estimate(log)
    theta = np.column_stack([out[c] for c in ("x0_m", "y0_m", "vx_m_s", "vy_m_s")])
    t, ox, oy, m = log.t_s, log.own_x_m, log.own_y_m, np.deg2rad(log.bearing_deg)
    jac = bearing_jacobian(theta, t, ox, oy, None)
    grad = np.einsum("nki,nk->ni", jac, bearing_residuals(theta, t, ox, oy, m, None))
    scale = np.sqrt(np.einsum("nkii->ni", jac[..., None] * jac[..., None, :]))
    rel = np.abs(grad) / (scale * np.sqrt(out["cost_rad2"])[:, None])
    assert np.median(rel.max(axis=1)) < 1e-3
    assert np.all(out["n_f_evals"] >= out["n_iter"] + 1)
    np.testing.assert_allclose(out["cost_rad2"], bearing_cost(theta, t, ox, oy, m, None))


def test_lm_respects_max_iter():
    log, _ = _log(n=20)
    out = build_estimator({"name": "lm", "max_iter": 2}).estimate(log)
    assert np.all(out["n_iter"] <= 2)
    assert not out["converged"].any()


def test_nbearings_exact_without_noise():
    log, truth = _log(n=200, sigma=0.0)
    out = build_estimator({"name": "nbearings"}).estimate(log)
    for col in ("x0_m", "y0_m"):
        np.testing.assert_allclose(out[col], truth[col], atol=1e-4)
    for col in ("vx_m_s", "vy_m_s"):
        np.testing.assert_allclose(out[col], truth[col], atol=1e-8)


def test_nbearings_equals_lstsq_of_the_spec_rows():
    log, _ = _log(n=30, sigma=0.5)
    out = build_estimator({"name": "nbearings"}).estimate(log)
    t, ox, oy = log.t_s, log.own_x_m, log.own_y_m
    for i in range(log.n_tracks):
        phi = np.deg2rad(log.bearing_deg[i])
        phi0, dt = phi[0], t[1:] - t[0]
        p = phi[1:]
        A = np.column_stack([np.sin(p - phi0), -dt * np.cos(p), dt * np.sin(p)])
        b = -((ox[1:] - ox[0]) * np.cos(p) - (oy[1:] - oy[0]) * np.sin(p))
        r0, vx, vy = np.linalg.lstsq(A, b, rcond=None)[0]
        np.testing.assert_allclose([out["x0_m"][i], out["y0_m"][i]],
                                   [r0 * np.sin(phi0), r0 * np.cos(phi0)], rtol=1e-7)
        np.testing.assert_allclose([out["vx_m_s"][i], out["vy_m_s"][i]], [vx, vy], rtol=1e-7)


def test_estimators_handle_missing_bearings():
    log, truth = _log(n=40, sigma=0.0)
    rng = np.random.default_rng(3)
    log.bearing_deg[rng.random(log.bearing_deg.shape) < 0.3] = np.nan
    log.bearing_deg[:, 0] = np.nan  # no track has a bearing at t = 0
    for name in ("lm", "nbearings"):
        out = build_estimator({"name": name}).estimate(log)
        np.testing.assert_allclose(out["x0_m"], truth["x0_m"], atol=1e-2)
        assert np.all(out["n_bearings"] < 601)


def test_too_few_bearings_is_a_clear_error():
    log, _ = _log(n=3)
    log.bearing_deg[1, 3:] = np.nan
    with pytest.raises(InputError, match=r"tracks 1 have fewer than 5 bearings"):
        build_estimator({"name": "lm"}).estimate(log)


def test_unknown_estimator_and_bad_parameters():
    with pytest.raises(ConfigError, match="unknown estimator .lmx.*known: .*lm, .*nbearings"):
        build_estimator({"name": "lmx"})
    with pytest.raises(ConfigError, match="lambda_up"):
        build_estimator({"name": "lm", "lambda_up": 0.5})
    with pytest.raises(ConfigError, match="bogus"):
        build_estimator({"name": "lm", "bogus": 1})
    with pytest.raises(ConfigError,
                       match="^estimator 'lm': lambda0 must be a number > 0, got 'ten'$"):
        build_estimator({"name": "lm", "lambda0": "ten"})
