"""Real logs as they come (issue 22, item 1): the row policy ``bad_rows=drop|fail`` for every
reader. A bad row (a missing or unreadable bearing, time or fix, a stamp that is not absolute
among absolute ones) is left out and counted per reason, in the log line and the manifest,
naming the first few lines or message times; a fix flagged "no fix", at exactly 0, 0 or far
off the rest is an outlier, left out and counted; a contact with fewer than ``min_bearings``
kept bearings is skipped and counted. Under ``bad_rows=fail`` each is the one-line refusal it
always was, naming the option. The recorded encounter (``recorded_geometry``) is still
recovered from what is kept."""

import json
import logging

import numpy as np
import pandas as pd
import pytest

from tests.conftest import run_stage_here
from tests.families.bearings2d.recorded_geometry import (
    EPOCH_NS,
    check_against_truth,
    estimate,
    ingest,
    iso,
    latlon,
    recorded,
)
from tests.families.bearings2d.test_bearings2d_sources_foxglove import write_foxglove
from tests.families.bearings2d.test_bearings2d_sources_nmea import gga, rmc, write_nmea
from tests.families.bearings2d.test_bearings2d_sources_own_mcap import write_scalar_log
from tests.families.bearings2d.test_bearings2d_sources_ros2 import (
    float64_messages,
    header,
    navsatfix_messages,
    write_ros2,
)
from tma.errors import ConfigError, InputError
from tma.families.bearings2d.log import channels
from tma.sources.align import far_off


def _manifest(root) -> dict:
    return json.loads((root / "manifest.json").read_text())


def _table(rec) -> pd.DataFrame:
    b = rec.bearings
    return pd.DataFrame({"timestamp_utc": iso(b.t_s), "lat": b.lat, "lon": b.lon,
                         "bearing_deg": b.bearing_deg, "contact": b.track})


def _refused_in_one_line(path, tmp_path, match, options=None, **kwargs):
    with pytest.raises(InputError, match=match) as err:
        ingest(path, data_dir=tmp_path / "strict", options={**(options or {}), "bad_rows": "fail"},
               **kwargs)
    assert "\n" not in str(err.value)
    assert not (tmp_path / "strict").exists()


# -- CSV ---------------------------------------------------------------------------------------

def test_csv_bad_rows_are_left_out_counted_and_named(tmp_path, caplog):
    rec = recorded(("T1", "T2"))
    df = _table(rec).astype({"bearing_deg": object, "timestamp_utc": object, "lat": object})
    df.loc[10, "bearing_deg"] = np.nan  # line 12
    df.loc[20, "bearing_deg"] = "n/a"  # line 22
    df.loc[30, "timestamp_utc"] = ""  # line 32
    df.loc[40, "lat"] = "?"  # line 42
    df.loc[50, "timestamp_utc"] = "2025-06-01T08:99:00Z"  # line 52: not a time
    path = tmp_path / "rec.csv"
    df.to_csv(path, index=False)
    with caplog.at_level(logging.WARNING):
        root = ingest(path, data_dir=tmp_path / "data")
    bad = _manifest(root)["bad_rows"]
    assert bad["policy"] == "drop" and bad["count"] == 5
    assert bad["reasons"] == {
        "time missing or unreadable": {"count": 2, "first": ["line 32", "line 52"]},
        "bearing missing or not a number": {"count": 2, "first": ["line 12", "line 22"]},
        "own-ship position missing or not a number": {"count": 1, "first": ["line 42"]}}
    line = next(r.getMessage() for r in caplog.records if "bad row" in r.getMessage())
    assert "left out 5 bad row(s) (bad_rows=drop)" in line
    assert "2 with bearing missing or not a number (line 12, line 22)" in line
    est = estimate(root)
    assert sorted(est.n_bearings) == [395, 400]  # rows 10, 20, 30, 40, 50 are T1's
    check_against_truth(est, t_offset_s=0.5)
    _refused_in_one_line(path, tmp_path, r"column timestamp_utc has missing times or values that "
                                         r"are not ISO-8601 times .*\(line 32, line 52\); "
                                         r"bad_rows=drop leaves such rows out")


