"""Command-line overrides under an experiment apply or fail in one line, never are ignored;
a multirun of aggregate ends with one table of all its jobs; every run's metrics are one
Parquet dataset (issue "one table per sweep")."""

import json

import pandas as pd
import pyarrow.compute as pc
import pytest
from hydra import compose, initialize_config_dir

from pipeline._common import CONF_DIR, estimator_nodes, scenario_nodes
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import run_stage_here
from tma.errors import ConfigError

SMALL = ["scenario.n_tracks=30", "scenario.shard_size=15", "progress=false", "parallel=serial"]


def _cfg(*overrides):
    """The config a stage gets from this command line (with Hydra's record of it)."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("config", overrides=list(overrides), return_hydra_config=True)


def _estimators(*overrides):
    return {n["name"]: n for n in estimator_nodes(_cfg(*overrides))}


def test_experiment_estimators_take_command_line_values():
    est = _estimators("experiment=bearings2d_table", "estimator.lambda0=1")
    assert est["lm"]["lambda0"] == 1 and "lambda0" not in est["nbearings"]
    est = _estimators("experiment=bearings2d_table", "estimator.max_range_rel_sd=0.3")
    assert est["lm"]["max_range_rel_sd"] == est["nbearings"]["max_range_rel_sd"] == 0.3
    est = _estimators("experiment=bearings2d_table", "estimator.rcond=1e-3")  # nbearings only
    assert est["nbearings"]["rcond"] == 1e-3 and "rcond" not in est["lm"]
    est = _estimators("experiment=radar2d_table", "estimator.p_stay=0.9")  # imm only
    assert est["imm"]["p_stay"] == 0.9 and set(est) == {"alphabeta", "fuzzy_mm", "imm"}
    assert list(_estimators("experiment=bearings2d_table", "estimator=nbearings")) == [
        "nbearings"]


def test_experiment_scenario_values_take_command_line_values():
    def sigmas(*overrides):
        return [n["sigma_deg"] for n in scenario_nodes(_cfg("experiment=bearings2d_table",
                                                            *overrides))]

    assert sigmas() == [0.0, 0.1, 0.2, 0.3, 0.5, 1.0]
    assert sigmas("scenario.sigma_deg=0.7") == [0.7]
    assert sigmas("scenario.sigma_deg=[0.1,0.7]") == [0.1, 0.7]
    nodes = scenario_nodes(_cfg("experiment=radar2d_table", "scenario.speed_m_s=[5.0,7.0]",
                                "scenario.sigma_m=[3.0,4.0]"))  # two axes: their product
    assert [(n["speed_m_s"], n["sigma_m"]) for n in nodes] == [
        (5.0, 3.0), (5.0, 4.0), (7.0, 3.0), (7.0, 4.0)]
    nodes = scenario_nodes(_cfg("scenario=radar2d", "scenario.radar_xy_m=[1.0,2.0]"))
    assert [n["radar_xy_m"] for n in nodes] == [[1.0, 2.0]]  # a list-valued key: one value


@pytest.mark.parametrize("overrides, match", [
    (["experiment=radar2d_table", "estimator.lambda0=1"], "estimator.lambda0=1: no estimator"),
    (["experiment=radar2d_table", "estimator=lm"], "estimator=lm: not an estimator of"),
    (["experiment=radar2d_table", "estimator=imm", "estimator.memory=3"], "'memory'"),
    (["experiment=bearings2d_table", "estimator=lm", "estimators.nbearings.rcond=1"],
     "'nbearings' is not run"),
    (["experiment=bearings2d_table", "estimator.lambda0=1", "estimators.lm.lambda0=2"],
     "both set 'lambda0'"),
    (["experiment=bearings2d_table", "~estimator.lambda0"], "~estimator.lambda0"),
])
def test_overrides_that_would_change_nothing_fail_naming_the_key(overrides, match):
    with pytest.raises(ConfigError, match=match):
        estimator_nodes(_cfg(*overrides))


def test_a_moved_grid_key_fails_naming_the_new_one():
    with pytest.raises(ConfigError, match=r"grid.scenario: .*scenario.sigma_deg=\["):
        scenario_nodes(_cfg("experiment=bearings2d_table", "+grid.scenario.sigma_deg=[0.1]"))


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Two small datasets (sigma 0.1, 0.5), each with an lm and an nbearings run."""
    root = tmp_path_factory.mktemp("sweeps")
    paths = [f"paths.data_dir={root / 'data'}", f"paths.tables_dir={root / 'tables'}"]
    for sigma in (0.1, 0.5):
        simulate_stage(_cfg(*SMALL, *paths, f"scenario.sigma_deg={sigma}"))
        for estimator in ("lm", "nbearings"):
            estimate_stage(_cfg(*SMALL, *paths, f"scenario.sigma_deg={sigma}",
                                f"estimator={estimator}"))
    return root, [*paths, *SMALL]


