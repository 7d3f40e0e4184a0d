"""simulate -> estimate -> aggregate: end to end, determinism, resume, integrity, sweeps."""

import json
import logging
import os
from pathlib import Path

import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import SMALL, compose_cfg, run_cli, run_stage_here
from tma.errors import ConfigError, IntegrityError
from tma.plan import renamed
from tma.plan.command import Command
from tma.plan.renamed import deprecation_note, renamed_arguments

EXPECTED_COLUMNS = (
    "estimator,sigma_deg,n_tracks,ref1,ref1_lo,ref1_hi,ref2,ref2_lo,ref2_hi,ref3,ref3_lo,"
    "ref3_hi,ref4,ref4_lo,ref4_hi,sqrt_ka_mean,sqrt_ka_median,nf_median,iter_median,n_converged,"
    "n_ok,n_not_converged,n_poor_fit,n_unobservable,n_manoeuvring,n_approximate,consistent,"
    "consistent_lo,consistent_hi"
)
GRID = ["experiment=bearings2d_table", "scenario.n_tracks=60", "scenario.shard_size=25",
        "scenario.sigma_deg=[0.0,0.5]", "progress=false"]


def _all_stages(overrides):
    cfg = compose_cfg(overrides)
    simulate_stage(cfg)
    estimate_stage(cfg)
    aggregate_stage(cfg)
    return cfg


def _files(root: Path):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and "hydra" not in p.parts
            # wall-clock bookkeeping (timing.json, shard sidecars) is not output
            and p.name != "timing.json" and not p.name.endswith(".done.json")}


