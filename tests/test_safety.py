"""Never destroy what tma did not create; never trust a stored file without a check.

Each test reproduces a defect a fuzzing user found (issue 8, items 1 and 3).
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import REPO, SMALL, compose_cfg, run_stage_here
from tests.families.bearings2d.recorded_geometry import ingest
from tma.errors import ConfigError, InputError, IntegrityError
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.io.owned import MARKER, building


def _tree(root: Path) -> dict:
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _csv(path: Path, n=2, sigma=0.3) -> Path:
    log, _ = simulate_shard(Config(n_tracks=n, shard_size=n, sigma_deg=sigma, seed=5), 0)
    rows = [{"time_s": t, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
             "bearing_deg": log.bearing_deg[i, k], "track_id": i}
            for k, t in enumerate(log.t_s) for i in range(n)]
    pd.DataFrame(rows).to_csv(path, index=False)
    return path


def _user_files(root: Path) -> dict:
    root.mkdir(parents=True, exist_ok=True)
    (root / "thesis.tex").write_text("years of work")
    (root / "sub").mkdir(exist_ok=True)
    (root / "sub" / "data.bin").write_bytes(b"\x00\x01")
    return _tree(root)


@pytest.mark.parametrize("name", ["ABSOLUTE", "../runs", "a/b", ".hidden", "..", "", "x y"])
def test_a_dataset_name_is_a_plain_name(tmp_path, name):
    victim = tmp_path / "victim"
    before = _user_files(victim)
    runs = tmp_path / "data" / "runs"
    runs_before = _user_files(runs)
    name = str(victim) if name == "ABSOLUTE" else name
    with pytest.raises(ConfigError, match="not a plain name"):
        ingest(_csv(tmp_path / "good.csv"), data_dir=tmp_path / "data", name=name, force=True)
    assert _tree(victim) == before and _tree(runs) == runs_before


def test_a_directory_tma_did_not_create_is_never_replaced(tmp_path):
    target = tmp_path / "data" / "datasets" / "trial7"
    before = _user_files(target)  # the user's own folder, no manifest, no marker
    for force in (False, True):
        with pytest.raises(InputError, match="not created by tma"):
            ingest(_csv(tmp_path / "good.csv"), data_dir=tmp_path / "data", name="trial7",
                   force=force)
        assert _tree(target) == before


def test_force_over_a_good_dataset_keeps_it_when_the_new_input_is_bad(tmp_path):
    root = ingest(_csv(tmp_path / "good.csv"), data_dir=tmp_path / "data", name="trial7")
    before = _tree(root)
    bad = tmp_path / "bad.csv"
    bad.write_text((tmp_path / "good.csv").read_text() + "1e3,0,0,not-a-number,0\n")
    with pytest.raises(InputError):
        ingest(bad, data_dir=tmp_path / "data", name="trial7", force=True,
               options={"bad_rows": "fail"})
    assert _tree(root) == before
    assert sorted(p.name for p in root.parent.iterdir()) == [".trial7.lock", "trial7"]
    # and a good replacement does replace it, completely
    ingest(_csv(tmp_path / "other.csv", n=3), data_dir=tmp_path / "data", name="trial7",
           force=True)
    assert json.loads((root / "manifest.json").read_text())["shards"]["log/shard-00000.mcap"][
        "tracks"] == 3


def _finished_run(tmp_path, parallel="serial"):
    cfg = compose_cfg([*SMALL, f"paths.data_dir={tmp_path / 'data'}",
                       f"paths.tables_dir={tmp_path / 'tables'}", f"parallel={parallel}"])
    simulate_stage(cfg)
    estimate_stage(cfg)
    dataset = next((tmp_path / "data" / "datasets").glob("*/manifest.json")).parent
    run = next((tmp_path / "data" / "runs").glob("*/lm-*"))
    return cfg, dataset, run


def _edit_json(path: Path, edit):
    record = json.loads(path.read_text())
    edit(record)
    path.write_text(json.dumps(record, indent=2))


DATASET_DAMAGE = {
    "shard deleted": lambda ds: (ds / "log" / "shard-00001.mcap").unlink(),
    "shard truncated": lambda ds: os.truncate(ds / "log" / "shard-00001.mcap", 100),
    "truth deleted": lambda ds: (ds / "truth.parquet").unlink(),
    "sigma relabelled": lambda ds: _edit_json(
        ds / "manifest.json", lambda m: m["config"].update(sigma_deg=0.4)),
    "content_hash edited": lambda ds: _edit_json(
        ds / "manifest.json", lambda m: m.update(content_hash="0" * 64)),
    "manifest key renamed": lambda ds: _edit_json(
        ds / "manifest.json", lambda m: m.update(shardz=m.pop("shards"))),
    "manifest not JSON": lambda ds: (ds / "manifest.json").write_text("{oops"),
}


@pytest.mark.parametrize("damage", sorted(DATASET_DAMAGE))
def test_a_damaged_dataset_is_refused_even_with_a_finished_run(tmp_path, damage):
    cfg, dataset, run = _finished_run(tmp_path)
    aggregate_stage(cfg)
    DATASET_DAMAGE[damage](dataset)
    run_before = _tree(run)
    for stage in (estimate_stage, aggregate_stage):
        with pytest.raises(IntegrityError):
            stage(cfg)
    assert _tree(run) == run_before
    # simulate notices the damage and makes the dataset again, byte for byte
    simulate_stage(cfg)
    estimate_stage(cfg)
    assert _tree(run) == run_before


RUN_DAMAGE = {
    "manifest not JSON": lambda run: (run / "manifest.json").write_text("[1, 2"),
    "manifest key renamed": lambda run: _edit_json(
        run / "manifest.json", lambda m: m.update(filez=m.pop("files"))),
    "estimates missing": lambda run: (run / "estimates" / "shard-00000.parquet").unlink(),
    "shard output garbage": lambda run: (run / "estimates" / "shard-00002.parquet").write_bytes(
        b"garbage"),
    "sidecar damaged": lambda run: (
        (run / "manifest.json").write_text("[1, 2"),  # the run broken, its shards reusable
        (run / "shards" / "shard-00001.parquet.done.json").write_text("[]")),
    # the folder is read whole: a file that is not the run's would join its estimates
    "stray file among the estimates": lambda run: (
        (run / "estimates" / "shard-00001 (copy).parquet").write_bytes(
            (run / "estimates" / "shard-00001.parquet").read_bytes())),
}


@pytest.mark.parametrize("damage", sorted(RUN_DAMAGE))
def test_a_damaged_run_is_a_clear_error_then_recomputed(tmp_path, damage):
    cfg, _, run = _finished_run(tmp_path)
    before = _tree(run)
    RUN_DAMAGE[damage](run)
    with pytest.raises(IntegrityError if (run / "manifest.json").exists() else InputError,
                       match="re-run estimate|run `python -m pipeline.estimate` first"):
        aggregate_stage(cfg)
    estimate_stage(cfg)
    after = _tree(run)
    for path in before:  # bookkeeping of wall time differs, the outputs do not
        if path.name != "timing.json" and not path.name.endswith(".done.json"):
            assert after[path] == before[path], path
    aggregate_stage(cfg)


def test_a_run_of_the_previous_format_is_recomputed_without_its_copies(tmp_path):
    """A run written before its estimates became a folder (format 2: ``estimates.parquet``,
    the shard outputs in ``shards/``) is computed again in the new layout, and neither its
    concatenated copy nor its old shard files stay beside the new estimates."""
    cfg, _, run = _finished_run(tmp_path)
    before = _tree(run)
    (run / "estimates.parquet").write_bytes(b"format 2's copy")
    (run / "shards" / "shard-00000.parquet").write_bytes(b"format 2's shard output")
    _edit_json(run / "manifest.json", lambda m: m.update(format_version=2))
    with pytest.raises(IntegrityError, match="format version 2 is not supported"):
        aggregate_stage(cfg)
    estimate_stage(cfg)
    after = _tree(run)
    assert not (run / "estimates.parquet").exists()
    assert not (run / "shards" / "shard-00000.parquet").exists()
    assert {p for p in after if not p.name.endswith(".done.json")} == {
        p for p in before if not p.name.endswith(".done.json")}


def test_kill_leaves_the_old_good_output_and_a_resumable_partial(tmp_path):
    """A ``force=true`` simulate killed half-way: the old dataset is untouched, the partial
    is tma's own, and the next run finishes it without leaving temporaries behind."""
    common = [f"paths.data_dir={tmp_path / 'data'}", "scenario.n_tracks=600",
              "scenario.shard_size=20", "progress=false", "parallel=serial"]
    run_stage_here("simulate", *common)
    dataset = next((tmp_path / "data" / "datasets").glob("*/manifest.json")).parent
    before = _tree(dataset)
    partial = dataset.with_name(f".{dataset.name}.partial")
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.simulate", *common, "force=true"],
                            cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(list(partial.glob("log/*.mcap"))) < 3 and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert (partial / MARKER).exists() and _tree(dataset) == before
    (partial / "log" / ".shard-00029.mcap.tmp-999999").write_bytes(b"left by a kill")
    run_stage_here("simulate", *common, "force=true")
    assert _tree(dataset) == before  # same config, same bytes
    leftovers = [p for p in (tmp_path / "data").rglob("*")
                 if ".tmp-" in p.name or ".old-" in p.name or p.name.endswith(".partial")]
    assert leftovers == []


