"""AIS as ground truth (issue 31, items 1, 2 and 4): the AIS of a sea trial read from the common
exports and from raw NMEA, its ships matched to the trial's contacts, the truth held against
an independent reference (``tests/data/ais/build_cases.py``: geodesic geometry between
positions interpolated in latitude/longitude), the trial's table, map and Python API scored
against it, and bad input refused in one line with nothing written."""

import json
from functools import reduce
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.conftest import data_paths, plain_messages, run_stage_here
from tests.families.bearings2d import ais_trial
from tma.ais.options import TruthError, TruthFileNotFound
from tma.ais.reports import read_reports

QUIET = ["progress=false", "parallel=serial"]


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    return ais_trial.write_trial(tmp_path_factory.mktemp("trial"))


@pytest.fixture(scope="module")
def reports():
    return ais_trial.ais_reports()


def _checksum(body: str) -> str:
    return f"{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def _as_reports(frame):
    return frame.sort_values(["mmsi", "t_s"], kind="stable").reset_index(drop=True)


# -- reading the AIS ---------------------------------------------------------------------------

def _exports(reports, d: Path) -> dict:
    """The same reports as the common exports write them."""
    t = pd.to_datetime(reports.t_s * 1e9, utc=True)
    out = {}
    ais_trial.write_ais_csv(d / "stone_soup.csv", reports)
    out["stone_soup.csv"] = 1e-3
    pd.DataFrame({"# Timestamp": t.dt.strftime("%d/%m/%Y %H:%M:%S"),  # whole seconds
                  "Type of mobile": "Class A", "MMSI": reports.mmsi,
                  "Latitude": reports.lat_deg, "Longitude": reports.lon_deg,
                  "Navigational status": "Under way using engine"}).to_csv(d / "dma.csv",
                                                                          index=False)
    out["dma.csv"] = 1.0
    pd.DataFrame({"MMSI": reports.mmsi, "BaseDateTime": t.dt.strftime("%Y-%m-%dT%H:%M:%S"),
                  "LAT": reports.lat_deg, "LON": reports.lon_deg, "SOG": reports.sog_kn,
                  "VesselName": "X"}).to_csv(d / "marinecadastre.csv", index=False)
    out["marinecadastre.csv"] = 1.0
    reports.assign(timestamp_utc=t.dt.strftime("%Y-%m-%dT%H:%M:%S.%fZ"))[
        ["mmsi", "timestamp_utc", "lat_deg", "lon_deg"]].to_csv(d / "tma.csv.gz", index=False)
    out["tma.csv.gz"] = 1e-6
    lines = ais_trial.nmea_lines(reports)
    (d / "tagged.nmea").write_text("\n".join(lines) + "\n")
    out["tagged.nmea"] = 1e-3
    # a leading ISO time, and a trailing Unix time, instead of the tag block
    iso = t.dt.strftime("%Y-%m-%d %H:%M:%S.%f").str[:-3]
    plain = [line.split("\\")[-1] for line in lines if ",1,1," in line]
    (d / "leading.txt").write_text("".join(f"{a} {b}\n" for a, b in zip(iso, plain,
                                                                         strict=True)))
    out["leading.txt"] = 1e-3
    (d / "trailing.log").write_text("".join(f"{b},{s:.3f}\n" for b, s in zip(
        plain, reports.t_s, strict=True)))
    out["trailing.log"] = 1e-3
    return out


def test_the_common_exports_and_raw_nmea_give_the_same_reports(reports, tmp_path):
    expected = _as_reports(reports)
    for name, time_tol in _exports(reports, tmp_path).items():
        got = read_reports(tmp_path / name)
        assert len(got) == len(expected), name
        assert got.kind == ("nmea" if name.endswith((".nmea", ".txt", ".log")) else "csv")
        assert (got.mmsi == expected.mmsi.to_numpy()).all(), name
        # times: as written (DMA and MarineCadastre write whole seconds)
        assert np.abs(got.t_ns / 1e9 - expected.t_s.to_numpy()).max() <= time_tol + 1e-5, name
        # NMEA holds positions in 1/10000 minute (0.19 m)
        pos_tol = 1e-4 / 60 if got.kind == "nmea" else 1e-9
        assert np.abs(got.lat_deg - expected.lat_deg.to_numpy()).max() <= pos_tol, name
        assert np.abs(got.lon_deg - expected.lon_deg.to_numpy()).max() <= pos_tol, name
        assert got.dropped.count == 0, (name, got.dropped.text())


