"""A sea-trial kit (issue 38): logs and AIS as real exports write them, own-ship from its AIS,
a campaign in one command. The trial is ``tests/families/bearings2d/ais_trial.py``'s (the
Solent recording, two contacts, 0.5 deg noise); each test changes what a real export would
change and checks what tma reads against what was written."""

import numpy as np
import pandas as pd
import pytest

from tests.conftest import data_paths, run_stage_here
from tests.families.bearings2d import ais_trial
from tma.ais.reports import read_reports

QUIET = ["progress=false", "parallel=serial"]


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    return ais_trial.write_trial(tmp_path_factory.mktemp("trial"))


def _sparse(reports: pd.DataFrame, every_s: float) -> pd.DataFrame:
    """Each ship's reports thinned to one per ``every_s`` (a satellite AIS's)."""
    slot = np.floor((reports.t_s - reports.t_s.min()) / every_s)
    return reports[~pd.DataFrame({"m": reports.mmsi, "s": slot}).duplicated()]


# -- item 7: the small fixes -------------------------------------------------------------------

def test_sparse_ais_is_refused_naming_truth_max_gap_s_and_a_value_that_works(trial, tmp_path,
                                                                             monkeypatch):
    """Ships reported every 5 minutes: every contact is matched, none has a truth under the
    90 s bound; the one line names truth.max_gap_s and a value, which then works (from the
    command line, and dotted in Python as the reader's options are)."""
    import tma

    ais_trial.write_ais_csv(tmp_path / "sparse.csv", _sparse(ais_trial.ais_reports(), 300.0))
    with pytest.raises(ValueError, match=r"truth\.max_gap_s=(\d+) to take") as caught:
        tma.read_log(trial / "trial.csv", truth=tmp_path / "sparse.csv")
    value = int(caught.value.args[0].split("truth.max_gap_s=")[1].split()[0])
    assert 300 <= value <= 620, caught.value
    rec = tma.read_log(trial / "trial.csv", truth=tmp_path / "sparse.csv",
                       options={"truth.max_gap_s": value})
    assert list(rec.truth["label"]) == ["T1", "T2"]
    rec = tma.read_log(trial / "trial.csv", options={"truth.file": str(tmp_path / "sparse.csv"),
                                                     "truth.max_gap_s": value})
    assert list(rec.truth["label"]) == ["T1", "T2"]
    monkeypatch.chdir(trial)
    proc = run_stage_here("ingest", "input=trial.csv", f"truth={tmp_path / 'sparse.csv'}",
                          *data_paths(tmp_path), *QUIET, check=False)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert f"set truth.max_gap_s={value}" in lines[0]


def test_nmea_sentences_that_are_not_ais_are_counted_as_such(tmp_path):
    """A satellite receiver's ``$PGHP`` lines and own-ship's ``$GPRMC`` between the
    ``!AIVDM`` sentences are NMEA of another kind, noted as such; only the garbage line is
    'not a readable AIS sentence'."""
    reports = ais_trial.ais_reports().head(20)
    lines = ais_trial.nmea_lines(reports)
    other = ["$PGHP,1,2016,1,12,13,28,0,0,219,1,,1,,*2A",
             "$GPRMC,132800,A,5047.500,N,00106.300,W,5.0,90.0,120116,,*1D"]
    (tmp_path / "sat.nmea").write_text("\n".join(lines[:10] + other * 3 + lines[10:]
                                                 + ["garbage"]) + "\n")
    got = read_reports(tmp_path / "sat.nmea")
    assert len(got) == 20
    assert got.dropped.reasons["not a readable AIS sentence"]["count"] == 1
    assert any("6 NMEA sentence(s) that are not AIS" in n and "3 $PGHP" in n
               and "3 $GPRMC" in n for n in got.notes), got.notes


# -- item 6: ids as written, from frames too ---------------------------------------------------

def test_a_frame_whose_ids_are_floats_says_that_two_ids_may_be_one(trial):
    """Contacts 7 and 7.0 mixed in a frame: pandas makes the column float64, where they are
    one number; the refusal says so and how to keep them apart, and the ids as text are two
    contacts, as in a CSV."""
    import tma

    frame = pd.read_csv(trial / "trial.csv")
    ids = np.where(frame.contact == "T1", 7, 7.0).astype(object)
    ids[frame.contact.to_numpy() == "T1"] = 7  # the Python int 7 and the float 7.0
    mixed = frame.assign(contact=pd.Series(list(ids)).astype(float))
    with pytest.raises(ValueError, match=r"holds floats .*7 and 7\.0 are one number.*as text"):
        tma.Recording.from_frames(mixed)
    apart = frame.assign(contact=pd.Series(list(ids), dtype=object))
    rec = tma.Recording.from_frames(apart)
    assert sorted(rec.bearings["label"].unique()) == ["7", "7.0"]
    assert any("alike but written differently" in n for n in rec.notes), rec.notes


def test_truth_options_dotted_in_python_are_those_of_the_command_line(trial):
    import tma

    with pytest.raises(ValueError, match="unknown option truth.nothing"):
        tma.read_log(trial / "trial.csv", truth=trial / "trial_ais.csv",
                     options={"truth.nothing": 1})
    rec = tma.read_log(trial / "trial.csv", truth=trial / "trial_ais.csv",
                       options={"truth.match": {"T1": 235031618}})
    assert list(rec.matches["how"]) == ["given", "bearings"]


# -- item 2: times as written ------------------------------------------------------------------

def _local_log(trial, d, zone="Europe/Madrid", pattern="%d-%m-%y %H:%M:%S"):
    """The trial's log with its times as a local clock writes them: day first, two-digit
    year, no zone, a column named in Spanish."""
    log = pd.read_csv(trial / "trial.csv")
    utc = pd.to_datetime(log.pop("timestamp_utc"), utc=True)
    log.insert(0, "Fecha", utc.dt.tz_convert(zone).dt.strftime(pattern))
    log.to_csv(d / "local.csv", index=False)
    return d / "local.csv", utc


