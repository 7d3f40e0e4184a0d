"""Fixtures the bearings2d tests share."""

import pytest

import tma

OWN_MODEL_N, OWN_MODEL_SEED = 800, 7
# the tests that read own_model_runs, in one pytest worker (make test: --dist loadgroup)
OWN_MODEL = pytest.mark.xdist_group("bearings2d_own_model")


@pytest.fixture(scope="session")
def own_model_runs():
    """``lm`` (the declared prior) on 800 targets that manoeuvre 3 times an hour, 0.5 deg,
    one shard: ship-like turns (``turn``) and bursts drawn from ``lm``'s own model
    (``burst``): shape -> (dataset, results)."""
    out = {}
    for shape in ("turn", "burst"):
        ds = tma.simulate("bearings2d", n_tracks=OWN_MODEL_N, sigma_deg=0.5,
                          seed=OWN_MODEL_SEED, shard_size=OWN_MODEL_N,
                          target={"manoeuvres": {"rate_per_h": 3.0, "shape": shape}})
        out[shape] = ds, tma.estimate(ds)
    return out
