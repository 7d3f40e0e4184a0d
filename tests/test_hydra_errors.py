"""Hydra's own errors and the launchers, as one ``error:`` line and exit status 2 (issue 22,
items 9 and 10): unknown keys and options name the key and the nearest valid one, bad
override syntax or values name the override, a bare argument is ``input=`` for ingest, a
SLURM sweep on a machine without SLURM creates nothing. Each case runs the stage's entry point
in this process (``run_stage_here``)."""

import shutil

import pandas as pd
import pytest

from tests.conftest import run_stage_here
from tma.families.bearings2d.scenario import Config, simulate_shard


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """A CSV bearing log and a regular file where a directory is expected."""
    root = tmp_path_factory.mktemp("hydra_errors")
    log, _ = simulate_shard(Config(n_tracks=2, shard_size=2, sigma_deg=0.3, seed=5), 0)
    pd.DataFrame([{"time_s": t, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
                   "bearing_deg": log.bearing_deg[i, k], "track_id": i}
                  for k, t in enumerate(log.t_s) for i in range(2)]
                 ).to_csv(root / "nav.csv", index=False)
    (root / "file").write_text("a regular file\n")
    return root


# case: (verb, overrides (with {root}), texts the one error line must contain)
CASES = {
    "unknown scenario key": ("simulate", ["scenario.sigma=0.5"],
                             ["scenario.sigma=0.5", "nearest: scenario.sigma_deg"]),
    "unknown estimator key": ("estimate", ["estimator.foo=1"],
                              ["estimator.foo=1", "no key 'foo'", "lambda0, "]),
    "unknown ingest group": ("ingest", ["input={root}/nav.csv", "colums.time=x"],
                             ["colums.time=x", "nearest: columns.time"]),
    "unknown estimator": ("estimate", ["estimator=bogus"],
                          ["estimator=bogus", "no estimator 'bogus'", "lm, mpekf, nbearings"]),
    "misspelt estimator": ("estimate", ["estimator=lmm"], ["estimator=lmm", "nearest: lm"]),
    "unknown estimator in a sweep": ("estimate", ["-m", "estimator=lm,bogus"],
                                     ["estimator=bogus", "no estimator 'bogus'"]),
    "launcher value of the wrong type": (
        "simulate", ["-m", "hydra/launcher=slurm_local", "hydra.launcher.mem_gb=abc",
                     "scenario.sigma_deg=0.1,0.2"],
        ["hydra.launcher.mem_gb=abc", "could not be converted to Integer"]),
    "a lone quote": ("ingest", ["input={root}/nav.csv", 'csv.delimiter="'],
                     ['csv.delimiter="', "cannot parse"]),
    "an unclosed list": ("estimate", ["estimator.lambda0=[1"],
                         ["estimator.lambda0=[1", "cannot parse"]),
    "data dir under a file": ("ingest", ["input={root}/nav.csv", "paths.data_dir={root}/file/d"],
                              ["Not a directory (errno 20)"]),
    "data dir under a file, multirun": ("simulate", ["-m", "paths.data_dir={root}/file/d",
                                                     "scenario.sigma_deg=0.1,0.2"],
                                        ["Not a directory (errno 20)"]),
    "interpolation in the data dir": ("simulate", ["paths.data_dir=${{oc.env:TMA_NOPE}}"],
                                      ["Environment variable 'TMA_NOPE' not found"]),
    "bare argument to estimate": ("estimate", ["trial7"],
                                  ["'trial7' is not KEY=VALUE", "dataset=trial7"]),
    "two bare arguments to ingest": ("ingest", ["{root}/nav.csv", "{root}/other.csv"],
                                     ["is not KEY=VALUE"]),
    "a flag among the overrides": ("simulate", ["scenario.n_tracks=10", "--multirun",
                                                "scenario.sigma_deg=0.1,0.2"],
                                   ["unrecognized arguments: scenario.sigma_deg=0.1,0.2",
                                    "flags such as -m go before the overrides"]),
    "local launcher and a partition": (
        "simulate", ["-m", "hydra/launcher=slurm_local", "hydra.launcher.partition=cpu",
                     "scenario.sigma_deg=0.1,0.2"],
        ["hydra.launcher.partition=cpu", "runs the jobs on this machine"]),
}


