"""Ingest of external bearing logs (CSV, MCAP) and the report for datasets without truth."""

import numpy as np
import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from tests.conftest import compose_cfg, run_cli
from tma.errors import ConfigError, InputError
from tma.families.bearings2d.ingest import ingest
from tma.families.bearings2d.log import write_bearings_log
from tma.families.bearings2d.scenario import Config, simulate_shard

T_OFFSET = 1.7e9  # e.g. unix time stamps


def _recording(sigma=0.2, n=3):
    log, truth = simulate_shard(Config(n_tracks=n, shard_size=n, sigma_deg=sigma, seed=11), 0)
    rows = [
        {"time_s": t + T_OFFSET, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
         "bearing_deg": log.bearing_deg[i, k], "track_id": int(log.track_id[i])}
        for k, t in enumerate(log.t_s) for i in range(n)
    ]
    return log, truth.to_pandas(), pd.DataFrame(rows)


def _estimate_and_report(tmp_path, name, sigma_flag=()):
    common = [f"paths.data_dir={tmp_path / 'data'}", f"paths.tables_dir={tmp_path / 'tables'}",
              f"dataset={name}", "estimator.initial_bearing_deg=null", "progress=false",
              "parallel=serial"]
    cfg = compose_cfg(common)
    estimate_stage(cfg)
    aggregate_stage(cfg)
    return pd.read_csv(tmp_path / "tables" / f"{name}-lm.csv")


def test_csv_ingest_estimate_report(tmp_path):
    log, truth, df = _recording()
    df.to_csv(tmp_path / "rec.csv", index=False)
    root = ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", name="rec")
    assert (root / "manifest.json").exists() and not (root / "truth.parquet").exists()
    report = _estimate_and_report(tmp_path, "rec")
    assert list(report.track_id) == [0, 1, 2]
    np.testing.assert_allclose(report.t_now_s, T_OFFSET + 1200.0)
    # truth now, against the estimate and its reported standard deviation
    t = 1200.0
    x = truth.x0_m + truth.vx_m_s * t - log.own_x_m[-1]
    y = truth.y0_m + truth.vy_m_s * t - log.own_y_m[-1]
    true_range = np.hypot(x, y)
    z = (report.range_now_m - true_range) / report.range_sd_m
    assert np.all(np.abs(z) < 5), z
    np.testing.assert_allclose(report.sigma_used_deg, 0.2, rtol=0.15)  # from residuals
    np.testing.assert_allclose(report.sqrt_ka_deg, 0.2, rtol=0.15)
    assert report.converged.all()
    assert "±" in (tmp_path / "tables" / "rec-lm.md").read_text()


def test_mcap_ingest_in_own_schema(tmp_path):
    log, truth, _ = _recording(sigma=0.1)
    write_bearings_log(tmp_path / "rec.mcap", log)
    ingest(tmp_path / "rec.mcap", data_dir=tmp_path / "data", sigma_deg=0.1)
    report = _estimate_and_report(tmp_path, "rec")
    np.testing.assert_allclose(report.sigma_used_deg, 0.1)
    speed = np.hypot(truth.vx_m_s, truth.vy_m_s)
    assert np.all(np.abs(report.speed_m_s - speed) < 5 * report.speed_sd_m_s)


def test_tracks_with_different_own_ships_get_their_own_shards(tmp_path):
    _, _, df = _recording()
    df.loc[df.track_id == 2, "own_x_m"] += 100.0
    df.to_csv(tmp_path / "two.csv", index=False)
    root = ingest(tmp_path / "two.csv", data_dir=tmp_path / "data")
    assert len(list((root / "log").glob("*.mcap"))) == 3


BAD_CSV = {
    "missing_column": (lambda df: df.drop(columns="own_y_m"), r"missing column\(s\) own_y_m"),
    "nan": (lambda df: df.assign(bearing_deg=df.bearing_deg.where(df.index != 7)),
            r"column bearing_deg has missing, NaN .* \(line 9\)"),
    "text": (lambda df: df.astype({"time_s": object}).assign(
        time_s=lambda d: d.time_s.where(d.index != 4, "noon")), "column time_s"),
    "duplicate_time": (lambda df: df.assign(time_s=df.time_s.where(df.index != 6,
                                                                   df.time_s[3])),
                       "duplicate time_s for track 0 on line 8"),
    "non_increasing": (lambda df: df.assign(time_s=df.time_s.where(df.index != 6,
                                                                   df.time_s[0])),
                       "non-increasing time_s for track 0 on line 8"),
    "radians_times_100": (lambda df: df.assign(bearing_deg=df.bearing_deg * 100),
                          r"outside \[-360, 360\]; bearings must be in degrees"),
    "too_few": (lambda df: df[(df.track_id != 1) | (df.index < 9)],
                r"track\(s\) 1 have 3 bearing\(s\).*at least 5"),
}


