"""One command from a recorded log to its report (issue 22, item 4): ``python -m pipeline.table
input=FILE`` runs ingest, estimate and aggregate and writes what the three commands write; an
estimator's defaults for a recorded log apply without being repeated; a re-run reuses the
dataset and the run and says so; ``aggregate`` without the exact run names the runs that exist
and the overrides that select them."""

import json

import numpy as np
import pandas as pd
import pytest

from tests.conftest import data_paths, run_stage_here
from tests.test_pipeline import _files
from tma.families.bearings2d.scenario import Config, simulate_shard

QUIET = ["progress=false", "parallel=serial"]


def _log(path, seed=5, n=3):
    log, _ = simulate_shard(Config(n_tracks=n, shard_size=n, sigma_deg=0.3, seed=seed), 0)
    pd.DataFrame([{"time_s": t, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
                   "bearing_deg": log.bearing_deg[i, k], "track_id": i}
                  for k, t in enumerate(log.t_s) for i in range(n)]).to_csv(path, index=False)
    return path


def _run_config(root, dataset="trial7"):
    """The config of each run of ``dataset``, by run directory name."""
    return {p.parent.name: json.loads(p.read_text())["config"]
            for p in (root / "data" / "runs" / dataset).glob("*/manifest.json")}


def _one_line(proc, *expected):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), (
        proc.returncode, proc.stderr)
    for text in expected:
        assert text in lines[0], lines[0]
    return lines[0]


def test_one_command_writes_what_the_three_commands_write(tmp_path):
    log = _log(tmp_path / "trial7.csv")
    one, three = tmp_path / "one", tmp_path / "three"
    proc = run_stage_here("table", f"input={log}", *data_paths(one), *QUIET)
    assert [line.split(" - ")[1].split(":")[0] for line in proc.stdout.splitlines()
            if " - stage " in line] == ["stage ingest", "stage estimate", "stage aggregate"]
    run_stage_here("ingest", f"input={log}", *data_paths(three), *QUIET)
    for verb in ("estimate", "aggregate"):  # the README's commands, as before
        run_stage_here(verb, "dataset=trial7", "estimator=lm",
                       "estimator.initial_bearing_deg=null", *data_paths(three), *QUIET)
    assert _files(one).keys() == _files(three).keys()
    assert [str(k) for k in _files(one) if _files(one)[k] != _files(three)[k]] == []
    assert (one / "tables" / "trial7-lm.csv").exists()
    [config] = _run_config(one).values()
    assert config["name"] == "lm" and config["initial_bearing_deg"] is None  # not repeated


def test_a_bare_log_and_any_ingest_or_estimator_option(tmp_path):
    log = _log(tmp_path / "rec.csv")
    run_stage_here("table", str(log), "name=trial7", "estimator=nbearings", "sigma_deg=0.3",
                   "estimator.max_range_rel_sd=0.3", *data_paths(tmp_path), *QUIET)
    [config] = _run_config(tmp_path).values()
    assert config["name"] == "nbearings" and config["max_range_rel_sd"] == 0.3
    manifest = json.loads((tmp_path / "data/datasets/trial7/manifest.json").read_text())
    assert manifest["sigma_deg"] == 0.3
    assert len(pd.read_csv(tmp_path / "tables" / "trial7-nbearings.csv")) == 3


def test_a_rerun_reuses_the_dataset_and_the_run_and_says_so(tmp_path):
    log = _log(tmp_path / "trial7.csv")
    run_stage_here("table", f"input={log}", *data_paths(tmp_path), *QUIET)
    before = _files(tmp_path / "data")
    proc = run_stage_here("table", f"input={log}", *data_paths(tmp_path), *QUIET)
    assert "trial7 reused (ingesting the log again gives the same dataset)" in proc.stdout
    assert "reused (finished before and verified" in proc.stdout
    assert _files(tmp_path / "data") == before
    assert not list((tmp_path / "data").glob(".tma-log-check-*"))  # the scratch copy is gone
    run_stage_here("table", f"input={log}", "estimator=last_leg", *data_paths(tmp_path), *QUIET)
    assert len(_run_config(tmp_path)) == 2
    # another log (or other reading options) under the same name: refused, nothing replaced
    (tmp_path / "other").mkdir()
    other = _log(tmp_path / "other" / "trial7.csv", seed=6)
    proc = run_stage_here("table", f"input={other}", *data_paths(tmp_path), *QUIET, check=False)
    _one_line(proc, "dataset", "trial7 exists", "force=true")
    proc = run_stage_here("table", f"input={log}", "time.format=unix_s", *data_paths(tmp_path),
                          *QUIET, check=False)
    _one_line(proc, "other reading options")
    assert {k: v for k, v in _files(tmp_path / "data").items() if k in before} == before


def test_estimate_says_when_it_reuses_a_run(tmp_path):
    log = _log(tmp_path / "trial7.csv")
    run_stage_here("ingest", f"input={log}", *data_paths(tmp_path), *QUIET)
    first = run_stage_here("estimate", "dataset=trial7", *data_paths(tmp_path), *QUIET)
    again = run_stage_here("estimate", "dataset=trial7", *data_paths(tmp_path), *QUIET)
    [run] = _run_config(tmp_path)
    assert f"{run}\n" in first.stdout and "reused" not in first.stdout
    assert f"{run} reused (finished before and verified; force=true recomputes it)" in (
        again.stdout)


def test_a_stored_dataset_is_estimated_and_aggregated_in_one_command(tmp_path):
    run_stage_here("ingest", f"input={_log(tmp_path / 'trial7.csv')}", *data_paths(tmp_path),
                   *QUIET)
    proc = run_stage_here("table", "dataset=trial7", *data_paths(tmp_path), *QUIET)
    assert "stage simulate" not in proc.stdout
    assert (tmp_path / "tables" / "trial7-lm.csv").exists()