def test_two_simulates_of_the_same_new_dataset_at_once_both_succeed(tmp_path):
    common = [sys.executable, "-m", "pipeline.simulate", f"paths.data_dir={tmp_path}",
              "scenario.n_tracks=1000", "scenario.shard_size=100", "progress=false",
              "parallel=serial"]
    procs = [subprocess.Popen(common, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    results = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], results
    manifests = list(tmp_path.glob("datasets/*/manifest.json"))
    assert len(manifests) == 1
    from tma.io.dataset import Dataset
    Dataset.open(manifests[0].parent).verify()


@pytest.mark.parametrize("resume", [True, False])
def test_building_swaps_complete_outputs_and_keeps_a_failed_one_to_resume(tmp_path, resume):
    """``building``: the lock -> recover -> stage -> swap of simulate, estimate and ingest."""
    target = tmp_path / "out"
    with building([target]) as outputs:
        stage = outputs.stage(target)
        (stage / "a").write_text("1")
        assert outputs.swap(target) == target
    assert (target / "a").read_text() == "1" and (target / MARKER).exists()
    assert not stage.exists() and not (tmp_path / ".out.lock").read_text()
    with pytest.raises(RuntimeError), building([target], resume=resume) as outputs:
        (outputs.stage(target, fresh=True) / "a").write_text("2")
        raise RuntimeError("killed")
    assert (target / "a").read_text() == "1"  # the good output is untouched
    assert stage.exists() == resume  # kept to resume from, or removed
    os.replace(target, tmp_path / f".out.old-{os.getpid()}")  # as a kill inside a swap leaves
    with building([target]) as outputs:  # recovered first
        assert (target / "a").read_text() == "1"
        (outputs.stage(target, adopt=True) / "b").write_text("3")
        outputs.swap(target)
    # resumed from the failed stage, or (none left) from the adopted output
    assert (target / "a").read_text() == ("2" if resume else "1")
    assert (target / "b").read_text() == "3" and not list(tmp_path.glob(".out.partial"))
