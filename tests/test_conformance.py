"""One conformance suite applied to every registered estimator (the idea of scikit-learn's
``parametrize_with_checks``): a new estimator is checked the day its family registers it.

Each estimator builds from its defaults, refuses a bad value naming the key, is
deterministic, gives per-track results that do not depend on which other tracks share the
shard (nor on their order), and handles a one-track shard.
"""

import dataclasses
from dataclasses import fields
from types import SimpleNamespace

import numpy as np
import pytest

from tma.config import to_plain
from tma.errors import ConfigError
from tma.families import build_estimator, estimator_class, estimator_names, family

N_TRACKS = 7  # differs from every other dimension of the logs below
SMALL = {  # a small, fast scenario of each family
    "bearings2d": {"sigma_deg": 0.5, "seed": 3},
    "ranges2d": {"seed": 3},
    "radar2d": {"seed": 3},
    "bearing_doppler3d": {"duration_s": 10.0, "seed": 3},
}
FAST = {  # settings that keep each check to a fraction of a second
    "prior_is": {"accuracy_m": 2.0},
    "adaptive_is": {"accuracy_m": 2.0},
    "cmnf": {"training_paths": 100},
    "prior_mean": {"bundle_paths": 100},
}


@pytest.fixture(scope="module")
def logs():
    out = {}
    for name, params in SMALL.items():
        scenario = family(name).scenario
        cfg = scenario.Config(n_tracks=N_TRACKS, shard_size=N_TRACKS, **params)
        out[name] = (cfg, scenario.simulate_shard(cfg, 0)[0])
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
        config = cls.prepare(to_plain(build_estimator({"name": name, **FAST.get(name, {})})
                                      .config), dataset, data_dir)
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