@pytest.mark.parametrize(("made", "asked", "expected"), [
    (["estimator.max_iter=50"], [],
     "or aggregate a run that exists: lm-{run} (estimator=lm estimator.max_iter=50)"),
    (["estimator.initial_bearing_deg=0"], [],
     "lm-{run} (estimator=lm estimator.initial_bearing_deg=0.0)"),
    ([], ["estimator.initial_bearing_deg=10"],
     "lm-{run} (estimator=lm)"),
    (["estimator=nbearings"], [], "nbearings-{run} (estimator=nbearings)"),
])
def test_aggregate_without_the_exact_run_names_those_that_exist(tmp_path, made, asked,
                                                                expected):
    run_stage_here("ingest", f"input={_log(tmp_path / 'trial7.csv')}", *data_paths(tmp_path),
                   *QUIET)
    run_stage_here("estimate", "dataset=trial7", *made, *data_paths(tmp_path), *QUIET)
    [run] = _run_config(tmp_path)
    proc = run_stage_here("aggregate", "dataset=trial7", "estimator=lm", *asked,
                          *data_paths(tmp_path), *QUIET, check=False)
    line = _one_line(proc, "no finished run of lm on dataset trial7 with these settings",
                     "python -m pipeline.estimate")
    assert expected.format(run=run.split("-", 1)[1]) in line
    selecting = line.rsplit("(", 1)[1].rstrip(")").split()  # select that run: aggregated
    run_stage_here("aggregate", "dataset=trial7", *selecting, *data_paths(tmp_path), *QUIET)
    assert (tmp_path / "data" / "runs" / "trial7" / run / "report.parquet").exists()


def test_a_simulated_dataset_keeps_the_simulated_start(tmp_path):
    """``recorded_defaults`` apply to recorded logs only: the simulated tables' runs, their
    keys and bytes, are those they were."""
    common = [*data_paths(tmp_path), *QUIET, "scenario.n_tracks=10"]
    run_stage_here("simulate", *common)
    run_stage_here("estimate", *common)
    [config] = [json.loads(p.read_text())["config"]
                for p in (tmp_path / "data" / "runs").glob("*/lm-*/manifest.json")]
    assert config["initial_bearing_deg"] == 0.0


def _estimates(root, dataset):
    [path] = (root / "data" / "runs" / dataset).glob("*/estimates")
    return pd.read_parquet(path)  # the run's shard files, one call


def test_a_diverged_estimate_is_blank_in_the_table_its_csv_plots_and_map(tmp_path):
    """Issue 28, item 4: an own-ship that never manoeuvres (no bearing gives the range): the
    run keeps the estimator's numbers, the table, its CSV and the map show none of them, each
    contact with its status and a note saying why (before: ranges of 1e4-1e15 m as numbers,
    `± ?`, and tracks on the map)."""
    from tests.conftest import plain_messages
    from tests.families.bearings2d.test_bearings2d_answers import straight_log
    from tma.families.bearings2d.track_report import ESTIMATE_COLUMNS

    log = straight_log(tmp_path / "straight.csv")
    proc = run_stage_here("table", f"input={log}", *data_paths(tmp_path), *QUIET)
    raw = _estimates(tmp_path, "straight")
    assert np.isfinite(raw["range_now_m"]).all()  # kept as the estimator gave them
    csv = pd.read_csv(tmp_path / "tables" / "straight-lm.csv")
    assert csv[ESTIMATE_COLUMNS].isna().all().all()
    assert list(csv["status"]) == list(raw["status"]) and "ok" not in set(csv["status"])
    assert csv["note"].str.contains("the estimate is not shown").all()
    md = (tmp_path / "tables" / "straight-lm.md").read_text()
    rows = [line.split(" | ") for line in md.splitlines() if line.startswith("| S")]
    header = next(line for line in md.splitlines() if line.startswith("| track")).split(" | ")
    assert len(rows) == 3
    for name in ("range now (m)", "bearing now (deg)", "course (deg)", "speed (m/s)",
                 "position now (lat, lon deg)"):
        assert {row[header.index(name)] for row in rows} == {"-"}, name
    assert "±" not in md.split("| track")[1]
    assert {ch.topic for ch, _, _ in plain_messages(tmp_path / "tables" / "straight-lm.mcap")
            } == {"/ownship/location_fix"}
    assert "for S0, S1, S2: not in the map" in proc.stdout + proc.stderr
    assert len(list((tmp_path / "tables").glob("straight-lm-S*.png"))) == 3


def test_last_leg_plots_contacts_whose_leg_starts_late(tmp_path):
    """Issue 28, item 5: ``last_leg`` re-solves turning targets on their last leg; the plot of
    each cuts the estimated track at its leg's start, not own-ship (before: "internal error
    (ValueError: operands could not be broadcast together...)"). Legs are sought as under a
    prior without manoeuvres (with them, only where the mixture fails the trend test)."""
    from tests.families.bearings2d.test_bearings2d_answers import late_leg_log

    log = late_leg_log(tmp_path / "turns.csv")
    run_stage_here("table", f"input={log}", "estimator=last_leg",
                   "estimator.manoeuvre_rate_per_h=0", *data_paths(tmp_path), *QUIET)
    raw = _estimates(tmp_path, "turns")
    assert (raw["leg_start_s"] > 0).sum() >= 3, raw["leg_start_s"]  # legs that start late
    assert len(list((tmp_path / "tables").glob("turns-last_leg-M*.png"))) == len(raw)
    assert (tmp_path / "tables" / "turns-last_leg.mcap").exists()
