"""The Python API for every family (issue 29, item 5): ``tma.estimate`` of a simulated or
stored dataset of each family gives what its commands measure; the results hold the report
and keep the estimator's own columns beside it through what pandas users do; what does not
apply is refused in one line naming what does; every entry point raises only the kinds
pandas users catch, in one line."""

import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import tma
from tests.conftest import run_stage_here
from tests.families.bearings2d.test_bearings2d_answers import line_data
from tests.test_docs import write_logs
from tma.families.bearings2d.metrics import REGIONS

# per family: the simulation (tma.simulate's overrides, the command's scenario.KEY=VALUE),
# the estimator, and the run file the command's aggregate writes per track or per scan
FAMILIES = {
    "bearings2d": ({"n_tracks": 12, "shard_size": 5, "sigma_deg": 0.5}, "lm", "metrics"),
    "radar2d": ({"n_tracks": 12, "shard_size": 5}, "fuzzy_mm", "metrics"),
    "ranges2d": ({"n_tracks": 6, "shard_size": 4, "mode": "population"}, "quadrature",
                 "metrics"),
    "bearing_doppler3d": ({"n_tracks": 12, "shard_size": 5, "duration_s": 20.0}, "ekf",
                          "path_metrics"),
}


@pytest.fixture(autouse=True)
def _close_figures():
    """The figures plot_contact returns are pyplot's: closed after each test, so that a
    worker's later tests do not meet matplotlib's warning of too many open figures."""
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


def one_line(exc) -> str:
    text = str(exc.value if hasattr(exc, "value") else exc)
    assert "\n" not in text, text
    return text


def _table(family, tmp_path) -> tuple[Path, pd.DataFrame]:
    """``python -m pipeline.table`` of the family's small simulation: the dataset's
    directory and the run's per-track (or per-scan) file that aggregate wrote."""
    overrides, estimator, metrics = FAMILIES[family]
    run_stage_here("table", f"scenario={family}", f"estimator={estimator}",
                   *[f"scenario.{k}={v}" for k, v in overrides.items()],
                   f"paths.data_dir={tmp_path / 'data'}", f"paths.tables_dir={tmp_path / 't'}",
                   "progress=false", "parallel=serial")
    (run,) = (tmp_path / "data" / "runs").glob(f"{family}-*/{estimator}-*")
    return (tmp_path / "data" / "datasets" / run.parent.name,
            pd.read_parquet(run / f"{metrics}.parquet"))


@pytest.mark.parametrize("family", FAMILIES)
def test_every_family_is_estimated_as_its_commands_measure(family, tmp_path):
    """``tma.estimate`` of a simulation (before: bearings2d only; radar2d raised
    AttributeError) gives one row per track with what the family's table measures of it,
    the same from the stored dataset of the same config; its errors are the estimate minus
    the truth, computed here from the truth alone."""
    overrides, estimator, _ = FAMILIES[family]
    stored, measured = _table(family, tmp_path)
    sim = tma.simulate(family, **overrides)
    results = tma.estimate(sim, estimator=estimator)
    pd.testing.assert_frame_equal(results, tma.estimate(tma.open_dataset(stored),
                                                        estimator=estimator))
    assert list(results["track_id"]) == list(range(overrides["n_tracks"]))
    assert results.tma.family == family and results.tma.estimator == estimator
    truth = sim.truth
    if family == "bearings2d":
        shown = results["range_now_m"].notna().to_numpy()
        assert shown.sum() >= 10
        for column in ("bearing_err_deg", "distance_rel_err", "course_err_deg", "nees"):
            np.testing.assert_allclose(results[column][shown], measured[column][shown],
                                       rtol=1e-9)
        for region in REGIONS:
            assert list(results[region]) == list(measured[region])
        theta = results.tma.estimates
        t = theta["t_last_s"].to_numpy()
        true_range = np.hypot(truth["x0_m"] + truth["vx_m_s"] * t - theta["own_x_last_m"],
                              truth["y0_m"] + truth["vy_m_s"] * t - theta["own_y_last_m"])
        np.testing.assert_allclose(results["distance_rel_err"][shown],
                                   ((results["range_now_m"] - true_range) / true_range)[shown],
                                   rtol=1e-9)
    elif family == "radar2d":
        pd.testing.assert_frame_equal(results.tma.tables["errors"], measured)
        assert list(results["track_lost"]) == list(
            measured.groupby("track_id")["track_lost"].first())
        last = results.tma.estimates.groupby("track_id").tail(1)
        assert list(results["status"]) == list(last["status"])  # the tracker's verdict
        assert set(results["status"]) <= {"ok", "divergent"}
        end = truth[truth["step"] == truth["step"].max()].set_index("track_id")
        np.testing.assert_allclose(results["position_err_m"], np.hypot(
            results["x_now_m"] - end.loc[results["track_id"], "x_m"].to_numpy(),
            results["y_now_m"] - end.loc[results["track_id"], "y_m"].to_numpy()), rtol=1e-12)
        late = measured[measured["t_s"] >= 27.0 - 1e-9]  # the window of J = 10 scans fills
        np.testing.assert_allclose(results["position_err_max_m"],
                                   late.groupby("track_id")["error_m"].max(), rtol=1e-12)
        assert "m" in results.tma.estimates.columns and "m" not in results.columns
    elif family == "ranges2d":
        np.testing.assert_allclose(results["position_err_m"], measured["position_err_m"],
                                   rtol=1e-12)
        np.testing.assert_allclose(results["x_err_m"], results["x_now_m"] - truth["x_m"])
        assert (results["status"] == "ok").all()
    else:
        pd.testing.assert_series_equal(results["track_lost"], measured["track_lost"])
        assert list(results["status"]) == list(np.where(results["filter_ok"], "ok", "divergent"))
        np.testing.assert_allclose(results["horizontal_err_max_m"],
                                   measured["horizontal_err_max_m"], rtol=1e-12)
        end = truth[truth["step"] == truth["step"].max()].reset_index(drop=True)
        np.testing.assert_allclose(results["x_err_m"], results["x_now_m"] - end["X_m"],
                                   rtol=1e-12)
        # the heading phi (rad, counter-clockwise from east) as a course (deg, clockwise
        # from north), as every family's results give it
        true_course = np.rad2deg(np.arctan2(np.cos(end["phi_rad"]), np.sin(end["phi_rad"])))
        np.testing.assert_allclose(
            (results["course_deg"] - true_course + 180.0) % 360.0 - 180.0,
            results["course_err_deg"], rtol=0, atol=1e-9)
        assert results["course_deg"].between(0, 360).all()
        assert results["nees"].between(0, 100).all()
        assert set(results.tma.tables) == {"estimates", "covariance"}