def test_a_zero_unix_stamp_among_absolute_ones_is_a_bad_row(tmp_path):
    rec = recorded(("T1",))
    b = rec.bearings
    df = pd.DataFrame({"time": EPOCH_NS / 1e9 + b.t_s, "lat": b.lat, "lon": b.lon,
                       "bearing_deg": b.bearing_deg})
    df.loc[7, "time"] = 0.0  # a clock not set: not "a relative clock"
    df.to_csv(tmp_path / "unix.csv", index=False)
    root = ingest(tmp_path / "unix.csv", data_dir=tmp_path / "data")
    m = _manifest(root)
    assert m["bad_rows"]["reasons"] == {
        "time not absolute among absolute times": {"count": 1, "first": ["line 9"]}}
    assert m["epoch_utc_ns"] == EPOCH_NS + 500_000_000
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"0": "T1"})
    _refused_in_one_line(tmp_path / "unix.csv", tmp_path,
                         r"not Unix times \(s\) like the others.*\(line 9\)")


def test_a_contact_with_too_few_bearings_is_skipped_and_counted(tmp_path, caplog):
    rec = recorded(("T1", "T2", "T3"))
    df = _table(rec)
    t3 = np.flatnonzero(df.contact == "T3")
    df = df.drop(index=t3[3:])  # T3 keeps 3 bearings
    df.to_csv(tmp_path / "few.csv", index=False)
    with caplog.at_level(logging.WARNING):
        root = ingest(tmp_path / "few.csv", data_dir=tmp_path / "data")
    m = _manifest(root)
    assert m["skipped_contacts"] == {"min_bearings": 5, "count": 1, "contacts": {"T3": 3}}
    assert sorted(m["track_labels"].values()) == ["T1", "T2"]
    assert "skipped 1 contact(s) with fewer than min_bearings = 5 bearings: T3 (3)" in caplog.text
    est = estimate(root)
    assert sorted(est.label) == ["T1", "T2"]
    check_against_truth(est, t_offset_s=0.5)
    _refused_in_one_line(tmp_path / "few.csv", tmp_path,
                         r"track\(s\) T3 have 3 bearing\(s\).*at least 5 \(min_bearings\); "
                         r"bad_rows=drop skips such contacts")
    # no contact left: the file is refused, saying so
    df[df.contact == "T3"].to_csv(tmp_path / "none.csv", index=False)
    with pytest.raises(InputError, match=r"no contact has min_bearings = 5 bearings: T3 \(3\)"):
        ingest(tmp_path / "none.csv", data_dir=tmp_path / "data")


def test_fixes_at_zero_zero_or_far_off_are_outliers(tmp_path):
    """A separate GPS table whose first fix is 0, 0 (a receiver before its first fix) and with
    one fix 3 km off: both left out, the plane's origin is the first real fix."""
    rec = recorded(("T1",))
    nav = rec.navigation
    gps = pd.DataFrame({"time": iso(nav.t_s), "lat": nav.lat, "lon": nav.lon})
    gps.loc[0, ["lat", "lon"]] = 0.0  # line 2
    far_lat, far_lon = latlon(np.array([3000.0]), np.array([-2000.0]))
    gps.loc[300, ["lat", "lon"]] = far_lat[0], far_lon[0]  # line 302
    gps.to_csv(tmp_path / "gps.csv", index=False)
    b = rec.bearings
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "bearing_deg": b.bearing_deg}).to_csv(
        tmp_path / "brg.csv", index=False)
    root = ingest(tmp_path / "brg.csv", navigation=tmp_path / "gps.csv",
                  data_dir=tmp_path / "data")
    m = _manifest(root)
    assert m["bad_rows"]["reasons"] == {
        "own-ship fix at 0, 0": {"count": 1, "first": ["line 2"]},
        "own-ship fix far off the track": {"count": 1, "first": ["line 302"]}}
    np.testing.assert_allclose(m["origin_deg"], [nav.lat[1], nav.lon[1]], atol=1e-12)
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"0": "T1"})
    _refused_in_one_line(tmp_path / "brg.csv", tmp_path, r"own-ship fix at 0, 0 .*\(line 2\)",
                         navigation=tmp_path / "gps.csv")


