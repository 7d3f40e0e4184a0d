"""radar2d trackers: alpha-beta = least squares, the fuzzy selector, the IMM, vectorisation."""

import numpy as np
import pytest

from tma.families import build_estimator
from tma.families.radar2d.estimators.base import alpha_beta_window
from tma.families.radar2d.fuzzy import memory_length_selector, sigmoid
from tma.families.radar2d.log import RadarLog
from tma.families.radar2d.scenario import Config, simulate_shard
from tma.families.radar2d.turn import coordinated_turn


def _log(n=20, **kw):
    return simulate_shard(Config(n_tracks=n, shard_size=n, **kw), 0)


def test_growing_memory_alpha_beta_is_the_least_squares_line():
    rng = np.random.default_rng(0)
    tau = 3.0
    for w in (2, 3, 7, 12):
        plots = rng.normal(0, 50, (5, w, 2)) + np.arange(w)[None, :, None] * [10.0, -4.0]
        pos, vel = alpha_beta_window(plots, tau)
        t = np.arange(w) * tau
        for i in range(5):
            for a in range(2):
                slope, intercept = np.polyfit(t, plots[i, :, a], 1)
                assert pos[i, a] == pytest.approx(intercept + slope * t[-1], abs=1e-10)
                assert vel[i, a] == pytest.approx(slope, abs=1e-10)


def test_memberships_and_rule_firing_by_hand():
    bad = sigmoid(5.0, 1.5)
    assert bad(1.5) == pytest.approx(0.5)
    assert bad(2.5) == pytest.approx(1 / (1 + np.exp(-5.0)))
    selector = memory_length_selector(4)  # inputs L2, L3, L4; rules m = 4, 3, 2, all bad
    L = np.array([[1.0, 2.0, 3.0]])
    b = 1 / (1 + np.exp(-5 * (L[0] - 1.5)))
    g = 1 - b
    expected = [g[0] * g[1] * g[2], g[0] * g[1] * b[2], g[0] * b[1] * b[2], b[0] * b[1] * b[2]]
    np.testing.assert_allclose(selector.firing(L)[0], expected, rtol=1e-12)
    consequents = np.array([4, 3, 2, 2])
    assert selector(L)[0] == pytest.approx(expected @ consequents / sum(expected))
    assert selector(np.zeros((1, 3)))[0] == pytest.approx(4, abs=0.01)  # all good -> J
    assert selector(np.full((1, 3), 3.0))[0] == pytest.approx(2, abs=0.01)  # all bad -> 2


def test_selector_keeps_J_when_straight_and_drops_in_the_turn():
    log, _ = _log(n=3, sigma_m=1e-6, speed_m_s=20.0)  # (nearly) noiseless plots
    out = build_estimator({"name": "fuzzy_mm", "sigma_hat_m": 10.0}).estimate(log)
    t = log.t_s
    straight = (t >= 27) & (t <= 42)
    turn = (t >= 48) & (t <= 90)
    assert np.all(out["m"][:, straight] == 10)
    assert np.all(out["m"][:, turn].min(axis=1) < 10)


def test_coordinated_turn_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    state = np.column_stack([rng.normal(0, 100, 6), rng.normal(0, 10, 6), rng.normal(0, 100, 6),
                             rng.normal(0, 10, 6), [0.05, -0.03, 1e-9, 0.0, 0.2, -0.2]])
    _, jac = coordinated_turn(state, 3.0)
    for k in range(5):
        h = 1e-6 if k == 4 else 1e-4
        plus, minus = state.copy(), state.copy()
        plus[:, k] += h
        minus[:, k] -= h
        fd = (coordinated_turn(plus, 3.0)[0] - coordinated_turn(minus, 3.0)[0]) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], fd, rtol=1e-5, atol=1e-5)


def test_imm_with_one_model_is_its_kalman_filter():
    log, _ = _log(n=4)
    cfg = {"name": "imm", "p_stay": 1.0, "initial_probs": [1.0, 0.0]}
    out = build_estimator(cfg).estimate(log)
    tau, q, r2 = 3.0, 0.01, 10.0**2
    F = np.array([[1, tau], [0, 1]])
    Q = q * np.array([[tau**3 / 3, tau**2 / 2], [tau**2 / 2, tau]])
    for run in range(4):
        for axis, col in ((0, "x_m"), (1, "y_m")):
            z = log.plots_m[run, :, axis]
            x = np.array([z[1], (z[1] - z[0]) / tau])
            P = np.array([[r2, r2 / tau], [r2 / tau, 2 * r2 / tau**2]])
            for i in range(2, z.size):
                x, P = F @ x, F @ P @ F.T + Q
                S = P[0, 0] + r2
                K = P[:, 0] / S
                x = x + K * (z[i] - x[0])
                P = P - np.outer(K, P[0])
                assert out[col][run, i] == pytest.approx(x[0], abs=1e-8)
    np.testing.assert_allclose(out["p_cv"][:, 2:], 1.0)


@pytest.mark.parametrize("name", ["alphabeta", "fuzzy_mm", "imm"])
def test_vectorised_equals_single_run(name):
    log, _ = _log(n=6, speed_m_s=20.0)
    est = build_estimator({"name": name})
    batch = est.estimate(log)
    for i in range(6):
        one = RadarLog(log.t_s, log.track_id[i:i + 1], log.plots_m[i:i + 1], log.sensor)
        single = est.estimate(one)
        assert single["status"][0] == batch["status"][i] == "ok"
        for key in batch.keys() - {"status"}:
            np.testing.assert_allclose(single[key][0], batch[key][i], rtol=1e-12, atol=1e-12)


def test_imm_model_probabilities_survive_underflowing_likelihoods():
    """Tiny process noise in a 20 m/s turn: both models' likelihoods underflow to 0, which
    made the model probabilities 0/0 = NaN for the rest of the run."""
    log, _ = _log(n=5, speed_m_s=20.0)
    out = build_estimator({"name": "imm", "cv_accel_psd": 1e-9, "ct_accel_psd": 1e-9,
                           "ct_omega_psd": 0.0, "initial_omega_sd": 0.0}).estimate(log)
    assert np.isfinite(out["x_m"]).all() and np.isfinite(out["p_turn"][:, 1:]).all()
    assert (out["status"] == "ok").all()


def test_tracker_without_a_start_is_flagged_divergent():
    log, _ = _log(n=3)
    log.plots_m[1, 1] = np.nan  # the IMM starts from the line through plots 0 and 1
    out = build_estimator({"name": "imm"}).estimate(log)
    assert list(out["status"]) == ["ok", "divergent", "ok"]
