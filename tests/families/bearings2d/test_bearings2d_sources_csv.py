"""CSV/TSV bearing tables as recorders write them: each variant of one recorded encounter
(known truth, ``recorded_geometry``) is written by pandas, ingested with no option beyond
those the variant needs, and ``lm`` must recover every contact (range now within 5 %, course
within 3 deg). Then the reader's own results against what was written, and its refusals."""

import json

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
from tma.errors import InputError
from tma.sources.csv_table import read_csv_table


def _iso_latlon(rec):
    b = rec.bearings
    return pd.DataFrame({"timestamp_utc": iso(b.t_s), "latitude_deg": b.lat,
                         "longitude_deg": b.lon, "bearing_deg": b.bearing_deg})


def _write(df, path, **kwargs):
    df.to_csv(path, index=False, **kwargs)
    return path


def _iso_latlon_csv(rec, d):
    return _write(_iso_latlon(rec), d / "nav_export.csv"), {}


def _bearing_rad(rec, d):
    df = _iso_latlon(rec)
    df["bearing_rad"] = np.deg2rad(df.pop("bearing_deg"))
    return _write(df, d / "rad.csv"), {}


def _extra_columns_crlf(rec, d):
    df = _iso_latlon(rec)
    df.insert(1, "sog_kn", 9.7)
    df.insert(0, "seq", np.arange(len(df)))
    df["operator_note"] = "ok, steady"
    return _write(df, d / "crlf.csv", lineterminator="\r\n"), {}


def _several_contacts(rec, d):
    b = rec.bearings
    df = _iso_latlon(rec)
    df["track_id"] = b.track.map({"T1": 1, "T2": 2, "T3": 3})
    return _write(df, d / "contacts.csv"), {}


def _semicolon_decimal_comma(rec, d):
    return _write(_iso_latlon(rec), d / "eu.csv", sep=";", decimal=","), {}


def _units_row(rec, d):
    b = rec.bearings
    path = d / "units.csv"
    df = pd.DataFrame({"time_s": b.t_s, "lat": b.lat, "lon": b.lon, "bearing": b.bearing_deg})
    with open(path, "w") as f:
        f.write("time_s,lat,lon,bearing\n[s],[deg],[deg],[deg]\n")
        df.to_csv(f, index=False, header=False, float_format="%.10f")
    return path, {"bearing": {"units": "deg"}}


def _text_ids(rec, d):
    b = rec.bearings
    df = _iso_latlon(rec)
    df["contact"] = b.track
    return _write(df, d / "labels.csv"), {}


def _unix_ms(rec, d):
    b = rec.bearings
    df = pd.DataFrame({"time": EPOCH_NS // 10**6 + np.round(b.t_s * 1000).astype(np.int64),
                       "lat": b.lat, "lon": b.lon, "bearing_deg": b.bearing_deg,
                       "track_id": b.track.map({"T1": 1, "T2": 2, "T3": 3})})
    return _write(df, d / "unix_ms.csv"), {}


def _tsv(rec, d):
    return _write(_iso_latlon(rec), d / "export.tsv", sep="\t"), {}


