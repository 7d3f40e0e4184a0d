"""The ``bearing_doppler3d`` model: Jacobians against finite differences, the Euler transition
against its dense form, Euler-Maruyama against the step loop, the initial distribution's
draws against its moments, the bearings-only readings, the model record."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from tma.config import to_plain
from tma.families.bearing_doppler3d.estimators.base import dataset_model_record
from tma.families.bearing_doppler3d.model import (
    SCENARIO_ONLY,
    AuvModel,
    model_record,
    transition_times,
)
from tma.families.bearing_doppler3d.scenario import Config, simulate_shard


@pytest.mark.parametrize("doppler", [True, False])
def test_observation_jacobian_matches_finite_differences(model, states, doppler):
    model = replace(model, doppler=doppler)
    x = states()
    _, jac = model.observe_with_jacobian(x)  # (m, 6, n)
    steps = np.array([1.0, 1.0, 1.0, 1e-4, 1e-6, 1e-4])
    for i, h in enumerate(steps):
        plus, minus = x.copy(), x.copy()
        plus[i] += h
        minus[i] -= h
        fd = (model.observe(plus) - model.observe(minus)) / (2 * h)
        np.testing.assert_allclose(jac[:, i], fd, rtol=1e-5, atol=1e-10)
    assert jac.shape[0] == (24 if doppler else 16)


def test_drift_jacobian_matches_finite_differences(model, states, dense):
    x = states()
    jac = dense(model.drift_jacobian(x), x.shape[1])
    for i in range(6):
        h = 1e-6 * max(1.0, np.abs(x[i]).max())
        plus, minus = x.copy(), x.copy()
        plus[i] += h
        minus[i] -= h
        np.testing.assert_allclose(jac[:, i], (model.drift(plus) - model.drift(minus)) / (2 * h),
                                   rtol=1e-6, atol=1e-9)


def test_transition_is_the_dense_euler_transition_in_any_row_order(model, states, dense):
    x, dt = states(5), 0.01
    F = model.drift_jacobian(x, dt)
    Phi = np.eye(6)[..., None] + dense(F, 5)
    M = np.random.default_rng(1).normal(size=(6, 3, 5))
    expected = np.einsum("ijn,jkn->ikn", Phi, M)
    np.testing.assert_allclose(transition_times(F, M.copy()), expected, rtol=1e-12, atol=1e-12)
    order = np.array([3, 5, 4, 0, 1, 2])  # rows held as (v, a, phi, X, Y, Z)
    np.testing.assert_allclose(transition_times(F, M[order], at=np.argsort(order)),
                               expected[order], rtol=1e-12, atol=1e-12)


def test_euler_maruyama_equals_the_step_loop(model, states):
    model = replace(model, lam=0.01, nu=0.001, mu=0.01, truth_step_s=1e-3)
    x0 = states(5)
    x = model.euler_maruyama(x0, 0.5, np.random.default_rng(3))
    xi = np.random.default_rng(3).standard_normal((5, 500), dtype=np.float32).astype(float)
    y = x0.T.copy()
    for k in range(500):
        a, phi, v = y[:, 5].copy(), y[:, 4].copy(), y[:, 3]
        y[:, 0] += v * np.cos(phi) * 1e-3
        y[:, 1] += v * np.sin(phi) * 1e-3
        y[:, 4] += a / v * 1e-3
        y[:, 5] += (-0.01 * a + 0.001) * 1e-3 + 0.01 * np.sqrt(1e-3) * xi[:, k]
    np.testing.assert_allclose(x.T, y, rtol=1e-12, atol=1e-9)


def test_initial_draws_have_the_initial_moments(model):
    """The two halves of the initial distribution (the simulation's draws, the filters'
    starting mean and covariance) describe the same distribution."""
    x = model.initial.sample(200_000, np.random.default_rng(1))
    mean, cov = model.initial.moments()
    sd = np.sqrt(np.diag(cov))
    # in units of the standard deviations (sampling errors ~0.002-0.003)
    np.testing.assert_allclose(x.mean(axis=1) / sd, mean / sd, rtol=0, atol=0.01)
    np.testing.assert_allclose(np.cov(x) / np.outer(sd, sd), cov / np.outer(sd, sd), rtol=0,
                               atol=0.02)


def test_bearings_only_readings_are_the_doppler_readings_without_omega(model, states):
    x = states()
    full, bearings = replace(model, doppler=True), replace(model, doppler=False)
    h = full.observe(x).T  # (n, 24): paths first, like a log's readings
    np.testing.assert_array_equal(bearings.select_readings(h), bearings.observe(x).T)
    np.testing.assert_array_equal(bearings.select_readings(full.obs_sd), bearings.obs_sd)
    np.testing.assert_array_equal(full.select_readings(h), h)
    cube = np.stack([h, 2 * h])  # (K, n, 24): any leading axes
    assert bearings.select_readings(cube).shape == (2, x.shape[1], 16)


def test_filters_train_for_and_read_the_same_model_record():
    cfg = Config(n_tracks=3, shard_size=3, duration_s=2.0, no_doppler=True)
    log, _ = simulate_shard(cfg, 0)
    assert log.model == model_record(cfg) and not set(SCENARIO_ONLY) & set(log.model)
    # ``prepare`` reads the dataset's manifest, ``estimate`` the log: the same record
    assert dataset_model_record(SimpleNamespace(manifest={"config": to_plain(cfg)})) == log.model
    model = AuvModel.from_record(log.model)
    assert not model.doppler and model.n_obs == log.obs.shape[2] == 16
    np.testing.assert_array_equal(model.epochs(), log.t_s)
