"""bearing_doppler3d: Jacobians, Euler-Maruyama, EKF = KF, SR-EKF = EKF, CMNF = KF on a linear
model, CMNF's own covariance on held-out paths, divergence, bad input, the pipeline."""

import json
import shutil
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import compose_cfg
from tma.errors import ConfigError, InputError
from tma.families import build_estimator, load_scenario
from tma.families.bearing_doppler3d.estimators.base import (
    drift_step,
    drift_times_rows,
    output_columns,
)
from tma.families.bearing_doppler3d.estimators.cmnf import CMNF, apply, model_prediction, train
from tma.families.bearing_doppler3d.estimators.ekf import predict_covariance, sequential_update
from tma.families.bearing_doppler3d.estimators.srekf import fold_noise, phi_times
from tma.families.bearing_doppler3d.log import (
    SCHEMA,
    read_hydrophone_log,
    topic,
    write_hydrophone_log,
)
from tma.families.bearing_doppler3d.metrics import divergent_paths, path_metrics
from tma.families.bearing_doppler3d.model import euler_maruyama
from tma.families.bearing_doppler3d.scenario import (
    Config,
    auv_model,
    epochs,
    model_record,
    simulate_paths,
    simulate_shard,
)
from tma.io.atomic import sha256_file
from tma.io.mcap_log import Channel, LogWriter

SHORT = {"duration_s": 10.0}


def _states(n=7, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.normal(0, 3000, n), rng.normal(20000, 3000, n),
                            rng.normal(-1000, 100, n), rng.uniform(5, 12, n),
                            rng.normal(-np.pi / 2, 1, n), rng.uniform(-0.2, 0.2, n)])


@pytest.mark.parametrize("doppler", [True, False])
def test_observation_jacobian_matches_finite_differences(doppler):
    model = auv_model({**model_record(Config()), "no_doppler": not doppler})
    x = _states()
    _, jac = model.observe_with_jacobian(x)
    steps = np.array([1.0, 1.0, 1.0, 1e-4, 1e-6, 1e-4])
    for i, h in enumerate(steps):
        plus, minus = x.copy(), x.copy()
        plus[:, i] += h
        minus[:, i] -= h
        fd = (model.observe(plus) - model.observe(minus)) / (2 * h)
        np.testing.assert_allclose(jac[..., i], fd, rtol=1e-5, atol=1e-10)
    assert jac.shape[1] == (24 if doppler else 16)


def test_drift_jacobian_matches_finite_differences():
    model = auv_model(model_record(Config()))
    x = _states()
    jac = model.drift_jacobian(x)
    for i in range(6):
        h = 1e-6 * max(1.0, np.abs(x[:, i]).max())
        plus, minus = x.copy(), x.copy()
        plus[:, i] += h
        minus[:, i] -= h
        np.testing.assert_allclose(jac[..., i], (model.drift(plus) - model.drift(minus)) / (2 * h),
                                   rtol=1e-6, atol=1e-9)


def test_euler_maruyama_equals_the_step_loop():
    x0 = _states(5)
    x = euler_maruyama(x0, 0.5, 1e-3, 0.01, 0.001, 0.01, np.random.default_rng(3))
    xi = np.random.default_rng(3).standard_normal((5, 500), dtype=np.float32).astype(float)
    y = x0.copy()
    for k in range(500):
        a, phi, v = y[:, 5].copy(), y[:, 4].copy(), y[:, 3]
        y[:, 0] += v * np.cos(phi) * 1e-3
        y[:, 1] += v * np.sin(phi) * 1e-3
        y[:, 4] += a / v * 1e-3
        y[:, 5] += (-0.01 * a + 0.001) * 1e-3 + 0.01 * np.sqrt(1e-3) * xi[:, k]
    np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-9)


