"""``prior_mean``: the unconditional mean of the state at each epoch (the mean of a large
simulated bundle, shared with ``cmnf``), with the bundle's covariance as its own error
covariance. It ignores the observations: the baseline every filter must beat."""

from dataclasses import dataclass

import numpy as np

from tma.config import require
from tma.families.bearing_doppler3d.estimators.base import AuvEstimator, dataset_model_record
from tma.families.bearing_doppler3d.estimators.bundle import MAX_PATHS, training_bundle
from tma.io.artefacts import is_record, load_arrays


@dataclass
class Config:
    name: str = "prior_mean"
    bundle_paths: int = 10000
    bundle_seed: int = 7  # the same bundle as cmnf's by default
    covariance_every: int = 10
    artefact: dict[str, str] | None = None  # filled in by the estimate stage

    def __post_init__(self):
        w = "estimator 'prior_mean'"
        require(100 <= self.bundle_paths <= MAX_PATHS, w,
                f"bundle_paths must be in [100, {MAX_PATHS}]")
        require(self.bundle_seed >= 0, w, "bundle_seed must be >= 0")
        require(self.covariance_every >= 1, w, "covariance_every must be >= 1")
        require(self.artefact is None or is_record(self.artefact), w,
                "artefact must be null or {kind, key, sha256} (set by the estimate stage)")


class PriorMean(AuvEstimator):
    training_size = "bundle_paths"  # the simulated paths its mean and covariance come from
    name = "prior_mean"
    Config = Config

    @classmethod
    def prepare(cls, config: dict, dataset, data_dir, engine=1, progress=False) -> dict:
        record = dataset_model_record(dataset)
        bundle = training_bundle(data_dir, record, config["bundle_paths"], config["bundle_seed"],
                                 engine, progress)
        return {**config, "artefact": bundle}

    def solve(self, model, t, obs):
        truth = load_arrays(self.config.artefact, self.data_dir)["truth"]
        if truth.shape[1] != t.size:
            raise ValueError("the bundle's epochs differ from the log's")
        mean = truth.mean(axis=0)  # (K, 6)
        centred = truth - mean
        cov = np.einsum("mki,mkj->kij", centred, centred) / (truth.shape[0] - 1)
        n = obs.shape[0]
        return (np.broadcast_to(mean, (n, *mean.shape)).copy(),
                np.broadcast_to(cov, (n, *cov.shape)), np.ones(n, dtype=bool))
