"""One conformance suite applied to every registered estimator (the idea of scikit-learn's
``parametrize_with_checks``): a new estimator is checked the day its family registers it.

Each estimator builds from its defaults and what it needs (``data_dir``, at construction),
refuses a bad value naming the key, returns the one output type of every family
(``tma.estimator.Estimates``: columns of its log's tracks, the side tables it declares) from
its family's typed result, is deterministic, gives per-track results that do not depend on
which other tracks share the shard (nor on their order), handles a one-track shard, gives the
columns it declares, has its name written once, lives in its family's ``estimators/`` with
nothing there but estimators and the family's base, and runs through the stages a user runs,
estimate and aggregate (a field the metrics or the report need and it forgot fails there).
It runs on the small scenario and with the fast settings it declares itself
(``conformance_scenario``, ``conformance_config``): a new family or estimator needs no edit
here.
"""

import dataclasses
import inspect
import re
import sys
import typing
from dataclasses import fields
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tma.config import to_plain
from tma.errors import ConfigError
from tma.estimator import Estimates
from tma.families import NAMES, build_estimator, estimator_class, estimator_names, family
from tma.stages.estimate import columns_to_table

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
        built[name] = build_estimator(config, data_dir)
    return built


def _subset(log, rows):
    """The log of tracks ``rows`` only (arrays whose first axis is the track axis)."""
    n = log.track_id.size
    changes = {f.name: getattr(log, f.name)[rows] for f in fields(log)
               if isinstance(getattr(log, f.name), np.ndarray)
               and getattr(log, f.name).ndim and getattr(log, f.name).shape[0] == n}
    return dataclasses.replace(log, **changes)


def _run(estimator, log):
    return estimator.estimate(log).columns  # (not the side tables: one track's draws...)


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
    # a number, or a number or null (an estimator whose settings are all optional)
    numeric = next(f.name for f in fields(cls.Config)
                   if {f.type, *typing.get_args(f.type)} & {float, int, "float", "int"})
    with pytest.raises(ConfigError, match=numeric):
        build_estimator({"name": name, numeric: float("nan")})


@pytest.mark.parametrize("name", estimator_names())
def test_it_returns_the_one_output_type(name, logs, estimators):
    """``Estimates`` whatever the family: a column per output, each of the log's tracks
    first; what the estimate stage writes of it is a table of those tracks."""
    log = logs[estimator_class(name).family][1]
    out = estimators[name].estimate(log)
    assert type(out) is Estimates
    out.check(estimators[name], N_TRACKS)  # what the estimate stage checks (estimate_log)
    assert all(isinstance(v, np.ndarray) for v in out.columns.values())
    for side in out.side_tables.values():
        assert all(isinstance(v, np.ndarray) for v in side.values())
    table = columns_to_table(log.track_id, out.columns)
    assert sorted(set(table.column("track_id").to_pylist())) == sorted(log.track_id.tolist())


@pytest.mark.parametrize("name", estimator_names())
def test_its_solve_is_typed_as_its_familys(name):
    """The hook an estimator writes, ``solve``, takes and returns its family's declared
    types (the family's base says which; no dict, no tuple, no magic key), and what it needs
    from outside comes at construction."""
    cls = estimator_class(name)
    base = next(b for b in cls.__mro__ if b.__dict__.get("family") == cls.family)
    declared = typing.get_type_hints(base.solve)
    assert "return" in declared and dataclasses.is_dataclass(declared["return"]), declared
    assert typing.get_type_hints(cls.solve).get("return", declared["return"]) is \
        declared["return"]
    params = [p for p in inspect.signature(base.solve).parameters if p != "self"]
    assert all(dataclasses.is_dataclass(declared[p]) for p in params), declared
    assert list(inspect.signature(cls.__init__).parameters) == ["self", "config", "data_dir"]


def test_the_contract_refuses_what_breaks_it(logs, estimators):
    """What the core refuses of an estimator's output (``Estimates.check``): a column that is
    not one value per track, per-step columns of two lengths, an undeclared side table."""
    estimator = next(e for e in estimators.values() if e.side_tables)
    declared = estimator.side_tables[0]
    ok = np.zeros(N_TRACKS)
    for bad, says in (({"x": np.zeros(N_TRACKS - 1)}, "shaped"),
                      ({"x": np.zeros((N_TRACKS, 2)), "y": np.zeros((N_TRACKS, 3))}, "steps")):
        with pytest.raises(RuntimeError, match=says):
            Estimates(bad).check(estimator, N_TRACKS)
    with pytest.raises(RuntimeError, match="declared"):
        Estimates({"x": ok}, {f"not_{declared}": {"x": ok}}).check(estimator, N_TRACKS)
    with pytest.raises(RuntimeError, match="one length"):
        Estimates({"x": ok}, {declared: {"x": ok[:3], "y": ok}}).check(estimator, N_TRACKS)
    Estimates({"x": ok}, {declared: {"x": ok[:3], "y": ok[:3]}}).check(estimator, N_TRACKS)


@pytest.mark.parametrize("name", NAMES)
def test_its_estimators_folder_holds_estimators(name):
    """Every file of a family's ``estimators/`` is one of its registered estimators (or the
    family's base): what is not an estimator lives beside them, named for what it is."""
    package = Path(sys.modules[family(name).scenario.__name__].__file__).parent
    files = {p.stem for p in (package / "estimators").glob("*.py")} - {"__init__", "base"}
    assert files == set(family(name).estimators)


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
    assert set(cls.outputs) <= set(out.columns), set(cls.outputs) - set(out.columns)
    assert set(cls.side_tables) <= set(out.side_tables), cls.side_tables


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