def test_square_root_prediction_is_the_qr_of_the_compound_array():
    rng = np.random.default_rng(4)
    x = _states(3).T
    S = np.tril(rng.normal(0, 1, (6, 6, 3)).transpose(2, 0, 1)).transpose(1, 2, 0)
    S[np.arange(6), np.arange(6)] = np.abs(S[np.arange(6), np.arange(6)]) + 1
    q = np.zeros((6, 3))
    q[1] = 0.3
    L = fold_noise(phi_times(S.copy(), x, 0.01, 0.01), q)
    for p in range(3):
        compound = np.hstack([phi_times(S.copy(), x, 0.01, 0.01)[:, :, p], q[:, p:p + 1]])
        R = np.linalg.qr(compound.T, mode="r")
        np.testing.assert_allclose(np.abs(L[:, :, p]), np.abs(R.T), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(L[:, :, p] @ L[:, :, p].T, compound @ compound.T, rtol=1e-10)
        assert np.allclose(np.triu(L[:, :, p], 1), 0) and np.all(np.diag(L[:, :, p]) > 0)


def test_structured_covariance_prediction_equals_the_general_form():
    rng = np.random.default_rng(3)
    x = _states(5).T.copy()
    B = rng.normal(size=(6, 6, 5))
    P = np.einsum("ikn,jkn->ijn", B, B)
    M = P + 0.01 * drift_times_rows(P, x, 0.01)
    expected = M + 0.01 * drift_times_rows(M.transpose(1, 0, 2), x, 0.01).transpose(1, 0, 2)
    expected[5, 5] += 0.01**2 * 0.01
    np.testing.assert_allclose(predict_covariance(P.copy(), x, 0.01, 0.01, 0.01), expected,
                               rtol=1e-12, atol=1e-12)


def test_sequential_update_equals_the_batch_ekf_update():
    model = auv_model(model_record(Config()))
    x = _states(4).T.copy()
    P = np.repeat(np.diag([1e6, 1e6, 1e4, 4.0, 0.01, 0.01])[:, :, None], 4, axis=2)
    y = model.observe(x.T) + model.obs_sd * np.random.default_rng(2).standard_normal((4, 24))
    h, H = model.observe_with_jacobian(x.T)
    R = np.diag(model.obs_sd**2)
    xs, Ps = sequential_update(x.copy(), P.copy(), y, model)
    for p in range(4):
        Pp = P[:, :, p]
        K = Pp @ H[p].T @ np.linalg.inv(H[p] @ Pp @ H[p].T + R)
        np.testing.assert_allclose(xs[:, p], x[:, p] + K @ (y[p] - h[p]), rtol=1e-9)
        np.testing.assert_allclose(Ps[:, :, p], Pp - K @ H[p] @ Pp, rtol=1e-6, atol=1e-9)


def test_ekf_on_a_nearly_linear_configuration_is_the_kalman_filter():
    """No manoeuvre noise, a = 0, tiny speed/heading uncertainty and a linear observation of
    the position: the EKF's prediction and update reduce to a plain Kalman filter."""
    n, dt = 3, 0.01
    H = np.zeros((4, 6))
    H[0, 0] = H[1, 1] = H[2, 2] = 1.0
    H[3, 0], H[3, 1] = 0.5, -0.5
    linear = SimpleNamespace(obs_sd=np.array([20.0, 20.0, 5.0, 10.0]),
                             observe_with_jacobian=lambda xs: (xs @ H.T, np.broadcast_to(
                                 H, (xs.shape[0], 4, 6)).copy()))
    x = _states(n).T.copy()
    x[5] = 0.0
    P = np.repeat(np.diag([1e4, 1e4, 100.0, 1e-12, 1e-12, 1e-14])[:, :, None], n, axis=2)
    rng = np.random.default_rng(5)
    ref_x, ref_P = x.copy(), P.copy()
    for _ in range(20):
        for _ in range(100):  # 1 s of Euler steps
            P = predict_covariance(P, x, dt, 0.01, 0.0)
            x = drift_step(x, dt, 0.01, 0.0)
        y = x.T @ H.T + linear.obs_sd * rng.standard_normal((n, 4))
        x, P = sequential_update(x, P, y, linear)
        for p in range(n):  # the plain KF: constant velocity, 1 s steps
            v, phi = ref_x[3, p], ref_x[4, p]
            F = np.eye(6)
            F[0, 3], F[1, 3] = np.cos(phi), np.sin(phi)
            ref_x[0, p] += v * np.cos(phi)
            ref_x[1, p] += v * np.sin(phi)
            Pp = F @ ref_P[:, :, p] @ F.T
            K = Pp @ H.T @ np.linalg.inv(H @ Pp @ H.T + np.diag(linear.obs_sd**2))
            ref_x[:, p] += K @ (y[p] - H @ ref_x[:, p])
            ref_P[:, :, p] = Pp - K @ H @ Pp
    np.testing.assert_allclose(x[:3], ref_x[:3], atol=1e-3)
    np.testing.assert_allclose(P[:3, :3], ref_P[:3, :3], rtol=1e-4)


def test_srekf_equals_ekf():
    log, _ = simulate_shard(Config(n_tracks=30, shard_size=30, **SHORT), 0)
    ekf = build_estimator({"name": "ekf"}).estimate(log)
    sr = build_estimator({"name": "srekf"}).estimate(log)
    for key in ("X_m", "Y_m", "Z_m", "v_m_s", "phi_rad", "a_m_s2", "sd_X_m", "sd_phi_rad"):
        np.testing.assert_allclose(sr[key], ekf[key], rtol=1e-8, atol=1e-10)
    for key in ("P_00", "P_01", "P_35", "P_55"):
        ref = ekf["extras"]["covariance"][key]
        np.testing.assert_allclose(sr["extras"]["covariance"][key], ref, rtol=1e-8,
                                   atol=1e-9 * np.abs(ref).max())


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
    record = model_record(Config(**SHORT))
    model = auv_model(record)
    t = epochs(record)
    truth, obs = simulate_paths(record, 20_000, np.random.default_rng(8))
    gains = train(truth, obs, model_prediction(model, record, t), model.observe, 1e-12)
    held_truth, held_obs = simulate_paths(record, 5_000, np.random.default_rng(9))
    est = apply(gains, held_obs, model_prediction(model, record, t), model.observe)
    measured = ((est - held_truth) ** 2).mean(axis=0)  # (K, 6)
    own = np.einsum("kii->ki", gains["K_hat"])
    np.testing.assert_allclose(measured[-1], own[-1], rtol=0.15)


def test_divergence_counting_on_a_constructed_case():
    t = np.arange(0.0, 21.0)
    e = np.zeros((5, t.size, 6))
    e[0, 12, 0] = 1500.0  # late and large: divergent
    e[1, 5, :2] = 2000.0  # large but before 10 s: not divergent
    e[2, 15, :2] = 800.0  # horizontal 1131 m at t = 15: divergent
    e[3, 18, 1] = np.nan  # lost: divergent
    ok = np.array([True, True, True, True, False])  # 4: non-finite covariance
    np.testing.assert_array_equal(divergent_paths(e, t, ok), [True, False, True, True, True])


def test_path_status_counts_nan_and_flagged_paths_as_divergent():
    t = np.arange(0.0, 21.0)
    e = np.zeros((4, t.size, 6))
    e[1, 15:, :2] = np.nan  # no estimate from 15 s on
    e[2, 12, 0] = 1500.0
    ok = np.array([True, True, True, False])
    m = path_metrics([10, 11, 12, 13], e, t, ok)
    assert list(m["status"]) == ["ok", "divergent", "divergent", "divergent"]
    assert list(m["track_id"]) == [10, 11, 12, 13]
    assert m["horizontal_err_max_m"].iloc[2] == 1500.0 and np.isnan(m["horizontal_err_max_m"][1])


def test_negative_variance_is_flagged_not_a_silent_nan_std():
    est = np.zeros((2, 3, 6))
    cov = np.broadcast_to(np.eye(6), (2, 3, 6, 6)).copy()
    cov[1, 2, 4, 4] = -1e-9  # a covariance that lost definiteness
    with np.errstate(invalid="ignore"):
        out = output_columns(est, cov, np.array([True, True]), np.arange(3.0), 1,
                             np.array([0, 1]))
    np.testing.assert_array_equal(out["filter_ok"], [True, False])


@pytest.mark.parametrize(("kw", "key"), [
    ({"lam": -0.01}, "lam"),
    ({"mu": -1.0}, "mu"),
    ({"filter_step_s": 0.3}, "filter_step_s"),
    ({"duration_s": 10.5}, "duration_s"),
    ({"sd_doppler_hz": 0.0}, "sd_doppler_hz"),
    ({"sensors_m": [[0.0, 0.0]]}, "sensors_m"),
    ({"seed": -1}, "seed"),
])
def test_impossible_scenarios_are_refused(kw, key):
    with pytest.raises(ConfigError, match=key):
        Config(**kw)


def test_impossible_initial_distributions_are_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"initial.speed_min_m_s"):
        load_scenario({"family": "bearing_doppler3d",
                       "initial": {"speed_min_m_s": 7.0, "speed_max_m_s": 7.0}})
    with pytest.raises(ConfigError, match=r"initial.position_sd_m\[2\] must be finite"):
        load_scenario({"family": "bearing_doppler3d",
                       "initial": {"position_sd_m": [1.0, 1.0, float("inf")]}})