def test_cli_experiment_applies_overrides(data):
    root, common = data
    before = {p.parent for p in root.glob("data/runs/*/*/manifest.json")}
    run_stage_here("estimate", "experiment=bearings2d_table", *common, "scenario.sigma_deg=0.5",
            "estimator.lambda0=1")
    new = {p.parent for p in root.glob("data/runs/*/*/manifest.json")} - before
    assert len(new) == 1  # nbearings unchanged (reused); lm at one sigma only, lambda0 = 1
    manifest = json.loads((new.pop() / "manifest.json").read_text())
    assert manifest["config"]["name"] == "lm" and manifest["config"]["lambda0"] == 1.0
    assert "sigma0.5" in manifest["dataset"]["name"]
    proc = run_stage_here("estimate", "experiment=radar2d_table", *common, "estimator.lambda0=1",
                          check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: estimator.lambda0=1: no estimator of this run has 'lambda0' "
        "(estimators: alphabeta, fuzzy_mm, imm)"]


def test_cli_aggregate_sweep_writes_one_table_of_all_jobs(data):
    """The jobs record their runs; the sweep's end writes every run's metrics and the one
    table (Markdown, CSV, plot, the paper's section), and nothing else under tables/."""
    root, common = data
    run_stage_here("aggregate", "-m", "estimator=lm,nbearings", "scenario.sigma_deg=0.1,0.5",
                   *common)
    tables = root / "tables"
    sweep = pd.read_csv(tables / "bearings2d-sweep.csv")
    assert list(zip(sweep.estimator, sweep.sigma_deg, strict=True)) == [
        ("lm", 0.1), ("lm", 0.5), ("nbearings", 0.1), ("nbearings", 0.5)]
    assert (sweep.n_tracks == 30).all()
    assert sorted(p.name for p in tables.iterdir()) == [  # no job's own table (job_tables)
        "bearings2d-sweep.csv", "bearings2d-sweep.md", "bearings2d-sweep.png",
        "bearings2d-sweep_paper.csv"]
    assert "| lm |" in (tables / "bearings2d-sweep.md").read_text()
    # the metrics of every run: one dataset, with the run's config values as columns
    from tma.stages.aggregate import metrics_dataset  # (imported here: new in this change)

    metrics = metrics_dataset(root / "data")
    assert metrics.count_rows() == 4 * 30
    df = metrics.to_table(filter=pc.field("scenario.sigma_deg") == 0.5,
                          columns=["estimator", "dataset", "ref1", "estimator.lambda0"]
                          ).to_pandas()
    assert sorted(df.groupby("estimator").size().items()) == [("lm", 30), ("nbearings", 30)]
    assert set(df.loc[df.estimator == "lm", "estimator.lambda0"]) == {10.0}
    assert df.loc[df.estimator == "nbearings", "estimator.lambda0"].isna().all()


def test_cli_experiment_sweep_names_its_tables(data):
    """``job_tables=true``: each job's own table too, named by its number."""
    root, common = data
    run_stage_here("aggregate", "-m", "experiment=bearings2d_table", "estimator=lm,nbearings",
            "scenario.sigma_deg=[0.1,0.5]", "table=exp", "job_tables=true", *common)
    tables = root / "tables"
    assert len(pd.read_csv(tables / "exp.csv")) == 4  # the sweep
    assert [len(pd.read_csv(tables / f"exp-{n}.csv")) for n in (0, 1)] == [2, 2]  # its jobs
    assert set(pd.read_csv(tables / "exp-1.csv").estimator) == {"nbearings"}
