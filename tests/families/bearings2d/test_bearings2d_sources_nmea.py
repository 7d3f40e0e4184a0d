"""NMEA 0183 own-ship navigation: GGA + RMC sentences written here (checksums computed here),
read back against what was written, refusals, and the whole chain: NMEA navigation + a
bearings CSV -> ingest -> ``lm`` recovers the contact of the recorded encounter."""

import datetime as dt
import json
from functools import reduce

import numpy as np
import pandas as pd
import pytest

from tests.families.bearings2d.recorded_geometry import (
    EPOCH_NS,
    check_against_truth,
    estimate,
    ingest,
    iso,
    recorded,
    source_options,
)
from tma.errors import ConfigError, InputError
from tma.io.atomic import sha256_file
from tma.sources import source_kind
from tma.sources.nmea import read_nmea


def _sentence(body: str) -> str:
    checksum = reduce(lambda a, c: a ^ ord(c), body, 0)
    return f"${body}*{checksum:02X}"


def _dm(value: float, hemispheres: str, degree_digits: int) -> str:
    """Degrees as NMEA ``(d)ddmm.mmmmmm`` and its hemisphere letter."""
    hemi = hemispheres[0] if value >= 0 else hemispheres[1]
    value = abs(value)
    degrees = int(value)
    minutes = (value - degrees) * 60
    return f"{degrees:0{degree_digits}d}{minutes:09.6f}", hemi


def gga(stamp: pd.Timestamp, lat, lon, talker="GP", quality=1) -> str:
    la, ns = _dm(lat, "NS", 2)
    lo, ew = _dm(lon, "EW", 3)
    return _sentence(f"{talker}GGA,{stamp.strftime('%H%M%S.%f')[:9]},{la},{ns},{lo},{ew},"
                     f"{quality},09,0.9,2.1,M,39.5,M,,")


def rmc(stamp: pd.Timestamp, lat, lon, talker="GN", status="A") -> str:
    la, ns = _dm(lat, "NS", 2)
    lo, ew = _dm(lon, "EW", 3)
    return _sentence(f"{talker}RMC,{stamp.strftime('%H%M%S.%f')[:9]},{status},{la},{ns},{lo},"
                     f"{ew},9.7,45.0,{stamp.strftime('%d%m%y')},,,A")


def _stamps(t_s, start=EPOCH_NS):
    return [pd.Timestamp(start + int(round(t * 1e9)), unit="ns", tz="UTC") for t in t_s]


def write_nmea(path, nav: pd.DataFrame, start=EPOCH_NS, garbage=True):
    """GGA (talker GP) + RMC (talker GN) per fix, as a GNSS receiver at 1 Hz logs them, and a
    few lines a serial log picks up: noise, a bad checksum, a satellites sentence."""
    lines = []
    for stamp, lat, lon in zip(_stamps(nav.t_s, start), nav.lat, nav.lon, strict=True):
        lines += [rmc(stamp, lat, lon), gga(stamp, lat, lon)]
    if garbage:
        lines.insert(5, "\x00\x13 line noise ~~~")
        bad = gga(_stamps([0.25], start)[0], 10.0, 10.0)
        lines.insert(9, bad[:-2] + ("00" if bad[-2:] != "00" else "11"))  # bad checksum
        lines.insert(12, _sentence("GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,00,13,06,"
                                   "292,00"))
        lines.insert(14, "$GPGGA,080003.000,5954.0000,N")  # cut mid-line, no checksum
    path.write_text("\r\n".join(lines) + "\r\n")
    return path


def test_fixes_are_read_back_and_garbage_counted(tmp_path):
    nav = recorded().navigation.head(60)
    path = write_nmea(tmp_path / "gps.nmea", nav)
    rec = read_nmea(path, source_options())
    assert rec.contacts is None and rec.navigation.geographic
    assert rec.navigation.epoch_utc_ns == EPOCH_NS
    np.testing.assert_allclose(rec.navigation.t_s, nav.t_s, atol=1e-9)
    # ddmm.mmmmmm keeps 1e-6 minutes: 2e-8 deg (2 mm)
    np.testing.assert_allclose(rec.navigation.lat_deg, nav.lat, atol=2e-8)
    np.testing.assert_allclose(rec.navigation.lon_deg, nav.lon, atol=2e-8)
    (note,) = rec.notes
    assert "60 GGA and 60 RMC fixes, 60 distinct times (60 merged)" in note
    assert "1 not NMEA" in note and "2 bad or missing checksum" in note
    assert "1 other sentences ignored" in note


def test_any_talker_southern_western_hemispheres_and_no_fix(tmp_path):
    s = _stamps([0.0, 1.0, 2.0, 3.0])
    path = tmp_path / "x.log"
    path.write_text("\n".join([
        rmc(s[0], -33.5, -70.25, talker="II"), gga(s[1], -33.5001, -70.2501, talker="GN"),
        gga(s[2], -33.5002, -70.2502, quality=0), rmc(s[3], -33.5003, -70.2503, status="V"),
        rmc(s[3], -33.5003, -70.2503, talker="GL")]) + "\n")
    rec = read_nmea(path, source_options())
    np.testing.assert_allclose(rec.navigation.t_s, [0.0, 1.0, 3.0])
    np.testing.assert_allclose(rec.navigation.lat_deg, [-33.5, -33.5001, -33.5003], atol=1e-9)
    np.testing.assert_allclose(rec.navigation.lon_deg, [-70.25, -70.2501, -70.2503], atol=1e-9)
    assert "2 no valid fix" in rec.notes[0]


