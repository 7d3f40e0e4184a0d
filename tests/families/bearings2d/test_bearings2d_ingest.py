"""Ingest of recorded bearing logs: the stage (options, manifest, refusals, CLI) and the report
for datasets without truth. The readers have their own test files (``..._sources_*.py``)."""

import json
import logging
import time

import numpy as np
import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from tests.conftest import compose_cfg, run_cli, run_stage_here
from tests.families.bearings2d.recorded_geometry import (
    EPOCH_NS,
    ORIGIN,
    check_against_truth,
    estimate,
    ingest,
    iso,
    latlon,
    ownship_en,
    recorded,
)
from tma.errors import ConfigError, InputError
from tma.families.bearings2d import contact_plots
from tma.families.bearings2d.log import write_bearings_log
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.families.bearings2d.status import INTERVAL_COLUMNS
from tma.io.atomic import sha256_file
from tma.sources import kinds

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


def test_csv_ingest_estimate_report(tmp_path, monkeypatch):
    log, truth, df = _recording()
    df.to_csv(tmp_path / "rec.csv", index=False)
    root = ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", name="rec")
    assert (root / "manifest.json").exists() and not (root / "truth.parquet").exists()
    titles = []
    draw = contact_plots._TrackPlots.draw
    monkeypatch.setattr(contact_plots._TrackPlots, "draw", lambda self, title, *a: (
        titles.append(title) or draw(self, title, *a)))
    report = _estimate_and_report(tmp_path, "rec")
    assert list(report.track_id) == [0, 1, 2]
    # times from the log's start and in UTC, never Unix seconds
    np.testing.assert_allclose(report.t_now_s, 1200.0)
    np.testing.assert_allclose(report.leg_start_s, 0.0)
    now = pd.Timestamp(T_OFFSET + 1200.0, unit="s", tz="UTC").strftime("%Y-%m-%dT%H:%M:%SZ")
    assert list(report.time_now_utc) == [now] * 3
    md = (tmp_path / "tables" / "rec-lm.md").read_text()
    assert "| t now (s from start) | now (UTC) |" in md and f"| 1200.0 | {now} |" in md
    assert "1.7e+09" not in md and "1700001200" not in md
    assert len(titles) == 3 and all(f"at {now}" in t for t in titles), titles
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
    # beside each number its 2-sd interval (the CSV has the 1-sd one too), ordered
    lo2, lo1, hi1, hi2 = (report[c].to_numpy() for c in INTERVAL_COLUMNS["range"])
    assert np.all((lo2 < lo1) & (lo1 < hi1) & (hi1 < hi2)), report[INTERVAL_COLUMNS["range"]]
    assert f"{report.range_now_m[0]:.0f} ± {report.range_sd_m[0]:.0f} [{lo2[0]:.0f}, " \
           f"{hi2[0]:.0f}]" in md


def test_mcap_ingest_in_own_schema(tmp_path):
    log, truth, _ = _recording(sigma=0.1)
    write_bearings_log(tmp_path / "rec.mcap", log)
    ingest(tmp_path / "rec.mcap", data_dir=tmp_path / "data", sigma_deg=0.1)
    report = _estimate_and_report(tmp_path, "rec")
    np.testing.assert_allclose(report.sigma_used_deg, 0.1)
    speed = np.hypot(truth.vx_m_s, truth.vy_m_s)
    shown = report.speed_m_s.notna()  # (blank where the heading is not determined)
    assert shown.sum() >= 2 and (shown | (report.status == "position_only")).all()
    assert np.all(np.abs(report.speed_m_s - speed)[shown] < 5 * report.speed_sd_m_s[shown])


def test_tracks_with_different_own_ships_get_their_own_shards(tmp_path):
    _, _, df = _recording()
    df.loc[df.track_id == 2, "own_x_m"] += 100.0
    df.to_csv(tmp_path / "two.csv", index=False)
    root = ingest(tmp_path / "two.csv", data_dir=tmp_path / "data")
    assert len(list((root / "log").glob("*.mcap"))) == 3


