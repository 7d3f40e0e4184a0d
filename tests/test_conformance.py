"""One conformance suite applied to every registered estimator (the idea of scikit-learn's
``parametrize_with_checks``): a new estimator is checked the day its family registers it.

Each estimator builds from its defaults, refuses a bad value naming the key, is
deterministic, gives per-track results that do not depend on which other tracks share the
shard (nor on their order), handles a one-track shard, gives the columns it declares, has
its name written once, and runs through the stages a user runs, estimate and aggregate (a
field the metrics or the report need and it forgot fails there). It runs on the small
scenario and with the fast settings it declares itself (``conformance_scenario``,
``conformance_config``): a new family or estimator needs no edit here.
"""

import dataclasses
import re
import sys
from dataclasses import fields
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tma.config import to_plain
from tma.errors import ConfigError
from tma.families import build_estimator, estimator_class, estimator_names, family

N_TRACKS = 7  # differs from every other dimension of the logs below


@pytest.fixture(scope="module")
def logs():
    """A small log of each family, the scenario its estimators declare
    (``Estimator.conformance_scenario``)."""
    out = {}
    for name in estimator_names():
        cls = estimator_class(name)
        if cls.family not in out:
            scenario = family(cls.family).scenario
            cfg = scenario.Config(n_tracks=N_TRACKS, shard_size=N_TRACKS,
                                  **cls.conformance_scenario)
            out[cls.family] = (cfg, scenario.simulate_shard(cfg, 0)[0])
    return out


@pytest.fixture(scope="module")
def estimators(logs, tmp_path_factory):
    """Each estimator with its fast settings, prepared (trained) once for its family's log."""
    data_dir = tmp_path_factory.mktemp("artefacts")
    built = {}
    for name in estimator_names():
        cls = estimator_class(name)
        cfg, _ = logs[cls.family]
        dataset = SimpleNamespace(family=cls.family, manifest={"config": to_plain(cfg)})
        config = cls.prepare(to_plain(build_estimator({"name": name,
                                                       **cls.conformance_config}).config),
                             dataset, data_dir)
        estimator = build_estimator(config)
        estimator.data_dir = data_dir
        built[name] = estimator
    return built


def _subset(log, rows):
    """The log of tracks ``rows`` only (arrays whose first axis is the track axis)."""
    n = log.track_id.size
    changes = {f.name: getattr(log, f.name)[rows] for f in fields(log)
               if isinstance(getattr(log, f.name), np.ndarray)
               and getattr(log, f.name).ndim and getattr(log, f.name).shape[0] == n}
    return dataclasses.replace(log, **changes)


def _run(estimator, log):
    out = estimator.estimate(log)
    out.pop("extras", None)  # side tables, e.g. one track's draws for a plot
    return out


def _assert_rows_equal(full, part, rows):
    assert full.keys() == part.keys()
    for column, values in full.items():
        expected, got = np.asarray(values)[rows], np.asarray(part[column])
        if expected.dtype.kind == "f":
            np.testing.assert_allclose(got, expected, rtol=1e-9, atol=0, err_msg=column)
        else:
            np.testing.assert_array_equal(got, expected, err_msg=column)


@pytest.mark.parametrize("name", estimator_names())
def test_builds_from_its_defaults_and_refuses_a_bad_value(name):
    cls = estimator_class(name)
    assert build_estimator({"name": name}).config == cls.Config()
    numeric = next(f.name for f in fields(cls.Config) if f.type in (float, int, "float", "int"))
    with pytest.raises(ConfigError, match=numeric):
        build_estimator({"name": name, numeric: float("nan")})


@pytest.mark.parametrize("name", estimator_names())
def test_is_deterministic(name, logs, estimators):
    log = logs[estimator_class(name).family][1]
    first, second = _run(estimators[name], log), _run(estimators[name], log)
    for column, values in first.items():
        np.testing.assert_array_equal(values, second[column], err_msg=column)


@pytest.mark.parametrize("name", estimator_names())
def test_a_track_does_not_depend_on_its_batch(name, logs, estimators):
    log = logs[estimator_class(name).family][1]
    full = _run(estimators[name], log)
    for rows in ([5, 2, 0], [3]):  # other companions, another order, and a one-track shard
        rows = np.array(rows)
        _assert_rows_equal(full, _run(estimators[name], _subset(log, rows)), rows)


@pytest.mark.parametrize("name", estimator_names())
def test_its_declared_outputs_appear(name, logs, estimators):
    cls = estimator_class(name)
    out = estimators[name].estimate(logs[cls.family][1])
    assert set(cls.outputs) <= set(out), set(cls.outputs) - set(out)
    assert set(cls.side_tables) <= set(out.get("extras", {})), cls.side_tables


@pytest.mark.parametrize("name", estimator_names())
def test_its_name_is_written_once(name):
    """The name is its module's file name: no registry key, ``Config.name`` or class
    attribute spells it again (``tma.estimator.module_name``)."""
    cls = estimator_class(name)
    module = sys.modules[cls.__module__]
    assert Path(module.__file__).stem == name == cls.name == cls.Config().name
    package = Path(sys.modules[f"tma.families.{cls.family}"].__file__).parent
    spelled = [str(p.relative_to(package)) for p in package.rglob("*.py")
               if re.search(rf"[\"']{re.escape(name)}[\"']", p.read_text())
               and p.name in (f"{name}.py", "__init__.py")]
    assert spelled == [], f"'{name}' written again in {spelled}"


@pytest.mark.parametrize("name", estimator_names())
def test_it_runs_through_estimate_and_aggregate(name, tmp_path):
    """The stages a user runs, on its family's small scenario: simulate, estimate with its
    fast settings, aggregate into its family's table. An estimator that leaves out what the
    metrics or the report read (a counter, a stop reason, a declared column) fails here, not
    in a user's first table."""
    from tests.conftest import data_paths, run_stage_here

    cls = estimator_class(name)
    scenario = [f"scenario.{k}={v}" for k, v in cls.conformance_scenario.items()]
    # a family whose table measures its estimators against a reference runs that one too
    references = [other for other in estimator_names() if other != name
                  and estimator_class(other).family == cls.family
                  and estimator_class(other).reference]
    if references:
        estimators = [f"+estimator@estimators.{e}={e}" for e in (name, *references)]
        estimators += [f"estimators.{name}.{k}={v}"
                       for k, v in cls.conformance_config.items()]
    else:
        estimators = [f"estimator={name}", *[f"estimator.{k}={v}"
                                             for k, v in cls.conformance_config.items()]]
    run_stage_here("table", f"scenario={cls.family}", f"scenario.n_tracks={N_TRACKS}",
                   f"scenario.shard_size={N_TRACKS}", *scenario, *estimators,
                   "progress=false", *data_paths(tmp_path))
    tables = list((tmp_path / "tables").glob("*.md"))
    assert tables, f"{name}: aggregate wrote no table"
    runs = list((tmp_path / "data" / "runs").glob(f"*/{name}-*/metrics.parquet"))
    assert runs, f"{name}: no metrics"