def _sentence(payload: str, fragments=1, number=1, seq="", fill=0, talker="AI") -> str:
    body = f"{talker}VDM,{fragments},{number},{seq},A,{payload},{fill}"
    return f"!{body}*{_checksum(body)}"


def _payload(fields: dict) -> tuple[str, int]:
    from pyais.encode import encode_dict

    (sentence,) = encode_dict(fields, talker_id="AI", sentence_type="VDM")
    parts = sentence.split(",")
    return parts[5], int(parts[6].split("*")[0])


def test_nmea_class_a_b_long_range_multipart_and_bad_sentences_counted(tmp_path):
    """Position reports of types 1, 2, 3, 18, 19 and 27 are read; a position report split
    over two sentences is assembled; type 5 (two parts) is counted, not used; a bad
    checksum, a part missing, a sentence without a time, 'not available' positions and
    garbage are left out and counted with their lines."""
    t0 = 1452605000
    lines, expected = [], []
    for k, kind in enumerate((1, 2, 3, 18, 19, 27)):
        lat, lon = 50.7 + k / 100, -1.1 - k / 100
        payload, fill = _payload({"type": kind, "mmsi": 235000000 + k, "lat": lat, "lon": lon})
        lines.append(f"\\c:{t0 + k}*{_checksum(f'c:{t0 + k}')}\\{_sentence(payload, fill=fill)}")
        expected.append((235000000 + k, t0 + k, lat, lon, 1e-4 / 60 if kind != 27 else 0.1 / 60))
    # a class B extended report (type 19) split over two sentences
    payload, fill = _payload({"type": 19, "mmsi": 235000099, "lat": 50.9, "lon": -1.3})
    half = len(payload) // 2
    lines += [f"{t0 + 10} {_sentence(payload[:half], 2, 1, 7)}",
              f"{t0 + 10} {_sentence(payload[half:], 2, 2, 7, fill)}"]
    expected.append((235000099, t0 + 10, 50.9, -1.3, 1e-4 / 60))
    from pyais.encode import encode_dict

    static = encode_dict({"type": 5, "mmsi": 235000001, "shipname": "TRIAL"}, talker_id="AI",
                         sentence_type="VDM", seq_id=3)
    lines += [f"{t0 + 11} {s}" for s in static]  # two parts: counted, not a position
    bad = _sentence(_payload({"type": 1, "mmsi": 235000050, "lat": 50.0, "lon": -1.0})[0])
    lines += [f"{t0 + 12} {bad[:-2]}00",  # bad checksum (line 11)
              f"{t0 + 13} {_sentence(payload[:half], 2, 1, 8)}",  # its second part missing
              _sentence(_payload({"type": 1, "mmsi": 235000051, "lat": 50.0, "lon": -1.0})[0]),
              f"{t0 + 15} {_sentence(_payload({'type': 1, 'mmsi': 235000052, 'lat': 91, 'lon': 181})[0])}",  # noqa: E501
              "garbage"]
    (tmp_path / "ais.nmea").write_text("\n".join(lines) + "\n")
    got = read_reports(tmp_path / "ais.nmea")
    assert len(got) == len(expected)
    for (mmsi, t, lat, lon, tol) in expected:
        (k,) = np.flatnonzero(got.mmsi == mmsi)
        assert got.t_ns[k] == t * 10**9
        assert abs(got.lat_deg[k] - lat) <= tol and abs(got.lon_deg[k] - lon) <= tol, mmsi
    reasons = got.dropped.reasons
    assert reasons["bad checksum"] == {"count": 1, "first": ["line 11"]}
    assert reasons["multi-part message missing a part"] == {"count": 1, "first": ["line 12"]}
    assert reasons["no time stamp"] == {"count": 1, "first": ["line 13"]}
    assert reasons["position not available (lat 91, lon 181)"]["first"] == ["line 14"]
    assert reasons["not a readable AIS sentence"]["first"] == ["line 15"]
    assert any("1 of type 5" in note for note in got.notes), got.notes


# -- the truth of the trial against an independent reference -----------------------------------

