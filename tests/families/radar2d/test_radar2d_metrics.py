"""radar2d metrics: segments derived from the legs and the memory, track loss, the table."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import compose_cfg
from tma.config import to_plain
from tma.families.radar2d.aggregate import aggregate_runs
from tma.families.radar2d.metrics import (
    per_scan_errors,
    segments,
    summary_row,
    table_columns,
)
from tma.families.radar2d.scenario import Config, simulate_shard
from tma.stages.aggregate import RunEntry

# 30 s straight, a 36 s right turn, 60 s straight, scans every 2 s: with J = 5 the window is
# full at (5 - 1) x 2 = 8 s, the turn covers [30, 66] s and the path ends at 126 s
LEGS = [{"duration_s": 30.0}, {"turn_radius_m": 200.0, "duration_s": 36.0, "direction": "right"},
        {"duration_s": 60.0}]
OTHER = {"legs": LEGS, "scan_period_s": 2.0}
TODAY_COLUMNS = (  # the default table's header (docs/formats.md)
    "estimator,speed_m_s,n_runs,straight1_mean_m,straight1_max_median_m,straight1_max_p95_m,"
    "turn_mean_m,turn_max_median_m,turn_max_p95_m,straight2_mean_m,straight2_max_median_m,"
    "straight2_max_p95_m,track_loss,m_median,m_min_turn_median,p_m_max_straight,"
    "recover_s_median,sigma_hat_60s_m,sigma_hat_90s_m,sigma_hat_120s_m,p_turn_model_in_turn")


def _truth(n=3, **kw):
    return simulate_shard(Config(n_tracks=n, shard_size=n, **kw), 0)[1].to_pandas()


def test_default_legs_give_the_spec_segments():
    segs = segments(to_plain(Config()), memory=10)
    assert segs.windows == {"straight1": (27.0, 42.0), "turn": (45.0, 90.0),
                            "straight2": (93.0, 120.0)}
    assert (segs.loss_from_s, segs.turn_end_s) == (27.0, 90.0)
    assert segs.sigma_times_s == (60.0, 90.0, 120.0)
    assert ",".join(table_columns(segs.sigma_times_s)) == TODAY_COLUMNS


def test_other_legs_and_memory_move_the_segments():
    segs = segments(to_plain(Config(**OTHER)), memory=5)
    assert segs.windows == {"straight1": (8.0, 28.0), "turn": (30.0, 66.0),
                            "straight2": (68.0, 126.0)}
    assert (segs.loss_from_s, segs.turn_end_s) == (8.0, 66.0)
    assert segs.sigma_times_s == (42.0, 66.0, 126.0)  # a third into the turn, its end, the end
    # a second turn (from 126 s) ends the second straight; no turn: one straight to the end
    two = segments(to_plain(Config(legs=[*LEGS, {"turn_radius_m": 300.0, "duration_s": 9.0,
                                                 "direction": "left"}], scan_period_s=2.0)), 5)
    assert two.windows["straight2"] == (68.0, 124.0) and two.windows["turn"] == (30.0, 66.0)
    straight = segments(to_plain(Config(legs=[{"duration_s": 60.0}])), 10)
    assert straight.windows["straight1"] == (27.0, 60.0)
    assert np.isnan(straight.windows["turn"]).all() and np.isnan(straight.turn_end_s)
    assert straight.sigma_times_s == (60.0,)
    assert segments(to_plain(Config(legs=[{"duration_s": 12.0}])), 10).loss_from_s == np.inf


def test_metrics_follow_the_segments_of_other_legs():
    """Errors of t / 10 m, m = 2 from the turn start until 72 s, sigma_hat = t: each statistic
    is a known function of the segment times (none matches the default legs' times)."""
    truth = _truth(**OTHER)
    t = truth["t_s"]
    est = truth.assign(x_m=truth["x_m"] + t / 10, status="ok", m=np.where(
        (t >= 30) & (t < 72), 2.0, 5.0), sigma_hat_m=t, p_turn=((t >= 30) & (t <= 66)) * 1.0)
    segs = segments(to_plain(Config(**OTHER)), memory=5)
    per_scan = per_scan_errors(est, truth, segs)
    row = summary_row(per_scan, "fuzzy_mm", 10.0, segs, memory=5)
    for name, (a, b) in (("straight1", (8, 28)), ("turn", (30, 66)), ("straight2", (68, 126))):
        assert row[f"{name}_mean_m"] == pytest.approx((a + b) / 20)
        assert row[f"{name}_max_median_m"] == pytest.approx(b / 10)
        assert row[f"{name}_max_p95_m"] == pytest.approx(b / 10)
    assert row["m_min_turn_median"] == 2
    assert row["p_m_max_straight"] == pytest.approx(39 / 41)  # 68 and 70 s still at m = 2
    assert row["recover_s_median"] == pytest.approx(72 - 66)
    assert [row[f"sigma_hat_{s}s_m"] for s in (42, 66, 126)] == [42.0, 66.0, 126.0]
    assert row["p_turn_model_in_turn"] == 1.0
    # track loss counts from the window fill (8 s): a jump at 6 s is not a loss, at 8 s it is
    jump = truth.assign(status="ok")
    jump.loc[(jump.track_id == 1) & (jump.t_s == 6.0), "x_m"] += 100.0
    jump.loc[(jump.track_id == 2) & (jump.t_s == 8.0), "x_m"] += 100.0
    lost = per_scan_errors(jump, truth, segs).groupby("track_id")["track_lost"].first()
    assert list(lost) == [False, False, True]


def test_nan_estimates_and_flagged_runs_count_as_track_lost():
    truth = _truth(n=4)
    segs = segments(to_plain(Config()))
    est = truth.assign(x_m=truth["x_m"] + 5.0, status="ok")  # 5 m off: within the gate
    est.loc[(est.track_id == 1) & (est.step >= 20), "x_m"] = np.nan  # no estimate from 60 s
    est.loc[est.track_id == 3, "status"] = "divergent"  # the tracker's own verdict
    per_scan = per_scan_errors(est, truth, segs)
    assert "status" not in per_scan  # the tracker's verdict is the estimates' column
    lost = per_scan.groupby("track_id")["track_lost"].first()
    assert list(lost) == [False, True, False, True]
    assert summary_row(per_scan, "imm", 10.0, segs)["track_loss"] == 0.5


def test_each_dataset_is_measured_on_its_own_segments(tmp_path):
    """Three datasets: default legs (fuzzy J = 10 + IMM), other legs (fuzzy J = 5 + IMM) and
    other legs with the IMM alone. A dataset's rows share its segments: the IMM takes the
    J of the fuzzy tracker beside it, and the default J = 10 when alone."""
    entries = []
    for name, speed, scenario, runs in [("a", 10.0, {}, {"fuzzy_mm": 10, "imm": None}),
                                        ("b", 20.0, OTHER, {"fuzzy_mm": 5, "imm": None}),
                                        ("c", 30.0, OTHER, {"imm": None})]:
        cfg = Config(n_tracks=2, shard_size=2, speed_m_s=speed, **scenario)
        truth = _truth(n=2, speed_m_s=speed, **scenario)
        t = truth["t_s"]
        dataset = SimpleNamespace(name=name, manifest={"config": to_plain(cfg)},
                                  read_truth=lambda truth=truth: truth)
        for estimator, memory in runs.items():
            est = truth.assign(x_m=truth["x_m"] + t / 10, status="ok")
            est = (est.assign(m=float(memory), sigma_hat_m=t) if memory
                   else est.assign(p_cv=0.5, p_turn=0.5))
            root = tmp_path / "runs" / name / estimator
            root.mkdir(parents=True)
            config = {"name": estimator, **({"memory": memory} if memory else {})}
            entries.append(RunEntry(dataset, estimator, root, {"config": config}, est))
    aggregate_runs(entries, tmp_path / "tables", "t")
    table = pd.read_csv(tmp_path / "tables" / "t.csv").set_index(["speed_m_s", "estimator"])
    assert [c for c in table if c.startswith("sigma_hat")] == [
        f"sigma_hat_{s}s_m" for s in (42, 60, 66, 90, 120, 126)]
    straight1 = table["straight1_mean_m"]
    assert straight1[10.0, "fuzzy_mm"] == straight1[10.0, "imm"] == pytest.approx(3.45)  # 27-42
    assert straight1[20.0, "fuzzy_mm"] == straight1[20.0, "imm"] == pytest.approx(1.8)  # 8-28
    assert straight1[30.0, "imm"] == pytest.approx(2.3)  # J = 10: 18-28 s
    assert table.loc[(20.0, "fuzzy_mm"), "sigma_hat_42s_m"] == 42.0
    assert np.isnan(table.loc[(10.0, "fuzzy_mm"), "sigma_hat_42s_m"])
    md = (tmp_path / "tables" / "t.md").read_text()
    assert "- `b`: first straight (8.0, 28.0) s, turn (30.0, 66.0) s" in md
    assert "- `c`: first straight (18.0, 28.0) s" in md


def test_polar_noise_and_pipeline_table(tmp_path):
    overrides = ["experiment=radar2d_table", "scenario.n_tracks=40", "scenario.shard_size=20",
                 "scenario.noise=polar", "parallel=serial", "progress=false",
                 f"paths.data_dir={tmp_path}/data", f"paths.tables_dir={tmp_path}/tables"]
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
    lost = sorted(pd.read_parquet(p).groupby("track_id")["track_lost"].first().mean()
                  for p in metrics)
    assert lost == sorted(table.track_loss)
    for name in ("radar2d.md", "radar2d.png", "radar2d_memory.png"):
        assert (tmp_path / "tables" / name).exists()
    assert "(first straight (27.0, 42.0) s, turn\n(45.0, 90.0) s" in (
        tmp_path / "tables" / "radar2d.md").read_text()