def test_a_local_time_log_is_read_by_its_pattern_and_zone(trial, tmp_path):
    """14:33 in Madrid (CET, +01:00, in January) is 13:33 UTC: the bearings' UTC times are
    those written, from the command's options and the API's."""
    import tma

    path, utc = _local_log(trial, tmp_path)
    with pytest.raises(ValueError, match=r"'12-01-16 14:33:00' on line 2 has no time zone.*"
                                         r"time\.zone="):
        tma.read_log(path, columns={"time": "Fecha"}, time={"format": "%d-%m-%y %H:%M:%S"})
    with pytest.raises(ValueError, match=r"time\.format='%Y/%m/%d %H:%M' matches no time of "
                                         r"column Fecha \(line 2: '12-01-16 14:33:00'\)"):
        tma.read_log(path, columns={"time": "Fecha"},
                     time={"format": "%Y/%m/%d %H:%M", "zone": "Europe/Madrid"})
    with pytest.raises(ValueError, match="time.zone=Mars/Olympus: no such IANA time zone"):
        tma.read_log(path, options={"time.zone": "Mars/Olympus"})
    rec = tma.read_log(path, options={"columns.time": "Fecha", "time.format": "%d-%m-%y %H:%M:%S",
                                      "time.zone": "Europe/Madrid"})
    got = rec.bearings.sort_values(["t_s", "label"])["time_utc"].reset_index(drop=True)
    want = utc.sort_values().reset_index(drop=True)
    assert (got == want).all()
    assert rec.start_utc == "2016-01-12T13:33:00Z"


def test_daylight_saving_repeats_and_gaps_are_refused_or_resolved_as_said():
    """Madrid's clocks went back at 03:00 CEST on 27 October 2019 (02:30 happened twice: at
    00:30 and 01:30 UTC) and forward at 02:00 CET on 31 March 2019 (02:30 never happened:
    00:30 UTC by the summer offset, 01:30 UTC by the winter one)."""
    import tma

    def frame(day, times):
        return pd.DataFrame({"time": [f"{day} {t}" for t in times],
                             "bearing_deg": np.arange(len(times), dtype=float),
                             "x": np.arange(len(times)) * 10.0, "y": 0.0})

    times = ["01:50", "02:30", "03:10", "03:30", "03:50"]
    both = {"earliest": "00:30", "latest": "01:30"}
    cases = {"27/10/2019": (times, "repeated when the clocks went back", both),
             "31/03/2019": (times, "skipped when the clocks went forward", both)}
    for day, (times, refusal, resolved) in cases.items():
        options = {"time.format": "%d/%m/%Y %H:%M", "time.zone": "Europe/Madrid",
                   "nav.max_gap_s": 1e5}
        with pytest.raises(ValueError, match=f"'{day} 02:30' on line 1 is a time of day in "
                                             f"Europe/Madrid {refusal}.*time.ambiguous="):
            tma.Recording.from_frames(frame(day, times), options=options)
        for how, hhmm in resolved.items():
            later = ["04:10", "04:30", "04:50", "05:10"]  # after the change: one instant each
            rec = tma.Recording.from_frames(frame(day, ["02:30", *later]),
                                            options={**options, "time.ambiguous": how})
            first = rec.bearings["time_utc"].iloc[0]
            iso = f"{day[6:]}-{day[3:5]}-{day[:2]}T{hhmm}:00Z"
            assert first == pd.Timestamp(iso), (day, how, first)


# -- item 1: AIS through the logs' table reader -------------------------------------------------

OTHER_NAMES = {"time": "Zeit", "mmsi": "Schiff", "lat": "Breite", "lon": "Laenge",
               "sog": "Fahrt"}
LOCAL = "%d-%m-%y %H:%M:%S"


def _other_export(reports: pd.DataFrame, path):
    """The reports as an export of another country writes them: its own column names, ';'
    between fields, a decimal comma, local (Madrid) times day first with a two-digit year,
    speed in knots."""
    utc = pd.to_datetime(np.round(reports.t_s) * 1e9, utc=True)
    pd.DataFrame({"Zeit": utc.dt.tz_convert("Europe/Madrid").dt.strftime(LOCAL),
                  "Schiff": reports.mmsi, "Breite": reports.lat_deg,
                  "Laenge": reports.lon_deg, "Fahrt": reports.sog_kn,
                  "Name": "X"}).to_csv(path, sep=";", decimal=",", index=False)
    return path


def _table_options(prefix="truth."):
    return {**{f"{prefix}columns.{r}": c for r, c in OTHER_NAMES.items()},
            f"{prefix}time.format": LOCAL, f"{prefix}time.zone": "Europe/Madrid"}


def test_an_ais_export_with_other_names_times_and_layout_is_read_by_its_options(trial,
                                                                             tmp_path):
    """Refused naming the options that fix it; read with them, the reports are those written
    (times to the second, positions exactly, SOG from knots to m/s), and the trial's contacts
    are matched to their ships as from the Stone Soup file."""
    import tma
    from tma.ais.options import truth_options

    reports = ais_trial.ais_reports()
    path = _other_export(reports, tmp_path / "export.csv")
    with pytest.raises(ValueError, match=r"no time or mmsi or lat or lon column among Zeit, "
                                         r"Schiff.*truth\.columns\.time=<name>"):
        read_reports(path)
    with pytest.raises(ValueError, match=r"Zeit '12-01-16 14:28:00' on line 2 is not a time "
                                         r"tma reads by itself.*truth\.time\.format="):
        read_reports(path, truth_options({k: v for k, v in _table_options("").items()
                                          if "time." not in k} | {"file": str(path)}))
    got = read_reports(path, truth_options({"file": str(path), **_table_options("")}))
    want = reports.sort_values(["mmsi", "t_s"], kind="stable")
    assert got.kind == "csv" and len(got) == len(want) and got.dropped.count == 0
    assert (got.mmsi == want.mmsi.to_numpy()).all()
    assert np.abs(got.t_ns / 1e9 - np.round(want.t_s.to_numpy())).max() < 1e-6
    assert np.abs(got.lat_deg - want.lat_deg.to_numpy()).max() < 1e-12
    assert np.allclose(got.sog_m_s, want.sog_kn.to_numpy() * 1852 / 3600, equal_nan=True)
    rec = tma.read_log(trial / "trial.csv", truth=path, options=_table_options())
    assert dict(zip(rec.truth["label"], rec.truth["mmsi"], strict=True)) == ais_trial.TRUTH


