"""What a command covers (``tma.plan``: its points, dataset resolution) and the
checks the entry points make before a stage (``pipeline._checks``), on plain configs: no Hydra
is composed or started here (the command line's behaviour is ``tests/test_sweeps.py``)."""

import json

import pytest

from pipeline._checks import check_stage_options
from tma.config_nodes import defaults
from tma.errors import ConfigError, IntegrityError
from tma.families import dataset_name, estimator_class, load_scenario, scenario_module
from tma.plan.datasets import dataset_roots, open_datasets
from tma.plan.points import Override, estimator_configs, scenario_points
from tma.stages.simulate import simulate_datasets


def _scenario(family="bearings2d", **values):
    return {**defaults(scenario_module(family).Config), **values}


def _estimator(name):
    return defaults(estimator_class(name).Config)


def _set(text):
    """An override ``key=value`` (values as the composed config would hold them)."""
    key, value = text.split("=", 1)
    return Override(key.lstrip("~"), text, value if key == "estimator" else None,
                    text.startswith("~"))


def test_a_list_on_a_single_value_is_an_axis_and_axes_multiply():
    points = scenario_points(_scenario("radar2d", speed_m_s=[5.0, 7.0], sigma_m=[3.0, 4.0]))
    assert [(p["speed_m_s"], p["sigma_m"]) for p in points] == [
        (5.0, 3.0), (5.0, 4.0), (7.0, 3.0), (7.0, 4.0)]  # the last axis varies fastest
    assert scenario_points(_scenario(sigma_deg=0.5))[0]["sigma_deg"] == 0.5  # one point
    nested = scenario_points(_scenario(observer={**_scenario()["observer"],
                                                 "speed_m_s": [4.0, 6.0]}))
    assert [p["observer"]["speed_m_s"] for p in nested] == [4.0, 6.0]


def test_a_list_valued_field_is_one_value_not_an_axis():
    points = scenario_points(_scenario("radar2d", radar_xy_m=[1.0, 2.0]))
    assert [p["radar_xy_m"] for p in points] == [[1.0, 2.0]]


def test_empty_axes_are_refused():
    with pytest.raises(ConfigError, match=r"scenario.sigma_deg: an empty list"):
        scenario_points(_scenario(sigma_deg=[]))


def test_an_unknown_family_is_left_to_validation():
    assert scenario_points({"family": "nope", "x": [1, 2]}) == [{"family": "nope", "x": [1, 2]}]


ESTIMATORS = {"lm": _estimator("lm"), "nbearings": _estimator("nbearings")}
KEYS = {**_estimator("lm"), **_estimator("nbearings")}  # the estimator_keys group, merged


def test_without_an_experiment_the_estimator_is_run_as_it_is():
    lm = _estimator("lm")
    assert estimator_configs(lm, None, []) == [lm]


def test_estimator_key_reaches_each_estimator_that_has_it():
    est = {n["name"]: n for n in estimator_configs({**KEYS, "lambda0": 1.0}, ESTIMATORS,
                                                   [_set("estimator.lambda0=1")])}
    assert est["lm"]["lambda0"] == 1.0 and "lambda0" not in est["nbearings"]
    both = estimator_configs({**KEYS, "max_range_rel_sd": 0.3}, ESTIMATORS,
                             [_set("estimator.max_range_rel_sd=0.3")])
    assert [n["max_range_rel_sd"] for n in both] == [0.3, 0.3]
    assert ESTIMATORS["lm"]["lambda0"] != 1.0  # the experiment itself is not edited


def test_estimator_name_runs_one_of_the_experiment():
    assert [n["name"] for n in estimator_configs(KEYS, ESTIMATORS, [_set("estimator=nbearings")])
            ] == ["nbearings"]


@pytest.mark.parametrize("texts, match", [
    (["estimator=imm"], r"estimator=imm: not an estimator of this experiment \(estimators: "
                        r"lm, nbearings\)"),
    (["estimator.p_stay=0.9"], r"no estimator of this run has 'p_stay'"),
    (["estimator=lm", "estimator.rcond=1"], r"no estimator of this run has 'rcond' "
                                            r"\(estimators: lm\)"),
    (["estimators.iv.max_iter=3"], r"'iv' is not run"),
    (["estimator.lambda0=2", "estimators.lm.lambda0=3"], r"both set 'lambda0' of lm"),
    (["~estimator.lambda0=1"], r"choose estimators with estimator=NAME"),
    (["estimator.name=iv"], r"choose estimators with estimator=NAME"),
])
def test_an_override_that_changes_nothing_fails_naming_it(texts, match):
    with pytest.raises(ConfigError, match=match):
        estimator_configs(KEYS, ESTIMATORS, [_set(t) for t in texts])


def test_dataset_roots_by_name_or_by_scenario(tmp_path):
    assert dataset_roots(tmp_path, "trial7", []) == [tmp_path / "datasets" / "trial7"]
    points = scenario_points(_scenario(sigma_deg=[0.1, 0.5], n_tracks=4, shard_size=4))
    names = [dataset_name(*load_scenario(p)) for p in points]
    assert dataset_roots(tmp_path, None, points) == [tmp_path / "datasets" / n for n in names]
    assert names[0] != names[1] and names[0].startswith("bearings2d-sigma0.1-n4-")


def test_open_datasets_says_how_to_create_a_missing_one_and_checks_its_origin(tmp_path):
    point = _scenario(n_tracks=4, shard_size=4)
    with pytest.raises(ConfigError, match=r"no dataset bearings2d-sigma0.5-n4-\w+ in .*: "
                                          r"create it first with\n  python -m pipeline."
                                          r"simulate scenario.n_tracks=4$"):
        open_datasets(tmp_path, None, [point], "scenario.n_tracks=4")
    (root,) = simulate_datasets([point], tmp_path, engine=1, progress=False)
    (dataset,) = open_datasets(tmp_path, None, [point])
    assert dataset.root == root and dataset.family == "bearings2d"
    assert open_datasets(tmp_path, root.name, [])[0].root == root  # dataset=NAME
    manifest = json.loads((root / "manifest.json").read_text())
    assert manifest["config"]["n_tracks"] == 4
    with pytest.raises(IntegrityError, match="not the dataset simulated from this scenario"):
        dataset.check_simulated_from({**manifest["config"], "seed": 1})


OK = {"paths": {"data_dir": "data", "tables_dir": "tables"}, "force": False, "progress": True,
      "estimators": None, "grid": None, "dataset": None, "table": None}


@pytest.mark.parametrize("change, match", [
    ({"colour": 1}, r"unknown option\(s\) colour"),
    ({"paths": {"data_dir": None, "tables_dir": "t"}}, r"paths.data_dir must be a directory"),
    ({"estimators": 5}, r"estimators must be null or \{name: estimator config"),
    ({"estimators": {"lm": 1}}, r"estimators must be null or"),
    ({"grid": 5}, r"grid must be null or \{estimators"),
    ({"grid": {"estimators": {"lm": 1}}}, r"grid must be null or"),
    ({"force": "yes"}, r"force must be true or false, got 'yes'"),
    ({"dataset": "../elsewhere"}, r"dataset"),
])
def test_stage_options_fail_in_one_line_naming_the_key(change, match):
    check_stage_options(OK, set(OK))
    with pytest.raises(ConfigError, match=match):
        check_stage_options({**OK, **change}, set(OK))