@pytest.mark.parametrize(("node", "key"), [
    ({"name": "cmnf", "pinv_rtol": 2.0}, "pinv_rtol"),
    ({"name": "cmnf", "covariance_every": 0}, "covariance_every"),
    ({"name": "prior_mean", "bundle_seed": -7}, "bundle_seed"),
    ({"name": "srekf", "covariance_every": -1}, "covariance_every"),
])
def test_impossible_filter_configs_are_refused(node, key):
    with pytest.raises(ConfigError, match=key):
        build_estimator(node)


def test_missing_readings_missing_channel_and_bad_covariance(tmp_path):
    log, _ = simulate_shard(Config(n_tracks=6, shard_size=6, **SHORT), 0)
    log.obs[1, 3, 5:9] = np.nan  # a sensor's readings missing at one epoch
    log.obs[2, :, 0:3] = np.nan  # one sensor silent for a path
    log.obs[0, 2, 0] = np.inf  # a non-finite reading is skipped like a missing one
    log.obs[4, 2, 1] = 1e200  # an absurd finite reading wrecks path 4's filter
    for name in ("ekf", "srekf"):
        out = build_estimator({"name": name}).estimate(log)
        assert np.all(np.isfinite(out["X_m"][[0, 1, 2, 3, 5]]))
        np.testing.assert_array_equal(out["filter_ok"], [True, True, True, True, False, True])
    write_hydrophone_log(tmp_path / "h.mcap", log)
    back = read_hydrophone_log(tmp_path / "h.mcap")
    np.testing.assert_array_equal(np.isnan(back.obs), ~np.isfinite(log.obs))
    # a log with seven sensor channels whose model record claims eight sensors
    channels = [Channel(topic(i), SCHEMA) for i in range(7)]
    meta = {"tma.model": {k: json.dumps(v) for k, v in log.model.items()}}
    with LogWriter(tmp_path / "seven.mcap", channels, meta) as w:
        for i in range(7):
            w.write(topic(i), 0.0, {"t_s": 0.0, "sensor_id": i, "track_id": log.track_id,
                                    "elevation_sin": log.obs[:, 0, 3 * i],
                                    "bearing_cos": log.obs[:, 0, 3 * i + 1],
                                    "doppler_hz": log.obs[:, 0, 3 * i + 2]})
    with pytest.raises(InputError, match=r"missing topic\(s\) /hydrophones/7"):
        read_hydrophone_log(tmp_path / "seven.mcap")


