"""radar2d: alpha-beta = least squares, the fuzzy selector, the IMM, vectorisation, bad input."""

import numpy as np
import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import compose_cfg
from tma.errors import ConfigError, InputError
from tma.families import build_estimator
from tma.families.radar2d.estimators.base import alpha_beta_window
from tma.families.radar2d.fuzzy import memory_length_selector, sigmoid
from tma.families.radar2d.log import RadarLog, read_radar_log, write_radar_log
from tma.families.radar2d.metrics import per_scan_errors, summary_row
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


def test_missing_plots_skip_the_scan_and_keep_the_track(tmp_path):
    log, _ = _log(n=4)
    log.plots_m[1, 20, :] = np.nan
    log.plots_m[2, 10:12, 0] = np.nan
    write_radar_log(tmp_path / "r.mcap", log)
    back = read_radar_log(tmp_path / "r.mcap")
    assert np.isnan(back.plots_m[1, 20]).all()
    for name in ("alphabeta", "fuzzy_mm", "imm"):
        out = build_estimator({"name": name}).estimate(back)
        assert np.all(np.isfinite(out["x_m"][:, 2:])), name


def test_bad_scan_times_and_contradicting_period(tmp_path):
    log, _ = _log(n=2)
    with pytest.raises(InputError, match=r"scan_period_s = 2 s in the config contradicts .* 3 s"):
        build_estimator({"name": "fuzzy_mm", "scan_period_s": 2.0}).estimate(log)
    bad = RadarLog(log.t_s.copy(), log.track_id, log.plots_m, log.sensor)
    bad.t_s[5] = bad.t_s[4]
    with pytest.raises(InputError, match="not increasing"):
        bad.validate("log")
    gap = RadarLog(np.delete(log.t_s, 7), log.track_id, np.delete(log.plots_m, 7, axis=1),
                   log.sensor)
    with pytest.raises(InputError, match="not uniform"):
        build_estimator({"name": "imm"}).estimate(gap)


def test_polar_noise_and_pipeline_table(tmp_path):
    overrides = ["experiment=radar2d_table", "scenario.n_tracks=40", "scenario.shard_size=20",
                 "scenario.noise=polar", "progress=false", f"paths.data_dir={tmp_path}/data",
                 f"paths.tables_dir={tmp_path}/tables"]
    cfg = compose_cfg(overrides)
    simulate_stage(cfg)
    estimate_stage(cfg)
    aggregate_stage(cfg)
    table = pd.read_csv(tmp_path / "tables" / "radar2d.csv")
    assert len(table) == 6 and set(table.speed_m_s) == {10, 20}
    fuzzy = table[table.estimator == "fuzzy_mm"]
    assert (fuzzy.m_median == 10).all() and (fuzzy.m_min_turn_median < 10).all()
    assert (table.straight1_mean_m < 15).all()
    metrics = sorted((tmp_path / "data" / "runs").glob("*/*/metrics.parquet"))
    assert len(metrics) == 6
    lost = sorted(pd.read_parquet(p).groupby("track_id")["status"].first().eq("track_lost")
                  .mean() for p in metrics)
    assert lost == sorted(table.track_loss)
    for name in ("radar2d.md", "radar2d.png", "radar2d_memory.png"):
        assert (tmp_path / "tables" / name).exists()


def test_nan_estimates_and_flagged_runs_count_as_track_lost():
    _, truth = _log(n=4)
    truth = truth.to_pandas()
    est = truth.assign(x_m=truth["x_m"] + 5.0, status="ok")  # 5 m off: within the gate
    est.loc[(est.track_id == 1) & (est.step >= 20), "x_m"] = np.nan  # no estimate from 60 s
    est.loc[est.track_id == 3, "status"] = "divergent"  # the tracker's own verdict
    per_scan = per_scan_errors(est, truth)
    status = per_scan.groupby("track_id")["status"].first()
    assert list(status) == ["ok", "track_lost", "ok", "track_lost"]
    assert summary_row(per_scan, "imm", 10.0)["track_loss"] == 0.5


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


@pytest.mark.parametrize(("node", "key"), [
    ({"name": "imm", "initial_probs": [-1.0, 2.0]}, "initial_probs"),
    ({"name": "imm", "cv_accel_psd": -0.01}, "cv_accel_psd"),
    ({"name": "imm", "p_stay": float("nan")}, "p_stay"),
    ({"name": "fuzzy_mm", "bad_centre": 4.0}, "bad_centre"),
    ({"name": "alphabeta", "scan_period_s": -3.0}, "scan_period_s"),
])
def test_impossible_tracker_configs_are_refused(node, key):
    with pytest.raises(ConfigError, match=key):
        build_estimator(node)


def test_impossible_scenarios_are_refused():
    with pytest.raises(ConfigError, match=r"legs\[1\]"):
        Config(legs=[{"duration_s": 45.0}, {"turn_radius_m": -300.0, "duration_s": 45.0,
                                            "direction": "left"}])
    with pytest.raises(ConfigError, match="scan_period_s"):
        Config(scan_period_s=100.0)  # a 120 s path seen in 2 scans