def test_end_to_end_table(paths, tmp_path):
    _all_stages([*GRID, *paths])
    tables = tmp_path / "tables"
    csv = (tables / "bearings2d.csv").read_text().splitlines()
    assert csv[0] == EXPECTED_COLUMNS
    df = pd.read_csv(tables / "bearings2d.csv")
    assert list(zip(df.estimator, df.sigma_deg, strict=True)) == [
        ("lm", 0.0), ("lm", 0.5), ("nbearings", 0.0), ("nbearings", 0.5)]
    assert (df.n_tracks == 60).all()
    exact = df[df.sigma_deg == 0]
    assert (exact.ref1 == 1.0).all()  # noiseless: both estimators recover every target
    lm = df[(df.estimator == "lm") & (df.sigma_deg == 0.5)].iloc[0]
    assert 0.4 < lm.sqrt_ka_median < 0.6
    assert lm.ref1_lo <= lm.ref1 <= lm.ref1_hi
    assert (tables / "bearings2d.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| lm | 0.5 | 60 |" in (tables / "bearings2d.md").read_text()
    runs = list((tmp_path / "data" / "runs").glob("*/lm-*"))
    metrics = pd.read_parquet(runs[0] / "metrics.parquet")
    assert len(metrics) == 60 and {"ref1", "bearing_err_deg"} <= set(metrics.columns)
    manifest = json.loads(next((tmp_path / "data" / "datasets").glob("*/manifest.json"))
                          .read_text())
    assert manifest["seed"] == 20260101 and manifest["package"]["name"] == "tma"
    assert all(len(r["sha256"]) == 64 for r in manifest["shards"].values())
    assert manifest["files"]["truth.parquet"]["rows"] == 60


def test_the_kind_of_table_is_declared_not_read_off_its_name(paths, tmp_path, monkeypatch,
                                                              caplog):
    """``table_kind=benchmark`` writes the benchmark table under any name; a kind the family
    does not have is one line naming those it has. The spellings of 0.6.0 (``report=``,
    ``grid.estimators.``) still work for one release, each with one line saying so."""
    _all_stages([*GRID, *paths])
    run_stage_here("aggregate", *GRID, *paths, "table=mine", "table_kind=benchmark")
    mine = (tmp_path / "tables" / "mine.md").read_text()
    assert "efficiency" in (tmp_path / "tables" / "mine.csv").read_text().splitlines()[0]
    proc = run_stage_here("aggregate", *GRID, *paths, "table_kind=bogus", check=False)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "table_kind=bogus: bearings2d has no such table; its kinds: benchmark, manoeuvre" \
        in proc.stderr

    monkeypatch.setattr(renamed, "_noted", set())
    with caplog.at_level(logging.WARNING, logger="tma"):
        run_stage_here("aggregate", *GRID, *paths, "table=old", "report=benchmark",
                       "grid.estimators.lm.max_iter=200")  # lm's default: the same runs
    notes = [r.getMessage() for r in caplog.records if "deprecated" in r.getMessage()]
    assert notes == [deprecation_note("report", "table_kind"),
                     deprecation_note("grid.estimators", "estimators")]
    assert all("\n" not in note for note in notes)
    old = (tmp_path / "tables" / "old.md").read_text()
    assert old.replace("old", "mine") == mine.replace("old", "mine")  # the same table


def test_an_experiment_written_in_the_old_spelling_runs_as_the_new_one(monkeypatch, caplog):
    """An experiment's file of 0.6.0 (``grid: {estimators: ...}``, ``report:``) is read as
    ``estimators`` and ``table_kind``, with one line each; ``grid`` holds nothing else."""
    lm, iv = {"name": "lm", "max_iter": 5}, {"name": "iv"}
    monkeypatch.setattr(renamed, "_noted", set())
    with caplog.at_level(logging.WARNING, logger="tma"):
        cmd = Command({"estimator": lm, "grid": {"estimators": {"lm": lm, "iv": iv}},
                       "report": "benchmark", "estimators": {"lm": {"name": "lm"}}})
        cmd.get("estimators")  # read when the stage first asks
    assert cmd.get("estimators") == {"lm": lm, "iv": iv} and "grid" not in cmd.settings
    assert cmd.get("table_kind") == "benchmark" and "report" not in cmd.settings
    assert [r.getMessage() for r in caplog.records] == [
        deprecation_note("grid.estimators", "estimators"),
        deprecation_note("report", "table_kind")]
    with pytest.raises(ConfigError, match=r"report=manoeuvre and table_kind=benchmark: give "):
        Command({"report": "manoeuvre", "table_kind": "benchmark"}).get("table_kind")
    with pytest.raises(ConfigError, match=r"grid.scenario: grid took only 'estimators'"):
        Command({"grid": {"scenario": {"sigma_deg": [0.1]}}}).get("scenario")
    assert renamed_arguments(["+estimator@grid.estimators.iv=iv", "report=manoeuvre,benchmark",
                              "~report", "-m", "grid.x=1", "estimator.report=1"]) == [
        "+estimator@estimators.iv=iv", "table_kind=manoeuvre,benchmark", "~table_kind", "-m",
        "grid.x=1", "estimator.report=1"]


def test_outputs_do_not_depend_on_n_jobs(tmp_path):
    trees = []
    for n_jobs in (1, 2):
        root = tmp_path / f"jobs{n_jobs}"
        _all_stages([*GRID, f"paths.data_dir={root}", f"paths.tables_dir={root}/tables",
                     f"parallel.n_jobs={n_jobs}"])
        trees.append(_files(root))
    assert trees[0].keys() == trees[1].keys()
    differing = [str(k) for k in trees[0] if trees[0][k] != trees[1][k]]
    assert differing == []
    assert any(k.parent.name == "estimates" for k in trees[0])


def test_one_process_table_writes_what_the_three_commands_write(tmp_path):
    """``python -m pipeline.table`` (what ``make table`` runs) against the three verbs run
    one after the other: the same datasets, runs and tables, byte for byte; with 2 joblib
    workers, so that runs are finished while others still compute."""
    trees = []
    for way in ("verbs", "table"):
        root = tmp_path / way
        overrides = [*GRID, f"paths.data_dir={root}", f"paths.tables_dir={root}/tables",
                     "parallel.n_jobs=2"]
        if way == "verbs":
            _all_stages(overrides)
        else:
            proc = run_cli("table", *overrides)
            assert [line.split(" - ")[1].split(":")[0] for line in proc.stdout.splitlines()
                    if "stage " in line] == ["stage simulate", "stage estimate",
                                            "stage aggregate"]
        trees.append(_files(root))
    assert trees[0].keys() == trees[1].keys()
    assert [str(k) for k in trees[0] if trees[0][k] != trees[1][k]] == []
    assert len({k.parent for k in trees[0] if k.parent.name == "estimates"}) == 4


def test_a_table_whose_estimate_fails_keeps_the_dataset_and_says_one_line(tmp_path):
    proc = run_stage_here("table", *GRID, f"paths.data_dir={tmp_path}",
                          f"paths.tables_dir={tmp_path}/tables", "estimator=lm",
                          "estimator.max_iter=-3", check=False)
    assert proc.returncode == 2 and proc.stderr.count("error:") == 1, proc.stderr
    assert "max_iter" in proc.stderr
    assert len(list(tmp_path.glob("datasets/*/manifest.json"))) == 2  # simulate finished


def test_rerun_reuses_shards_resumes_and_force_recomputes(paths, tmp_path):
    overrides = [*SMALL, *paths, "parallel=serial"]
    cfg = compose_cfg(overrides)
    simulate_stage(cfg)
    estimate_stage(cfg)
    run = next((tmp_path / "data" / "runs").glob("*/lm-*"))
    shards = sorted((run / "estimates").glob("*.parquet"))
    assert len(shards) == 3 and not (run / "estimates.parquet").exists()  # no copy
    stamps = {p: os.stat(p).st_mtime_ns for p in shards}
    before = {p: p.read_bytes() for p in shards}

    # a killed run: one shard output lost
    shards[1].unlink()
    estimate_stage(cfg)
    assert os.stat(shards[0]).st_mtime_ns == stamps[shards[0]]  # reused
    assert os.stat(shards[2]).st_mtime_ns == stamps[shards[2]]
    assert {p: p.read_bytes() for p in shards} == before

    # a damaged shard output fails its hash check and is recomputed
    shards[2].write_bytes(b"garbage")
    estimate_stage(cfg)
    assert {p: p.read_bytes() for p in shards} == before

    estimate_stage(compose_cfg([*overrides, "force=true"]))
    assert os.stat(shards[0]).st_mtime_ns != stamps[shards[0]]
    assert {p: p.read_bytes() for p in shards} == before


def test_simulate_resumes_after_a_kill(paths, tmp_path):
    cfg = compose_cfg([*SMALL, *paths, "parallel=serial"])
    simulate_stage(cfg)
    ds = next((tmp_path / "data" / "datasets").glob("*/manifest.json")).parent
    reference = _files(ds)
    (ds / "manifest.json").unlink()  # killed before the manifest was written
    simulate_stage(cfg)
    assert _files(ds) == reference


def test_tampered_dataset_is_refused(paths, tmp_path):
    cfg = compose_cfg([*SMALL, *paths, "parallel=serial"])
    simulate_stage(cfg)
    shard = next((tmp_path / "data" / "datasets").glob("*/log/shard-00001.mcap"))
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(bytes(data))
    with pytest.raises(IntegrityError, match="does not match the manifest"):
        estimate_stage(cfg)


def test_a_truncated_shard_stops_estimate_before_any_work(paths, tmp_path):
    """Before a stage starts, every file of its datasets is checked to be there at its size
    (no reading); a shard cut short fails there, before a worker starts or a run is made."""
    cfg = compose_cfg([*SMALL, *paths, "parallel=serial"])
    simulate_stage(cfg)
    shard = next((tmp_path / "data" / "datasets").glob("*/log/shard-00002.mcap"))
    shard.write_bytes(shard.read_bytes()[:-100])
    with pytest.raises(IntegrityError, match="truncated or replaced"):
        estimate_stage(cfg)
    assert not (tmp_path / "data" / "runs").exists()


def test_each_stage_checks_the_sha256_of_what_it_reads(paths, tmp_path):
    """The sha256 of a file is checked where its bytes are read: aggregate reads the truth
    (refused when edited) and not the logs, whose results are the finished runs."""
    cfg = compose_cfg([*SMALL, *paths, "parallel=serial"])
    simulate_stage(cfg)
    estimate_stage(cfg)
    dataset = next((tmp_path / "data" / "datasets").glob("*/manifest.json")).parent
    for name in ("log/shard-00001.mcap", "truth.parquet"):
        data = bytearray((dataset / name).read_bytes())
        data[len(data) // 2] ^= 0xFF  # same size: only the hash tells
        (dataset / name).write_bytes(bytes(data))
    with pytest.raises(IntegrityError, match="truth.parquet: sha256 .* does not match"):
        aggregate_stage(cfg)
    with pytest.raises(IntegrityError, match="shard-00001.mcap: sha256 .* does not match"):
        estimate_stage(compose_cfg([*SMALL, *paths, "parallel=serial", "force=true"]))


def test_the_table_command_loads_the_family_aggregate_while_the_workers_estimate():
    import sys

    from tma.stages.aggregate import prefetch_aggregate

    thread = prefetch_aggregate("ranges2d")
    thread.join()
    assert "tma.families.ranges2d.aggregate" in sys.modules
    assert prefetch_aggregate("nosuch") is None


def test_a_runs_estimates_are_its_shard_files_read_as_one_dataset(paths, tmp_path):
    """Issue 32, item 3: a run's estimates are the folder of its shard files, no concatenated
    copy: pandas and pyarrow read it in one call, rows in shard order (the dataset's track
    order), the same table aggregate reads; ``metrics_dataset`` reads the folders too."""
    import pyarrow.dataset as pds

    from tma.io.dataset import Dataset
    from tma.io.runs import open_run
    from tma.stages.aggregate import metrics_dataset

    cfg = compose_cfg([*SMALL, *paths, "parallel.n_jobs=2"])
    simulate_stage(cfg)
    estimate_stage(cfg)
    run = next((tmp_path / "data" / "runs").glob("*/lm-*"))
    folder = run / "estimates"
    manifest, table = open_run(run)
    assert sorted(p.name for p in folder.iterdir()) == sorted(manifest["shards"]) == [
        "shard-00000.parquet", "shard-00001.parquet", "shard-00002.parquet"]
    assert not list(run.glob("*estimates*.parquet"))
    frame = pd.read_parquet(folder)
    pd.testing.assert_frame_equal(frame, table.to_pandas())
    pd.testing.assert_frame_equal(pds.dataset(folder).to_table().to_pandas(), frame)
    truth = Dataset.open(run.parent.parent.parent / "datasets" / run.parent.name).read_truth()
    assert frame["track_id"].tolist() == truth["track_id"].tolist() == sorted(
        truth["track_id"])  # shard order
    parts = [pd.read_parquet(folder / name) for name in sorted(manifest["shards"])]
    pd.testing.assert_frame_equal(frame, pd.concat(parts, ignore_index=True))
    every = metrics_dataset(tmp_path / "data", name="estimates").to_table().to_pandas()
    ours = every[every["run"] == run.name].reset_index(drop=True)
    pd.testing.assert_frame_equal(ours[frame.columns], frame)


def test_cli_sweep_and_joblib_launcher(tmp_path):
    common = [f"paths.data_dir={tmp_path}", "scenario.n_tracks=30", "scenario.shard_size=15",
              "progress=false"]
    run_stage_here("simulate", "-m", "scenario.sigma_deg=0.1,0.5", *common)
    run_stage_here("estimate", "-m", "estimator=lm,nbearings", "scenario.sigma_deg=0.1,0.5",
                   *common)
    runs = sorted(p.parent.name + "/" + p.name.split("-")[0]
                  for p in tmp_path.glob("runs/*/*/estimates"))
    assert len(runs) == 4
    stamp = {p: p.stat().st_mtime_ns for p in tmp_path.glob("runs/*/*/estimates/*.parquet")}
    proc = run_cli("estimate", "-m", "hydra/launcher=parallel", "estimator=lm,nbearings",
                   "scenario.sigma_deg=0.1,0.5", *common)
    output = proc.stdout + proc.stderr
    assert "Joblib.Parallel(n_jobs=2" in output and "is launching 4 jobs" in output
    assert "shards run serially inside each job" in output  # one parallel layer only
    assert {p: p.stat().st_mtime_ns for p in stamp} == stamp  # finished shards reused
