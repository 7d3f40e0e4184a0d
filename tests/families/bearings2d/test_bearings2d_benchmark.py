"""The benchmark table (``tma.families.bearings2d.benchmark``) from real runs of the pipeline
stages: every figure recomputed here from the run and dataset files, and the experiments."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline._common import estimator_nodes, open_datasets, scenario_nodes
from tests.conftest import compose_cfg, run_stage_here
from tma.families.bearings2d import benchmark, metrics
from tma.families.bearings2d.log import read_bearings_log
from tma.io.runs import open_run, run_path, seconds_per_track
from tma.plan.datasets import full_config
from tma.stages.aggregate import RunEntry

N = 40


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The outliers experiment, shrunk: 4 datasets (2 shards each) x 5 estimator runs."""
    root = tmp_path_factory.mktemp("bench")
    args = ["experiment=bearings2d_outliers", f"scenario.n_tracks={N}", "scenario.shard_size=20",
            "parallel=serial", "progress=false", f"paths.data_dir={root / 'data'}",
            f"paths.tables_dir={root / 'tables'}"]
    run_stage_here("simulate", *args)
    run_stage_here("estimate", *args)
    cfg = compose_cfg(args)  # the runs as the aggregate stage finds them
    entries = []
    for dataset in open_datasets(cfg):
        for node in estimator_nodes(cfg):
            run_root = run_path(root / "data", dataset, full_config(dataset, node))
            manifest, estimates = open_run(run_root)
            entries.append(RunEntry(dataset, node["name"], run_root, manifest,
                                    estimates.to_pandas(), seconds_per_track(run_root)))
    return root, entries


def test_table_rows_recomputed_from_the_run_files(runs):
    root, entries = runs
    paths = benchmark.write_benchmark(entries, root / "tables", "bearings2d_outliers")
    assert [p.name for p in paths] == [f"bearings2d_outliers.{e}" for e in ("csv", "md", "png")]
    table = pd.read_csv(paths[0])
    assert list(table.columns) == benchmark.COLUMNS
    assert len(table) == 28
    assert set(table["estimator"]) == {"lm", "nbearings", "iv", "mpekf",
                                       "mpekf gate_sigmas=4.0", "lm loss=huber",
                                       "lm loss=cauchy"}
    assert table["starts_changed"].isna().all()  # one start each
    assert sorted(set(table["outlier_prob"])) == [0.0, 0.01, 0.05, 0.1]
    assert (table["sigma_deg"] == 0.5).all() and (table["n_tracks"] == N).all()
    for entry in entries:
        label = benchmark.estimator_label(entry.estimator, entry.manifest["config"])
        prob = entry.dataset.manifest["config"]["outliers"]["prob"]
        row = table[(table["estimator"] == label) & (table["outlier_prob"] == prob)].iloc[0]
        est = entry.estimates
        truth = pd.read_parquet(entry.dataset.root / "truth.parquet").set_index("track_id") \
            .loc[est["track_id"]]
        t = est["t_last_s"].to_numpy()
        true_range = np.hypot(truth["x0_m"] + truth["vx_m_s"] * t - est["own_x_last_m"],
                              truth["y0_m"] + truth["vy_m_s"] * t - est["own_y_last_m"])
        range_err = est["range_now_m"].to_numpy() - true_range.to_numpy()
        speed_err = est["speed_m_s"].to_numpy() - truth["speed_m_s"].to_numpy()
        finite = np.isfinite(range_err)
        assert row["n_failed"] == (~finite).sum()
        assert row["rmse_range_m"] == pytest.approx(np.sqrt(np.mean(range_err[finite] ** 2)),
                                                    rel=1e-5)
        assert row["rmse_speed_m_s"] == pytest.approx(np.sqrt(np.mean(speed_err[finite] ** 2)),
                                                      rel=1e-5)
        bound = pd.concat([metrics.crlb_now(read_bearings_log(entry.dataset.verified_path(p)),
                                            truth.reset_index())
                           for p in entry.dataset.shard_paths])
        assert row["crlb_range_m"] == pytest.approx(
            np.sqrt(np.mean(bound["crlb_range_m"].to_numpy()[finite] ** 2)), rel=1e-5)
        assert row["efficiency_range"] == pytest.approx(
            (row["crlb_range_m"] / row["rmse_range_m"]) ** 2, rel=1e-4)
        assert row["ok"] == pytest.approx(np.mean(est["status"] == "ok"))
        assert row["ok_lo"] <= row["ok"] <= row["ok_hi"]
        ref1 = metrics.track_metrics(est, truth.reset_index())["ref1"].mean()
        assert row["ref1"] == pytest.approx(ref1)
        timing = json.loads((entry.run_root / "timing.json").read_text())["shards"].values()
        assert row["ms_per_track"] == pytest.approx(
            1e3 * sum(s["seconds"] for s in timing) / N, rel=1e-5)
    text = paths[1].read_text()
    assert "estimators against the Cramer-Rao bound" in text and "| mpekf gate_sigmas=4.0 |" in text
    assert paths[2].stat().st_size > 10_000


def test_the_bound_is_the_same_for_every_estimator_of_a_dataset(runs):
    _, entries = runs
    table = benchmark.benchmark_table(entries)
    clean = table[table["outlier_prob"] == 0]
    # failed tracks are left out per estimator, so compare where none failed
    full = clean[clean["n_failed"] == 0]
    assert len(full) >= 2 and np.ptp(full["crlb_range_m"]) <= 1e-9 * full["crlb_range_m"].max()


def test_only_truth_datasets_and_names():
    assert benchmark.write_benchmark([], "/nonexistent", "x") == []
    assert benchmark.estimator_label("iv", {"name": "iv", "iterations": 10}) == "iv"
    assert benchmark.estimator_label("iv", {"name": "iv", "iterations": 3}) == "iv iterations=3"
    assert np.isnan(seconds_per_track(Path("/nonexistent")))


def test_experiments_compose():
    cfg = compose_cfg(["experiment=bearings2d_benchmark"])
    assert cfg.table_kind == "benchmark"  # the kind of table, declared (not read off its name)
    assert [n["sigma_deg"] for n in scenario_nodes(cfg)] == [0.0, 0.1, 0.2, 0.3, 0.5, 1.0]
    assert [n["name"] for n in estimator_nodes(cfg)] == ["lm", "nbearings", "iv", "mpekf", "lm"]
    assert cfg.table == "bearings2d_benchmark"
    cfg = compose_cfg(["experiment=bearings2d_outliers"])
    nodes = scenario_nodes(cfg)
    assert [n["outliers"]["prob"] for n in nodes] == [0.0, 0.01, 0.05, 0.1]
    assert {n["sigma_deg"] for n in nodes} == {0.5}
    estimators = estimator_nodes(cfg)
    assert [n["name"] for n in estimators] == ["lm", "nbearings", "iv", "mpekf", "mpekf", "lm",
                                               "lm"]
    assert [n.get("gate_sigmas") for n in estimators[3:5]] == [None, 4.0]


def test_starts_changed_is_the_share_of_tracks_an_extra_start_won():
    got = benchmark.starts_changed(pd.DataFrame({"start_won": [0, 2, 0, 1, 0, 0, 0, 0]}))
    assert got["starts_changed"] == 0.25
    assert got["starts_changed_lo"] < 0.25 < got["starts_changed_hi"]
    assert np.isnan(benchmark.starts_changed(pd.DataFrame({"x": [1]}))["starts_changed"])
