"""ranges2d report: per-run status in the metrics and the table, the pipeline end to end."""

import numpy as np
import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import compose_cfg
from tma.families.ranges2d.metrics import summary_row, track_metrics


def test_status_in_metrics_and_counted_in_the_table():
    est = pd.DataFrame({"track_id": [0, 1, 2], "x_m": [1.0, np.nan, 1.2],
                        "y_m": [2.0, np.nan, 2.1], "se_x_m": 0.1, "se_y_m": 0.1, "re_x": 1.0,
                        "re_y": 1.0, "corr_x": 0.5, "corr_y": 0.5, "samples_used": 100,
                        "n_evaluations": 0, "reached_accuracy": [True, False, False],
                        "status": ["ok", "box_too_small", "not_converged"]})
    ref = pd.DataFrame({"track_id": [0, 1, 2], "x_m": [1.0, 1.0, 1.0], "y_m": [2.0] * 3})
    m = track_metrics(est, ref, None, 0.95)
    assert list(m["status"]) == ["ok", "box_too_small", "not_converged"]
    row = summary_row("prior_is", m, 0.1)
    assert (row["n_ok"], row["n_not_converged"], row["n_box_too_small"], row["n_failed"]) == (
        1, 1, 1, 0)
    assert row["n_runs"] == 3 and row["reached_accuracy"] == pytest.approx(1 / 3)
    assert row["err_abs_max_m"] == pytest.approx(0.2)  # over the runs with an estimate
    assert row["x_mean_m"] == pytest.approx(1.1)


def test_pipeline_table(tmp_path):
    overrides = ["experiment=ranges2d_table", "scenario.n_tracks=6", "scenario.shard_size=3",
                 "estimators.prior_is.accuracy_m=1.0",
                 "estimators.adaptive_is.accuracy_m=1.0",
                 "estimators.adaptive_is.n_bisections=1000", "parallel=serial",
                 "progress=false", f"paths.data_dir={tmp_path}/data",
                 f"paths.tables_dir={tmp_path}/tables"]
    cfg = compose_cfg(overrides)
    simulate_stage(cfg)
    estimate_stage(cfg)
    aggregate_stage(cfg)
    table = pd.read_csv(tmp_path / "tables" / "ranges2d.csv")
    assert list(table.estimator) == ["quadrature", "prior_is", "adaptive_is"]
    assert (table.n_runs == 6).all()
    assert (table.loc[1:, "err_abs_max_m"] < 1.5).all()
    assert (table.n_ok + table.n_not_converged == 6).all()
    assert table.reached_accuracy.tolist() == (table.n_ok / 6).tolist()
    metrics = list((tmp_path / "data" / "runs").glob("*/*/metrics.parquet"))
    assert len(metrics) == 3
    for path in metrics:
        assert set(pd.read_parquet(path)["status"]) <= {"ok", "not_converged"}
    assert "prior / adaptive" in (tmp_path / "tables" / "ranges2d.md").read_text()
    assert (tmp_path / "tables" / "ranges2d.png").stat().st_size > 10_000