BAD_CSV = {
    "missing_column": (lambda df: df.drop(columns="own_y_m"),
                       r"no y column: columns found: time_s, own_x_m, bearing_deg, track_id; "
                       r"set columns.y=<name>"),
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
    """Under bad_rows=fail (bad rows are left out and counted by default:
    ``test_bearings2d_bad_rows.py``)."""
    _, _, df = _recording()
    edit, message = BAD_CSV[case]
    edit(df).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(InputError, match=message):
        ingest(tmp_path / "bad.csv", data_dir=tmp_path / "data", options={"bad_rows": "fail"})
    assert not (tmp_path / "data").exists()


def test_bad_ingest_arguments(tmp_path):
    with pytest.raises(ConfigError, match="needs input="):
        ingest(None, data_dir=tmp_path)
    (tmp_path / "x.dat").write_text("1")
    *others, last = kinds()
    with pytest.raises(ConfigError, match=f"set {', '.join(f'format={k}' for k in others)} or "
                                          f"format={last}"):
        ingest(tmp_path / "x.dat", data_dir=tmp_path)
    with pytest.raises(InputError, match="the first line holds numbers, not column names"):
        ingest(tmp_path / "x.dat", data_dir=tmp_path, fmt="csv")
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
    with pytest.raises(InputError, match="look like radians. Set bearing.units=rad"):
        ingest(tmp_path / "rad.csv", data_dir=tmp_path / "data")
    assert not (tmp_path / "data").exists()
    ingest(tmp_path / "rad.csv", data_dir=tmp_path / "data", options={"bearing": {"units": "rad"}},
           name="rec")
    report = _estimate_and_report(tmp_path, "rec")
    assert report.status.isin(["ok", "position_only"]).all()  # (a recording: may manoeuvre)
    np.testing.assert_allclose(report.sqrt_ka_deg, 0.2, rtol=0.15)


@pytest.mark.parametrize("options, message", [
    ({"min_bearings": 0}, "min_bearings must be"), ({"min_bearings": 1.5}, "min_bearings"),
    ({"min_bearings": True}, "min_bearings"), ({"sigma_deg": "abc"}, "sigma_deg must be"),
    ({"sigma_deg": 0.0}, "sigma_deg must be"),
    ({"options": {"bearing": {"units": "grad"}}}, "bearing.units must be one of null, deg, rad"),
    ({"options": {"columns": {"foo": "x"}}}, r"unknown option columns.foo \(the columns options"),
    ({"options": {"time": {"format": "local"}}}, "time.format must be one of"),
    ({"options": {"nav": {"max_gap_s": -1}}}, "nav.max_gap_s must be"),
    ({"options": {"origin": {"lat": 59.9}}}, "origin.lat and origin.lon go together"),
    ({"options": {"csv": {"delimiter": "::"}}}, "csv.delimiter must be one character"),
    ({"fmt": "xls"}, f"format must be auto, {', '.join(kinds()[:-1])} or {kinds()[-1]}"),
])
def test_bad_ingest_options_are_refused(tmp_path, options, message):
    _, _, df = _recording()
    df.to_csv(tmp_path / "rec.csv", index=False)
    with pytest.raises(ConfigError, match=message):
        ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", **options)


def test_booleans_are_refused_and_integers_beyond_2_53_kept_as_text(tmp_path):
    _, _, df = _recording()
    df.assign(bearing_deg=True).to_csv(tmp_path / "bool.csv", index=False)
    with pytest.raises(InputError, match="column bearing_deg holds true/false"):
        ingest(tmp_path / "bool.csv", data_dir=tmp_path / "data")
    huge = {i: "9" * 40 + str(i) for i in range(3)}  # not exact as a number: kept as written
    df.assign(track_id=df.track_id.map(huge)).to_csv(tmp_path / "id.csv", index=False)
    root = ingest(tmp_path / "id.csv", data_dir=tmp_path / "data")
    labels = json.loads((root / "manifest.json").read_text())["track_labels"]
    assert sorted(labels.values()) == sorted(huge.values())


# -- the ingest options on the command line --------------------------------------------------

def _one_line(proc, expected):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert expected in lines[0], lines[0]


@pytest.mark.parametrize("override, expected", [
    ("columns.foo=bar", "unknown option columns.foo (the columns options: columns.time, "),
    ("+columns.foo=bar", "unknown option columns.foo"),
    ("nav.max_gap=3", "unknown option nav.max_gap (the nav options: nav.max_extrapolation_s, "
                      "nav.max_gap_s, nav.max_bridge_s, nav.max_speed_m_s)"),
    ("bad_rows=skip", "bad_rows must be one of drop, fail, got 'skip'"),
    ("nav.max_speed_m_s=0", "nav.max_speed_m_s must be in (0, 1e5), got 0"),
    ("bearing.units=grad", "bearing.units must be one of null, deg, rad, got 'grad'"),
    ("time.format=local", "time.format must be one of auto, s, unix_s"),
    ("nav.max_extrapolation_s=abc", "nav.max_extrapolation_s must be a number in [0, 1e9), "
                                    "got 'abc'"),
    ("origin.lat=95", "origin.lat must be in (-90, 90), got 95"),
    ("origin.lat=59.9", "origin.lat and origin.lon go together"),
    ("nmea.date=1.6.2025", "nmea.date must be a date YYYY-MM-DD, got '1.6.2025'"),
    ("columns.time=[a,b]", "columns.time must be null or text, got ['a', 'b']"),
    ("sigma_deg=abc", "sigma_deg must be null or a number in [0.001, 90), got 'abc'"),
    ("min_bearings=4", "min_bearings must be >= 5, got 4"),
])
def test_cli_bad_reading_options_are_one_line(tmp_path, override, expected):
    _, _, df = _recording()
    df.to_csv(tmp_path / "rec.csv", index=False)
    proc = run_stage_here("ingest", f"input={tmp_path / 'rec.csv'}", override,
                          f"paths.data_dir={tmp_path / 'data'}", "progress=false", check=False)
    _one_line(proc, expected)
    assert not (tmp_path / "data" / "datasets").exists()


def test_cli_unknown_column_option_in_a_new_process(tmp_path):
    proc = run_cli("ingest", f"input={tmp_path / 'rec.csv'}", "columns.foo=bar",
                   f"paths.data_dir={tmp_path / 'data'}", check=False)
    _one_line(proc, "unknown option columns.foo")


def test_cli_reading_options_reach_the_readers(tmp_path):
    """``;`` separated, decimal commas, odd column names, radians, relative times: every
    option on the command line as a user types it."""
    _, _, df = _recording()
    df = df.rename(columns={"time_s": "tid", "own_x_m": "ost", "own_y_m": "nord",
                            "bearing_deg": "peiling", "track_id": "kontakt"})
    df["tid"] -= T_OFFSET
    df["peiling"] = np.deg2rad(df["peiling"])
    df.to_csv(tmp_path / "rec.csv", index=False, sep=";", decimal=",")
    run_stage_here("ingest", f"input={tmp_path / 'rec.csv'}", "name=rec", "columns.time=tid",
                   "columns.x=ost", "columns.y=nord", "columns.bearing=peiling",
                   "columns.track=kontakt", "bearing.units=rad", "csv.delimiter=semicolon",
                   "csv.decimal=comma", "time.format=s", f"paths.data_dir={tmp_path / 'data'}",
                   "progress=false")
    manifest = json.loads((tmp_path / "data" / "datasets" / "rec" / "manifest.json").read_text())
    assert manifest["config"]["options"]["bearing"]["units"] == "rad"
    assert manifest["epoch_utc_ns"] is None and manifest["time_origin_s"] == 0.0
    assert manifest["shards"]["log/shard-00000.mcap"]["tracks"] == 3
    report = _estimate_and_report(tmp_path, "rec")
    assert report.status.isin(["ok", "position_only"]).all()  # (a recording: may manoeuvre)


# -- what the manifest records --------------------------------------------------------------

def test_manifest_records_time_origin_labels_navigation_and_choices(tmp_path):
    rec = recorded(("T1", "T2"))
    b = rec.bearings
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "contact": b.track,
                  "bearing_deg": b.bearing_deg}).to_csv(tmp_path / "brg.csv", index=False)
    nav = rec.navigation[rec.navigation.t_s >= 3.0]  # own-ship starts 2.5 s after a bearing
    nav = nav[(nav.t_s < 100) | (nav.t_s > 130)]  # and has a 32 s gap
    pd.DataFrame({"time": iso(nav.t_s), "lat": nav.lat, "lon": nav.lon}).to_csv(
        tmp_path / "gps.csv", index=False)
    root = ingest(tmp_path / "brg.csv", navigation=tmp_path / "gps.csv",
                  data_dir=tmp_path / "data", name="trial")
    m = json.loads((root / "manifest.json").read_text())
    first_kept = 6.5  # the bearings at 0.5 s were more than 1 s before the first fix at 3 s
    assert m["epoch_utc_ns"] == EPOCH_NS + int(first_kept * 1e9)
    assert m["start_utc"] == "2025-06-01T08:00:06.5Z"
    assert m["time_origin_s"] == m["epoch_utc_ns"] / 1e9
    lat0, lon0 = latlon(*ownship_en(np.array([3.0])))
    np.testing.assert_allclose(m["origin_deg"], [lat0[0], lon0[0]], atol=1e-12)
    assert m["track_labels"] == {"0": "T1", "1": "T2"}
    assert m["dropped_bearings"]["count"] == 2 and m["dropped_bearings"]["before_navigation"] == 2
    assert "nav.max_extrapolation_s" in m["dropped_bearings"]["why"]
    gaps = m["nav_gaps"]
    assert gaps["count"] == 1 and gaps["longest_s"] == 32.0  # fixes at 99 s, then 131 s
    assert gaps["gaps"][0]["from_s"] == 99.0 - first_kept
    assert gaps["gaps"][0]["bearings_inside"] == 2 * 5  # 102.5 ... 126.5 s, two contacts
    assert any("timestamp_utc" in n for n in m["notes"])
    assert m["navigation"]["sha256"] == sha256_file(tmp_path / "gps.csv")
    assert m["input"]["sha256"] == sha256_file(tmp_path / "brg.csv")
    assert m["navigation"]["kind"] == "csv" and m["input"]["kind"] == "csv"