def test_an_ais_parquet_is_read_as_its_csv(trial, tmp_path):
    reports = ais_trial.ais_reports()
    frame = pd.DataFrame({"BaseDateTime": pd.to_datetime(reports.t_s * 1e9, utc=True),
                          "MMSI": reports.mmsi, "LAT": reports.lat_deg,
                          "LON": reports.lon_deg, "SOG": reports.sog_kn})
    frame.to_parquet(tmp_path / "ais.parquet")
    got = read_reports(tmp_path / "ais.parquet")
    csv = read_reports(trial / "trial_ais.csv")
    assert got.kind == "parquet" and len(got) == len(csv)
    assert (got.mmsi == csv.mmsi).all() and np.abs(got.t_ns - csv.t_ns).max() <= 10**6
    assert np.allclose(got.lat_deg, csv.lat_deg, rtol=0, atol=1e-9)


def test_the_command_reads_an_ais_export_by_its_options(trial, tmp_path, monkeypatch):
    monkeypatch.chdir(trial)
    path = _other_export(ais_trial.ais_reports(), tmp_path / "export.csv")
    options = [f"{k}={v}" if " " not in v else f"{k}='{v}'" for k, v in _table_options().items()]
    proc = run_stage_here("ingest", "input=trial.csv", f"truth={path}", "name=export", *options,
                          *data_paths(tmp_path), *QUIET, check=False)
    assert proc.returncode == 0, proc.stderr
    truth = pd.read_parquet(tmp_path / "data" / "datasets" / "export" / "truth.parquet")
    assert dict(zip(truth["label"], truth["mmsi"], strict=True)) == ais_trial.TRUTH
    proc = run_stage_here("ingest", "input=trial.csv", f"truth={path}", "name=export2",
                          *options[:4], *data_paths(tmp_path), *QUIET, check=False)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "truth.time.zone=" in lines[0], lines


# -- item 3: own-ship from its AIS -------------------------------------------------------------

def _bare_log(trial, d):
    """The trial's log as a sonar alone writes it: time, contact, bearing."""
    pd.read_csv(trial / "trial.csv")[["timestamp_utc", "contact", "bearing_deg"]].to_csv(
        d / "bare.csv", index=False)
    return d / "bare.csv"


def test_own_ship_from_its_ais_scores_a_log_of_bearings_alone(trial, tmp_path, monkeypatch):
    """``truth.own_mmsi``: own-ship is its AIS track (the trial's own-ship positions were
    built from it: they agree to centimetres), the contacts are scored as with the full log,
    and the table, the map and the manifest say where own-ship came from."""
    import json

    import tma

    bare = _bare_log(trial, tmp_path)
    ais = trial / "trial_ais.csv"
    with pytest.raises(ValueError, match=r"no own-ship position.*truth\.own_mmsi=<MMSI>"):
        tma.read_log(bare, truth=ais)
    with pytest.raises(ValueError, match=r"truth.own_mmsi=211000003: no position report of "
                                         r"MMSI 211000003 in truth="):
        tma.read_log(bare, truth={"file": ais, "own_mmsi": 211000003})
    own = {"truth.own_mmsi": ais_trial.OWN, "nav.max_gap_s": 30}
    rec = tma.read_log(bare, truth=ais, options=own)
    full = tma.read_log(trial / "trial.csv", truth=ais)
    assert np.abs(rec.ownship.lat_deg - full.ownship.lat_deg).max() * 111e3 < 0.05
    assert np.allclose(rec.truth.range_now_m, full.truth.range_now_m, rtol=0, atol=0.05)
    assert ais_trial.OWN not in set(rec.matches["mmsi"])
    # own-ship reports every ~10 s: under nav.max_gap_s = 10 s the bearings in its longer
    # gaps are left out and counted, never interpolated across
    strict = tma.read_log(bare, truth=ais, options={"truth.own_mmsi": ais_trial.OWN})
    assert len(strict.bearings) < len(rec.bearings) == len(full.bearings)
    assert "own-ship's AIS longer than nav.max_gap_s" in json.dumps(strict.dropped)
    monkeypatch.chdir(tmp_path)
    run_stage_here("table", "input=bare.csv", f"truth={ais}",
                   f"truth.own_mmsi={ais_trial.OWN}", "nav.max_gap_s=30", "name=bare",
                   *data_paths(tmp_path), *QUIET)
    table = pd.read_csv(tmp_path / "tables" / "bare-lm.csv")
    assert list(table["truth_mmsi"]) == list(ais_trial.TRUTH.values()) and table.covered.all()
    md = (tmp_path / "tables" / "bare-lm.md").read_text()
    assert f"own-ship: AIS of MMSI {ais_trial.OWN} in {ais}" in md
    manifest = json.loads((tmp_path / "data" / "datasets" / "bare" / "manifest.json")
                          .read_text())
    assert manifest["navigation"]["kind"] == "ais"
    assert manifest["navigation"]["mmsi"] == ais_trial.OWN
    from mcap.reader import make_reader

    with open(tmp_path / "tables" / "bare-lm.mcap", "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert f"MMSI {ais_trial.OWN}" in json.dumps(meta)


def test_own_ship_from_ais_says_it_leaves_the_logs_own_positions_aside(trial, tmp_path,
                                                                         caplog):
    """A log with own-ship columns found without being named, scored with ``truth.own_mmsi``:
    the AIS's own-ship is used and a warning says the log's positions are left aside (named
    columns are refused in one line); a frame with ``truth.own_mmsi`` is
    told that this is a file's option, never told to give it; a campaign of a DataFrame is one
    line."""
    import logging

    import tma

    ais = trial / "trial_ais.csv"
    with caplog.at_level(logging.WARNING):
        tma.read_log(trial / "trial.csv", truth=ais,
                     options={"truth.own_mmsi": ais_trial.OWN, "nav.max_gap_s": 30})
    assert any("the log's own-ship positions are left aside (drop truth.own_mmsi"
               in r.getMessage() for r in caplog.records), caplog.text
    frame = pd.read_csv(_bare_log(trial, tmp_path))
    with pytest.raises((TypeError, ValueError), match=r"takes own-ship from the AIS for a log "
                                                      r"file \(tma\.read_log") as err:
        tma.estimate(frame, truth=ais, options={"truth.own_mmsi": ais_trial.OWN})
    assert "give it" not in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ValueError, match=r"no own-ship position") as err:
        tma.Recording.from_frames(frame, truth=ais)
    assert "truth.own_mmsi" not in str(err.value)
    with pytest.raises(TypeError, match=r"campaign takes a folder or a glob of log files, got "
                                        r"DataFrame; a DataFrame is scored by tma\.estimate"):
        tma.campaign(frame, truth=ais)


