"""``ekf`` and ``srekf``: the compiled filters against a textbook per-path EKF written here
(dense matrices, batch update), the covariance prediction against its general form, the
square-root prediction against a QR, the sequential update against the batch EKF update, the
EKF against a plain Kalman filter, SR-EKF = EKF, the carried heading cosines, missing
readings, flagged paths."""

from dataclasses import replace

import numpy as np
import pytest

from tma.families import build_estimator
from tma.families.bearing_doppler3d.estimators import ekf, srekf
from tma.families.bearing_doppler3d.estimators.base import Solution, output_columns
from tma.families.bearing_doppler3d.estimators.srekf import INVERSE, ORDER
from tma.families.bearing_doppler3d.model import PHI, A, AuvModel, euler_columns, model_record
from tma.families.bearing_doppler3d.scenario import Config, simulate_shard

SHORT = {"duration_s": 10.0}
STATES = ("X_m", "Y_m", "Z_m", "v_m_s", "phi_rad", "a_m_s2")


def _predict(kernel, x, factor, dt, n_steps, model, block=3):
    kernel(x, factor, dt, n_steps, model.lam, model.nu, model.mu, block)


def _textbook_ekf(model, t, obs):
    """One path at a time with dense matrices: Euler steps x <- x + a(x) dt and
    P <- Phi P Phi^T + Q (Phi = I + F dt, Q = b b^T dt), then at each epoch the batch EKF
    update with the readings present, K = P H^T (H P H^T + R)^-1."""
    n, K, m = obs.shape
    mean0, cov0 = model.initial.moments()
    dt = model.filter_step_s
    Q = np.zeros((6, 6))
    Q[A, A] = model.mu**2 * dt
    R = np.diag(model.obs_sd**2)
    est, cov = np.empty((n, K, 6)), np.empty((n, K, 6, 6))
    for p in range(n):
        x, P = mean0.copy(), cov0.copy()
        for k in range(K):
            for _ in range(model.n_filter_steps(t[k] - t[k - 1]) if k else 0):
                F = np.zeros((6, 6))
                for (i, j), value in model.drift_jacobian(x[:, None], dt).items():
                    F[i, j] = np.ravel(value)[0]
                Phi = np.eye(6) + F
                P = Phi @ P @ Phi.T + Q
                x = x + model.drift(x[:, None])[:, 0] * dt
            h, H = model.observe_with_jacobian(x[:, None])
            have = np.isfinite(obs[p, k])
            h, H = h[have, 0], H[have, :, 0]
            gain = P @ H.T @ np.linalg.inv(H @ P @ H.T + R[np.ix_(have, have)])
            x = x + gain @ (obs[p, k, have] - h)
            P = (np.eye(6) - gain @ H) @ P
            est[p, k], cov[p, k] = x, P
    return est, cov


@pytest.mark.parametrize("doppler", [True, False])
def test_compiled_filters_are_the_textbook_ekf(doppler):
    log, _ = simulate_shard(Config(n_tracks=4, shard_size=4, no_doppler=not doppler, **SHORT), 0)
    log.obs[1, 3, 5:9] = np.nan  # readings missing at one epoch
    model = AuvModel.from_record(log.model)
    est, cov = _textbook_ekf(model, log.t_s, log.obs)
    sd = np.sqrt(np.einsum("nkii->nki", cov))
    for name in ("ekf", "srekf"):
        out = build_estimator({"name": name}).estimate(log)
        for i, state in enumerate(STATES):
            scale = np.abs(est[..., i]).max() + sd[..., i].max()
            np.testing.assert_allclose(out[state], est[..., i], rtol=0, atol=1e-11 * scale)
            np.testing.assert_allclose(out[f"sd_{state}"], sd[..., i], rtol=1e-10)


