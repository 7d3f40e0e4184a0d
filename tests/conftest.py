"""Shared fixtures: Hydra compose against the repo's conf/, small datasets in tmp dirs."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from pipeline._common import CONF_DIR

REPO = Path(__file__).resolve().parents[1]
SMALL = ["scenario.n_tracks=60", "scenario.shard_size=25", "progress=false"]


def compose_cfg(overrides=(), config_name="config"):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(config_name=config_name, overrides=list(overrides))


def run_cli(verb, *overrides, check=True, cwd=REPO):
    """Run ``python -m pipeline.<verb>`` in a subprocess; returns the CompletedProcess."""
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.run([sys.executable, "-m", f"pipeline.{verb}", *overrides], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)
    if check and proc.returncode != 0:
        raise AssertionError(f"pipeline.{verb} failed:\n{proc.stdout}\n{proc.stderr}")
    return proc


@pytest.fixture
def paths(tmp_path):
    return [f"paths.data_dir={tmp_path / 'data'}", f"paths.tables_dir={tmp_path / 'tables'}"]