def test_own_ship_ais_too_sparse_for_nav_max_gap_s_is_one_line(trial, tmp_path):
    import tma

    ais_trial.write_ais_csv(tmp_path / "sparse.csv", _sparse(ais_trial.ais_reports(), 60.0))
    with pytest.raises(ValueError, match=r"every bearing lies in a gap of own-ship's AIS.*set "
                                         r"nav\.max_gap_s=(\d+) to interpolate"):
        tma.read_log(_bare_log(trial, tmp_path), truth=tmp_path / "sparse.csv",
                     options={"truth.own_mmsi": ais_trial.OWN})


# -- item 4: a campaign in one command -----------------------------------------------------------

def _campaign(trial, d):
    """Three logs in a folder, each with its AIS beside it: the trial (CSV AIS), the trial
    again with the NMEA AIS, and a log whose bearings are 20 deg off (no ship fits: not
    scored, said)."""
    logs = d / "logs"
    logs.mkdir()
    log = pd.read_csv(trial / "trial.csv")
    log.to_csv(logs / "t1.csv", index=False)
    (logs / "t1_ais.csv").write_bytes((trial / "trial_ais.csv").read_bytes())
    log.to_csv(logs / "t2.csv", index=False)
    (logs / "t2_ais.nmea").write_bytes((trial / "trial_ais.nmea").read_bytes())
    log.assign(bearing_deg=(log.bearing_deg + 20) % 360).to_csv(logs / "off.csv", index=False)
    (logs / "off_ais.csv").write_bytes((trial / "trial_ais.csv").read_bytes())
    return logs


def _wilson(k, n, z=1.959963984540054):
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def test_a_campaign_pools_each_logs_verdicts_in_one_table(trial, tmp_path, monkeypatch):
    """Each log's own table as ``input=LOG`` writes it, and the campaign's: per log and
    pooled, the counts and z-scores of each log's own scores, the covered share with its
    Wilson interval; the log no ship fits is not scored and says why. The API returns the
    same table."""
    import tma

    logs = _campaign(trial, tmp_path)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match=r"log t3\.csv has no AIS: name it t3_ais\.csv"):
        (logs / "t3.csv").write_bytes((logs / "t1.csv").read_bytes())
        tma.campaign(logs)
    (logs / "t3.csv").unlink()
    table = tma.campaign(logs)
    assert list(table["log"]) == ["off.csv", "t1.csv", "t2.csv", "pooled"]
    off = table.set_index("log").loc["off.csv"]
    assert "no contact" in off.note and pd.isna(off.contacts)
    own = {name: tma.estimate(tma.read_log(logs / name, truth=logs / ais))
           for name, ais in (("t1.csv", "t1_ais.csv"), ("t2.csv", "t2_ais.nmea"))}
    pooled = pd.concat(own.values())
    for name, report in [*own.items(), ("pooled", pooled)]:
        row = table.set_index("log").loc[name]
        ok = report[(report.status == "ok") & report.covered.notna()]
        assert (row.contacts, row.ok, row.covered) == (len(report), len(ok),
                                                       int(ok.covered.sum()))
        assert np.isclose(row.range_z_mean, ok.range_z.mean())
        assert np.isclose(row.range_in_interval, np.mean(ok.range_iz.abs() <= 2))
        inside = int((ok.range_iz.abs() <= 2).sum())
        assert np.allclose([row.range_in_interval_lo, row.range_in_interval_hi],
                           _wilson(inside, int(ok.range_iz.notna().sum())))
        assert np.allclose([row.covered_lo, row.covered_hi], _wilson(row.covered, row.ok))
    proc = run_stage_here("table", "input=logs", *data_paths(tmp_path), *QUIET, check=False)
    assert proc.returncode == 0, proc.stderr
    tables = tmp_path / "tables"
    assert {"t1-lm.csv", "t2-lm.md", "logs-campaign-lm.md", "logs-campaign-lm.png"} <= {
        p.name for p in tables.iterdir()}
    written = pd.read_csv(tables / "logs-campaign-lm.csv")
    assert list(written["log"]) == list(table["log"])
    assert np.allclose(written["covered_share"], table["covered_share"], equal_nan=True)
    md = (tables / "logs-campaign-lm.md").read_text()
    assert "| `off.csv` | not scored: " in md and "(1 not scored)" in md