def test_structured_covariance_prediction_equals_the_general_form(model, states, dense):
    rng = np.random.default_rng(3)
    x, dt = states(5), 0.01
    B = rng.normal(size=(6, 6, 5))
    P = np.einsum("ikn,jkn->ijn", B, B)
    Phi = np.eye(6)[..., None] + dense(model.drift_jacobian(x, dt), 5)
    expected = np.einsum("ijn,jkn,lkn->iln", Phi, P, Phi)
    expected[A, A] += model.mu**2 * dt  # b b^T dt
    x_next = x + model.drift(x) * dt
    _predict(ekf.predict, x, P, dt, 1, model)
    np.testing.assert_allclose(P, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(x, x_next, rtol=1e-15)


def test_square_root_prediction_is_the_qr_of_the_compound_array(model, states, dense):
    """S+ triangularises [Phi S, b sqrt(dt)] (rows in the square-root order)."""
    rng = np.random.default_rng(4)
    model, x, dt = replace(model, mu=3.0), states(3), 0.01
    S = np.tril(rng.normal(0, 1, (6, 6, 3)).transpose(2, 0, 1)).transpose(1, 2, 0)
    S[np.arange(6), np.arange(6)] = np.abs(S[np.arange(6), np.arange(6)]) + 1
    L = S.copy()
    Phi = (np.eye(6)[..., None] + dense(model.drift_jacobian(x, dt), 3))[np.ix_(ORDER, ORDER)]
    _predict(srekf.predict, x.copy(), L, dt, 1, model)
    noise = np.zeros(6)
    noise[INVERSE[A]] = model.mu * np.sqrt(dt)
    for p in range(3):
        compound = np.hstack([Phi[:, :, p] @ S[:, :, p], noise[:, None]])
        R = np.linalg.qr(compound.T, mode="r")
        np.testing.assert_allclose(np.abs(L[:, :, p]), np.abs(R.T), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(L[:, :, p] @ L[:, :, p].T, compound @ compound.T, rtol=1e-10)
        assert np.allclose(np.triu(L[:, :, p], 1), 0) and np.all(np.diag(L[:, :, p]) > 0)


def test_sequential_update_equals_the_batch_ekf_update(model, states):
    x = states(4)
    P = np.repeat(np.diag([1e6, 1e6, 1e4, 4.0, 0.01, 0.01])[:, :, None], 4, axis=2)
    y = model.observe(x).T + model.obs_sd * np.random.default_rng(2).standard_normal((4, 24))
    h, H = model.observe_with_jacobian(x)
    R = np.diag(model.obs_sd**2)
    xs, Ps = x.copy(), P.copy()
    ekf.update(xs, Ps, h, H, y, model.obs_sd**2)
    for p in range(4):
        Pp, Hp = P[:, :, p], H[:, :, p]
        K = Pp @ Hp.T @ np.linalg.inv(Hp @ Pp @ Hp.T + R)
        np.testing.assert_allclose(xs[:, p], x[:, p] + K @ (y[p] - h[:, p]), rtol=1e-9)
        np.testing.assert_allclose(Ps[:, :, p], Pp - K @ Hp @ Pp, rtol=1e-6, atol=1e-9)


def test_ekf_on_a_nearly_linear_configuration_is_the_kalman_filter(model, states):
    """No manoeuvre noise, a = 0, tiny speed/heading uncertainty and a linear observation of
    the position: the EKF's prediction and update reduce to a plain Kalman filter."""
    n, dt = 3, 0.01
    model = replace(model, lam=0.01, nu=0.0, mu=0.0)
    H = np.zeros((4, 6))
    H[0, 0] = H[1, 1] = H[2, 2] = 1.0
    H[3, 0], H[3, 1] = 0.5, -0.5
    sd = np.array([20.0, 20.0, 5.0, 10.0])
    x = states(n)
    x[A] = 0.0
    P = np.repeat(np.diag([1e4, 1e4, 100.0, 1e-12, 1e-12, 1e-14])[:, :, None], n, axis=2)
    rng = np.random.default_rng(5)
    ref_x, ref_P = x.copy(), P.copy()
    for _ in range(20):
        _predict(ekf.predict, x, P, dt, 100, model)  # 1 s of Euler steps
        y = x.T @ H.T + sd * rng.standard_normal((n, 4))
        ekf.update(x, P, H @ x, np.repeat(H[..., None], n, axis=2), y, sd**2)
        for p in range(n):  # the plain KF: constant velocity, 1 s steps
            v, phi = ref_x[3, p], ref_x[4, p]
            F = np.eye(6)
            F[0, 3], F[1, 3] = np.cos(phi), np.sin(phi)
            ref_x[0, p] += v * np.cos(phi)
            ref_x[1, p] += v * np.sin(phi)
            Pp = F @ ref_P[:, :, p] @ F.T
            K = Pp @ H.T @ np.linalg.inv(H @ Pp @ H.T + np.diag(sd**2))
            ref_x[:, p] += K @ (y[p] - H @ ref_x[:, p])
            ref_P[:, :, p] = Pp - K @ H @ Pp
    np.testing.assert_allclose(x[:3], ref_x[:3], atol=1e-3)
    np.testing.assert_allclose(P[:3, :3], ref_P[:3, :3], rtol=1e-4)


def test_carried_heading_cosines_stay_those_of_the_heading(states):
    """100 Euler steps carry cos and sin of phi by rotations (series): within 1e-13 of
    cos(phi), sin(phi); a turn rate beyond the series' range takes exact ones."""
    model = AuvModel.from_record(model_record(Config()))
    x = states(40)
    x[A, :5] = 50.0  # |a / v dt| > 1e-2 on these paths
    c, s = np.cos(x[PHI]), np.sin(x[PHI])
    for _ in range(100):
        euler_columns(x, c, s, model.lam, model.nu, 0.01)
    np.testing.assert_allclose(c, np.cos(x[PHI]), rtol=0, atol=1e-13)
    np.testing.assert_allclose(s, np.sin(x[PHI]), rtol=0, atol=1e-13)


def test_srekf_equals_ekf():
    log, _ = simulate_shard(Config(n_tracks=30, shard_size=30, **SHORT), 0)
    ekf_out = build_estimator({"name": "ekf"}).estimate(log)
    sr = build_estimator({"name": "srekf"}).estimate(log)
    for key in ("X_m", "Y_m", "Z_m", "v_m_s", "phi_rad", "a_m_s2", "sd_X_m", "sd_phi_rad"):
        np.testing.assert_allclose(sr[key], ekf_out[key], rtol=1e-8, atol=1e-10)
    for key in ("P_00", "P_01", "P_35", "P_55"):
        ref = ekf_out.side_tables["covariance"][key]
        np.testing.assert_allclose(sr.side_tables["covariance"][key], ref, rtol=1e-8,
                                   atol=1e-9 * np.abs(ref).max())


def test_missing_readings_are_skipped_and_a_wrecked_path_is_flagged():
    log, _ = simulate_shard(Config(n_tracks=6, shard_size=6, **SHORT), 0)
    log.obs[1, 3, 5:9] = np.nan  # a sensor's readings missing at one epoch
    log.obs[2, :, 0:3] = np.nan  # one sensor silent for a path
    log.obs[0, 2, 0] = np.inf  # a non-finite reading is skipped like a missing one
    log.obs[4, 2, 1] = 1e200  # an absurd finite reading wrecks path 4's filter
    for name in ("ekf", "srekf"):
        out = build_estimator({"name": name}).estimate(log)
        assert np.all(np.isfinite(out["X_m"][[0, 1, 2, 3, 5]]))
        np.testing.assert_array_equal(out["filter_ok"], [True, True, True, True, False, True])


def test_negative_variance_is_flagged_not_a_silent_nan_std():
    est = np.zeros((2, 3, 6))
    cov = np.broadcast_to(np.eye(6), (2, 3, 6, 6)).copy()
    cov[1, 2, 4, 4] = -1e-9  # a covariance that lost definiteness
    with np.errstate(invalid="ignore"):
        out = output_columns(Solution(est, cov, np.array([True, True])), np.arange(3.0), 1,
                             np.array([0, 1]))
    np.testing.assert_array_equal(out["filter_ok"], [True, False])
