"""The simulated training bundle shared by ``cmnf`` and ``prior_mean``: ``n_paths`` paths of
the dataset's model (``AuvModel.simulate``: every reading, Doppler included; bearings-only
consumers select theirs with ``AuvModel.select_readings``), truth at the observation epochs
(float64) and readings (float32), built in parallel shards and cached as an artefact keyed by
the model, size and seed."""

import numpy as np

from tma.families.bearing_doppler3d.model import AuvModel
from tma.io.artefacts import load_or_build
from tma.runtime.parallel import run_tasks

SHARD = 2500
# About 15 kB per path at the default 101 epochs (float64 truth, float32 observations), held
# in memory at once: beyond this no machine trains on it.
MAX_PATHS = 10_000_000


def _bundle_shard(task):
    record, seed, index, n = task
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))
    # an extreme (valid) model can overflow: the consumers' filters flag such paths
    with np.errstate(over="ignore", invalid="ignore"):
        truth, obs = AuvModel.from_record(record).simulate(n, rng)
        return truth, obs.astype(np.float32)


def bundle_spec(model_record: dict, n_paths: int, seed: int) -> dict:
    return {"model": {**model_record, "no_doppler": False}, "n_paths": n_paths, "seed": seed}


def training_bundle(data_dir, model_record, n_paths, seed, engine=1, progress=False) -> dict:
    """The record of the bundle artefact (simulated on first use)."""
    spec = bundle_spec(model_record, n_paths, seed)

    def build():
        tasks = [(spec["model"], seed, i, min(SHARD, n_paths - i * SHARD))
                 for i in range(-(-n_paths // SHARD))]
        parts = run_tasks(_bundle_shard, tasks, engine=engine, desc="training bundle",
                          progress=progress)
        return {"truth": np.concatenate([p[0] for p in parts]),
                "obs": np.concatenate([p[1] for p in parts])}

    return load_or_build(data_dir, "bundle", spec, build)