def test_the_results_hold_the_report_and_keep_the_estimates_beside_them(tmp_path):
    """The frame is the report (the estimator's own columns, before in it, are
    ``results.tma.estimates``); a selection of it (filtered, sorted, some columns, pickled)
    still plots and maps its own contacts, row for row; what loses the link (a merge, a concat
    with other frames, a CSV file) is refused in one line saying so."""
    sim = tma.simulate("bearings2d", n_tracks=6, shard_size=4, sigma_deg=0.3)  # two logs
    results = tma.estimate(sim)
    assert not {"x0_m", "jtj_00", "t_last_s", "cost_rad2"} & set(results.columns)
    theta = results.tma.estimates
    assert list(theta["track_id"]) == list(results["track_id"]) and "jtj_33" in theta
    picked = results.sort_values("range_now_m", ascending=False)
    selections = {
        "sorted": picked,
        "filtered": results[results["track_id"] % 2 == 1],
        "query": results.query("track_id >= 3"),
        "head of sorted": picked.head(3),
        "columns": picked[["label", "status"]],
        "track ids only": picked[["track_id"]].reset_index(drop=True),
        "copy": picked.copy(),
        "pickled": pickle.loads(pickle.dumps(picked)),
        "concat of its rows": pd.concat([picked.iloc[:2], picked.iloc[4:]]),
    }
    by_id = theta.set_index("track_id")
    for name, rows in selections.items():
        ids = list(rows["track_id"] if "track_id" in rows else
                   results.set_index("label").loc[rows["label"], "track_id"])
        assert list(rows.tma.estimates["track_id"]) == ids, name
        label = str(ids[-1])
        e = by_id.loc[ids[-1]]
        x, y = line_data(tma.plot_contact(rows, sim, label), "estimated track")
        t = sim.logs[ids[-1] // 4].t_s[-1]  # the track's own estimate is drawn
        np.testing.assert_allclose([x[-1], y[-1]], np.array([e.x0_m + e.vx_m_s * t,
                                                             e.y0_m + e.vy_m_s * t]) / 1e3)
        with pytest.raises(ValueError) as exc:  # its own contacts only
            tma.plot_contact(rows, sim, "no such contact")
        assert one_line(exc).startswith("no contact 'no such contact' in these results")
    lost = {
        "merge": results.merge(pd.DataFrame({"track_id": [0], "x": [1]}), on="track_id"),
        "concat with another frame": pd.concat([results, pd.DataFrame({"label": ["9"]})]),
        "csv": pd.read_csv(_csv(results, tmp_path)),
        "parquet": pd.read_parquet(_parquet(results, tmp_path)),
    }
    for name, frame in lost.items():
        with pytest.raises(ValueError) as exc:
            tma.plot_contact(frame, sim, "0")
        assert one_line(exc).startswith("plot_contact: these results carry no estimate"), name
        with pytest.raises(ValueError):
            frame.tma.estimates  # noqa: B018
    with pytest.raises(ValueError) as exc:
        tma.plot_contact(results[["status"]], sim, "0")
    assert "neither a track_id nor a label column" in one_line(exc)


def _csv(frame, tmp_path):
    frame.to_csv(tmp_path / "results.csv", index=False)
    return tmp_path / "results.csv"


def _parquet(frame, tmp_path):
    """Written as pandas writes ``attrs``, as JSON: the family and estimator, no table
    (before: TypeError, the tables are not JSON)."""
    frame.to_parquet(tmp_path / "results.parquet")
    assert pd.read_parquet(tmp_path / "results.parquet").attrs == {
        "tma": {"family": "bearings2d", "estimator": "lm"}}
    return tmp_path / "results.parquet"


def test_what_does_not_apply_is_refused_naming_what_does(tmp_path):
    radar = tma.simulate("radar2d", n_tracks=2, shard_size=2)
    boats = tma.estimate(radar)
    bearings = tma.simulate("bearings2d", n_tracks=2, shard_size=2)
    found = tma.estimate(bearings)
    relative = tma.Recording.from_frames(pd.DataFrame({
        "time_s": np.arange(0.0, 600.0, 10.0), "own_x_m": 0.0,
        "own_y_m": np.arange(0.0, 600.0, 10.0) * 5, "bearing_deg": 45.0, "track_id": 1}))
    cases = [
        (lambda: tma.estimate(radar, estimator="lm"),
         "estimator 'lm' reads bearings2d logs, these are radar2d's: choose one of alphabeta, "
         "fuzzy_mm, imm"),
        (lambda: tma.estimate(radar, estimator="nope"),
         "unknown estimator 'nope': radar2d's are alphabeta, fuzzy_mm, imm"),
        (lambda: tma.estimate(radar, sigma_deg=0.5),
         "sigma_deg is the bearing noise of a bearing log; a radar2d dataset's noise is its "
         "scenario's: tma.simulate('radar2d', ...) sets it"),
        (lambda: tma.estimate(tma.simulate("bearing_doppler3d", n_tracks=2, shard_size=2,
                                           duration_s=5.0), estimator="cmnf"),
         "estimator 'cmnf' trains an artefact under data/artefacts before it runs, which "
         "tma.estimate does not write: run it with python -m pipeline.table "
         "scenario=bearing_doppler3d estimator=cmnf"),
        (lambda: tma.plot_contact(boats, radar, "0"),
         "plot_contact draws the contacts of bearings2d estimates (own-ship, bearings, track); "
         "these are radar2d's, which it cannot draw: their estimates are "
         "results.tma.estimates"),
        (lambda: tma.write_map(boats, radar, tmp_path / "m.mcap"),
         "write_map maps the contacts of bearings2d estimates (in latitude/longitude, at UTC "
         "times); these are radar2d's"),
        (lambda: tma.plot_contact(found, radar, "0"),
         "these results are of bearings2d logs, the recording given is a radar2d one: pass "
         "the recording given to tma.estimate"),
        (lambda: tma.write_map(found, bearings, tmp_path / "m.mcap"),
         "a map needs own-ship in latitude/longitude; this log's is in local x/y metres"),
        (lambda: tma.write_map(tma.estimate(relative), relative, tmp_path / "m.mcap"),
         "a map needs own-ship in latitude/longitude"),
        (lambda: tma.runs(tmp_path, as_dataset=True),
         "tma.runs() got an unexpected keyword argument 'as_dataset'; the pyarrow dataset is "
         "tma.runs_dataset(data_dir, family)"),
    ]
    for call, message in cases:
        with pytest.raises((ValueError, TypeError)) as exc:
            call()
        assert one_line(exc).startswith(message), exc.value
    assert not (tmp_path / "m.mcap").exists()
    # the fix the map's refusal names works: a log of relative times in x/y, dated and placed
    dated = tma.Recording.from_frames(pd.DataFrame({
        "time_s": np.arange(0.0, 600.0, 10.0), "own_x_m": 0.0,
        "own_y_m": np.arange(0.0, 600.0, 10.0) * 5, "bearing_deg": 45.0, "track_id": 1}),
        origin={"lat": 50.8, "lon": -1.3})
    with pytest.raises(ValueError) as exc:
        tma.write_map(tma.estimate(dated), dated, tmp_path / "m.mcap")
    assert one_line(exc) == ("a map needs UTC times; this log's are relative: read it with "
                             "time={'start_utc': ...}")
    dated = tma.Recording.from_frames(pd.DataFrame({
        "time_s": np.arange(0.0, 600.0, 10.0), "own_x_m": 0.0,
        "own_y_m": np.arange(0.0, 600.0, 10.0) * 5, "bearing_deg": 45.0, "track_id": 1}),
        origin={"lat": 50.8, "lon": -1.3}, time={"start_utc": "2025-06-01T08:00:00Z"})
    assert tma.write_map(tma.estimate(dated), dated, tmp_path / "m.mcap").exists()


def test_runs_and_runs_dataset_each_return_one_type(tmp_path):
    _table("radar2d", tmp_path)
    frame = tma.runs(tmp_path / "data")
    dataset = tma.runs_dataset(tmp_path / "data", family="radar2d")
    assert isinstance(frame, pd.DataFrame) and not isinstance(dataset, pd.DataFrame)
    assert dataset.to_table().num_rows == len(frame) > 0
    for call in (tma.runs, tma.runs_dataset):
        with pytest.raises(FileNotFoundError) as exc:
            call(tmp_path / "nowhere")
        assert one_line(exc).startswith(f"{tmp_path / 'nowhere'}: no such directory; give "
                                        "data_dir")


# -- every entry point, every argument, values of every kind -----------------------------------

BAD = {"None": None, "an int": 3, "a negative float": -1.5, "a bool": True, "empty text": "",
       "a word": "no_such_thing", "a list": [], "a dict": {}, "an object": object(),
       "a DataFrame": pd.DataFrame({"a": [1, 2]}), "a missing file": "/nonexistent/x.csv",
       "nan": float("nan"), "bytes": b"x", "an array": np.zeros((2, 2))}


@pytest.fixture(scope="module")
def place(tmp_path_factory):
    root = write_logs(tmp_path_factory.mktemp("walk"))
    run_stage_here("table", f"input={root / 'nav_export.csv'}", "name=nav",
                   f"paths.data_dir={root / 'data'}", f"paths.tables_dir={root / 't'}",
                   "progress=false", "parallel=serial")
    _table("radar2d", root)
    return root


def test_every_entry_point_raises_only_what_pandas_users_catch(place, monkeypatch):
    """Each argument of each function of the API, in an otherwise good call, given a value
    of every kind: accepted, or one line of ValueError, TypeError or FileNotFoundError (the
    map's path: the OSError the system gave, e.g. IsADirectoryError)."""
    monkeypatch.chdir(place)
    frame = pd.read_csv("nav_export.csv")
    rec = tma.read_log("nav_export.csv")
    found = tma.estimate(rec)
    calls = {  # name: (function, good positional arguments, good keyword arguments)
        "read_log": (tma.read_log, ["nav_export.csv"],
                     {"navigation": None, "format": "auto", "sigma_deg": None,
                      "min_bearings": 5, "truth": None, "options": None, "columns": {}}),
        "Recording.from_frames": (tma.Recording.from_frames, [frame, None],
                                  {"options": None, "sigma_deg": 0.5, "time": {}}),
        "estimate": (tma.estimate, [rec], {"estimator": None, "sigma_deg": None,
                                           "max_iter": 50}),
        "plot_contact": (tma.plot_contact, [found, rec, "T1"], {}),
        "write_map": (tma.write_map, [found, rec, "m.mcap"], {}),
        "open_dataset": (tma.open_dataset, ["nav", "data"], {}),
        "runs": (tma.runs, ["data", None], {}),
        "runs_dataset": (tma.runs_dataset, ["data", "radar2d"], {}),
        "simulate": (tma.simulate, ["radar2d"], {"n_tracks": 2, "shard_size": 2,
                                                 "options": None}),
    }
    import matplotlib.pyplot as plt

    for name, (function, args, kwargs) in calls.items():
        function(*args, **kwargs)  # the good call is good
        slots = [*range(len(args)), *kwargs]
        for slot in slots:
            for kind, value in BAD.items():
                a, kw = list(args), dict(kwargs)
                if isinstance(slot, int):
                    a[slot] = value
                else:
                    kw[slot] = value
                where = f"{name}({slot}={kind})"
                caught = (OSError if (name, slot) == ("write_map", 2) else FileNotFoundError)
                try:
                    function(*a, **kw)
                    plt.close("all")
                except (ValueError, TypeError, caught) as exc:
                    assert "\n" not in str(exc), (where, str(exc))
                    assert "Traceback" not in str(exc) and str(exc), where
