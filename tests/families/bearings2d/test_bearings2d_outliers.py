"""``scenario.outliers.prob``: the share of replaced bearings, their distribution, and prob 0
leaving every dataset exactly as it was before the option existed."""

import hashlib

import numpy as np
import pytest
from scipy.stats import binomtest, kstest

from tma.errors import ConfigError
from tma.families.bearings2d.scenario import Config, OutlierConfig, label, simulate_shard

# sha256 of the bearings and truth columns of Config(n_tracks=7, shard_size=5, sigma_deg=0.3)
# shards 0 and 1, computed before outliers.prob was added: prob 0 must keep every byte.
BEFORE = {0: "c349da5f7ab0ab0056ef79c3c14c3077379d9b493ab398d529572d893b8b7cff",
          1: "fb7d4241d96d9cce96a032685d732e05b1dee26222a13426938047199e6d46f3"}


def _digest(log, truth) -> str:
    h = hashlib.sha256(np.ascontiguousarray(log.bearing_deg).tobytes())
    for column in truth.column_names:
        h.update(np.ascontiguousarray(truth[column].to_numpy()).tobytes())
    return h.hexdigest()


def _shard(prob, n=200, sigma=0.5, seed=3):
    cfg = Config(n_tracks=n, shard_size=n, sigma_deg=sigma, seed=seed,
                 outliers=OutlierConfig(prob=prob))
    return simulate_shard(cfg, 0)


@pytest.mark.parametrize("shard", [0, 1])
def test_prob_zero_keeps_todays_bytes(shard):
    cfg = Config(n_tracks=7, shard_size=5, sigma_deg=0.3)
    assert cfg.outliers.prob == 0
    assert _digest(*simulate_shard(cfg, shard)) == BEFORE[shard]
    assert label(cfg) == "sigma0.3-n7"  # dataset names without outliers unchanged too


@pytest.mark.parametrize("prob", [0.01, 0.05, 0.1])
def test_share_of_replaced_bearings_matches_prob(prob):
    clean, truth_clean = _shard(0.0)
    dirty, truth_dirty = _shard(prob)
    assert truth_dirty.equals(truth_clean)  # same targets
    replaced = dirty.bearing_deg != clean.bearing_deg
    n = replaced.size
    # a replaced bearing equal to the clean one has probability 0; the count is binomial
    test = binomtest(int(replaced.sum()), n, prob)
    assert test.pvalue > 1e-3, (replaced.mean(), prob)
    lo, hi = test.proportion_ci(0.999)
    assert lo <= prob <= hi


def test_replacements_are_uniform_on_the_circle_and_independent_of_the_truth():
    clean, _ = _shard(0.0, n=300)
    dirty, _ = _shard(0.1, n=300)
    replaced = dirty.bearing_deg != clean.bearing_deg
    wild = dirty.bearing_deg[replaced]
    assert kstest(wild / 360.0, "uniform").pvalue > 1e-3
    # wrapped error of an outlier: uniform too (it carries no information about the target)
    error = (wild - clean.bearing_deg[replaced] + 180.0) % 360.0
    assert kstest(error / 360.0, "uniform").pvalue > 1e-3
    # the other bearings keep their noise: the outlier stream is apart from the noise stream
    np.testing.assert_array_equal(dirty.bearing_deg[~replaced], clean.bearing_deg[~replaced])


def test_outliers_of_a_smaller_prob_are_a_subset_and_do_not_depend_on_sigma():
    clean = _shard(0.0)[0].bearing_deg
    few = _shard(0.02)[0].bearing_deg != clean
    many = _shard(0.1)[0].bearing_deg != clean
    assert few.sum() > 0 and not (few & ~many).any()
    clean_s, dirty_s = _shard(0.0, sigma=1.0)[0].bearing_deg, _shard(0.1, sigma=1.0)[0].bearing_deg
    np.testing.assert_array_equal(dirty_s != clean_s, many)


def test_all_outliers_and_label():
    clean, _ = _shard(0.0, n=5)
    dirty, _ = _shard(1.0, n=5)
    assert (dirty.bearing_deg != clean.bearing_deg).all()
    assert label(Config(n_tracks=5, outliers=OutlierConfig(prob=0.05))) == "sigma0.5-out0.05-n5"


@pytest.mark.parametrize("prob", [-0.1, 1.5, float("nan"), float("inf")])
def test_bad_prob_is_refused_naming_the_key(prob):
    with pytest.raises(ConfigError, match="outliers.prob"):
        Config(outliers=OutlierConfig(prob=prob))
