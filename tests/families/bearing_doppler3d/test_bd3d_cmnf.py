"""``cmnf``: the Kalman filter on a scalar linear model, its own covariance against the errors
on held-out paths."""

import numpy as np
import pytest

from tma.families.bearing_doppler3d.estimators.cmnf import apply, model_functions, train
from tma.families.bearing_doppler3d.model import AuvModel, model_record
from tma.families.bearing_doppler3d.scenario import Config


def test_cmnf_reproduces_the_kalman_filter_on_a_scalar_linear_model():
    rng = np.random.default_rng(6)
    M, K, rho, q, r = 100_000, 15, 0.9, 0.1, 0.25
    x = np.empty((M, K, 1))
    x[:, 0, 0] = rng.standard_normal(M)
    for k in range(1, K):
        x[:, k, 0] = rho * x[:, k - 1, 0] + np.sqrt(q) * rng.standard_normal(M)
    y = x + np.sqrt(r) * rng.standard_normal((M, K, 1))
    gains = train(x, y, lambda xh, k: rho * xh, lambda xs: xs, 1e-12)
    P, kf_gain = 1.0, []
    kf_cov = []
    for k in range(K):
        if k:
            P = rho * rho * P + q
        gain = P / (P + r)
        kf_gain.append(gain)
        P = (1 - gain) * P
        kf_cov.append(P)
    np.testing.assert_allclose(gains["H"][:, 0, 0], kf_gain, atol=0.01)
    np.testing.assert_allclose(gains["K_hat"][:, 0, 0], kf_cov, rtol=0.03)
    np.testing.assert_allclose(gains["F"][1:, 0, 0], 1.0, atol=0.02)  # xi is already E[x|past]


@pytest.mark.slow
def test_cmnf_own_covariance_matches_held_out_errors():
    """Trained on 20,000 paths, CMNF's own error variances are those measured on 5,000 other
    paths, at every epoch and with and without Doppler. The truth is simulated at 5 ms: the
    default 1 ms costs five times as much and changes nothing here (the gains are fitted to
    whatever paths the model simulates; 5 ms is still finer than the filter's 10 ms step)."""
    record = model_record(Config(duration_s=10.0, truth_step_s=5e-3))
    simulator = AuvModel.from_record(record)
    truth, obs = simulator.simulate(20_000, np.random.default_rng(8))
    held_truth, held_obs = simulator.simulate(5_000, np.random.default_rng(9))
    for no_doppler in (False, True):
        model = AuvModel.from_record({**record, "no_doppler": no_doppler})
        functions = model_functions(model, model.epochs())
        gains = train(truth, model.select_readings(obs), *functions, 1e-12)
        est = apply(gains, model.select_readings(held_obs), *functions)
        measured = ((est - held_truth) ** 2).mean(axis=0)  # (K, 6)
        own = np.einsum("kii->ki", gains["K_hat"])
        np.testing.assert_allclose(measured, own, rtol=0.15, err_msg=f"no_doppler={no_doppler}")