# -- item 7: the truth's own uncertainty where the AIS is sparse -------------------------------

def test_sparse_ais_truth_carries_its_own_uncertainty_into_z_and_covered(trial, tmp_path,
                                                                        monkeypatch):
    """Reports every 5 minutes: the truth at the last bearing is interpolated across a gap,
    its position sd per axis is a tau (T - tau) / 2 (from the gap's reports, read off the
    file independently), the z-scores divide by the estimate's and the truth's sd together,
    the normalised error shrinks against the exact truth's, and the table says so."""
    import tma

    sparse = _sparse(ais_trial.ais_reports(), 300.0)
    ais_trial.write_ais_csv(tmp_path / "sparse.csv", sparse)
    truth = {"file": tmp_path / "sparse.csv", "max_gap_s": 620}
    rec = tma.read_log(trial / "trial.csv", truth=truth)
    exact = tma.read_log(trial / "trial.csv", truth={**truth, "accel_sd_m_s2": 0})
    written = pd.to_datetime(pd.read_csv(tmp_path / "sparse.csv").Time, utc=True)
    for row in rec.truth.itertuples():
        t = pd.Timestamp(rec.start_utc) + pd.Timedelta(seconds=row.t_now_s)
        times = written[(sparse.mmsi == row.mmsi).to_numpy()].sort_values()
        before, after = times[times <= t].iloc[-1], times[times > t].iloc[0]
        tau, rest = (t - before).total_seconds(), (after - t).total_seconds()
        assert np.isclose(row.truth_pos_sd_m, 0.02 * tau * rest / 2, rtol=1e-6), row.label
        assert row.truth_vel_sd_m_s > 0.1  # its 120-s span lies in a 5-min gap
    assert (exact.truth.truth_pos_sd_m == 0).all()
    scored, plain = tma.estimate(rec), tma.estimate(exact)
    sd = np.hypot(scored.range_sd_m, scored.truth_pos_sd_m)
    assert np.allclose(scored.range_z, scored.range_err_m / sd)
    assert (scored.nees < plain.nees).all() and (plain.truth_pos_sd_m == 0).all()
    monkeypatch.chdir(trial)
    run_stage_here("table", "input=trial.csv", f"truth={tmp_path / 'sparse.csv'}",
                   "truth.max_gap_s=620", "name=sparse", *data_paths(tmp_path), *QUIET)
    md = (tmp_path / "tables" / "sparse-lm.md").read_text()
    assert "include the truth's own uncertainty where its AIS is sparse" in md


# -- item 5: the README's files ------------------------------------------------------------------