def test_bearings_of_two_platforms_in_one_log_are_refused(tmp_path):
    """A navigation export of two vessels' bearings with no platform column tma finds
    (``vessel``), rows alternating every 5 s between ships 6 km apart: one line saying
    own-ship jumps between places and naming ``columns.platform``, never a track of one
    own-ship jumping back and forth."""
    t = np.arange(0.0, 1200.0, 5.0)
    second = np.arange(t.size) % 2 == 1
    east = np.where(second, 6000.0, 0.0) + 4.0 * t
    lat, lon = latlon(east, np.zeros(t.size))
    frame = pd.DataFrame({"timestamp_utc": iso(t), "vessel": np.where(second, "B", "A"),
                          "latitude_deg": lat, "longitude_deg": lon, "contact": "T1",
                          "bearing_deg": 45.0})
    frame.to_csv(tmp_path / "two.csv", index=False)
    with pytest.raises(InputError, match=r"239 of 239 steps between successive own-ship fixes "
                       r"\(100%\) are faster than nav\.max_speed_m_s = .* up to 6\.0 km: "
                       r"own-ship jumps between places.*several platforms.*"
                       r"columns\.platform=<column>"
                       ) as err:
        ingest(tmp_path / "two.csv", data_dir=tmp_path / "data")
    assert "\n" not in str(err.value)
    assert not (tmp_path / "data" / "datasets").exists()
    # a few fixes off (one platform's bad fixes) are still left out and counted
    frame.loc[second, ["latitude_deg", "longitude_deg"]] = np.column_stack(
        latlon(4.0 * t[second], np.zeros(second.sum())))
    frame.loc[[11, 101], ["latitude_deg", "longitude_deg"]] = lat[11] + 0.05, lon[11]
    frame.to_csv(tmp_path / "one.csv", index=False)
    root = ingest(tmp_path / "one.csv", data_dir=tmp_path / "data")
    assert _manifest(root)["bad_rows"]["reasons"]["own-ship fix far off the track"][
        "count"] == 2


