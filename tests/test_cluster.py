"""Shards on a Dask cluster (a LocalCluster of two worker processes, as ``parallel=dask``
starts one): the same bytes as in this process, and a worker killed mid-run costs only its
shard. Sweeps through the SLURM preset's local twin (submitit's local executor)."""

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from pipeline._common import engine, scenario_nodes
from tests.conftest import compose_cfg, run_cli
from tests.test_pipeline import GRID, _all_stages, _files
from tma.errors import ConfigError, InputError
from tma.parallel import Engine, close_dask_clients, dask_client, run_tasks
from tma.simulate import simulate_datasets

pytest.importorskip("distributed")
DASK = Engine(kind="dask", n_workers=2)


@pytest.fixture(scope="module", autouse=True)
def cluster():
    yield dask_client(DASK.address, DASK.n_workers)
    close_dask_clients()


def test_parallel_dask_gives_the_bytes_of_parallel_serial(tmp_path):
    trees = []
    for choice in ("serial", "dask"):
        root = tmp_path / choice
        _all_stages([*GRID, f"paths.data_dir={root}", f"paths.tables_dir={root}/tables",
                     f"parallel={choice}"])
        trees.append(_files(root))
    assert trees[0].keys() == trees[1].keys()
    assert [str(k) for k in trees[0] if trees[0][k] != trees[1][k]] == []
    assert sum(str(k).endswith("estimates.parquet") for k in trees[0]) == 4


def _kill_when_shards_exist(stage: Path, pid: int, at: int, report: dict):
    deadline = time.monotonic() + 120
    while len(list(stage.glob("log/shard-*.mcap"))) < at and time.monotonic() < deadline:
        time.sleep(0.005)
    report["manifest before kill"] = (stage.parent / stage.name[1:-8] / "manifest.json").exists()
    report["shards before kill"] = len(list(stage.glob("log/shard-*.mcap")))
    os.kill(pid, signal.SIGKILL)


def test_a_worker_killed_mid_run_costs_only_its_shard(tmp_path, cluster):
    nodes = scenario_nodes(compose_cfg(["scenario.n_tracks=900", "scenario.shard_size=15"]))
    victim = next(iter(cluster.run(os.getpid).values()))
    name = simulate_datasets(nodes, tmp_path / "serial", engine=1, progress=False)[0].name
    stage = tmp_path / "dask" / "datasets" / f".{name}.partial"
    report = {}
    killer = threading.Thread(target=_kill_when_shards_exist, args=(stage, victim, 6, report))
    killer.start()
    simulate_datasets(nodes, tmp_path / "dask", engine=DASK, progress=False)
    killer.join()
    assert not report["manifest before kill"] and report["shards before kill"] < 60
    assert victim not in cluster.run(os.getpid).values()  # the nanny started a new worker
    serial, dask = _files(tmp_path / "serial"), _files(tmp_path / "dask")
    assert serial == dask  # nothing half-written, nothing missing, the same bytes
    assert not list((tmp_path / "dask").rglob("*.tmp-*"))


@pytest.mark.parametrize(("override", "message"), [
    ("parallel.address=nowhere", "parallel.address must be null or a scheduler address"),
    ("parallel.n_workers=0", "parallel.n_workers must be a whole number >= 1"),
    ("+parallel.threads=4", "unknown option(s) parallel.threads"),
])
def test_bad_cluster_options_are_one_clear_line(override, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        engine(compose_cfg(["parallel=dask", override]))


def test_slurm_preset_composes_and_its_local_twin_runs_a_sweep_one_layer_deep(tmp_path):
    slurm = compose_cfg(["hydra/launcher=slurm", f"paths.data_dir={tmp_path}"],
                        return_hydra_config=True).hydra.launcher
    assert slurm._target_.endswith("SlurmLauncher") and slurm.cpus_per_task == 1
    common = [f"paths.data_dir={tmp_path}", "scenario.n_tracks=40", "scenario.shard_size=20",
              "progress=false"]
    proc = run_cli("simulate", "-m", "hydra/launcher=slurm_local", "scenario.sigma_deg=0.1,0.5",
                   *common)
    assert "Submitit 'local' sweep output dir" in proc.stdout + proc.stderr
    datasets = sorted(tmp_path.glob("datasets/*/manifest.json"))
    assert len(datasets) == 2
    logs = list(tmp_path.glob("hydra/simulate-multirun/*/*/simulate.log"))
    assert len(logs) == 2
    assert all(p.read_text().count("shards run serially inside each job") == 1 for p in logs)
    # the jobs' results on the console (issue 22, item 9), in job order; no folder named %j
    shown = [line for line in proc.stdout.splitlines() if "][tma][INFO] - dataset " in line]
    assert [line.split()[0] for line in shown] == ["#0", "#1"]
    assert sorted(line.split()[-1] for line in shown) == [str(p.parent) for p in datasets]
    assert not [p for p in tmp_path.rglob("*") if "%" in p.name]


def _refuse_three(task):
    if task == 3:
        raise InputError(f"shard {task}: bad input")
    return task * 2


def test_a_failing_shard_stops_the_run_with_its_own_error():
    with pytest.raises(InputError, match="shard 3: bad input"):
        run_tasks(_refuse_three, range(40), engine=DASK, progress=False)
    assert run_tasks(_refuse_three, [1, 2], engine=DASK, progress=False) == [2, 4]