def test_the_readmes_trial_files_are_what_their_script_writes_and_small():
    import importlib.util

    from tests.conftest import REPO

    here = REPO / "tests" / "data" / "trials"
    spec = importlib.util.spec_from_file_location("trials_build", here / "build.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    for name, text in build.files().items():
        assert (here / name).read_text() == text, name
        assert len(text.encode()) < 40_000, name


# -- review of issue 38 --------------------------------------------------------------------------

def test_a_campaign_of_logs_of_one_name_in_several_folders_scores_each_under_its_own_name(
        trial, tmp_path, monkeypatch):
    """``input='days/*/leg.csv'``: three logs named alike (the third's bearings 20 deg off, so
    its verdict differs): three datasets, three rows, each labelled by its folder, none lost
    or overwritten; the counts stay whole beside a refused log, which is counted."""
    import tma

    log = pd.read_csv(trial / "trial.csv")
    for day, shift in (("d1", 0), ("d2", 0), ("d3", 20)):
        (tmp_path / "days" / day).mkdir(parents=True)
        log.assign(bearing_deg=(log.bearing_deg + shift) % 360).to_csv(
            tmp_path / "days" / day / "leg.csv", index=False)
    ais = trial / "trial_ais.csv"
    monkeypatch.chdir(tmp_path)
    table = tma.campaign("days/*/leg.csv", truth=ais)
    assert list(table["log"]) == ["d1/leg.csv", "d2/leg.csv", "d3/leg.csv", "pooled"]
    assert "no contact" in table.set_index("log").loc["d3/leg.csv"].note
    assert table["contacts"].dtype == "Int64"
    proc = run_stage_here("table", "input=days/*/leg.csv", f"truth={ais}", "name=days",
                          *data_paths(tmp_path), *QUIET, check=False)
    assert proc.returncode == 0, proc.stderr
    datasets = {p.name for p in (tmp_path / "data" / "datasets").iterdir()}
    assert {"days-d1-leg", "days-d2-leg"} <= datasets, datasets
    written = pd.read_csv(tmp_path / "tables" / "days-campaign-lm.csv")
    assert list(written["log"]) == list(table["log"])
    assert (written["contacts"].iloc[[0, 1, 3]] == [2, 2, 4]).all()
    md = (tmp_path / "tables" / "days-campaign-lm.md").read_text()
    assert "Campaign of 3 log(s) (1 not scored): 4 of 4 contacts" in md, md
    assert "4.0" not in md


def test_logs_whose_folders_differ_only_in_punctuation_keep_their_own_labels(tmp_path):
    """Folders ``d 1``, ``d_1`` and ``D-1`` (alike once made plain names) and ``leg.csv``
    beside ``leg.tsv``: each log is labelled by its own path, its dataset stem unique and the
    same from run to run; no label names another log's folder."""
    from tma.ais.campaign import log_labels

    logs = []
    for folder in ("d 1", "d_1", "D-1"):
        (tmp_path / folder).mkdir()
        logs.append(tmp_path / folder / "leg.csv")
    logs += [tmp_path / "d_1" / "leg.tsv"]
    for p in logs:
        p.write_text("t\n")
    labels = log_labels(logs)
    assert [labels[p][0] for p in logs] == ["d 1/leg.csv", "d_1/leg.csv", "D-1/leg.csv",
                                            "d_1/leg.tsv"]
    stems = [labels[p][1] for p in logs]
    assert len(set(stems)) == 4 and all("/" not in s and " " not in s for s in stems), stems
    assert stems[2] == "D-1-leg" and stems[0].startswith("d_1-leg-"), stems
    assert log_labels(list(reversed(logs))) == labels  # stable, whatever the order


def test_sparse_ais_keeps_its_ships_turns_and_drops_a_position_error_counted_and_named(
        trial, tmp_path, caplog):
    """Reports every 5 minutes: a ship turns between them, so its genuine reports lie far
    (km) off the line between their neighbours; every one is kept (the spike bound grows with
    the gap), while a report moved 50 km off is dropped, counted in the manifest's truth
    ``dropped`` and named (MMSI and time) in a warning."""
    import logging

    import tma
    from tma.ais.tracks import SPIKE_REASON, vessel_tracks

    sparse = _sparse(ais_trial.ais_reports(), 300.0).reset_index(drop=True)
    ship = ais_trial.TRUTH["T1"]
    rows = sparse.index[sparse.mmsi == ship]
    bad = rows[len(rows) // 2]
    moved = sparse.copy()
    moved.loc[bad, "lat_deg"] += 0.45  # 50 km north: no ship gets there in 10 minutes
    ais_trial.write_ais_csv(tmp_path / "sparse.csv", moved)
    reports = read_reports(tmp_path / "sparse.csv")
    kept = vessel_tracks(reports)
    for mmsi, group in sparse.groupby("mmsi"):  # every genuine report kept, the bad one not
        expected = len(group) - (mmsi == ship)
        assert kept[mmsi].t_ns.size == expected, mmsi
    with caplog.at_level(logging.WARNING, logger="tma"):
        rec = tma.read_log(trial / "trial.csv", truth={"file": tmp_path / "sparse.csv",
                                                       "max_gap_s": 620})
    dropped = rec._read.truth.record["dropped"]
    assert dropped["count"] == 1 and dropped["reasons"][SPIKE_REASON]["count"] == 1
    when = pd.Timestamp(moved.loc[bad, "t_s"] * 1e9, tz="UTC").strftime("%H:%M:%S")
    named = dropped["reasons"][SPIKE_REASON]["first"][0]
    assert f"MMSI {ship}" in named and when in named, named
    assert any(SPIKE_REASON in r.getMessage() and f"MMSI {ship}" in r.getMessage()
               for r in caplog.records)


def test_a_ship_whose_ais_ends_before_the_log_is_named_with_what_would_score_it(trial,
                                                                              tmp_path):
    """T1's ship's last report a minute before the last bearing: it is no candidate, and
    what the contact's note (and a given match's refusal) says names that ship, that it fits
    the bearings its AIS covers, and what would score it."""
    import tma

    reports = ais_trial.ais_reports()
    log = pd.read_csv(trial / "trial.csv")
    end = pd.to_datetime(log.timestamp_utc, utc=True).max().value / 1e9
    ship = ais_trial.TRUTH["T1"]
    cut = reports[(reports.mmsi != ship) | (reports.t_s < end - 60)]
    ais_trial.write_ais_csv(tmp_path / "short.csv", cut)
    rec = tma.read_log(trial / "trial.csv", truth=tmp_path / "short.csv")
    note = rec.matches.set_index("label").loc["T1", "note"]
    assert rec.matches.set_index("label").loc["T1", "mmsi"] is None or pd.isna(
        rec.matches.set_index("label").loc["T1", "mmsi"])
    assert f"MMSI {ship} fits the" in note and "give an AIS file whose reports" in note, note
    with pytest.raises(ValueError, match=rf"MMSI {ship}'s AIS .* give an AIS file whose"):
        tma.read_log(trial / "trial.csv", truth={"file": tmp_path / "short.csv",
                                                 "match": {"T1": ship}})


def test_own_ship_ais_sparser_than_nav_max_gap_s_warns_how_many_bearings_and_a_value(
        trial, tmp_path, caplog):
    """Own-ship's AIS every 20 s under the default nav.max_gap_s (10 s): the bearings in its
    gaps are left out, and a WARNING says how many of how many and a nav.max_gap_s that
    keeps them (which does); nothing says own-ship is interpolated across the gaps."""
    import logging

    import tma

    reports = ais_trial.ais_reports()
    own = reports.mmsi == ais_trial.OWN
    ais_trial.write_ais_csv(tmp_path / "ais.csv", pd.concat(
        [reports[~own], _sparse(reports[own], 20.0)]))
    bare = _bare_log(trial, tmp_path)
    with caplog.at_level(logging.INFO, logger="tma"):
        rec = tma.read_log(bare, truth=tmp_path / "ais.csv",
                           options={"truth.own_mmsi": ais_trial.OWN})
    total = len(pd.read_csv(bare))
    left = total - len(rec.bearings)
    assert 0 < left < total
    line = next(r for r in caplog.records if "lie in gaps of own-ship's AIS" in r.getMessage())
    assert line.levelno == logging.WARNING
    assert f"{left} of {total} bearings" in line.getMessage(), line.getMessage()
    value = int(line.getMessage().split("nav.max_gap_s=")[1].split()[0])
    assert not any("interpolated across them" in r.getMessage() and "not" not in
                   r.getMessage() for r in caplog.records)
    kept = tma.read_log(bare, truth=tmp_path / "ais.csv",
                        options={"truth.own_mmsi": ais_trial.OWN, "nav.max_gap_s": value})
    assert len(kept.bearings) == total


def test_own_ship_from_ais_and_the_logs_own_ship_columns_named_both_is_one_line(trial):
    """``truth.own_mmsi`` with ``columns.lat``/``columns.lon`` named: two own-ships asked
    for; refused in one line saying which to drop (each way then reads)."""
    import tma

    ais = trial / "trial_ais.csv"
    own = {"truth.own_mmsi": ais_trial.OWN, "nav.max_gap_s": 30}
    cols = {"columns.lat": "latitude_deg", "columns.lon": "longitude_deg"}
    with pytest.raises(ValueError, match=r"not both: drop truth\.own_mmsi .* or "
                                         r"columns\.lat, columns\.lon to use the AIS's") as e:
        tma.read_log(trial / "trial.csv", truth=ais, options={**own, **cols})
    assert "\n" not in str(e.value)
    assert len(tma.read_log(trial / "trial.csv", truth=ais, options=cols).bearings)
    assert len(tma.read_log(trial / "trial.csv", truth=ais, options=own).bearings)


def test_ais_times_to_the_minute_merge_reports_counted_and_said(trial, tmp_path, caplog):
    """An export that writes times to the minute: a ship's reports of one minute share a
    time and all but the first are merged; the count (own-ship's and the contacts' ships')
    is in the manifest and a warning, which says the times are good to the minute only."""
    import logging

    import tma
    from tma.ais.tracks import MERGED_REASON

    reports = ais_trial.ais_reports()
    minute = reports.assign(t_s=np.floor(reports.t_s / 60) * 60)
    ais_trial.write_ais_csv(tmp_path / "minutes.csv", minute)
    own = minute[minute.mmsi == ais_trial.OWN]
    own_merged = len(own) - own.t_s.nunique()
    with caplog.at_level(logging.INFO, logger="tma"):
        rec = tma.read_log(_bare_log(trial, tmp_path), truth={
            "file": tmp_path / "minutes.csv", "own_mmsi": ais_trial.OWN, "max_gap_s": 130},
            options={"nav.max_gap_s": 130})
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    own_line = next(m for m in said if m.startswith(f"truth.own_mmsi={ais_trial.OWN}"))
    assert f"{own_merged} with {MERGED_REASON}" in own_line, own_line
    assert "good to the minute only" in own_line
    merged = rec._read.truth.record["dropped"]["reasons"][MERGED_REASON]
    assert merged["count"] > 0
    assert any(f"left out {merged['count']}" in m and "good to the minute" in m for m in said)


def test_ais_in_local_time_without_its_zone_names_the_zone_option(trial, tmp_path):
    """The AIS written in Madrid time (UTC+1 in January) read as UTC: as own-ship's AIS and
    as the truth, the one line says the clocks are 1 h apart and names truth.time.zone."""
    import tma

    reports = ais_trial.ais_reports()
    ais_trial.write_ais_csv(tmp_path / "local.csv", reports.assign(t_s=reports.t_s + 3600))
    with pytest.raises(ValueError, match=r"they would if the bearings were \+1 h later .*"
                       r"truth\.time\.zone=<Area/City>") as err:
        tma.read_log(_bare_log(trial, tmp_path), truth=tmp_path / "local.csv",
                     options={"truth.own_mmsi": ais_trial.OWN, "nav.max_gap_s": 30})
    assert "Europe/Madrid" not in str(err.value)  # no zone named as if it were known
    with pytest.raises(ValueError, match=r"[+-]1 h apart.*truth\.time\.zone="):
        tma.read_log(trial / "trial.csv", truth=tmp_path / "local.csv")
    rec = tma.read_log(trial / "trial.csv", truth=tmp_path / "local.csv",
                       options={"truth.time.zone": "Europe/Madrid"})
    assert list(rec.truth["label"]) == ["T1", "T2"]


def test_ais_with_decimal_commas_read_with_a_decimal_point_names_truth_csv_decimal(tmp_path):
    from tma.ais.options import truth_options

    path = _other_export(ais_trial.ais_reports().head(30), tmp_path / "comma.csv")
    bad = truth_options({"file": str(path), **_table_options(""), "csv.delimiter": ";",
                         "csv.decimal": "."})
    with pytest.raises(ValueError, match=r"decimal comma \(\d+,\d+\); set truth\.csv\."
                                         r"decimal=, to read them"):
        read_reports(path, bad)


def test_a_log_across_the_autumn_change_says_it_crosses_it_and_what_to_give():
    """Madrid, 27 October 2019: 02:40-02:55 CEST, then the clocks go back and 02:00-02:15
    CET follow. With either time.ambiguous the times go back; the one line says the log
    crosses the change back and to give UTC times or offsets (which then read)."""
    import tma

    local = ["02:40", "02:45", "02:50", "02:55", "02:00", "02:05", "02:10", "02:15"]
    offset = ["+02:00"] * 4 + ["+01:00"] * 4
    frame = pd.DataFrame({"time": [f"27/10/2019 {t}" for t in local],
                          "bearing_deg": np.arange(8.0), "x": np.arange(8) * 10.0, "y": 0.0})
    options = {"time.format": "%d/%m/%Y %H:%M", "time.zone": "Europe/Madrid",
               "nav.max_gap_s": 1e5}
    for how in ("earliest", "latest"):
        with pytest.raises(ValueError, match=r"line \d+ .*crosses the daylight-saving change "
                                             r"back in Europe/Madrid.*give its times in UTC "
                                             r"or with their offset") as e:
            tma.Recording.from_frames(frame, options={**options, "time.ambiguous": how})
        assert "\n" not in str(e.value)
    iso = frame.assign(time=[f"2019-10-27T{t}:00{o}" for t, o in zip(local, offset,
                                                                        strict=True)])
    rec = tma.Recording.from_frames(iso, options={"nav.max_gap_s": 1e5})
    assert rec.bearings["time_utc"].iloc[4] - rec.bearings["time_utc"].iloc[3] == pd.Timedelta(
        minutes=5)


def test_a_frame_is_scored_against_ais_as_a_file_is(trial):
    """``Recording.from_frames(df, truth=AIS)`` and ``estimate(df, truth=AIS)`` give the
    file's truth and scores; own-ship from the AIS is read_log's, refused in one line."""
    import tma

    ais = trial / "trial_ais.csv"
    frame = pd.read_csv(trial / "trial.csv")
    from_file = tma.read_log(trial / "trial.csv", truth=ais)
    rec = tma.Recording.from_frames(frame, truth=ais)
    assert dict(zip(rec.truth["label"], rec.truth["mmsi"], strict=True)) == ais_trial.TRUTH
    assert np.allclose(rec.truth.range_now_m, from_file.truth.range_now_m)
    dotted = tma.Recording.from_frames(frame, options={"truth.file": str(ais)})
    assert list(dotted.truth["label"]) == ["T1", "T2"]
    scored, want = tma.estimate(frame, truth=ais), tma.estimate(from_file)
    assert list(scored["truth_mmsi"]) == list(want["truth_mmsi"])
    assert np.allclose(scored["range_z"], want["range_z"], equal_nan=True)
    with pytest.raises(TypeError, match=r"truth\.own_mmsi=.*tma\.read_log"):
        tma.Recording.from_frames(frame, truth={"file": ais, "own_mmsi": ais_trial.OWN})


def test_the_truths_own_uncertainty_is_stated_and_a_vague_truth_velocity_leaves_campaigns(
        trial, tmp_path):
    """Reports every 9 minutes: the truth's velocity sd per axis exceeds half the ship's
    speed; the coverage line states the truth's uncertainty even with no `ok` contact, names
    those contacts, and a campaign leaves their course and speed z-scores out (its range
    z-scores in); the CSV's truth sd is written as computed, without float noise."""
    import tma
    from tma.ais.campaign import campaign_table
    from tma.families.bearings2d.truth_report import VAGUE_VELOCITY, coverage_text

    ais_trial.write_ais_csv(tmp_path / "sparse.csv", _sparse(ais_trial.ais_reports(), 540.0))
    rec = tma.read_log(trial / "trial.csv", truth={"file": tmp_path / "sparse.csv",
                                                   "max_gap_s": 1200})
    report = tma.estimate(rec)
    vague = report.truth_vel_sd_m_s >= VAGUE_VELOCITY * report.true_speed_m_s
    assert vague.any(), report[["truth_vel_sd_m_s", "true_speed_m_s"]]
    text = coverage_text(report.assign(status="diverged"))
    assert "none of them `ok`" in text and "truth's own uncertainty" in text, text
    for label in report.label[vague]:
        assert f"{label} (" in text
    row = campaign_table({"log": report.assign(status="ok")}).iloc[0]
    ok = report.covered.notna()
    assert np.isclose(row.range_z_mean, report.range_z[ok].mean())
    kept = report.course_z[ok & ~vague]
    assert (np.isnan(row.course_z_mean) if kept.empty
            else np.isclose(row.course_z_mean, kept.mean()))
    assert all(len(repr(v)) < 16 for v in rec.truth.truth_pos_sd_m)


def test_naive_datetimes_with_a_zone_are_read_as_its_local_times(trial, tmp_path):
    """A DataFrame's and a Parquet AIS's datetime column without a zone, with time.zone /
    truth.time.zone: local times of that zone (Madrid, UTC+1 in January), as the same
    times written as text are read; the autumn repeat read as time.ambiguous says."""
    import tma

    frame = pd.read_csv(trial / "trial.csv")
    utc = pd.to_datetime(frame.timestamp_utc, utc=True)
    local = frame.assign(timestamp_utc=utc.dt.tz_convert("Europe/Madrid").dt.tz_localize(None))
    rec = tma.Recording.from_frames(local, time={"zone": "Europe/Madrid"})
    assert (rec.bearings["time_utc"].reset_index(drop=True)
            == tma.read_log(trial / "trial.csv").bearings["time_utc"].reset_index(
                drop=True)).all()
    reports = ais_trial.ais_reports()
    t = pd.to_datetime(reports.t_s * 1e9, utc=True).dt.tz_convert("Europe/Madrid")
    pd.DataFrame({"BaseDateTime": t.dt.tz_localize(None), "MMSI": reports.mmsi,
                  "LAT": reports.lat_deg, "LON": reports.lon_deg}).to_parquet(
        tmp_path / "naive.parquet")
    got = read_reports(tmp_path / "naive.parquet", __import__(
        "tma.ais.options", fromlist=["truth_options"]).truth_options(
        {"file": str(tmp_path / "naive.parquet"), "time.zone": "Europe/Madrid"}))
    assert np.abs(np.sort(got.t_ns) / 1e9 - np.sort(reports.t_s.to_numpy())).max() < 1e-3
    repeat = pd.DataFrame({"time": pd.to_datetime(["2019-10-27 02:30", "2019-10-27 03:30",
                                                   "2019-10-27 03:40", "2019-10-27 03:50",
                                                   "2019-10-27 04:00"]),
                           "bearing_deg": np.arange(5.0), "x": np.arange(5) * 10.0, "y": 0.0})
    options = {"time.zone": "Europe/Madrid", "nav.max_gap_s": 1e5}
    with pytest.raises(ValueError, match=r"time\.ambiguous=earliest or latest"):
        tma.Recording.from_frames(repeat, options=options)
    rec = tma.Recording.from_frames(repeat, options={**options, "time.ambiguous": "latest"})
    assert rec.bearings["time_utc"].iloc[0] == pd.Timestamp("2019-10-27T01:30:00Z")