def test_wrong_family_and_pipeline(tmp_path):
    common = [f"paths.data_dir={tmp_path}/data", f"paths.tables_dir={tmp_path}/tables",
              "progress=false"]
    bearings = compose_cfg(["scenario.n_tracks=10", "scenario.shard_size=10", *common])
    simulate_stage(bearings)
    with pytest.raises(ConfigError, match="'ekf' reads 'bearing_doppler3d' datasets"):
        estimate_stage(compose_cfg(["scenario.n_tracks=10", "scenario.shard_size=10",
                                    "estimator=ekf", *common]))
    cfg = compose_cfg(["experiment=bearing_doppler3d_table", "scenario.n_tracks=40",
                       "scenario.shard_size=20", "scenario.duration_s=60",
                       "grid.estimators.cmnf.training_paths=400",
                       "grid.estimators.prior_mean.bundle_paths=400", *common])
    simulate_stage(cfg)
    estimate_stage(cfg)
    aggregate_stage(cfg)
    table = pd.read_csv(tmp_path / "tables" / "bearing_doppler3d.csv")
    assert len(table) == 8 and set(table.doppler) == {True, False}
    assert (table.training_paths.dropna() == 400).all()
    paths = sorted((tmp_path / "data" / "runs").glob("*/*/path_metrics.parquet"))
    assert len(paths) == 8
    shares = sorted((pd.read_parquet(p)["status"] == "divergent").mean() for p in paths)
    assert shares == sorted(table.divergence_share)
    ekf = table[(table.estimator == "ekf") & table.doppler].iloc[0]
    prior = table[(table.estimator == "prior_mean") & table.doppler].iloc[0]
    assert ekf.rmse_X_T < prior.rmse_X_T and ekf.rmse_phi_T < prior.rmse_phi_T
    artefacts = list((tmp_path / "data" / "artefacts").glob("cmnf-*/arrays.npz"))
    assert len(artefacts) == 2  # one per observation model, reused on the next run
    stamp = {p: p.stat().st_mtime_ns for p in artefacts}
    estimate_stage(cfg)
    assert {p: p.stat().st_mtime_ns for p in artefacts} == stamp
    cmnf = CMNF.prepare({"name": "cmnf", "training_paths": 400, "training_seed": 7,
                         "pinv_rtol": 1e-12, "covariance_every": 10, "artefact": None},
                        _dataset(tmp_path), tmp_path / "data")
    assert cmnf["artefact"]["sha256"] == sha256_file(
        tmp_path / "data" / "artefacts" / cmnf["artefact"]["key"] / "arrays.npz")
    assert "path" not in cmnf["artefact"]  # the run key must not depend on a path's spelling
    # aggregate trains nothing: without the artefacts it still reads the finished runs
    shutil.rmtree(tmp_path / "data" / "artefacts")
    aggregate_stage(cfg)
    assert not (tmp_path / "data" / "artefacts").exists()


def _dataset(tmp_path):
    from tma.io.dataset import Dataset

    root = next(p for p in (tmp_path / "data" / "datasets").iterdir()
                if p.name.startswith("bearing_doppler3d-doppler"))
    return Dataset.open(root)
