"""Shared pieces of the ``bearing_doppler3d`` estimators: the contract between the base and an
estimator (the family's model and the ``Readings`` in, a ``Solution`` out of ``solve``).

Every estimator receives the family's model (``AuvModel``, built from the log's model
record) and never simulates itself: the maths of the model lives in ``model.py`` alone.

Filters keep paths on the last axis (state (6, n), covariance (6, 6, n)) so that each state
row is a contiguous vector over paths: the compiled prediction loops over blocks of paths
innermost (SIMD across paths). Both Kalman filters propagate the covariance of the
Euler-discretised linearised SDE over each step dt: with Phi = I + F dt (F the drift
Jacobian at the mean), P <- Phi P Phi^T + b b^T dt, b = (0, 0, 0, 0, 0, mu): the Euler step of
dP = (F P + P F^T + b b^T) dt plus its own O(dt^2) term F P F^T dt^2, which keeps P positive
definite and is exactly what the square-root filter propagates. Observations are processed as
scalars in sequence against one linearisation point per epoch (the batch EKF update, since R
is diagonal); a missing reading (NaN) is skipped.

Outputs per path and epoch: the estimate and its standard deviations; the covariance's upper
triangle every ``covariance_every`` epochs goes to the run's ``covariance.parquet`` (for
NEES); ``filter_ok`` is False for a path whose estimate or covariance became non-finite or
whose covariance has a negative variance (it is kept, the others go on).
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param
from tma.estimator import Estimates, Estimator, EstimatorConfig
from tma.families.bearing_doppler3d.log import HydrophoneLog
from tma.families.bearing_doppler3d.model import STATE_NAMES, AuvModel, model_record

IU = np.triu_indices(6)
BLOCK_PATHS = 128  # paths per block of the compiled prediction (cache-resident)


def dataset_model_record(dataset) -> dict:
    """The model record of a dataset of this family (from its manifest's scenario config):
    what ``prepare`` trains for."""
    return model_record(dataset.manifest["config"])


@dataclass
class AuvConfig(EstimatorConfig):
    """What every ``bearing_doppler3d`` filter's config holds."""

    covariance_every: int = param(10, "store the full covariance every this many epochs "
                                  "(for the NEES)", "[1, inf)")


@dataclass(frozen=True)
class Readings:
    """One shard's readings as every estimator takes them: the epochs ``t_s`` (K,, s) and the
    hydrophones' readings ``obs`` (n, K, m: per sensor elevation sine, bearing cosine and,
    with Doppler, the frequency (Hz), in the model's order; NaN where missing)."""

    t_s: np.ndarray
    obs: np.ndarray


@dataclass(frozen=True)
class Solution:
    """What ``solve`` returns: each path's estimated state ``mean`` (n, K, 6, in the order of
    ``model.STATE_NAMES``) and its own error ``covariance`` (n, K, 6, 6) at every epoch, and
    ``filter_ok`` (n,): False where the estimator knows the path went wrong (non-finite)."""

    mean: np.ndarray
    covariance: np.ndarray
    filter_ok: np.ndarray


class AuvEstimator(Estimator):
    """Base of the ``bearing_doppler3d`` estimators; subclasses implement ``solve``. Every
    output carries per path and epoch the state, its own standard deviations and the path's
    ``filter_ok``, and the side table ``covariance``."""

    side_tables = ("covariance",)  # full covariances every covariance_every epochs
    family = "bearing_doppler3d"
    conformance_scenario = {"duration_s": 10.0, "seed": 3}
    training_size = None  # the config field holding the paths it was trained on, if any

    def estimate(self, log: HydrophoneLog) -> Estimates:
        """The ``Estimates`` of every path of ``log``: its model and ``Readings``, ``solve``,
        the columns (``output_columns``)."""
        model = AuvModel.from_record(log.model)
        if log.obs.shape[2] != model.n_obs:
            raise ValueError(f"the log holds {log.obs.shape[2]} readings per epoch, the model "
                             f"{model.n_obs}")
        # a wrecked path overflows on its own (paths never mix); it is flagged, not raised
        with np.errstate(all="ignore"):
            solution = self.solve(model, Readings(log.t_s, log.obs))
            return output_columns(solution, log.t_s, self.config.covariance_every,
                                  log.track_id)

    def solve(self, model: AuvModel, readings: Readings) -> Solution:
        """The estimator's own step: its ``Solution`` from the ``readings`` under ``model``."""
        raise NotImplementedError


class KalmanFilterBase(AuvEstimator):
    """The continuous-discrete Kalman filter driver shared by ``ekf`` and ``srekf``: Euler
    sub-steps of ``filter_step_s`` between observations, one update per epoch against the
    observation model at the predicted mean (``AuvModel.observe_with_jacobian``, vectorised
    over the paths). Subclasses hold the covariance their way and give the compiled loops:
    ``initial_factor``, ``predict`` and ``update`` (in place), ``covariance``."""

    def solve(self, model: AuvModel, readings: Readings) -> Solution:
        t, obs = readings.t_s, readings.obs
        n, K, _ = obs.shape
        dt = model.filter_step_s
        mean0, cov0 = model.initial.moments()
        x = np.repeat(mean0[:, None], n, axis=1)
        factor = self.initial_factor(cov0, n)
        r = np.ascontiguousarray(model.obs_sd**2)
        xs, Ps = np.empty((K, 6, n)), np.empty((K, 6, 6, n))
        for k in range(K):
            if k:
                self.predict(x, factor, dt, model.n_filter_steps(t[k] - t[k - 1]), model.lam,
                             model.nu, model.mu, BLOCK_PATHS)
            # views with paths first in memory: what the per-path update reads is contiguous
            h, H = model.observe_with_jacobian(x)  # (m, n), (m, 6, n)
            self.update(x, factor, h, H, obs[:, k], r)
            xs[k], Ps[k] = x, self.covariance(factor)
        est, cov = to_paths_first(xs, Ps)
        ok = np.isfinite(cov).all(axis=(1, 2, 3)) & np.isfinite(est).all(axis=(1, 2))
        return Solution(est, cov, ok)


def output_columns(solution: Solution, t, covariance_every, track_id) -> Estimates:
    """Per-epoch estimates and standard deviations, and the side table ``covariance``: the
    upper triangle of the covariance every ``covariance_every`` epochs and at the last (for
    NEES)."""
    est, cov, ok = solution.mean, solution.covariance, solution.filter_ok
    n, K, _ = est.shape
    variance = np.einsum("nkii->nki", cov)
    # a negative variance (a covariance that lost definiteness) has no std: flagged too
    ok = (ok & np.isfinite(est).all(axis=(1, 2)) & np.isfinite(cov).all(axis=(1, 2, 3))
          & (variance >= 0).all(axis=(1, 2)))
    out = {"t_s": np.broadcast_to(t, (n, K)).copy(), "filter_ok": ok}
    for i, name in enumerate(STATE_NAMES):
        out[name] = est[..., i]
    sd = np.sqrt(variance)
    for i, name in enumerate(STATE_NAMES):
        out[f"sd_{name}"] = sd[..., i]
    steps = np.unique(np.r_[np.arange(0, K, covariance_every), K - 1])
    covariance = {"track_id": np.repeat(track_id, steps.size),
                  "step": np.tile(steps, n)}
    for i, j in zip(*IU, strict=True):
        covariance[f"P_{i}{j}"] = cov[:, steps, i, j].ravel()
    return Estimates(out, {"covariance": covariance})


def to_paths_first(x_hist, P_hist):
    """(K, 6, n), (K, 6, 6, n) -> (n, K, 6), (n, K, 6, 6)."""
    return np.moveaxis(x_hist, -1, 0), np.moveaxis(P_hist, -1, 0)
