"""tma from Python (``tma.api``, issue 23): the documented examples run as written, and every
function gives what the commands give for the same input."""

import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import tma
from tests.conftest import REPO, run_stage_here
from tests.test_docs import fenced, write_logs

SMALL = ["scenario.n_tracks=20", "scenario.shard_size=20", "progress=false", "parallel=serial"]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """The logs the README names, ``trial7`` ingested from one, and a small aggregated table
    of two estimators at sigma 0.5 (data/, tables/)."""
    root = write_logs(tmp_path_factory.mktemp("api"))
    paths = [f"paths.data_dir={root / 'data'}", f"paths.tables_dir={root / 'tables'}"]
    run_stage_here("ingest", f"input={root / 'my_log.csv'}", "name=trial7", *paths,
                   "progress=false")
    run_stage_here("simulate", *SMALL, *paths, "scenario.sigma_deg=0.5")
    for verb in ("estimate", "aggregate"):
        run_stage_here(verb, "-m", *SMALL, *paths, "scenario.sigma_deg=0.5",
                       "estimator=lm,nbearings")
    return root


@pytest.fixture(autouse=True)
def _close_figures():
    """The figures plot_contact returns are pyplot's: closed after each test, so that a
    worker's later tests do not meet matplotlib's warning of too many open figures."""
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


@pytest.mark.parametrize("doc", ["docs/api.md", "README.md"])
def test_the_documented_python_runs_as_written(doc, workdir, monkeypatch):
    """Every python block of the page, in order, in one namespace, nothing prepended."""
    monkeypatch.chdir(workdir)
    blocks = [text for _, _, text in fenced(REPO / doc, "python")]
    assert blocks
    namespace = {}
    for block in blocks:
        exec(compile(block, doc, "exec"), namespace)
    assert len(namespace["results"]) >= 1


def test_two_lines_from_a_dataframe_to_its_contacts():
    """The README's count: ``import tma`` and one call."""
    text = (REPO / "README.md").read_text()
    assert "```python\nimport tma\nresults = tma.estimate(frame)\n```" in text


