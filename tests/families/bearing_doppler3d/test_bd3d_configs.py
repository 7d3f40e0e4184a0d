"""``bearing_doppler3d`` configs: impossible scenarios, initial distributions and filter
settings are refused naming the key."""

import pytest

from tma.errors import ConfigError
from tma.families import build_estimator, load_scenario
from tma.families.bearing_doppler3d.scenario import Config


@pytest.mark.parametrize(("kw", "key"), [
    ({"lam": -0.01}, "lam"),
    ({"mu": -1.0}, "mu"),
    ({"filter_step_s": 0.3}, "filter_step_s"),
    ({"duration_s": 10.5}, "duration_s"),
    ({"sd_doppler_hz": 0.0}, "sd_doppler_hz"),
    ({"sensors_m": [[0.0, 0.0]]}, "sensors_m"),
    ({"seed": -1}, "seed"),
])
def test_impossible_scenarios_are_refused(kw, key):
    with pytest.raises(ConfigError, match=key):
        Config(**kw)


def test_impossible_initial_distributions_are_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"initial.speed_min_m_s"):
        load_scenario({"family": "bearing_doppler3d",
                       "initial": {"speed_min_m_s": 7.0, "speed_max_m_s": 7.0}})
    with pytest.raises(ConfigError, match=r"initial.position_sd_m\[2\] must be finite"):
        load_scenario({"family": "bearing_doppler3d",
                       "initial": {"position_sd_m": [1.0, 1.0, float("inf")]}})


@pytest.mark.parametrize(("node", "key"), [
    ({"name": "cmnf", "pinv_rtol": 2.0}, "pinv_rtol"),
    ({"name": "cmnf", "covariance_every": 0}, "covariance_every"),
    ({"name": "prior_mean", "bundle_seed": -7}, "bundle_seed"),
    ({"name": "srekf", "covariance_every": -1}, "covariance_every"),
])
def test_impossible_filter_configs_are_refused(node, key):
    with pytest.raises(ConfigError, match=key):
        build_estimator(node)
