"""``ekf``: continuous-discrete extended Kalman filter (EKF-1), batched over paths.

Between observations: Euler steps of ``filter_step_s`` for the mean (dx = a(x) dt) and the
covariance (see ``estimators/base.py``); at each observation the EKF update with the analytic
observation Jacobian at the predicted mean, processed as sequential scalar updates.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import require
from tma.families.bearing_doppler3d.estimators.base import KalmanFilterBase
from tma.families.bearing_doppler3d.model import A, transition_times


@dataclass
class Config:
    name: str = "ekf"
    covariance_every: int = 10  # store the full covariance every this many epochs (NEES)

    def __post_init__(self):
        require(self.covariance_every >= 1, f"estimator '{self.name}'",
                "covariance_every must be >= 1")


def predict_covariance(P, x, dt, model):
    """P <- Phi P Phi^T + b b^T dt, Phi = I + F dt (F the drift Jacobian at x); P (6, 6, n),
    x (6, n). In place: Phi changes four rows of P, then Phi^T four of its columns."""
    F = model.drift_jacobian(x, dt)
    transition_times(F, P)  # Phi P
    transition_times(F, P.swapaxes(0, 1))  # (Phi P) Phi^T
    P[A, A] += model.mu * model.mu * dt  # b b^T dt
    return P


def sequential_update(x, P, obs_k, model):
    """EKF update with one epoch's readings obs_k (n, m) (NaN = missing), in place."""
    h, H = model.observe_with_jacobian(x)  # (m, n), (m, 6, n)
    x_lin = x.copy()
    r = model.obs_sd**2
    for j in range(h.shape[0]):
        Ph = np.einsum("ijn,jn->in", P, H[j])  # P H_j^T
        s = np.einsum("in,in->n", H[j], Ph) + r[j]
        valid = np.isfinite(obs_k[:, j])
        innovation = np.where(valid, obs_k[:, j] - h[j]
                              - np.einsum("in,in->n", H[j], x - x_lin), 0.0)
        K = np.where(valid, Ph / s, 0.0)
        x += K * innovation
        P -= K[:, None, :] * Ph[None, :, :]
    return x, P


class EKF(KalmanFilterBase):
    name = "ekf"
    Config = Config

    def initial_factor(self, cov0, n):
        return np.repeat(cov0[:, :, None], n, axis=2)

    def predict_factor(self, P, x, dt, model):
        return predict_covariance(P, x, dt, model)

    def update(self, x, P, obs_k, model):
        return sequential_update(x, P, obs_k, model)

    def covariance(self, P):
        return P
