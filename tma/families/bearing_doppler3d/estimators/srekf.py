"""``srekf``: the square-root form of ``ekf`` (same filter, Cholesky factor S with P = S S^T),
compiled, batched over paths.

In the state order (v, a, phi, X, Y, Z) the drift Jacobian is lower triangular, so
Phi = I + F dt is too and Phi S stays lower triangular. Each Euler step triangularises
[Phi S, b sqrt(dt)] orthogonally: Givens rotations fold the single noise column into Phi S
(a structured QR, equal to ``numpy.linalg.qr`` of the same array up to signs). Each scalar
reading updates by the array algorithm: Givens rotations triangularise
[[sqrt(r), h S], [0, S]] into [[sqrt(alpha), 0], [K sqrt(alpha), S+]].
"""

import math
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
from tma.runtime.jit import njit

ORDER = np.array([3, 5, 4, 0, 1, 2])  # (v, a, phi, X, Y, Z) in the model's state indices
INVERSE = np.argsort(ORDER)  # INVERSE[i]: the row of state i in the square-root order
SA = int(INVERSE[A])  # the row of a, the state the manoeuvre noise drives


@dataclass
class Config(AuvConfig):
    pass  # what every filter of the family has (base.AuvConfig)


@njit(error_model="numpy")
def fold_noise(L, q):
    """L <- the lower-triangular L' with L' L'^T = L L^T + q q^T, in place, for L (6, 6, k)
    and q (6, k) zero above row SA (Givens rotations; q is overwritten)."""
    for k in range(SA, 6):
        for p in range(L.shape[2]):
            lkk, qk = L[k, k, p], q[k, p]
            rkk = math.sqrt(lkk * lkk + qk * qk)
            c, s = rkk / lkk, qk / lkk
            L[k, k, p] = rkk
            for i in range(k + 1, 6):
                L[i, k, p] = (L[i, k, p] + s * q[i, p]) / c
                q[i, p] = c * q[i, p] - s * L[i, k, p]


@njit(error_model="numpy", depends=(jacobian_columns, transition, euler_columns))
def predict(x, S, dt, n_steps, lam, nu, mu, block):
    """``n_steps`` Euler steps of dt of the means x (6, n) and factors S (6, 6, n) (rows and
    columns in the square-root order), in place: S <- the triangular factor of
    [Phi S, b sqrt(dt)], then x <- x + a(x) dt. Blocks of paths as in ``ekf.predict``."""
    n = x.shape[1]
    noise = mu * math.sqrt(dt)
    for b0 in range(0, n, block):
        nb = min(block, n - b0)
        xb = np.ascontiguousarray(x[:, b0:b0 + nb])
        Sb = np.ascontiguousarray(S[:, :, b0:b0 + nb])
        Fb, qb = np.empty((7, nb)), np.empty((6, nb))  # contiguous: the loops vectorise
        c, s = np.cos(xb[PHI]), np.sin(xb[PHI])
        for _ in range(n_steps):
            jacobian_columns(xb, c, s, lam, dt, Fb)
            transition(Sb, Fb, INVERSE)  # Phi S
            qb[:] = 0.0
            qb[SA] = noise
            fold_noise(Sb, qb)
            euler_columns(xb, c, s, lam, nu, dt)
        x[:, b0:b0 + nb] = xb
        S[:, :, b0:b0 + nb] = Sb


@njit(error_model="numpy")
def update(x, S, h, H, obs, r):
    """Array-algorithm update of x (6, n) and S (6, 6, n) in place with one epoch's readings
    obs (n, m) (non-finite = missing: skipped), one scalar at a time against the predicted
    mean's readings h (m, n) and Jacobian H (m, 6, n); r (m,) the reading variances."""
    x_lin, xp, Sp = np.empty(6), np.empty(6), np.empty((6, 6))
    u, gain, old = np.empty(6), np.empty(6), np.empty(6)
    for p in range(x.shape[1]):
        for i in range(6):
            x_lin[i] = xp[i] = x[i, p]
            for j in range(6):
                Sp[i, j] = S[i, j, p]
        for j in range(obs.shape[1]):
            if not np.isfinite(obs[p, j]):
                continue
            moved = 0.0
            for i in range(6):
                moved += H[j, i, p] * (xp[i] - x_lin[i])  # the mean moved since linearising
            innovation = obs[p, j] - h[j, p] - moved
            for col in range(6):  # u = h S, h in the square-root order
                acc = 0.0
                for i in range(6):
                    acc += Sp[i, col] * H[j, ORDER[i], p]
                u[col] = acc
            rho = math.sqrt(r[j])
            gain[:] = 0.0
            for col in range(5, -1, -1):  # right to left keeps S lower triangular
                rho_new = math.sqrt(rho * rho + u[col] * u[col])  # rho >= sqrt(r) > 0
                c, s = rho / rho_new, u[col] / rho_new
                for i in range(6):
                    old[i] = Sp[i, col]
                    Sp[i, col] = -s * gain[i] + c * old[i]
                    gain[i] = c * gain[i] + s * old[i]
                rho = rho_new
            for i in range(6):
                xp[i] += gain[INVERSE[i]] / rho * innovation
        for i in range(6):
            x[i, p] = xp[i]
            for j in range(6):
                S[i, j, p] = Sp[i, j]


class SquareRootEKF(KalmanFilterBase):
    Config = Config
    predict = staticmethod(predict)
    update = staticmethod(update)

    def initial_factor(self, cov0, n):
        # cov0 is diagonal (independent initial components): its Cholesky factor is the
        # root of the diagonal, which exists even where a variance underflowed to 0
        return np.repeat(np.diag(np.sqrt(np.diag(cov0)[ORDER]))[:, :, None], n, axis=2)

    def covariance(self, S):
        return np.einsum("ikn,jkn->ijn", S, S)[np.ix_(INVERSE, INVERSE)]