def test_separate_navigation_file_recovers_the_target(tmp_path):
    rec = recorded(("T1", "T2", "T3"))
    b, nav = rec.bearings, rec.navigation
    pd.DataFrame({"utc": iso(b.t_s), "track": b.track, "bearing_deg": b.bearing_deg}).to_csv(
        tmp_path / "brg.csv", index=False)
    pd.DataFrame({"unix_time": EPOCH_NS / 1e9 + nav.t_s, "latitude": nav.lat,
                  "longitude": nav.lon}).to_csv(tmp_path / "gps.csv", index=False)
    root = ingest(tmp_path / "brg.csv", navigation=tmp_path / "gps.csv",
                  data_dir=tmp_path / "data")
    m = json.loads((root / "manifest.json").read_text())
    np.testing.assert_allclose(m["origin_deg"], ORIGIN, atol=1e-12)  # the first fix, at t = 0
    check_against_truth(estimate(root), t_offset_s=(m["epoch_utc_ns"] - EPOCH_NS) / 1e9)


def _relative_latlon(tmp_path, rec):
    b = rec.bearings
    pd.DataFrame({"time_s": b.t_s, "lat": b.lat, "lon": b.lon, "bearing_deg": b.bearing_deg}
                 ).to_csv(tmp_path / "rel.csv", index=False)
    return tmp_path / "rel.csv"