@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_bad_csv_is_a_clear_error_and_writes_nothing(tmp_path, case):
    _, _, df = _recording()
    edit, message = BAD_CSV[case]
    edit(df).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(InputError, match=message):
        ingest(tmp_path / "bad.csv", data_dir=tmp_path / "data")
    assert not (tmp_path / "data").exists()


def test_bad_ingest_arguments(tmp_path):
    with pytest.raises(ConfigError, match="needs input="):
        ingest(None, data_dir=tmp_path)
    (tmp_path / "x.txt").write_text("1")
    with pytest.raises(ConfigError, match="set format=csv or format=mcap"):
        ingest(tmp_path / "x.txt", data_dir=tmp_path)
    with pytest.raises(InputError, match="no such file"):
        ingest(tmp_path / "absent.csv", data_dir=tmp_path)


def test_existing_dataset_is_not_overwritten(tmp_path):
    _, _, df = _recording()
    df.to_csv(tmp_path / "rec.csv", index=False)
    ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data")
    with pytest.raises(InputError, match="exists"):
        ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data")
    ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", force=True)


def test_cli_ingest_of_a_truncated_mcap(tmp_path):
    log, _, _ = _recording()
    write_bearings_log(tmp_path / "rec.mcap", log)
    data = (tmp_path / "rec.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) - 100])
    proc = run_cli("ingest", f"input={tmp_path / 'cut.mcap'}", f"paths.data_dir={tmp_path}/d",
                   check=False)
    assert proc.returncode == 2
    assert "error:" in proc.stderr and "cut.mcap" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "d" / "datasets").exists()


def test_a_log_in_radians_is_refused_unless_its_units_are_stated(tmp_path):
    log, truth, df = _recording(sigma=0.2)
    df.assign(bearing_deg=np.deg2rad(df.bearing_deg)).to_csv(tmp_path / "rad.csv", index=False)
    with pytest.raises(InputError, match="look like radians. Set bearing_units=rad"):
        ingest(tmp_path / "rad.csv", data_dir=tmp_path / "data")
    assert not (tmp_path / "data").exists()
    ingest(tmp_path / "rad.csv", data_dir=tmp_path / "data", bearing_units="rad", name="rec")
    report = _estimate_and_report(tmp_path, "rec")
    assert (report.status == "ok").all()
    np.testing.assert_allclose(report.sqrt_ka_deg, 0.2, rtol=0.15)


@pytest.mark.parametrize("options, message", [
    ({"min_bearings": 0}, "min_bearings must be"), ({"min_bearings": 1.5}, "min_bearings"),
    ({"min_bearings": True}, "min_bearings"), ({"sigma_deg": "abc"}, "sigma_deg must be"),
    ({"sigma_deg": 0.0}, "sigma_deg must be"), ({"bearing_units": "grad"}, "bearing_units"),
])
def test_bad_ingest_options_are_refused(tmp_path, options, message):
    _, _, df = _recording()
    df.to_csv(tmp_path / "rec.csv", index=False)
    with pytest.raises(ConfigError, match=message):
        ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", **options)


def test_columns_of_booleans_or_absurd_integers_are_refused(tmp_path):
    _, _, df = _recording()
    df.assign(bearing_deg=True).to_csv(tmp_path / "bool.csv", index=False)
    with pytest.raises(InputError, match="column bearing_deg holds true/false"):
        ingest(tmp_path / "bool.csv", data_dir=tmp_path / "data")
    df.astype({"track_id": object}).assign(track_id="9" * 400).to_csv(tmp_path / "id.csv",
                                                                       index=False)
    with pytest.raises(InputError, match="track_id"):
        ingest(tmp_path / "id.csv", data_dir=tmp_path / "data")