def test_gga_dates_follow_the_rmc_across_midnight(tmp_path):
    day = pd.Timestamp("2025-06-01T23:59:58Z")
    stamps = [day + pd.Timedelta(seconds=k) for k in range(4)]  # 23:59:58 ... 00:00:01
    path = tmp_path / "midnight.nmea"
    path.write_text("\n".join([gga(stamps[0] - pd.Timedelta(seconds=1), 59.9, 10.7),
                               rmc(stamps[0], 59.9, 10.7)]
                              + [gga(s, 59.9, 10.7) for s in stamps[1:]]) + "\n")
    rec = read_nmea(path, source_options())
    start = int((day - pd.Timedelta(seconds=1)).value)
    assert rec.navigation.epoch_utc_ns == start
    np.testing.assert_allclose(rec.navigation.t_s, [0.0, 1.0, 2.0, 3.0, 4.0])
    assert dt.datetime.fromtimestamp((start + 4 * 10**9) / 1e9, dt.UTC).day == 2


def _gga_only(path, nav, start=EPOCH_NS):
    path.write_text("\n".join(gga(s, lat, lon) for s, lat, lon in zip(
        _stamps(nav.t_s, start), nav.lat, nav.lon, strict=True)) + "\n")
    return path


def test_gga_without_any_rmc_is_refused_naming_nmea_date(tmp_path):
    path = _gga_only(tmp_path / "gga.nmea", recorded().navigation.head(2))
    with pytest.raises(InputError, match=r"GGA sentences carry no date and nothing else dates "
                                         r"them: set nmea.date=YYYY-MM-DD \(or log RMC"):
        read_nmea(path, source_options())


@pytest.mark.parametrize("start", ["2025-06-01T08:00:00Z", "2025-06-01T23:55:00Z"])
def test_gga_only_is_dated_by_the_bearings(tmp_path, start):
    """GGA-only navigation (no RMC) with a bearings table of UTC times: the date is the
    bearings', across midnight too (a 40 min log from 23:55)."""
    epoch = int(pd.Timestamp(start).value)
    rec = recorded(("T1",))
    b = rec.bearings
    nav_path = _gga_only(tmp_path / "gga.nmea", rec.navigation, start=epoch)
    stamps = pd.to_datetime(epoch + np.round(b.t_s * 1e9).astype(np.int64), utc=True)
    pd.DataFrame({"timestamp_utc": [s.strftime("%Y-%m-%dT%H:%M:%S.%fZ") for s in stamps],
                  "bearing_deg": b.bearing_deg}).to_csv(tmp_path / "brg.csv", index=False)
    root = ingest(tmp_path / "brg.csv", navigation=nav_path, data_dir=tmp_path / "data")
    m = json.loads((root / "manifest.json").read_text())
    assert m["epoch_utc_ns"] == epoch + 500_000_000
    assert any("GGA dated 2025-06-01 from the bearings' times (nmea.date=" in n
               for n in m["notes"])
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"0": "T1"})


def test_nmea_date_dates_gga_only_navigation(tmp_path):
    nav = recorded().navigation.head(5)
    path = _gga_only(tmp_path / "gga.nmea", nav)
    rec = read_nmea(path, source_options({"nmea": {"date": "2025-06-01"}}))
    assert rec.navigation.epoch_utc_ns == EPOCH_NS
    np.testing.assert_allclose(rec.navigation.t_s, nav.t_s)
    assert "GGA dated 2025-06-01 by nmea.date" in rec.notes[-1]
    with pytest.raises(ConfigError, match="nmea.date must be a date YYYY-MM-DD, got '1.6.2025'"):
        source_options({"nmea": {"date": "1.6.2025"}})


def test_nothing_usable_is_refused_with_the_counts(tmp_path):
    path = tmp_path / "junk.nmea"
    path.write_text("$GPGGA,1,2,3*00\nhello\n" + _sentence("GPGSV,1,1,00") + "\n")
    with pytest.raises(InputError, match=r"no own-ship fix .*: 1 not NMEA, 1 bad or missing "
                                         r"checksum"):
        read_nmea(path, source_options())


def test_kind_is_told_from_the_first_line(tmp_path):
    path = tmp_path / "gps.txt"
    path.write_text(_sentence("GPGSV,1,1,00") + "\n")
    assert source_kind(path) == "nmea"
    (tmp_path / "b.csv").write_text("time_s,bearing_deg\n0,1\n")
    assert source_kind(tmp_path / "b.csv") == "csv"


def test_nmea_navigation_with_a_bearings_table_recovers_the_target(tmp_path):
    rec = recorded(("T1", "T2"))
    b = rec.bearings
    nav_path = write_nmea(tmp_path / "gps.nmea", rec.navigation)
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "track": b.track,
                  "bearing_deg": b.bearing_deg}).to_csv(tmp_path / "brg.csv", index=False)
    root = ingest(tmp_path / "brg.csv", navigation=nav_path, data_dir=tmp_path / "data")
    m = json.loads((root / "manifest.json").read_text())
    assert m["navigation"] == {"path": str(nav_path), "sha256": sha256_file(nav_path),
                               "kind": "nmea"}
    assert m["epoch_utc_ns"] == EPOCH_NS + 500_000_000
    assert m["track_labels"] == {"0": "T1", "1": "T2"}
    assert m["dropped_bearings"]["count"] == 0 and m["nav_gaps"]["count"] == 0
    check_against_truth(estimate(root), t_offset_s=0.5)


def test_nmea_as_the_input_names_navigation(tmp_path):
    path = write_nmea(tmp_path / "gps.nmea", recorded().navigation.head(5), garbage=False)
    with pytest.raises(InputError, match="NMEA holds own-ship navigation only: give it as "
                                         "navigation=FILE"):
        ingest(path, data_dir=tmp_path / "data")