def test_start_utc_makes_a_relative_log_absolute(tmp_path):
    """time.start_utc is the UTC of the log's own time 0: the dataset starts at its first
    bearing (0.5 s), and every output is dated, the map MCAP too."""
    rec = recorded(("T1",))
    path = _relative_latlon(tmp_path, rec)
    root = ingest(path, data_dir=tmp_path / "data", name="rel",
                  options={"time": {"start_utc": "2025-06-01T10:00:00+02:00"}})
    m = json.loads((root / "manifest.json").read_text())
    assert m["epoch_utc_ns"] == EPOCH_NS + 500_000_000
    assert m["start_utc"] == "2025-06-01T08:00:00.5Z"
    assert any("time.start_utc" in n for n in m["notes"])
    report = _estimate_and_report(tmp_path, "rel")
    t_last = report.t_now_s[0]  # seconds from the first bearing
    assert pd.Timestamp(report.time_now_utc[0]) == pd.Timestamp(
        EPOCH_NS + 500_000_000 + round(t_last * 1e9), tz="UTC")
    with open(tmp_path / "tables" / "rel-lm.mcap", "rb") as f:
        from mcap.reader import make_reader
        first = next(make_reader(f).iter_messages())[2]
    assert first.log_time == EPOCH_NS + 500_000_000
    # an absolute log has its own UTC: the option is refused, in one line
    _recording()[2].to_csv(tmp_path / "abs.csv", index=False)
    with pytest.raises(ConfigError, match=r"time.start_utc=2025-06-01T08:00:00Z applies to logs "
                                          r"of relative times: .*abs.csv has UTC times"):
        ingest(tmp_path / "abs.csv", data_dir=tmp_path / "data",
               options={"time": {"start_utc": "2025-06-01T08:00:00Z"}})
    with pytest.raises(ConfigError, match=r"time.start_utc must be an ISO-8601 time with a zone "
                                          r"\(e.g. .*\), got '08:00'$"):
        ingest(path, data_dir=tmp_path / "data", options={"time": {"start_utc": "08:00"}})


