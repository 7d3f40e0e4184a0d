"""``ekf``: continuous-discrete extended Kalman filter (EKF-1), batched over paths.

Between observations: Euler steps of ``filter_step_s`` for the mean (dx = a(x) dt) and the
covariance (see ``estimators/base.py``); at each observation the EKF update with the analytic
observation Jacobian at the predicted mean, processed as sequential scalar updates.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import require
from tma.families.bearing_doppler3d.estimators.base import KalmanFilterBase
from tma.families.bearing_doppler3d.model import PHI, A, V, X, Y


@dataclass
class Config:
    name: str = "ekf"
    covariance_every: int = 10  # store the full covariance every this many epochs (NEES)

    def __post_init__(self):
        require(self.covariance_every >= 1, f"estimator '{self.name}'",
                "covariance_every must be >= 1")


def predict_covariance(P, x, dt, lam, mu):
    """P <- Phi P Phi^T + b b^T dt with Phi = I + A dt; P (6, 6, n), x (6, n).

    Only rows and columns X, Y, phi, a of A are non-zero, so M = Phi P changes four rows of P
    and M Phi^T four columns of M (``drift_times_rows`` is the general form). Updated in place,
    in an order where each row (column) reads only rows (columns) not yet updated.
    """
    c, s, v, a = np.cos(x[PHI]), np.sin(x[PHI]), x[V], x[A]
    cdt, sdt, vsdt, vcdt = c * dt, s * dt, v * s * dt, v * c * dt
    adt, idt, keep_a = -a / (v * v) * dt, dt / v, 1.0 - lam * dt
    P[X] += cdt * P[V] - vsdt * P[PHI]
    P[Y] += sdt * P[V] + vcdt * P[PHI]
    P[PHI] += adt * P[V] + idt * P[A]
    P[A] *= keep_a
    P[:, X] += cdt * P[:, V] - vsdt * P[:, PHI]
    P[:, Y] += sdt * P[:, V] + vcdt * P[:, PHI]
    P[:, PHI] += adt * P[:, V] + idt * P[:, A]
    P[:, A] *= keep_a
    P[A, A] += mu * mu * dt
    return P


def sequential_update(x, P, obs_k, model):
    """EKF update with one epoch's readings obs_k (n, m) (NaN = missing), in place."""
    h, H = model.observe_with_jacobian(x.T)  # (n, m), (n, m, 6)
    x_lin = x.copy()
    r = model.obs_sd**2
    for j in range(h.shape[1]):
        hj = H[:, j].T  # (6, n)
        Ph = np.einsum("ijn,jn->in", P, hj)
        s = np.einsum("in,in->n", hj, Ph) + r[j]
        valid = np.isfinite(obs_k[:, j])
        innovation = np.where(valid, obs_k[:, j] - h[:, j]
                              - np.einsum("in,in->n", hj, x - x_lin), 0.0)
        K = np.where(valid, Ph / s, 0.0)
        x += K * innovation
        P -= K[:, None, :] * Ph[None, :, :]
    return x, P


class EKF(KalmanFilterBase):
    name = "ekf"
    Config = Config

    def initial_factor(self, cov0, n, record):
        return np.repeat(cov0[:, :, None], n, axis=2)

    def predict_factor(self, P, x, dt, record):
        return predict_covariance(P, x, dt, record["lam"], record["mu"])

    def update(self, x, P, obs_k, model):
        return sequential_update(x, P, obs_k, model)

    def covariance(self, P):
        return P
