"""Local workers of a command fork from a server that imported what they need
(``tma.runtime.forkserver.preload_workers``): no thread runs in it when it forks, Python
sessions keep loky's own start, and a sweep's jobs (the joblib Hydra launcher's workers) see the
sweep and write what the same points give in one command, byte for byte."""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from tests.conftest import REPO, run_cli

LINUX = pytest.mark.skipif(sys.platform != "linux", reason="the fork server is Linux's only")

PROBE = """
import json, os, sys
from tma.runtime.forkserver import preload_workers
from tma.runtime.parallel import run_tasks

def probe(_):
    ppid = os.getppid()
    with open(f"/proc/{ppid}/status") as f:
        threads = next(int(line.split()[1]) for line in f if line.startswith("Threads:"))
    return {"ppid": ppid, "parent_threads": threads,
            "preloaded": "tma.stages.estimate" in sys.modules}

if __name__ == "__main__":
    server = preload_workers(["pipeline._common", "matplotlib.pyplot"])  # as a sweep does
    print(json.dumps({"server": server, "main": os.getpid(),
                      "workers": run_tasks(probe, [0, 1, 2, 3], engine=2, progress=False)}))
"""


def _probe(tmp_path, env=None) -> tuple[dict, str]:
    script = tmp_path / "probe.py"
    script.write_text(PROBE)
    proc = subprocess.run([sys.executable, str(script)], cwd=REPO, check=True,
                          capture_output=True, text=True, env={**os.environ, **(env or {})})
    return json.loads(proc.stdout), proc.stderr


@LINUX
def test_workers_fork_from_a_server_where_no_thread_runs(tmp_path):
    out, _ = _probe(tmp_path)
    assert out["server"] is True
    parents = {w["ppid"] for w in out["workers"]}
    assert len(parents) == 1 and out["main"] not in parents  # forked by the server
    assert all(w["parent_threads"] == 1 for w in out["workers"])
    assert all(w["preloaded"] for w in out["workers"])  # its imports came with the fork


@LINUX
def test_a_module_that_fails_in_the_server_is_left_to_the_workers(tmp_path):
    """matplotlib refuses an unknown backend with a ValueError: multiprocessing's server would
    die of it (it survives ImportError only); tma's leaves the module to the worker."""
    out, err = _probe(tmp_path, {"MPLBACKEND": "no-such-backend"})
    assert len({w["ppid"] for w in out["workers"]}) == 1 and out["main"] not in {
        w["ppid"] for w in out["workers"]}
    assert "Traceback" not in err


@pytest.mark.parametrize(("argv", "command"), [
    (["python", "-m", "pipeline.table", "-m", "estimator=lm"], "pipeline.table"),
    (["python", "-X", "importtime", "-m", "pipeline.simulate"], "pipeline.simulate"),
    (["python", "-m", "pipeline"], None),
    (["python", "-c", "import pipeline"], None),
    (["python", "-m", "pytest", "-m", "pipeline.table"], None),
    (["python", "script.py", "-m", "pipeline.table"], None),
    (["python", "-W", "error", "-m", "pipeline.aggregate", "table=x"], "pipeline.aggregate"),
    (["python", "-m"], None),
])
def test_a_command_is_recognised_by_how_python_was_started(monkeypatch, argv, command):
    import pipeline

    monkeypatch.setattr(sys, "orig_argv", argv)
    assert pipeline._command() == command


@LINUX
def test_a_command_runs_its_shards_in_forked_workers_and_says_nothing_else(tmp_path):
    """The command line itself, with warnings shown: its workers fork from the server."""
    proc = run_cli("simulate", "scenario.n_tracks=40", "scenario.shard_size=20",
                   "progress=false", "parallel.n_jobs=2", "hydra.verbose=tma.runtime.forkserver",
                   f"paths.data_dir={tmp_path}", warnings=True)
    output = proc.stdout + proc.stderr
    assert "local workers fork from the server that preloaded their modules" in output
    assert "Warning" not in output and "Traceback" not in output


def _estimates(data: Path) -> dict:
    return {p.relative_to(data).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(data.glob("runs/*/*/estimates/*.parquet"))}


def test_a_sweep_on_the_joblib_launcher_gives_the_points_of_one_command(tmp_path):
    """``-m hydra/launcher=parallel``: four jobs in forked workers, each one point; their
    sweep table has the four rows (the jobs saw the sweep's id), and the same points in one
    command give the same runs byte for byte."""
    small = ["scenario.n_tracks=30", "scenario.shard_size=15", "progress=false"]
    sweep = tmp_path / "sweep"
    proc = run_cli("table", "-m", "hydra/launcher=parallel", *small,
                   "scenario.sigma_deg=0.1,0.5", "estimator=lm,nbearings",
                   f"paths.data_dir={sweep}/data", f"paths.tables_dir={sweep}/tables",
                   f"hydra.sweep.dir={sweep}/multirun", warnings=True)
    assert "Traceback" not in proc.stderr and "Warning" not in proc.stderr
    table = pd.read_csv(sweep / "tables" / "bearings2d-sweep.csv")
    assert sorted(zip(table.estimator, table.sigma_deg, strict=True)) == [
        ("lm", 0.1), ("lm", 0.5), ("nbearings", 0.1), ("nbearings", 0.5)]
    assert sorted(p.name for p in (sweep / "tables").iterdir()) == [  # the sweep's only
        "bearings2d-sweep.csv", "bearings2d-sweep.md", "bearings2d-sweep.png",
        "bearings2d-sweep_paper.csv"]
    assert len(list((sweep / "data").glob("runs/*/*/metrics.parquet"))) == 4
    one = tmp_path / "one"
    run_cli("table", *small, "scenario.sigma_deg=[0.1,0.5]",
            "+estimator@estimators.lm=lm", "+estimator@estimators.nbearings=nbearings",
            f"paths.data_dir={one}/data", f"paths.tables_dir={one}/tables")
    runs = _estimates(sweep / "data")
    assert len({Path(k).parents[1] for k in runs}) == 4 and runs == _estimates(one / "data")
