"""ranges2d input: the range log round trip, bad logs, impossible configs."""

import numpy as np
import pytest

from tma.errors import ConfigError, InputError
from tma.families import build_estimator
from tma.families.ranges2d.log import read_ranges_log, write_ranges_log
from tma.families.ranges2d.scenario import Config, simulate_shard


def _log(n=1, **kw):
    return simulate_shard(Config(n_tracks=n, shard_size=n, **kw), 0)[0]


def test_ranges_log_round_trip_and_bad_input(tmp_path):
    log = _log(n=3, mode="population")
    write_ranges_log(tmp_path / "r.mcap", log)
    back = read_ranges_log(tmp_path / "r.mcap")
    np.testing.assert_array_equal(back.ranges_m, log.ranges_m)
    assert back.model == log.model
    for edit, message in [(lambda r: r.__setitem__((1, 0, 2), -5.0), "negative range"),
                          (lambda r: r.__setitem__((0, 1, 0), np.nan), "NaN range")]:
        bad = _log(n=3, mode="population")
        edit(bad.ranges_m)
        write_ranges_log(tmp_path / "bad.mcap", bad)
        with pytest.raises(InputError, match=message):
            read_ranges_log(tmp_path / "bad.mcap")
    one = _log(n=1, ranges_m=[[2981.0], [2969.0]])
    one.ranges_m = one.ranges_m[:, :1, :]
    one.landmarks_m = one.landmarks_m[:1]
    with pytest.raises(InputError, match="fewer ranges"):
        one.validate("test")


@pytest.mark.parametrize(("node", "key"), [
    ({"name": "prior_is", "min_samples": 1}, "min_samples"),
    ({"name": "prior_is", "max_samples": 10, "min_samples": 100}, "max_samples"),
    ({"name": "prior_is", "seed": -1}, "seed"),
    ({"name": "adaptive_is", "box_m": [0.0, 1.0, float("nan"), 1.0]}, r"box_m\[2\]"),
    ({"name": "adaptive_is", "shift": 0.0}, "shift"),
    ({"name": "adaptive_is", "max_mass_outside": 2.0}, "max_mass_outside"),
    ({"name": "quadrature", "log_cut": float("inf")}, "log_cut"),
    ({"name": "quadrature", "search_sd": -1.0}, "search_sd"),
])
def test_impossible_estimator_configs_are_refused(node, key):
    with pytest.raises(ConfigError, match=key):
        build_estimator(node)


@pytest.mark.parametrize(("kw", "key"), [
    ({"ranges_m": [[2981.0, -5.0], [2969.0, 3002.0]]}, "ranges_m"),
    ({"mode": "population", "n_pairs": 1, "landmarks_m": [[0.0, 0.0]]}, "at least 2 ranges"),
    ({"prior_sd_m": [100.0, 0.0]}, "prior_sd_m"),
    ({"seed": -3}, "seed"),
])
def test_impossible_scenarios_are_refused(kw, key):
    with pytest.raises(ConfigError, match=key):
        Config(**kw)