VARIANTS = {  # name: (writer, contacts)
    "iso_utc_latlon": (_iso_latlon_csv, ("T1",)),
    "bearing_rad": (_bearing_rad, ("T2",)),
    "extra_columns_crlf": (_extra_columns_crlf, ("T3",)),
    "several_contacts": (_several_contacts, ("T1", "T2", "T3")),
    "semicolon_decimal_comma": (_semicolon_decimal_comma, ("T1",)),
    "units_row": (_units_row, ("T2",)),
    "text_ids": (_text_ids, ("T1", "T2")),
    "unix_ms": (_unix_ms, ("T1", "T3")),
    "tsv": (_tsv, ("T3",)),
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_recorded_table_variants_recover_the_target(tmp_path, variant):
    write, contacts = VARIANTS[variant]
    rec = recorded(contacts)
    path, options = write(rec, tmp_path)
    root = ingest(path, data_dir=tmp_path / "data", options=options)
    m = json.loads((root / "manifest.json").read_text())
    est = estimate(root)
    assert len(est) == len(contacts)
    if variant == "units_row":  # relative seconds: t = 0 is the first bearing
        offset = rec.bearings.t_s.min()
        assert m["epoch_utc_ns"] is None and m["time_origin_s"] == offset
    else:
        offset = (m["epoch_utc_ns"] - EPOCH_NS) / 1e9
        assert m["epoch_utc_ns"] == EPOCH_NS + int(rec.bearings.t_s.min() * 1e9)
    numbers = {"1": "T1", "2": "T2", "3": "T3", "0": contacts[0]}
    check_against_truth(est, t_offset_s=offset, labels=numbers)
    if variant == "text_ids":
        assert m["track_labels"] == {"0": "T1", "1": "T2"}
        assert list(est.label) == ["T1", "T2"]
    else:
        assert m["track_labels"] is None


# -- what the reader returns, against what was written --------------------------------------

def _read(path, navigation=True, contacts=True, **options):
    return read_csv_table(path, source_options(options), navigation=navigation,
                          contacts=contacts)


def test_iso_times_positions_and_labels_are_read_exactly(tmp_path):
    rec = recorded(("T2", "T1"))
    b = rec.bearings
    df = _iso_latlon(rec)
    df["contact"] = b.track
    (one,) = _read(_write(df, tmp_path / "x.csv"))
    assert one.navigation.epoch_utc_ns == one.contacts.epoch_utc_ns == EPOCH_NS + 500_000_000
    np.testing.assert_allclose(one.contacts.t_s, b.t_s - 0.5, atol=1e-9)
    assert list(one.contacts.track) == list(b.track)
    np.testing.assert_array_equal(one.contacts.values, b.bearing_deg)
    first = b.drop_duplicates("t_s")  # one fix per time (the contacts share the own-ship)
    np.testing.assert_array_equal(one.navigation.lat_deg, first.lat)
    np.testing.assert_array_equal(one.navigation.lon_deg, first.lon)
    np.testing.assert_allclose(one.navigation.t_s, first.t_s - 0.5, atol=1e-9)


@pytest.mark.parametrize("values, fmt, scale, epoch", [
    (EPOCH_NS // 10**9 + np.array([0.0, 1.25, 2.5]), "auto", 1.0, EPOCH_NS),
    (EPOCH_NS // 10**6 + np.array([0, 1250, 2500]), "auto", 1e-3, EPOCH_NS),
    (EPOCH_NS + np.array([0, 1_250_000_000, 2_500_000_000]), "auto", 1e-9, EPOCH_NS),
    (np.array([0, 1250, 2500]) + 10**6, "unix_ms", 1e-3, 10**12),
    (np.array([3.0, 4.25, 5.5]), "auto", 1.0, None),
])
def test_time_formats(tmp_path, values, fmt, scale, epoch):
    df = pd.DataFrame({"t": values, "x": [0.0, 1.0, 2.0], "y": 0.0, "bearing_deg": 10.0})
    (one,) = _read(_write(df, tmp_path / "t.csv"), time={"format": fmt},
                   columns={"time": "t", "x": "x", "y": "y"})
    assert one.contacts.epoch_utc_ns == epoch
    expected = (values - values[0]) * scale if epoch is not None else values
    np.testing.assert_allclose(one.contacts.t_s, expected, atol=1e-9)


def test_units_row_is_skipped_and_says_radians(tmp_path):
    path = tmp_path / "u.csv"
    path.write_text("time_s,own_x_m,own_y_m,brg\ns,m,m,rad\n0,0,0,0.5\n1,1,0,0.25\n")
    (one,) = _read(path)
    np.testing.assert_allclose(one.contacts.values, np.rad2deg([0.5, 0.25]))
    assert one.contacts.units_stated
    assert any("units row" in n for n in one.notes)


def test_a_utf8_bom_and_spaces_around_names(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes("\ufefftime_s , own_x_m, own_y_m , bearing_deg\r\n0, 0, 0, 45\r\n"
                     "2, 10, 0, 46\r\n".encode())
    (one,) = _read(path)
    np.testing.assert_array_equal(one.contacts.values, [45.0, 46.0])
    np.testing.assert_array_equal(one.navigation.x_m, [0.0, 10.0])


def test_a_delimiter_ending_every_row(tmp_path):
    path = tmp_path / "trailing.csv"
    path.write_text("time_s,own_x_m,own_y_m,bearing_deg\n0,0,0,45,\n2,10,0,46,\n")
    (one,) = _read(path)
    np.testing.assert_array_equal(one.contacts.values, [45.0, 46.0])
    np.testing.assert_array_equal(one.contacts.t_s, [0.0, 2.0])


def test_navigation_table_with_repeated_fixes(tmp_path):
    df = pd.DataFrame({"time_s": [0.0, 1.0, 1.0, 2.0], "lat": [59.9, 59.91, 59.91, 59.92],
                       "lon": 10.7})
    (one,) = _read(_write(df, tmp_path / "nav.csv"), contacts=False)
    assert one.contacts is None
    np.testing.assert_array_equal(one.navigation.t_s, [0.0, 1.0, 2.0])
    df.loc[2, "lat"] = 59.95
    with pytest.raises(InputError, match=r"two different own-ship positions at the time of "
                                         r"line 3 \(time_s\)"):
        _read(_write(df, tmp_path / "nav.csv"), contacts=False)


# -- refusals: one line, naming the file, the line and the option ----------------------------

REFUSED = {
    "no zone": ("timestamp_utc,lat,lon,bearing_deg\n2025-06-01T08:00:00,59.9,10.7,10\n"
                "2025-06-01T08:00:01,59.9,10.7,11\n", {},
                r"timestamp_utc '2025-06-01T08:00:00' on line 2 has no time zone: .* set "
                r"time.format=iso_utc"),
    "zone name": ("timestamp_utc,lat,lon,bearing_deg\n2025-06-01 08:00:00 CET,59.9,10.7,10\n"
                  "2025-06-01 08:00:01 CET,59.9,10.7,11\n", {},
                  r"timestamp_utc '2025-06-01 08:00:00 CET' on line 2 names its zone \(CET\), "
                  r"which is no offset: write it as one \(2025-06-01 08:00:00\+01:00, say\) or "
                  r"Z for UTC"),
    "no time": ("when,lat,lon,bearing_deg\n1,59.9,10.7,10\n", {},
                r"no time column: columns found: when, lat, lon, bearing_deg; set "
                r"columns.time=<name>"),
    "no bearing": ("time_s,lat,lon,heading\n1,59.9,10.7,10\n", {},
                   r"no bearing column: columns found: time_s, lat, lon, heading; set "
                   r"columns.bearing=<name>"),
    "named column absent": ("time_s,lat,lon,bearing_deg\n1,59.9,10.7,10\n",
                            {"columns": {"bearing": "brg"}},
                            r"columns.bearing=brg: no such column; columns found: time_s, lat"),
    "lat without lon": ("time_s,latitude,bearing_deg\n1,59.9,10\n", {},
                        r"own-ship latitude in column 'latitude' but no lon column: .* set "
                        r"columns.lon=<name>"),
    "lat out of range": ("time_s,lat,lon,bearing_deg\n1,159.9,10.7,10\n", {},
                         r"lat 159.9 on line 2 is not a latitude in degrees"),
    "not iso": ("timestamp_utc,lat,lon,bearing_deg\n2025-06-01T08:00:00Z,59.9,10.7,10\n"
                "yesterday noon,59.9,10.7,11\nlater,59.9,10.7,12\n", {},
                r"timestamp_utc '.*' on line 3 has no time zone"),
    "bad iso with zone": ("timestamp_utc,lat,lon,bearing_deg\n2025-06-01T08:00:00Z,59.9,10.7,1\n"
                          "2025-13-45T08:00:01Z,59.9,10.7,2\n", {"bad_rows": "fail"},
                          r"column timestamp_utc has missing times or values that are not "
                          r"ISO-8601 times .*\(line 3\); bad_rows=drop leaves such rows out"),
    "unix and relative mixed": ("time,x,y,bearing_deg\n1748764800,0,0,1\n1748764801,0,0,2\n"
                                "5,0,0,3\n", {"bad_rows": "fail"},
                                r"column time has times that are not Unix times \(s\) like the "
                                r"others: .* \(line 4\); bad_rows=drop"),
    "radians beyond 2 pi": ("time_s,x,y,bearing_rad\n0,0,0,1\n1,0,0,7\n", {},
                            r"bearing_rad 7 on line 3 is outside \[-2 pi, 2 pi\]"),
    "missing track id": ("time_s,x,y,bearing_deg,track\n0,0,0,1,T1\n1,0,0,2,\n",
                         {"bad_rows": "fail"}, r"column track has missing track ids \(line 3\)"),
    "nothing usable": ("time_s,x,y,bearing_deg\n0,0,0,\n1,0,0,x\n", {},
                       r"no usable row: 2 with bearing missing or not a number \(line 2, line "
                       r"3\)"),
    "duplicate label time": ("time_s,x,y,bearing_deg,track\n0,0,0,1,T1\n1,0,0,2,T1\n"
                             "1,0,0,3,T1\n", {}, r"duplicate time_s for track T1 on line 4"),
    "midnight wrap": ("time_s,x,y,bearing_deg\n86380,0,0,1\n86390,0,0,2\n0,0,0,3\n", {},
                      r"non-increasing time_s for track .* on line 4 .* go back by 24.0 h "
                      r"there: a clock of the time of day wraps at midnight.* with its date"),
    "not utf8": (b"time_s,x,y,bearing_deg\n0,0,0,1\n\xff\xfe,0,0,1\n", {},
                 r"not UTF-8 text"),
    "header only": ("time_s,x,y,bearing_deg\n", {}, r"no rows"),
    "ragged": ("time_s,x,y,bearing_deg\n0,0,0,1\n1,0,0,2,5,6\n", {}, r"not a readable CSV"),
    "every row one longer": ("time_s,x,y,bearing_deg\n0,0,0,1,9\n1,0,0,2,9\n", {},
                             r"not a readable CSV"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_refusals_name_the_line_and_the_option(tmp_path, case):
    text, options, message = REFUSED[case]
    path = tmp_path / "bad.csv"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(InputError, match=message):
        _read(path, **options)


def test_a_table_of_radians_with_unstated_units_is_refused_with_the_option(tmp_path):
    rec = recorded()
    df = _iso_latlon(rec)
    df["bearing_deg"] = np.deg2rad(df["bearing_deg"])  # mislabelled: radians in *_deg
    path = _write(df, tmp_path / "x.csv")
    with pytest.raises(InputError, match=r"look like radians. Set bearing.units=rad"):
        ingest(path, data_dir=tmp_path / "data")
    root = ingest(path, data_dir=tmp_path / "data", options={"bearing": {"units": "rad"}})
    check_against_truth(estimate(root), t_offset_s=0.5, labels={"0": "T1"})


# -- contact ids as written ------------------------------------------------------------------

@pytest.mark.parametrize("ids", [("007", "7"), ("1e3", "1000"), ("NA", "T2")])
def test_contact_ids_are_kept_as_written(tmp_path, ids):
    """``007`` and ``7`` (``1e3`` and ``1000``) are two contacts, never one number; ``NA`` is
    a name, not a missing id."""
    rec = recorded(("T1", "T2"))
    df = _iso_latlon(rec)
    df["contact"] = rec.bearings.track.map({"T1": ids[0], "T2": ids[1]})
    path = _write(df, tmp_path / "ids.csv")
    (one,) = _read(path)
    assert sorted(set(one.contacts.track)) == sorted(ids)
    root = ingest(path, data_dir=tmp_path / "data")
    m = json.loads((root / "manifest.json").read_text())
    assert sorted(m["track_labels"].values()) == sorted(ids)
    est = estimate(root)
    assert sorted(est.label) == sorted(ids)
    check_against_truth(est, t_offset_s=0.5, labels={ids[0]: "T1", ids[1]: "T2"})


def test_canonical_integer_ids_stay_numbers(tmp_path):
    """Ids written as plain integers are the ids themselves (no labels), as before."""
    df = pd.DataFrame({"time_s": [0.0, 0.0, 1.0, 1.0], "own_x_m": [0.0, 0.0, 1.0, 1.0],
                       "own_y_m": 0.0, "bearing_deg": 10.0, "track_id": [12, -3, 12, -3]})
    (one,) = _read(_write(df, tmp_path / "n.csv"))
    assert one.contacts.track.dtype == np.int64
    np.testing.assert_array_equal(one.contacts.track, [12, -3, 12, -3])


def test_times_ending_in_utc_are_utc(tmp_path):
    """``2025-06-01 08:00:00.5 UTC`` (as many loggers write it) is a UTC time, not a time
    without zone (whose suggestion was ``...UTCZ``)."""
    path = tmp_path / "utc.csv"
    path.write_text("timestamp_utc,lat,lon,bearing_deg\n2025-06-01 08:00:00.5 UTC,59.9,10.7,10\n"
                    "2025-06-01 08:00:01.5 UTC,59.9,10.7,11\n2025-06-01 08:00:02.5 utc,59.9,10.7,"
                    "12\n")
    (one,) = _read(path)
    assert one.contacts.epoch_utc_ns == EPOCH_NS + 500_000_000
    np.testing.assert_allclose(one.contacts.t_s, [0.0, 1.0, 2.0])
    assert any("' UTC' read as the zone Z" in n for n in one.notes)


def test_a_time_pattern_without_a_year_is_refused_with_a_pattern_that_works(tmp_path):
    """A clock of the time of day alone (strptime reads it as on 1900-01-01, and it wraps
    at midnight) is refused in one line naming a pattern with the date, which reads."""
    text = "time,lat,lon,bearing_deg\n{},59.9,10.7,10\n{},59.9,10.71,11\n{},59.9,10.72,12\n"
    clock = tmp_path / "clock.csv"
    clock.write_text(text.format("23:59:50", "00:00:00", "00:00:10"))
    with pytest.raises((InputError, ValueError), match=r"no year in it.*'%Y-%m-%d %H:%M:%S'"):
        _read(clock, time={"format": "%H:%M:%S", "zone": "UTC"})
    dated = tmp_path / "dated.csv"
    dated.write_text(text.format("2025-09-14 23:59:50", "2025-09-15 00:00:00",
                                 "2025-09-15 00:00:10"))
    (one,) = _read(dated, time={"format": "%Y-%m-%d %H:%M:%S", "zone": "UTC"})
    np.testing.assert_allclose(one.contacts.t_s, [0.0, 10.0, 20.0])