def test_each_contact_is_matched_by_its_bearings_and_its_truth_is_the_reference(trial):
    """Automatic matching finds each contact's ship (RMS about the bearings' 0.5 deg noise,
    every other ship far off), and the truth at the last bearing is build_cases' (geodesic
    range and bearing, the last 120 s's geodesic course and speed) within what the two
    geometries differ by: the map's meridian convergence (< 0.05 deg) and centimetres."""
    import tma

    bc = ais_trial.cases_module()
    reference = bc.build_cases(cases=[bc.CASES[n - 1] for n in ais_trial.CASES])[1]
    for name in ("trial_ais.csv", "trial_ais.nmea"):
        rec = tma.read_log(trial / "trial.csv", truth=trial / name)
        matches = rec.matches.set_index("label")
        for label, mmsi in ais_trial.TRUTH.items():
            m = matches.loc[label]
            assert (m.mmsi, m.how, m.verdict) == (mmsi, "bearings", "matched"), m.note
            assert 0.4 < m.rms_deg < 0.6 and m.runner_up["rms_deg"] > 10, m.note
        truth = rec.truth.set_index("label")
        for k, label in enumerate(ais_trial.TRUTH):
            ref = reference.iloc[k]
            got = truth.loc[label]
            assert got.mmsi == ref.target_mmsi
            assert abs(got.range_now_m - ref.range_m) < 0.5, (name, got.range_now_m, ref.range_m)
            assert abs((got.bearing_now_deg - ref.bearing_deg + 180) % 360 - 180) < 0.05
            assert abs((got.course_deg - ref.course_deg + 180) % 360 - 180) < 0.1
            assert abs(got.speed_m_s - ref.speed_m_s) < 2e-3 * ref.speed_m_s
            assert abs(got.lat_now_deg - ref.target_lat_deg) < 1e-5
            assert abs(got.lon_now_deg - ref.target_lon_deg) < 1e-5


def _with_reports(trial: Path, d: Path, change) -> Path:
    """``trial_ais.csv`` with its reports changed by ``change(reports) -> reports``."""
    reports = change(ais_trial.ais_reports())
    ais_trial.write_ais_csv(d / "ais.csv", reports)
    return d / "ais.csv"


def test_an_ambiguous_match_is_said_and_a_given_match_settles_it(trial, tmp_path):
    """A second ship sailing 20 m beside T1's fits its bearings as well: T1 gets no truth and
    the line says both MMSIs and how to choose; truth.match chooses."""
    import tma

    def twin(reports):
        t1 = reports[reports.mmsi == ais_trial.TRUTH["T1"]]
        return pd.concat([reports, t1.assign(mmsi=235999999, lat_deg=t1.lat_deg + 2e-4)])

    ais = _with_reports(trial, tmp_path, twin)
    rec = tma.read_log(trial / "trial.csv", truth=ais)
    m = rec.matches.set_index("label").loc["T1"]
    assert m.verdict == "ambiguous" and pd.isna(m.mmsi)
    assert "235031618" in m.note and "235999999" in m.note and "truth.match={T1:" in m.note
    assert list(rec.truth["label"]) == ["T2"]
    rec = tma.read_log(trial / "trial.csv", truth={"file": ais, "match": {"T1": 235031618}})
    assert list(rec.matches["verdict"]) == ["given", "matched"]
    assert list(rec.truth["label"]) == ["T1", "T2"]


def test_a_gap_in_the_ais_refuses_that_contact_with_the_reason(trial, tmp_path):
    import tma

    def gap(reports):
        t = reports.t_s - reports.t_s.min()
        hole = (reports.mmsi == ais_trial.TRUTH["T2"]) & (t > 1000) & (t < 1150)
        return reports[~hole]

    rec = tma.read_log(trial / "trial.csv", truth=_with_reports(trial, tmp_path, gap))
    m = rec.matches.set_index("label").loc["T2"]
    assert m.verdict == "gap" and m.mmsi == ais_trial.TRUTH["T2"]
    assert "gap of 200 s at 2016-01-12T13:44:20Z" in m.note and "truth.max_gap_s = 90 s" in m.note
    assert list(rec.truth["label"]) == ["T1"]
    rec = tma.read_log(trial / "trial.csv", truth={"file": str(tmp_path / "ais.csv"),
                                                   "max_gap_s": 250})
    assert list(rec.truth["label"]) == ["T1", "T2"]


# -- the trial's table, map and Python API -----------------------------------------------------