def test_a_relative_log_with_lat_lon_is_not_dated_1970(tmp_path, caplog):
    rec = recorded(("T1",))
    path = _relative_latlon(tmp_path, rec)
    with caplog.at_level(logging.WARNING):
        ingest(path, data_dir=tmp_path / "data", name="rel")
    assert "relative times: the outputs give no UTC and no map MCAP is written (it would be " \
           "dated 1970); give time.start_utc=<ISO-8601 UTC of the log's time 0>" in caplog.text
    with caplog.at_level(logging.INFO):
        _estimate_and_report(tmp_path, "rel")
    assert not (tmp_path / "tables" / "rel-lm.mcap").exists()
    assert "no map MCAP (rel-lm.mcap): the dataset's times are relative" in caplog.text


def test_a_bearings_table_without_own_ship_names_the_options(tmp_path):
    rec = recorded()
    rec.bearings[["t_s", "bearing_deg"]].to_csv(tmp_path / "brg.csv", index=False)
    with pytest.raises(InputError, match=r"no own-ship position: columns found: t_s, "
                                         r"bearing_deg; set columns.lat=<name> .*navigation=FILE"):
        ingest(tmp_path / "brg.csv", data_dir=tmp_path / "data")


def test_mixed_absolute_and_relative_clocks_are_refused(tmp_path):
    rec = recorded()
    b, nav = rec.bearings, rec.navigation
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "bearing_deg": b.bearing_deg}).to_csv(
        tmp_path / "brg.csv", index=False)
    pd.DataFrame({"time_s": nav.t_s, "own_x_m": nav.east_m, "own_y_m": nav.north_m}).to_csv(
        tmp_path / "nav.csv", index=False)
    with pytest.raises(InputError, match=r"nav.csv has relative times .*brg.csv has absolute "
                                         r"UTC times \(time.format=auto\)"):
        ingest(tmp_path / "brg.csv", navigation=tmp_path / "nav.csv", data_dir=tmp_path / "d")
    assert not (tmp_path / "d").exists()


# -- speed ------------------------------------------------------------------------------------

def _big_table(path, n_tracks, n=1_000_000):
    per = n // n_tracks
    t = np.repeat(np.arange(per) * 2.0, n_tracks)
    rng = np.random.default_rng(3)
    pd.DataFrame({"time_s": t, "own_x_m": 3.0 * t, "own_y_m": 500.0 * np.sin(t / 600.0),
                  "bearing_deg": rng.uniform(0.0, 360.0, t.size),
                  "track_id": np.tile(np.arange(n_tracks), per)}).to_csv(path, index=False)


@pytest.mark.slow
@pytest.mark.parametrize("n_tracks", [1, 1000])
def test_a_million_bearings_ingest(tmp_path, n_tracks, capsys):
    """Measured, not asserted (the machine is shared): the whole ``ingest()`` call on 1M
    bearings, and the part of it spent writing the dataset MCAP (write_bearings_log)."""
    _big_table(tmp_path / "big.csv", n_tracks)
    writes = []

    def timed_write(*args, **kwargs):
        start = time.perf_counter()
        try:
            return write_bearings_log(*args, **kwargs)
        finally:
            writes.append(time.perf_counter() - start)

    start = time.perf_counter()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("tma.families.bearings2d.scenario.write_bearings_log", timed_write)
        root = ingest(tmp_path / "big.csv", data_dir=tmp_path / "data")
    total = time.perf_counter() - start
    m = json.loads((root / "manifest.json").read_text())
    assert sum(s["tracks"] for s in m["shards"].values()) == n_tracks
    with capsys.disabled():
        print(f"\n1M bearings, {n_tracks} track(s): ingest {total:.2f} s, of which "
              f"write_bearings_log {sum(writes):.2f} s")