def test_the_example_runs_as_a_script(tmp_path):
    env = {**os.environ, "TMA_EXAMPLE_OUT": str(tmp_path), "PYTHONWARNINGS": "ignore"}
    proc = subprocess.run([sys.executable, str(REPO / "examples" / "real_log.py")], env=env,
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert {"contacts.csv", "contacts.mcap", "247007000.png"} <= {
        p.name for p in tmp_path.iterdir()}
    assert " ok " in proc.stdout and "truth" in proc.stdout
    first = (REPO / "examples" / "real_log.py").read_text().splitlines()[:8]
    assert "#   jupytext:" in first and "#       format_name: percent" in first


def test_estimate_is_what_the_commands_report(workdir, tmp_path):
    """``pipeline.table input=`` and ``tma.estimate(tma.read_log(...))`` on one log: the
    same numbers in the same columns."""
    paths = [f"paths.data_dir={tmp_path / 'data'}", f"paths.tables_dir={tmp_path / 't'}"]
    run_stage_here("table", f"input={workdir / 'nav_export.csv'}", "name=nav", "sigma_deg=0.5",
                   *paths, "progress=false", "parallel=serial")
    cli = pd.read_csv(tmp_path / "t" / "nav-lm.csv")
    api = tma.estimate(tma.read_log(workdir / "nav_export.csv", sigma_deg=0.5))
    assert list(api.columns) == list(cli.columns)  # the report alone (issue 29, item 5)
    for column in ("range_now_m", "range_sd_m", "course_deg", "speed_sd_m_s",
                   "motion_p_value", "lat_now_deg"):
        np.testing.assert_allclose(api[column], cli[column], rtol=1e-12)
    assert list(api["status"]) == list(cli["status"])
    assert list(api["time_now_utc"]) == list(cli["time_now_utc"])


def _export(workdir) -> pd.DataFrame:
    return pd.read_csv(workdir / "nav_export.csv")


@pytest.mark.parametrize("form", ["iso text", "datetime64 utc", "datetime64 naive",
                                  "unix seconds"])
def test_frames_read_as_the_same_table_written_to_a_file(workdir, form, caplog):
    frame = _export(workdir)
    times = pd.to_datetime(frame["timestamp_utc"], utc=True)
    if form == "datetime64 utc":
        frame["timestamp_utc"] = times
    elif form == "datetime64 naive":
        frame["timestamp_utc"] = times.dt.tz_localize(None)
    elif form == "unix seconds":
        frame["timestamp_utc"] = (times - pd.Timestamp(0, tz="UTC")).dt.total_seconds()
    with caplog.at_level(logging.INFO, logger="tma"):
        rec = tma.Recording.from_frames(frame, sigma_deg=0.5)
    from_file = tma.read_log(workdir / "nav_export.csv", sigma_deg=0.5)
    np.testing.assert_allclose(rec.logs[0].bearing_deg, from_file.logs[0].bearing_deg)
    np.testing.assert_allclose(rec.logs[0].own_x_m, from_file.logs[0].own_x_m, atol=1e-6)
    assert rec.start_utc == from_file.start_utc
    if form == "datetime64 naive":
        assert any("without time zone read as UTC" in n for n in rec.notes)
    pd.testing.assert_frame_equal(tma.estimate(rec)[["range_now_m", "status"]],
                                  tma.estimate(from_file)[["range_now_m", "status"]],
                                  rtol=1e-6)


def test_own_ship_in_its_own_frame_and_bad_frames(workdir):
    frame = _export(workdir)
    bearings = frame[["timestamp_utc", "bearing_deg", "contact"]]
    navigation = frame[["timestamp_utc", "latitude_deg", "longitude_deg"]].drop_duplicates(
        "timestamp_utc")
    apart = tma.Recording.from_frames(bearings, navigation)
    together = tma.Recording.from_frames(frame)
    np.testing.assert_allclose(apart.logs[0].bearing_deg, together.logs[0].bearing_deg)
    np.testing.assert_allclose(apart.logs[0].own_y_m, together.logs[0].own_y_m, atol=1e-6)
    from tma.errors import InputError
    with pytest.raises(InputError, match="no bearing column"):
        tma.Recording.from_frames(frame.drop(columns="bearing_deg"))
    with pytest.raises(InputError, match="bearings frame: no rows"):
        tma.Recording.from_frames(frame.iloc[:0])
    bad = frame.copy()
    bad.loc[3, "bearing_deg"] = np.nan  # one bad row: dropped and counted, named by position
    rec = tma.Recording.from_frames(bad)
    assert rec.dropped["bad_rows"]["count"] == 1
    assert "line 3" in str(rec.dropped["bad_rows"])


def test_recording_frames_and_options(workdir):
    rec = tma.read_log(workdir / "log.csv", options={"columns.time": "tid",
                                                     "columns.lat": "breite"},
                       columns={"lon": "laenge", "bearing": "peilung", "track": "kontakt"},
                       csv={"delimiter": "semicolon", "decimal": "comma"},
                       bearing={"units": "rad"}, time={"format": "unix_ms"})
    b = rec.bearings
    assert list(b.columns) == ["log", "t_s", "time_utc", "track_id", "label", "bearing_deg"]
    assert set(b.label) == {"T1", "T2"} and len(b) == int(np.isfinite(
        rec.logs[0].bearing_deg).sum())
    own = rec.ownship
    assert {"lat_deg", "lon_deg", "x_m"} <= set(own.columns) and len(own) == rec.logs[0].t_s.size
    assert rec.origin_deg is not None and rec.start_utc.endswith("Z")
    assert "Recording of" in repr(rec)


def test_simulate_gives_the_numbers_of_the_stored_dataset(workdir):
    sim = tma.simulate("bearings2d", n_tracks=20, shard_size=20, sigma_deg=0.5)
    stored = next(d for d in (workdir / "data" / "datasets").iterdir()
                  if d.name.startswith("bearings2d-sigma0.5-n20"))
    opened = tma.open_dataset(stored)
    assert len(opened.logs) == len(sim.logs) == 1
    np.testing.assert_array_equal(opened.logs[0].bearing_deg, sim.logs[0].bearing_deg)
    pd.testing.assert_frame_equal(opened.truth.to_pandas() if hasattr(opened.truth, "to_pandas")
                                  else opened.truth, sim.truth)
    assert not opened.recorded and tma.open_dataset("trial7", workdir / "data").recorded


def test_runs_name_those_without_metrics(workdir, caplog):
    metrics = tma.runs(workdir / "data", family="bearings2d")
    assert set(metrics["estimator"]) == {"lm", "nbearings"} and not metrics.attrs[
        "without_metrics"]
    run = next((workdir / "data" / "runs").glob("bearings2d-*/lm-*"))
    (run / "metrics.parquet").rename(run / "metrics.kept")
    try:
        with caplog.at_level(logging.WARNING, logger="tma"):
            metrics = tma.runs(workdir / "data", family="bearings2d")
        assert metrics.attrs["without_metrics"] == [f"{run.parent.name}/{run.name}"]
        assert "without metrics.parquet" in caplog.text and run.name in caplog.text
        assert set(metrics["estimator"]) == {"nbearings"}
    finally:
        (run / "metrics.kept").rename(run / "metrics.parquet")


def test_plot_and_map(workdir, tmp_path):
    rec = tma.read_log(workdir / "nav_export.csv")
    found = tma.estimate(rec, estimator="last_leg")
    figure = tma.plot_contact(found, rec, "T2")
    assert "contact T2" in figure.axes[0].get_title()
    with pytest.raises(ValueError, match="no contact 'T9' in these results; their contacts: "
                       "T1, T2"):
        tma.plot_contact(found, rec, "T9")
    path = tma.write_map(found, rec, tmp_path / "m.mcap")
    from tests.conftest import plain_messages
    topics = {ch.topic for ch, _, _ in plain_messages(path)}
    assert {"/tma/estimate/T1", "/tma/estimate/T2", "/ownship/location_fix"} <= topics
    with pytest.raises(ValueError, match="these results carry no estimate"):
        tma.plot_contact(pd.read_csv(workdir / "nav_export.csv"), rec, "T1")


def test_results_show_no_number_that_is_not_an_answer(tmp_path):
    """Issue 28, item 4: an own-ship that never manoeuvres: the estimator's numbers diverge
    or collapse; the results frame, the plot and the map show none of them (before: ranges
    of 1e4-1e15 m and their x0_m.. as numbers, tracks drawn and mapped)."""
    from tests.families.bearings2d.test_bearings2d_answers import line_data, straight_log
    from tma.families import build_estimator
    from tma.families.bearings2d.track_report import ESTIMATE_COLUMNS

    rec = tma.read_log(straight_log(tmp_path / "straight.csv"))
    found = tma.estimate(rec)
    raw = build_estimator({"name": "lm", "initial_bearing_deg": None}).estimate(rec.logs[0])
    assert np.isfinite(raw["range_now_m"]).all()
    assert found[ESTIMATE_COLUMNS].isna().all().all()
    assert found.tma.estimates[["x0_m", "y0_m", "vx_m_s", "vy_m_s"]].isna().all().all()
    assert list(found["status"]) == list(raw["status"]) and "ok" not in set(found["status"])
    assert found["note"].str.contains("the estimate is not shown").all()
    figure = tma.plot_contact(found, rec, "S1")
    assert "no estimate shown" in figure.axes[0].get_title()
    assert line_data(figure, "estimated")[0].size == 0
    from tests.conftest import plain_messages
    topics = {ch.topic for ch, _, _ in plain_messages(tma.write_map(found, rec,
                                                                    tmp_path / "m.mcap"))}
    assert topics == {"/ownship/location_fix"}


def test_plot_contact_of_a_leg_that_starts_late(tmp_path):
    """Issue 28, item 5: the plot of a contact ``last_leg`` solved on a late leg shows
    own-ship's whole path and every bearing, and the estimated track from its leg's start
    (before: ValueError, operands could not be broadcast together): the trajectory its answer
    rests on where the estimator kept it (a recording's ``path``), else the straight line of
    its answer. Legs are sought as under a prior without manoeuvres (with them, only where
    the mixture fails the trend test)."""
    from tests.families.bearings2d.test_bearings2d_answers import late_leg_log, line_data

    rec = tma.read_log(late_leg_log(tmp_path / "turns.csv"))
    found = tma.estimate(rec, estimator="last_leg", manoeuvre_rate_per_h=0)
    late = found[(found["leg_start_s"] > 0) & found["range_now_m"].notna()]
    assert len(late) >= 3, found[["label", "leg_start_s", "status"]]
    (log,) = rec.logs
    theta = found.tma.estimates.set_index("track_id")
    paths = found.tma.tables["path"]
    drawn_paths = 0
    for r in late.itertuples(index=False):
        e = theta.loc[r.track_id]
        figure = tma.plot_contact(found, rec, r.label)
        assert line_data(figure, "own-ship")[0].size == log.t_s.size
        row = list(log.track_id).index(r.track_id)
        first = np.flatnonzero(np.isfinite(log.bearing_deg[row]))[0]
        t = log.t_s[np.isfinite(log.bearing_deg[row])]
        held = t[t >= r.leg_start_s]
        kept = paths[paths["track_id"] == r.track_id]
        if len(kept):  # the trajectory the answer rests on, from the leg's start to now
            drawn_paths += 1
            assert kept["t_s"].min() >= r.leg_start_s and kept["t_s"].max() == t[-1]
            x, y = line_data(figure, "estimated track")  # (to now, where position_only)
            assert x.size == len(kept) and t[0] < kept["t_s"].min()
            start = kept[["x_m", "y_m"]].to_numpy()[0]
        elif r.status == "position_only":  # its heading not determined: now alone
            x, y = line_data(figure, "estimated position now")
            assert x.size == 1
            start = np.array([e.x0_m + e.vx_m_s * t[-1], e.y0_m + e.vy_m_s * t[-1]])
        else:
            x, y = line_data(figure, "estimated track")
            assert x.size == held.size < t.size
            start = np.array([e.x0_m + e.vx_m_s * held[0], e.y0_m + e.vy_m_s * held[0]])
        np.testing.assert_allclose([x[0], y[0]], start / 1e3, rtol=1e-12)
        lines = line_data(figure, "bearings")  # from the contact's first bearing on
        np.testing.assert_allclose([lines[0][0], lines[1][0]],
                                   [log.own_x_m[first] / 1e3, log.own_y_m[first] / 1e3])
    assert drawn_paths == len(late)  # every one shown has a motion fit here


def _relative_frame(n=2):
    from tma.families.bearings2d.scenario import Config, simulate_shard

    log, _ = simulate_shard(Config(n_tracks=n, shard_size=n, sigma_deg=0.3, seed=5), 0)
    return pd.DataFrame([{"time_s": t, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
                          "bearing_deg": log.bearing_deg[i, k], "track_id": i}
                         for k, t in enumerate(log.t_s) for i in range(n)])


def test_plot_contact_of_a_log_of_relative_times():
    """Issue 30: results of a log of relative times, plotted with that log or with it dated
    (``time.start_utc``) afterwards: titled in seconds from the start (before: TypeError)."""
    frame = _relative_frame()
    rec = tma.Recording.from_frames(frame)
    found = tma.estimate(rec)
    assert found["time_now_utc"].isna().all()
    dated = tma.Recording.from_frames(frame, time={"start_utc": "2025-06-01T08:00:00Z"})
    for recording in (rec, dated):
        title = tma.plot_contact(found, recording, "1").axes[0].get_title()
        assert "contact 1, status" in title and title.endswith("at t = 1200 s from the start")
    title = tma.plot_contact(tma.estimate(dated), dated, 1).axes[0].get_title()
    assert title.endswith("at 2025-06-01T08:20:00Z")
    later = tma.Recording.from_frames(frame, time={"start_utc": "2025-06-02T08:00:00Z"})
    with pytest.raises(ValueError, match="not estimated from this recording .contact '0': "
                       "its last bearing is at 2025-06-01T08:20:00Z there, at another UTC"):
        tma.plot_contact(tma.estimate(dated), later, "0")


def test_plot_and_map_refuse_what_they_cannot_draw_in_one_line(workdir):
    """Issue 30: an unknown label, another recording's results, arguments of the wrong kind:
    one exception a pandas user catches, one line naming the cause and the fix (before:
    KeyError, StopIteration, AttributeError)."""
    rec = tma.read_log(workdir / "nav_export.csv")
    found = tma.estimate(rec)
    other = tma.Recording.from_frames(_relative_frame())
    cases = [
        (lambda: tma.plot_contact(found, rec, "T9"), ValueError,
         "no contact 'T9' in these results; their contacts: T1, T2"),
        (lambda: tma.plot_contact(found, other, "T1"), ValueError,
         "these results were not estimated from this recording (contact 'T1': "),
        (lambda: tma.write_map(tma.estimate(other), rec, "x.mcap"), ValueError,
         "); pass the recording given to tma.estimate"),
        (lambda: tma.plot_contact(found.to_dict(), rec, "T1"), TypeError,
         "plot_contact needs the results DataFrame tma.estimate returned, got dict"),
        (lambda: tma.write_map(found, "nav_export.csv", "x.mcap"), TypeError,
         "write_map needs a Recording, a pandas DataFrame, or a dataset"),
    ]
    for call, kind, message in cases:
        with pytest.raises(kind) as caught:
            call()
        assert message in str(caught.value) and "\n" not in str(caught.value), caught.value


def test_write_map_names_the_path_it_cannot_write(workdir, tmp_path):
    """Issue 30: the map's own path in one line, not its temporary file's; no directory made
    for a mistyped one; an existing map is kept when a new one cannot be written."""
    rec = tma.read_log(workdir / "nav_export.csv")
    found = tma.estimate(rec)
    missing = tmp_path / "no" / "such" / "m.mcap"
    with pytest.raises(FileNotFoundError, match=f"cannot write the map to {missing}: there is "
                       f"no directory {missing.parent}; create it or choose another path"):
        tma.write_map(found, rec, missing)
    assert not (tmp_path / "no").exists()
    with pytest.raises(IsADirectoryError, match=f"{tmp_path}: it is a directory; give a file "
                       "name"):
        tma.write_map(found, rec, tmp_path)
    if Path("/proc/self").is_dir():  # a directory that holds no files (Linux)
        with pytest.raises(FileNotFoundError) as caught:
            tma.write_map(found, rec, "/proc/m.mcap")
        text = str(caught.value)
        assert "cannot write the map to /proc/m.mcap: No such file or directory" in text
        assert ".tmp-" not in text and "\n" not in text
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "locked"
        locked.mkdir()
        kept = tma.write_map(found, rec, locked / "m.mcap").read_bytes()
        locked.chmod(0o500)
        try:
            with pytest.raises(PermissionError, match=f"cannot write the map to "
                               f"{locked / 'm.mcap'}: Permission denied"):
                tma.write_map(found, rec, locked / "m.mcap")
        finally:
            locked.chmod(0o700)
        assert (locked / "m.mcap").read_bytes() == kept


def test_import_tma_is_light():
    """``import tma`` loads neither numpy nor pandas (what makes it fast; no timing here: a
    shared machine's seconds say nothing)."""
    code = "import sys, tma; print('numpy' in sys.modules, 'pandas' in sys.modules)"
    numpy_loaded, pandas_loaded = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True,
        cwd=REPO).stdout.split()
    assert numpy_loaded == pandas_loaded == "False"
    assert set(tma.API) <= set(dir(tma))
    with pytest.raises(AttributeError):
        tma.nothing_here  # noqa: B018


def test_compiling_is_said_once_per_module(tmp_path):
    """A cold numba cache: the first estimate says it compiles, once for each module of
    kernels; a second process with the cache warm says nothing."""
    code = ("import tma; sim = tma.simulate(n_tracks=4, shard_size=4); "
            "tma.estimate(sim); tma.estimate(sim)")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "PYTHONWARNINGS": "ignore"}
    start = time.perf_counter()
    cold = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, check=True, cwd=REPO).stderr
    note = "note: compiling bearings2d marquardt kernels (numba), once per machine"
    assert cold.count(note) == 1, cold
    warm = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, check=True, cwd=REPO).stderr
    assert "compiling" not in warm, warm
    assert time.perf_counter() - start < 240