def test_the_trial_table_scores_each_contact_and_the_map_shows_its_ship(trial, tmp_path,
                                                                       monkeypatch):
    import tma

    monkeypatch.chdir(trial)
    paths = data_paths(tmp_path)
    run_stage_here("table", "input=trial.csv", "truth=trial_ais.nmea", "name=trial", *paths,
                   *QUIET)
    table = pd.read_csv(tmp_path / "tables" / "trial-lm.csv")
    assert list(table["label"]) == ["T1", "T2"]
    assert list(table["truth_mmsi"]) == list(ais_trial.TRUTH.values())
    # (T2's course sd is 32 deg: its position, not its heading, is the answer)
    assert list(table["status"]) == ["ok", "position_only"] and table["covered"].all()
    # z = error / sd, error = estimate - truth
    for q, est, sd in (("range", "range_now_m", "range_sd_m"), ("course", "course_deg",
                                                                "course_sd_deg")):
        unit = "m" if q == "range" else "deg"
        err = table[f"{q}_err_{unit}"]
        truth = table[f"true_{q}_{unit}"]
        assert np.allclose(((table[est] - truth + 180) % 360 - 180) if unit == "deg"
                           else table[est] - truth, err, equal_nan=True)
        assert np.allclose(err / table[sd], table[f"{q}_z"], equal_nan=True)
    md = (tmp_path / "tables" / "trial-lm.md").read_text()
    assert "1 of the 1 `ok` ones are covered" in md and "against the AIS of its trial" in md
    # in units of the answer's own intervals: |z| <= 2 exactly where the truth is inside
    # [a, b] (the AIS is dense: no truth uncertainty to fold in)
    for q, unit in (("range", "m"), ("course", "deg"), ("speed", "m_s")):
        lo, hi, truth = (table[f"{q}_lo2_{unit}"], table[f"{q}_hi2_{unit}"],
                         table[f"true_{q}_{unit}"])
        shown = table[f"{q}_iz"].notna()
        inside = ((truth - lo) % 360 <= (hi - lo) % 360) if q == "course" else (
            (lo <= truth) & (truth <= hi))
        assert shown.any() and ((table[f"{q}_iz"].abs() <= 2) == inside)[shown].all(), q
    assert "z in [a, b] range / course / speed" in md
    manifest = json.loads((tmp_path / "data" / "datasets" / "trial" / "manifest.json")
                          .read_text())
    assert manifest["truth"]["kind"] == "nmea" and manifest["truth"]["with_truth"] == 2
    assert set(manifest["files"]) == {"truth.parquet", "truth_track.parquet"}
    # the map: each contact's AIS track beside its estimate, at its bearing times
    messages = plain_messages(tmp_path / "tables" / "trial-lm.mcap")
    topics = {ch.topic for ch, _, _ in messages}
    assert {"/tma/truth/T1", "/tma/truth/T2", "/tma/estimate/T1"} <= topics
    track = pd.read_parquet(tmp_path / "data" / "datasets" / "trial" / "truth_track.parquet")
    fixes = [f for ch, _, f in messages if ch.topic == "/tma/truth/T2"]
    t2 = track[track.track_id == 1]
    assert len(fixes) == len(t2)
    assert np.allclose([f["latitude"] for f in fixes], t2.lat_deg)
    # the Python API returns the same columns
    results = tma.estimate(tma.read_log("trial.csv", truth="trial_ais.nmea"))
    for column in ("truth_mmsi", "true_range_m", "range_z", "course_z", "speed_z", "range_iz",
                   "course_iz", "speed_iz", "nees"):
        assert np.allclose(results[column].astype(float), table[column], equal_nan=True), column
    assert list(results["covered"]) == list(table["covered"])


# -- bad input: one line, nothing written ------------------------------------------------------

def _shifted(trial, d, **shift):
    def change(reports):
        return reports.assign(t_s=reports.t_s + shift.get("seconds", 0.0),
                              lat_deg=reports.lat_deg + shift.get("lat", 0.0))
    return _with_reports(trial, d, change).name


