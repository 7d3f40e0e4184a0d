"""``prior_mean``: the unconditional mean of the state at each epoch (the mean of a large
simulated bundle, shared with ``cmnf``), with the bundle's covariance as its own error
covariance. It ignores the observations: the baseline every filter must beat."""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.bearing_doppler3d.estimators.base import (
    AuvConfig,
    AuvEstimator,
    Readings,
    Solution,
    dataset_model_record,
)
from tma.families.bearing_doppler3d.training_bundle import MAX_PATHS, training_bundle
from tma.io.artefacts import is_record, load_arrays


@dataclass
class Config(AuvConfig):
    bundle_paths: int = param(10000, "simulated paths whose mean is the estimate",
                              f"[100, {MAX_PATHS}]")
    bundle_seed: int = param(7, "seed of the bundle (by default the same bundle as cmnf's)",
                             "[0, inf)")
    artefact: dict[str, str] | None = param(None, "the bundle's mean {kind, key, sha256}: set "
                                            "by the estimate stage")

    def __post_init__(self):
        super().__post_init__()
        require(self.artefact is None or is_record(self.artefact), self.where,
                "artefact must be null or {kind, key, sha256} (set by the estimate stage)")


class PriorMean(AuvEstimator):
    training_size = "bundle_paths"  # the simulated paths its mean and covariance come from
    conformance_config = {"bundle_paths": 100}
    Config = Config

    @classmethod
    def prepare(cls, config: dict, dataset, data_dir, engine=1, progress=False) -> dict:
        record = dataset_model_record(dataset)
        bundle = training_bundle(data_dir, record, config["bundle_paths"], config["bundle_seed"],
                                 engine, progress)
        return {**config, "artefact": bundle}

    def solve(self, model, readings: Readings) -> Solution:
        truth = load_arrays(self.config.artefact, self.data_dir)["truth"]
        if truth.shape[1] != readings.t_s.size:
            raise ValueError("the bundle's epochs differ from the log's")
        mean = truth.mean(axis=0)  # (K, 6)
        centred = truth - mean
        cov = np.einsum("mki,mkj->kij", centred, centred) / (truth.shape[0] - 1)
        n = readings.obs.shape[0]
        return Solution(np.broadcast_to(mean, (n, *mean.shape)).copy(),
                        np.broadcast_to(cov, (n, *cov.shape)), np.ones(n, dtype=bool))
