"""``cmnf``: the conditionally minimax nonlinear filter, trained on a simulated bundle.

Offline, on ``training_paths`` paths of the dataset's model: basic prediction
xi = the model's own Euler prediction of the previous estimate over one observation step,
basic correction zeta = y - h(x_tilde). At each epoch, with sample moments over the bundle,
F = Cov(x, xi) Cov(xi)^+, f = E x - F E xi, x_tilde = F xi + f; H = Cov(x - x_tilde, zeta)
Cov(zeta)^+, h = -H E zeta, x_hat = x_tilde + H zeta + h, and the filter's own error
covariance K_hat = Cov(x - x_tilde) - Cov(x - x_tilde, zeta) H^T. Pseudo-inverses by truncated
SVD of the standardised covariance (relative threshold ``pinv_rtol``). The gains are an
artefact (hashed, reused by later runs with the same model and training config) that the run
records; online, the filter applies them to each test path. A missing reading takes its
training mean (it then carries no correction).
"""

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
from tma.families.bearing_doppler3d.model import AuvModel
from tma.families.bearing_doppler3d.training_bundle import MAX_PATHS, training_bundle
from tma.io.artefacts import is_record, load_arrays, load_or_build


@dataclass
class Config(AuvConfig):
    training_paths: int = param(10000, "simulated paths the gains are trained on",
                                f"[100, {MAX_PATHS}]")
    training_seed: int = param(7, "seed of the training paths", "[0, inf)")
    pinv_rtol: float = param(1e-12, "relative threshold of the pseudo-inverses of the gains",
                             "(0, 1)")
    artefact: dict[str, str] | None = param(None, "the trained gains {kind, key, sha256}: set "
                                            "by the estimate stage")

    def __post_init__(self):
        super().__post_init__()
        require(self.artefact is None or is_record(self.artefact), self.where,
                "artefact must be null or {kind, key, sha256} (set by the estimate stage)")


def regression_gain(cov_xy, cov_yy, rtol):
    """cov_xy cov_yy^+ with the pseudo-inverse taken on the standardised (correlation) matrix;
    NaN if a covariance is not finite (an overflowed bundle: the SVD would not converge)."""
    if not (np.isfinite(cov_xy).all() and np.isfinite(cov_yy).all()):
        return np.full(cov_xy.shape, np.nan)
    d = np.sqrt(np.diag(cov_yy))
    d = np.where(d > 0, d, 1.0)
    return (cov_xy / d) @ np.linalg.pinv(cov_yy / np.outer(d, d), rcond=rtol, hermitian=True) / d


def _cov(a, b):
    return (a - a.mean(0)).T @ (b - b.mean(0)) / (a.shape[0] - 1)


def train(truth, obs, predict, observe, rtol):
    """Gains per epoch from a bundle: truth (M, K, d), obs (M, K, m); ``predict(x_hat, k)``
    is the basic prediction to epoch k, ``observe(x)`` the observation function."""
    M, K, d = truth.shape
    m = obs.shape[2]
    gains = {"F": np.zeros((K, d, d)), "f": np.zeros((K, d)), "H": np.zeros((K, d, m)),
             "h": np.zeros((K, d)), "K_hat": np.zeros((K, d, d)), "zeta_mean": np.zeros((K, m))}
    x_hat = None
    for k in range(K):
        x = truth[:, k]
        if k == 0:
            x_tilde = np.broadcast_to(x.mean(0), x.shape).copy()  # xi is constant: F = 0
            gains["f"][0] = x.mean(0)
        else:
            xi = predict(x_hat, k)
            F = regression_gain(_cov(x, xi), _cov(xi, xi), rtol)
            f = x.mean(0) - F @ xi.mean(0)
            x_tilde = xi @ F.T + f
            gains["F"][k], gains["f"][k] = F, f
        zeta = obs[:, k].astype(float) - observe(x_tilde)  # the bundle stores float32
        err = x - x_tilde
        H = regression_gain(_cov(err, zeta), _cov(zeta, zeta), rtol)
        h = -H @ zeta.mean(0)
        x_hat = x_tilde + zeta @ H.T + h
        gains["H"][k], gains["h"][k], gains["zeta_mean"][k] = H, h, zeta.mean(0)
        gains["K_hat"][k] = _cov(err, err) - _cov(err, zeta) @ H.T
    return gains


def apply(gains, obs, predict, observe):
    """Run the trained filter on paths with observations obs (n, K, m); NaN readings take
    their training mean. Returns the estimates (n, K, d)."""
    n, K, _ = obs.shape
    est = np.empty((n, K, gains["f"].shape[1]))
    x_hat = None
    for k in range(K):
        if k == 0:
            x_tilde = np.broadcast_to(gains["f"][0], (n, gains["f"].shape[1])).copy()
        else:
            x_tilde = predict(x_hat, k) @ gains["F"][k].T + gains["f"][k]
        zeta = obs[:, k] - observe(x_tilde)
        zeta = np.where(np.isfinite(zeta), zeta, gains["zeta_mean"][k])
        x_hat = x_tilde + zeta @ gains["H"][k].T + gains["h"][k]
        est[:, k] = x_hat
    return est


def model_functions(model, t):
    """The AUV model's basic prediction (its Euler prediction of the mean over
    [t_(k-1), t_k]) and observation function, on paths-first arrays (n, 6) as ``train`` and
    ``apply`` take them."""

    def predict(x_hat, k):
        return model.predict_mean(x_hat.T, t[k] - t[k - 1]).T

    def observe(x):
        return model.observe(x.T).T

    return predict, observe


class CMNF(AuvEstimator):
    training_size = "training_paths"
    conformance_config = {"training_paths": 100}
    Config = Config

    @classmethod
    def prepare(cls, config: dict, dataset, data_dir, engine=1, progress=False) -> dict:
        """Train (or reuse) the gains for the dataset's model; returns the config with the
        artefact's record (kind, key, sha256), which the run manifest keeps."""
        record = dataset_model_record(dataset)
        bundle = training_bundle(data_dir, record, config["training_paths"],
                                 config["training_seed"], engine, progress)
        spec = {"model": record, "bundle": bundle["sha256"], "pinv_rtol": config["pinv_rtol"]}

        def build():
            arrays = load_arrays(bundle, data_dir)
            model = AuvModel.from_record(record)
            obs = model.select_readings(arrays["obs"])  # the bundle holds every reading
            # a bundle that overflowed gives non-finite gains: the paths are flagged online
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                return train(arrays["truth"], obs, *model_functions(model, model.epochs()),
                             config["pinv_rtol"])

        return {**config, "artefact": load_or_build(data_dir, cls.name, spec, build)}

    def solve(self, model: AuvModel, readings: Readings) -> Solution:
        gains = load_arrays(self.config.artefact, self.data_dir)
        est = apply(gains, readings.obs, *model_functions(model, readings.t_s))
        n, K, _ = readings.obs.shape
        cov = np.broadcast_to(gains["K_hat"][None], (n, K, 6, 6))
        return Solution(est, cov, np.isfinite(est).all(axis=(1, 2)))
