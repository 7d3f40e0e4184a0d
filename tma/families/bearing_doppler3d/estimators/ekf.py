"""``ekf``: continuous-discrete extended Kalman filter (EKF-1), compiled, batched over paths.

Between observations: Euler steps of ``filter_step_s`` for the mean (dx = a(x) dt) and the
covariance (see ``estimators/base.py``); at each observation the EKF update with the analytic
observation Jacobian at the predicted mean, processed as sequential scalar updates.
"""

from dataclasses import dataclass

import numpy as np

from tma.families.bearing_doppler3d.estimators.base import AuvConfig, KalmanFilterBase
from tma.families.bearing_doppler3d.model import (
    PHI,
    A,
    euler_columns,
    jacobian_columns,
    transition,
)
from tma.jit import njit

STATE_ROWS = np.arange(6)  # the covariance holds the states in the model's order


@dataclass
class Config(AuvConfig):
    pass  # what every filter of the family has (base.AuvConfig)


@njit(error_model="numpy", depends=(jacobian_columns, transition, euler_columns))
def predict(x, P, dt, n_steps, lam, nu, mu, block):
    """``n_steps`` Euler steps of dt of the means x (6, n) and covariances P (6, 6, n), in
    place: P <- Phi P Phi^T + b b^T dt with Phi = I + F dt at the mean, then x <- x + a(x) dt.

    Blocks of ``block`` paths are copied out, stepped together (every loop runs over the
    paths innermost) and copied back; cos and sin of the heading are carried by rotations
    (``euler_columns``)."""
    n = x.shape[1]
    for b0 in range(0, n, block):
        nb = min(block, n - b0)
        xb = np.ascontiguousarray(x[:, b0:b0 + nb])
        Pb = np.ascontiguousarray(P[:, :, b0:b0 + nb])
        Fb = np.empty((7, nb))  # contiguous, as every block array: the loops vectorise
        c, s = np.cos(xb[PHI]), np.sin(xb[PHI])
        for _ in range(n_steps):
            jacobian_columns(xb, c, s, lam, dt, Fb)
            transition(Pb, Fb, STATE_ROWS)  # Phi P
            for i in range(6):  # (Phi P) Phi^T: Phi applied to each row of Phi P
                transition(Pb[i].reshape((6, 1, nb)), Fb, STATE_ROWS)
            Pb[A, A] += mu * mu * dt  # b b^T dt
            euler_columns(xb, c, s, lam, nu, dt)
        x[:, b0:b0 + nb] = xb
        P[:, :, b0:b0 + nb] = Pb


@njit(error_model="numpy")
def update(x, P, h, H, obs, r):
    """EKF update of x (6, n), P (6, 6, n) in place with one epoch's readings obs (n, m)
    (non-finite = missing: skipped), one scalar at a time against the predicted mean's
    readings h (m, n) and Jacobian H (m, 6, n); r (m,) the reading variances. (Scalar
    readings one at a time, compiled per path: the batched forms of mpekf and imm would
    form matrices this never needs.)"""
    x_lin, xp, Pp, Ph = np.empty(6), np.empty(6), np.empty((6, 6)), np.empty(6)
    for p in range(x.shape[1]):
        for i in range(6):
            x_lin[i] = xp[i] = x[i, p]
            for j in range(6):
                Pp[i, j] = P[i, j, p]
        for j in range(obs.shape[1]):
            if not np.isfinite(obs[p, j]):
                continue
            for i in range(6):
                acc = 0.0
                for k in range(6):
                    acc += Pp[i, k] * H[j, k, p]
                Ph[i] = acc  # P H_j^T
            s = moved = 0.0
            for i in range(6):
                s += H[j, i, p] * Ph[i]
                moved += H[j, i, p] * (xp[i] - x_lin[i])  # the mean moved since linearising
            s += r[j]
            innovation = obs[p, j] - h[j, p] - moved
            for i in range(6):
                gain = Ph[i] / s
                xp[i] += gain * innovation
                for k in range(6):
                    Pp[i, k] -= gain * Ph[k]
        for i in range(6):
            x[i, p] = xp[i]
            for j in range(6):
                P[i, j, p] = Pp[i, j]


class EKF(KalmanFilterBase):
    Config = Config
    predict = staticmethod(predict)
    update = staticmethod(update)

    def initial_factor(self, cov0, n):
        return np.repeat(cov0[:, :, None], n, axis=2)

    def covariance(self, P):
        return P