BAD = {
    "other times": (lambda trial, d: [f"truth={_shifted(trial, d, seconds=86400.0)}"],
                    "AIS of another time"),
    "another place": (lambda trial, d: [f"truth={_shifted(trial, d, lat=5.0)}"],
                      "AIS of another place"),
    "a given MMSI far away": (
        lambda trial, d: [f"truth={_with_reports(trial, d, lambda r: pd.concat([r, r[r.mmsi == 247007000].assign(mmsi=211000001, lat_deg=r.lat_deg + 2.0)])).name}",  # noqa: E501
                          "truth.match={T1:211000001}"],
        "MMSI 211000001 never comes within 100 km"),
    "a given MMSI that does not fit": (
        lambda trial, d: ["truth=trial_ais.csv", "truth.match={T1:247007000}"],
        "MMSI 247007000 does not fit contact T1's bearings"),
    "a given MMSI not in the file": (
        lambda trial, d: ["truth=trial_ais.csv", "truth.match={T1:211000002}"],
        "MMSI 211000002 (contact T1) has no position report"),
    "a given contact not in the log": (
        lambda trial, d: ["truth=trial_ais.csv", "truth.match={T9:211000002}"],
        "names contact T9, which"),
    "corrupt sentences": (
        lambda trial, d: [f"truth={_corrupt(trial, d)}"], "no AIS position report could be read"),
    "the bearing log as truth": (lambda trial, d: ["truth=trial.csv"],
                                 "not AIS position reports: no mmsi column"),
    "own-ship NMEA as truth": (lambda trial, d: [f"truth={_gga(d)}"],
                               "NMEA without AIS sentences"),
    "an MCAP as truth": (lambda trial, d: [f"truth={_mcap(d)}"], "an MCAP log, not AIS"),
    "no such file": (lambda trial, d: ["truth=nowhere.csv"], "nowhere.csv: no such file"),
    "a bad match value": (lambda trial, d: ["truth=trial_ais.csv", "truth.match={T1:abc}"],
                          "truth.match"),
    "a bad bound": (lambda trial, d: ["truth=trial_ais.csv", "truth.max_gap_s=-1"],
                    "truth.max_gap_s must be in (0, 1e6)"),
}


def _corrupt(trial, d):
    lines = (trial / "trial_ais.nmea").read_text().splitlines()
    (d / "corrupt.nmea").write_text("\n".join(line[:-2] + "00" if line[-2:] != "00" else
                                              line[:-2] + "01" for line in lines) + "\n")
    return "corrupt.nmea"


def _gga(d):
    (d / "gps.nmea").write_text("$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M"
                                ",,*47\n")
    return "gps.nmea"


def _mcap(d):
    (d / "log.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(100))
    return "log.mcap"


@pytest.mark.parametrize("case", list(BAD))
def test_bad_truth_is_one_line_and_nothing_is_written(case, trial, tmp_path, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    for name in ("trial.csv", "trial_ais.csv"):
        (work / name).write_bytes((trial / name).read_bytes())
    (work / "trial_ais.nmea").write_bytes((trial / "trial_ais.nmea").read_bytes())
    make, expected = BAD[case]
    arguments = make(trial, work)
    monkeypatch.chdir(work)
    for verb in ("ingest", "table"):
        proc = run_stage_here(verb, "input=trial.csv", *arguments, *data_paths(tmp_path),
                              *QUIET, check=False)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), (
            verb, proc.stderr)
        assert expected in lines[0], lines[0]
        assert not list((tmp_path / "data" / "datasets").glob("*/manifest.json"))
        assert not (tmp_path / "tables").exists()


def test_in_python_bad_truth_is_a_value_error_or_file_not_found(trial, tmp_path):
    import tma

    with pytest.raises(ValueError, match="AIS of another time"):
        tma.read_log(trial / "trial.csv", truth=tmp_path / _shifted(trial, tmp_path,
                                                                     seconds=86400.0))
    with pytest.raises(FileNotFoundError, match="no such file"):
        tma.read_log(trial / "trial.csv", truth=tmp_path / "nowhere.csv")
    with pytest.raises(TruthError):
        read_reports(trial / "trial.csv")
    assert issubclass(TruthFileNotFound, FileNotFoundError)


def test_a_log_without_utc_or_lat_lon_cannot_be_scored(trial, tmp_path):
    import tma

    export = pd.read_csv(trial / "trial.csv")
    t = pd.to_datetime(export.timestamp_utc)
    export.assign(timestamp_utc=(t - t.min()).dt.total_seconds()).to_csv(
        tmp_path / "relative.csv", index=False)
    with pytest.raises(ValueError, match="needs UTC times"):
        tma.read_log(tmp_path / "relative.csv", truth=trial / "trial_ais.csv")
