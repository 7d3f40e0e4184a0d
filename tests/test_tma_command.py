"""The ``tma`` command that ``pip install`` puts beside the interpreter (``[project.scripts]``):
``tma <verb> [overrides]`` runs the Hydra app of ``python -m pipeline.<verb>``, the same bytes
and the same one-line errors, from any directory; ``tma --help`` lists the verbs. Run as a user
runs it: the installed script, in a new process."""

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from pipeline import VERBS
from tests.conftest import REPO
from tma.families.bearings2d.scenario import Config, simulate_shard

TMA = Path(sys.executable).with_name("tma")  # where pip installs it, beside the interpreter


def _tma(*args, cwd, check=True, warnings=False):
    """``tma ARGS`` in ``cwd``; ``warnings``: Python's default filters, as a user runs it."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    if not warnings:
        env["PYTHONWARNINGS"] = "ignore"
    proc = subprocess.run([str(TMA), *args], cwd=cwd, capture_output=True, text=True, env=env,
                          timeout=600)
    if check and proc.returncode != 0:
        raise AssertionError(f"tma {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
    return proc


def _module(verb, *args, cwd):
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-m", f"pipeline.{verb}", *args], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc


def test_the_command_is_installed_and_lists_the_verbs(tmp_path):
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"tma": "pipeline.cli:main"}
    assert TMA.is_file() and os.access(TMA, os.X_OK), "pip install -e . installs bin/tma"
    listed = _tma("--help", cwd=tmp_path).stdout
    assert all(f"\n  {verb} " in listed for verb in VERBS)
    for args, line in [((), "error: tma needs a verb: simulate, ingest, estimate, aggregate or "
                            "table (tma --help says what each does)"),
                       (("tabel", "input=x.csv"), "error: tma tabel: no verb 'tabel' (nearest: "
                                                  "table; tma --help lists them)")]:
        proc = _tma(*args, cwd=tmp_path, check=False)
        assert (proc.returncode, proc.stderr.strip(), proc.stdout) == (2, line, "")
    help_text = _tma("ingest", "--help", cwd=tmp_path).stdout  # Hydra's help of the app
    assert "ingest is powered by Hydra" in help_text and "csv:" in help_text


def test_tma_table_is_python_m_pipeline_table(tmp_path):
    """``tma table input=log.csv`` (run elsewhere than the checkout) writes what ``python -m
    pipeline.table input=log.csv`` writes, byte for byte; a bad option is the same one line."""
    log, _ = simulate_shard(Config(n_tracks=2, shard_size=2, sigma_deg=0.3, seed=5), 0)
    pd.DataFrame([{"time_s": t, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
                   "bearing_deg": log.bearing_deg[i, k], "track_id": i}
                  for k, t in enumerate(log.t_s) for i in range(2)]).to_csv(
        tmp_path / "log.csv", index=False)
    for run, where in ((_tma, "a"), (_module, "b")):
        (tmp_path / where).mkdir()
        run("table", f"input={tmp_path / 'log.csv'}", "sigma_deg=0.3", "progress=false",
            cwd=tmp_path / where)
    for name in ("log-lm.csv", "log-lm.md"):
        assert (tmp_path / "a" / "tables" / name).read_bytes() == \
            (tmp_path / "b" / "tables" / name).read_bytes()
    assert sorted(p.name for p in (tmp_path / "a" / "data" / "hydra").iterdir()) == ["table"]
    bad = _tma("ingest", str(tmp_path / "log.csv"), "csv.delimiter=::", cwd=tmp_path / "a",
               check=False)
    assert bad.returncode == 2 and bad.stderr.strip() == (
        "error: csv.delimiter must be one character or one of comma, semicolon, tab, \\t, "
        "pipe, space, got '::'")


@pytest.mark.skipif(sys.platform != "linux", reason="the fork server is Linux's")
def test_its_workers_fork_from_the_server_as_the_module_commands_do(tmp_path):
    proc = _tma("simulate", "scenario.n_tracks=40", "scenario.shard_size=20", "progress=false",
                "parallel.n_jobs=2", "hydra.verbose=tma.runtime.forkserver",
                f"paths.data_dir={tmp_path}", cwd=tmp_path, warnings=True)
    output = proc.stdout + proc.stderr
    assert "local workers fork from the server that preloaded their modules" in output
    assert "Warning" not in output and "Traceback" not in output
