"""Fixtures the bearings2d tests share."""

import pytest

import tma
from tests.conftest import once_per_run

OWN_MODEL_N, OWN_MODEL_SEED = 1000, 7


@pytest.fixture(scope="session")
def own_model_runs(tmp_path_factory):
    """``lm`` (the declared prior) on 1,000 targets that manoeuvre 3 times an hour, 0.5 deg,
    one shard: ship-like turns (``turn``) and bursts drawn from ``lm``'s own model
    (``burst``): shape -> (dataset, results); once per test run (``once_per_run``)."""
    def runs():
        out = {}
        for shape in ("turn", "burst"):
            ds = tma.simulate("bearings2d", n_tracks=OWN_MODEL_N, sigma_deg=0.5,
                              seed=OWN_MODEL_SEED, shard_size=OWN_MODEL_N,
                              target={"manoeuvres": {"rate_per_h": 3.0, "shape": shape}})
            out[shape] = ds, tma.estimate(ds)
        return out

    return once_per_run(tmp_path_factory, "bearings2d-own-model", runs)