def test_the_outlier_rule_never_drops_a_fix_of_a_real_track(tmp_path):
    """A fast own-ship (20 m/s) turning hard every 30 s, fixes at 1 Hz with 10 m noise: no
    fix is far off by the rule (a bound any fix within nav.max_speed_m_s meets)."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 1800.0)
    course = np.deg2rad(90.0 * (t // 30 % 4))
    east = np.cumsum(20.0 * np.sin(course)) + rng.normal(0, 10, t.size)
    north = np.cumsum(20.0 * np.cos(course)) + rng.normal(0, 10, t.size)
    lat, lon = latlon(east, north)
    pd.DataFrame({"time_s": t, "lat": lat, "lon": lon}).to_csv(tmp_path / "gps.csv",
                                                               index=False)
    pd.DataFrame({"time_s": t[::6] + 0.5, "bearing_deg": rng.uniform(0, 360, t[::6].size)}
                 ).to_csv(tmp_path / "brg.csv", index=False)
    root = ingest(tmp_path / "brg.csv", navigation=tmp_path / "gps.csv",
                  data_dir=tmp_path / "data")
    assert _manifest(root)["bad_rows"]["count"] == 0


def test_far_off_finds_every_injected_outlier_and_nothing_else():
    """A track at up to 15 m/s with 10 m noise, fixes every 0.5-3 s; 40 runs of 1 to 9 fixes
    moved 5-50 km away (fewer than half of any window; beyond the rule's bound, at most
    sqrt(2) 50 m/s x 30 s + 100 m = 2.2 km here): exactly those are found."""
    rng = np.random.default_rng(8)
    n = 20_000
    t = np.cumsum(rng.uniform(0.5, 3.0, n))
    heading = np.cumsum(rng.normal(0, 0.2, n))
    step = rng.uniform(0, 15, n) * np.diff(t, prepend=t[0])
    x = np.cumsum(step * np.sin(heading)) + rng.normal(0, 10, n)
    y = np.cumsum(step * np.cos(heading)) + rng.normal(0, 10, n)
    truth = np.zeros(n, dtype=bool)
    for start in rng.choice(np.arange(0, n - 10, 400), 40, replace=False):
        run = slice(start, start + rng.integers(1, 10))
        angle, distance = rng.uniform(0, 2 * np.pi), rng.uniform(5e3, 5e4)
        x[run] += distance * np.sin(angle)
        y[run] += distance * np.cos(angle)
        truth[run] = True
    np.testing.assert_array_equal(far_off(t, x, y, 50.0), truth)


def test_own_ship_too_far_names_the_input_not_a_staging_file(tmp_path):
    """A real voyage of 2,400 km (at 40 m/s: no fix is an outlier) cannot be one plane."""
    t = np.arange(0.0, 60_000.0, 300.0)
    lat, lon = latlon(np.zeros(t.size), 40.0 * t, origin=(10.0, 0.0))
    pd.DataFrame({"time_s": t, "lat": lat, "lon": lon, "bearing_deg": 45.0}).to_csv(
        tmp_path / "voyage.csv", index=False)
    with pytest.raises(InputError) as err:
        ingest(tmp_path / "voyage.csv", data_dir=tmp_path / "data")
    message = str(err.value)
    assert message.startswith(str(tmp_path / "voyage.csv")) and "partial" not in message
    assert "farther than 2000 km from the origin" in message and "split the log" in message
    assert not (tmp_path / "data" / "datasets").exists()


# -- NMEA --------------------------------------------------------------------------------------

def test_nmea_no_fix_zero_zero_and_garbage_are_counted(tmp_path):
    rec = recorded(("T1",))
    nav = rec.navigation
    path = write_nmea(tmp_path / "gps.nmea", nav)  # garbage: 1 not NMEA, 2 checksums
    stamp = {t: pd.Timestamp(EPOCH_NS + int(t * 1e9), unit="ns", tz="UTC")
             for t in (100.5, 150.5, 200.5)}
    lines = [gga(stamp[200.5], 0.0, 0.0), rmc(stamp[100.5], 59.91, 10.71, status="V"),
             gga(stamp[150.5], 59.91, 10.71, quality=0)]
    path.write_text("\r\n".join(lines) + "\r\n" + path.read_text())
    b = rec.bearings
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "bearing_deg": b.bearing_deg}).to_csv(
        tmp_path / "brg.csv", index=False)
    root = ingest(tmp_path / "brg.csv", navigation=path, data_dir=tmp_path / "data")
    reasons = _manifest(root)["bad_rows"]["reasons"]
    assert reasons["own-ship fix at 0, 0"] == {"count": 1, "first": ["line 1"]}
    assert reasons["own-ship fix flagged no fix"] == {"count": 2, "first": ["line 2", "line 3"]}
    assert reasons["NMEA line with a bad or missing checksum"] == {
        "count": 2, "first": ["line 13", "line 18"]}
    assert reasons["NMEA line not NMEA"] == {"count": 1, "first": ["line 9"]}
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"0": "T1"})
    # under fail, a damaged line refuses the file; the receiver's own "no fix" does not
    _refused_in_one_line(tmp_path / "brg.csv", tmp_path, r"gps.nmea: a line that is not NMEA "
                         r"\(line 9\); bad_rows=drop", navigation=path)


# -- MCAP: ROS 2, Foxglove, tma's own ----------------------------------------------------------

def test_ros2_zero_stamp_nan_bearing_and_no_fix(tmp_path):
    rec = recorded(("T1",))
    fixes = navsatfix_messages(rec.navigation, status=np.where(
        np.arange(len(rec.navigation)) == 600, -1, 0))
    log_time, message = fixes[100]
    fixes[100] = (log_time, {**message, "header": header(0)})  # one unset stamp among 2402
    bearings = float64_messages(rec.bearings)
    bearings[50] = (bearings[50][0], {"data": float("nan")})
    path = write_ros2(tmp_path / "run.mcap", ("/gps/fix", "sensor_msgs/msg/NavSatFix", fixes),
                      ("/bearing", "std_msgs/msg/Float64", bearings))
    opts = {"bearing": {"topic": "/bearing"}}
    root = ingest(path, data_dir=tmp_path / "data", options=opts)
    m = _manifest(root)
    assert m["epoch_utc_ns"] == EPOCH_NS + 500_000_000  # not "a relative clock"
    assert m["bad_rows"]["reasons"] == {
        "time not absolute among absolute times": {
            "count": 1, "first": ["/gps/fix at log time 2025-06-01T08:01:40.04Z"]},
        "bearing missing or not a number": {
            "count": 1, "first": ["/bearing at 2025-06-01T08:05:00.5Z"]},
        "own-ship fix flagged no fix": {"count": 1, "first": ["/gps/fix at 2025-06-01T08:10:00Z"]}}
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"/bearing": "T1"})
    _refused_in_one_line(path, tmp_path, r"run.mcap: /gps/fix: a time stamp before 2000 among UTC "
                         r"stamps \(/gps/fix at log time 2025-06-01T08:01:40.04Z\)", options=opts)


def test_an_mcap_own_ship_replaced_by_a_navigation_file_is_not_read(tmp_path):
    """With navigation=FILE the MCAP's own-ship topic is not decoded: its bad fixes are
    neither counted nor, under bad_rows=fail, a reason to refuse the file."""
    rec = recorded(("T1",))
    fixes = navsatfix_messages(rec.navigation, status=np.where(
        np.arange(len(rec.navigation)) == 600, -1, 0))  # a NO_FIX the command must not see
    path = write_ros2(tmp_path / "run.mcap", ("/gps/fix", "sensor_msgs/msg/NavSatFix", fixes),
                      ("/bearing", "std_msgs/msg/Float64", float64_messages(rec.bearings)))
    nav = rec.navigation
    pd.DataFrame({"time": iso(nav.t_s), "lat": nav.lat, "lon": nav.lon}).to_csv(
        tmp_path / "gps.csv", index=False)
    opts = {"bearing": {"topic": "/bearing"}, "bad_rows": "fail"}
    root = ingest(path, navigation=tmp_path / "gps.csv", data_dir=tmp_path / "data",
                  options=opts)
    assert not _manifest(root).get("bad_rows", {}).get("reasons")
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"/bearing": "T1"})


def test_foxglove_null_bearing_and_zero_zero_fix(tmp_path):
    rec = recorded(("T1",))
    rec.navigation.loc[200, ["lat", "lon"]] = 0.0
    rec.bearings = rec.bearings.astype({"bearing_deg": object})
    rec.bearings.loc[30, "bearing_deg"] = None  # written as JSON null
    path = write_foxglove(tmp_path / "fox.mcap", rec)
    opts = {"bearing": {"topic": "/contacts", "field": "bearing_deg"}}
    root = ingest(path, data_dir=tmp_path / "data", options=opts)
    reasons = _manifest(root)["bad_rows"]["reasons"]
    assert reasons == {
        "bearing missing or not a number": {
            "count": 1, "first": ["/contacts at 2025-06-01T08:03:00.5Z"]},
        "own-ship fix at 0, 0": {"count": 1, "first": ["/gps at 2025-06-01T08:03:20Z"]}}
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"1": "T1"})


def test_own_schema_null_bearing(tmp_path):
    rec = recorded(("T1",))
    path = write_scalar_log(tmp_path / "own.mcap", rec, channels=channels("json"),
                            extra=[(1000.0, {"t_s": 1000.0, "track_id": 1, "bearing_deg": None})])
    root = ingest(path, data_dir=tmp_path / "data")
    assert _manifest(root)["bad_rows"]["reasons"] == {
        "bearing missing or not a number": {
            "count": 1, "first": ["/sonar/bearings at 2025-06-01T08:16:40Z"]}}
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"1": "T1"})
    _refused_in_one_line(path, tmp_path, r"/sonar/bearings: a bearing missing or not a number")


def test_bad_rows_option_is_checked():
    with pytest.raises(ConfigError, match="bad_rows must be one of drop, fail, got 'skip'"):
        ingest("x.csv", data_dir="d", options={"bad_rows": "skip"})


def test_on_the_command_line(tmp_path):
    rec = recorded(("T1",))
    df = _table(rec).astype({"bearing_deg": object})
    df.loc[3, "bearing_deg"] = "-"
    df.to_csv(tmp_path / "rec.csv", index=False)
    common = [f"input={tmp_path / 'rec.csv'}", f"paths.data_dir={tmp_path / 'data'}",
              "progress=false"]
    proc = run_stage_here("ingest", *common, "bad_rows=fail", check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("error: ") and "(line 5); bad_rows=drop leaves such rows out" in line
    assert not (tmp_path / "data" / "datasets").exists()
    proc = run_stage_here("ingest", *common)
    assert "left out 1 bad row(s) (bad_rows=drop): 1 with bearing missing or not a number " \
           "(line 5)" in proc.stderr + proc.stdout
    assert _manifest(tmp_path / "data" / "datasets" / "rec")["bad_rows"]["count"] == 1