def _assert_one_line(proc, expected):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for text in expected:
        assert text in lines[0], lines[0]


@pytest.mark.parametrize("case", sorted(CASES))
def test_hydras_errors_are_one_line(root, tmp_path, case):
    verb, overrides, expected = CASES[case]
    data = tmp_path / "data"
    flags = [o for o in overrides if o == "-m"]  # Hydra's flags go before the overrides
    proc = run_stage_here(verb, *flags, f"paths.data_dir={data}", "progress=false",
                          *[o.format(root=root) for o in overrides if o not in flags],
                          check=False)
    _assert_one_line(proc, expected)
    assert not (data / "datasets").exists() and not (data / "runs").exists()


def test_a_bare_argument_to_ingest_is_its_input(root, tmp_path):
    run_stage_here("ingest", str(root / "nav.csv"), f"paths.data_dir={tmp_path}",
                   "progress=false")
    assert (tmp_path / "datasets" / "nav" / "manifest.json").exists()


def test_a_bare_argument_with_hydra_syntax_in_it_is_quoted(root, tmp_path):
    odd = tmp_path / "a log, [v2].csv"
    shutil.copy(root / "nav.csv", odd)
    run_stage_here("ingest", str(odd), "name=odd", f"paths.data_dir={tmp_path}",
                   "progress=false")
    assert (tmp_path / "datasets" / "odd" / "manifest.json").exists()


@pytest.mark.skipif(shutil.which("srun") is not None, reason="this machine has SLURM")
def test_a_slurm_sweep_without_slurm_creates_nothing(tmp_path):
    data = tmp_path / "data"
    proc = run_stage_here("simulate", "-m", "hydra/launcher=slurm", "scenario.sigma_deg=0.1,0.5",
                          f"paths.data_dir={data}", "progress=false", check=False)
    _assert_one_line(proc, ["hydra/launcher=slurm", "SLURM", "hydra/launcher=slurm_local"])
    assert not data.exists()


@pytest.mark.parametrize("value", ["nav.csv", "a log, [v2].csv", "it's", "back\\slash",
                                   "ends\\", "x${y}", "1e3", "true", "null", "a=b", "~x", 0.0,
                                   None, 1e-5, [1, 2.5], True, "  lead"])
def test_a_value_written_as_an_override_reads_back_as_itself(value):
    """``override_text`` (a bare argument as ``input=``, the overrides that select a run) is
    read back by Hydra's parser and OmegaConf as the value it was written from."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    from tma.plan.points import override_text

    parsed = OverridesParser.create().parse_override(override_text("input", value))
    assert OmegaConf.create({"v": parsed.value()}).v == value


def test_an_unknown_key_names_the_nearest_or_the_keys_there():
    from pipeline._messages import unknown_choice_line, unknown_key_line

    root = {"columns": {"time": None, "x": None}, "csv": {"delimiter": None}}
    assert unknown_key_line(root, "colums", "colums.time=x", "colums.time") == (
        "colums.time=x: no key 'colums' (nearest: columns.time)")
    assert unknown_key_line(root, "colums", "colums.when=x", "colums.when") == (
        "colums.when=x: no key 'colums' (nearest: columns)")
    assert unknown_key_line(root["columns"], "columns.tmie", "columns.tmie=3",
                            "columns.tmie") == (
        "columns.tmie=3: no key 'tmie' in columns (nearest: columns.time)")
    assert unknown_key_line(root["csv"], "csv.foo", "csv.foo=1", "csv.foo") == (
        "csv.foo=1: no key 'foo' in csv (csv has: delimiter)")
    assert unknown_choice_line("hydra/launcher", "slurmm", ["basic", "slurm"]) == (
        "hydra/launcher=slurmm: no launcher 'slurmm' (nearest: slurm)")
