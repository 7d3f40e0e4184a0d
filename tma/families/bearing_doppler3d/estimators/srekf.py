"""``srekf``: the square-root form of ``ekf`` (same filter, Cholesky factor S with P = S S^T).

In the state order (v, a, phi, X, Y, Z) the drift Jacobian is lower triangular, so
Phi = I + F dt is too and Phi S stays lower triangular. Each Euler step triangularises
[Phi S, b sqrt(dt)] orthogonally: Givens rotations fold the single noise column into Phi S
(a structured QR, equal to ``numpy.linalg.qr`` of the same array up to signs). Each scalar
reading updates by the array algorithm: Givens rotations triangularise
[[sqrt(r), h S], [0, S]] into [[sqrt(alpha), 0], [K sqrt(alpha), S+]].
"""

from dataclasses import dataclass

import numpy as np

from tma.config import require
from tma.families.bearing_doppler3d.estimators.base import KalmanFilterBase
from tma.families.bearing_doppler3d.model import A, transition_times

ORDER = np.array([3, 5, 4, 0, 1, 2])  # (v, a, phi, X, Y, Z) in the model's state indices
INVERSE = np.argsort(ORDER)  # INVERSE[i]: the row of state i in the square-root order
SA = INVERSE[A]  # the row of a, the state the manoeuvre noise drives


@dataclass
class Config:
    name: str = "srekf"
    covariance_every: int = 10

    def __post_init__(self):
        require(self.covariance_every >= 1, "estimator 'srekf'", "covariance_every must be >= 1")


def fold_noise(L, q):
    """Lower-triangular L' with L' L'^T = L L^T + q q^T, q (6, n) (Givens, in place)."""
    q = q.copy()
    for k in range(6):
        if not np.any(q[k]):
            continue
        r = np.hypot(L[k, k], q[k])
        c, s = r / L[k, k], q[k] / L[k, k]
        L[k, k] = r
        L[k + 1:, k] = (L[k + 1:, k] + s * q[k + 1:]) / c
        q[k + 1:] = c * q[k + 1:] - s * L[k + 1:, k]
        q[k] = 0.0
    return L


def scalar_update(S, h, r, innovation, valid):
    """Array-algorithm update of S with one scalar reading; returns (S+, gain (6, n))."""
    u = np.einsum("iln,in->ln", S, h)  # h S
    u = np.where(valid, u, 0.0)
    rho = np.full(u.shape[1], np.sqrt(r))
    gain_col = np.zeros_like(h)
    for col in range(5, -1, -1):  # right to left keeps S lower triangular
        rho_new = np.hypot(rho, u[col])
        c, s = rho / rho_new, u[col] / rho_new
        old = S[:, col].copy()
        S[:, col] = -s * gain_col + c * old
        gain_col = c * gain_col + s * old
        rho = rho_new
    return S, np.where(valid, gain_col / rho, 0.0) * np.where(valid, innovation, 0.0)


def square_root_update(x, S, obs_k, model):
    """One epoch's readings, scalar by scalar, against the predicted mean's linearisation."""
    h, H = model.observe_with_jacobian(x)  # (m, n), (m, 6, n)
    x_lin = x.copy()
    r = model.obs_sd**2
    for j in range(h.shape[0]):
        valid = np.isfinite(obs_k[:, j])
        innovation = obs_k[:, j] - h[j] - np.einsum("in,in->n", H[j], x - x_lin)
        S, step = scalar_update(S, H[j][ORDER], r[j], innovation, valid)
        x = x + step[INVERSE]
    return x, S


class SquareRootEKF(KalmanFilterBase):
    name = "srekf"
    Config = Config

    def initial_factor(self, cov0, n):
        # cov0 is diagonal (independent initial components): its Cholesky factor is the
        # root of the diagonal, which exists even where a variance underflowed to 0
        return np.repeat(np.diag(np.sqrt(np.diag(cov0)[ORDER]))[:, :, None], n, axis=2)

    def predict_factor(self, S, x, dt, model):
        """S <- the triangular factor of [Phi S, b sqrt(dt)]."""
        transition_times(model.drift_jacobian(x, dt), S, at=INVERSE)  # Phi S
        q = np.zeros((6, S.shape[2]))
        q[SA] = model.mu * np.sqrt(dt)
        return fold_noise(S, q)

    def update(self, x, S, obs_k, model):
        return square_root_update(x, S, obs_k, model)

    def covariance(self, S):
        return np.einsum("ikn,jkn->ijn", S, S)[np.ix_(INVERSE, INVERSE)]
