"""``iv``: the instrumental-variable (bias-compensated pseudo-linear) bearings-only estimator.

Pseudo-linear form: with the target at (x0 + vx t, y0 + vy t) and own-ship at (ox, oy), a
bearing beta (clockwise from north, so dx = r sin beta, dy = r cos beta) makes
dx cos beta - dy sin beta = 0, i.e. one linear equation in theta = (x0, y0, vx, vy):

    a_k^T theta = b_k,  a_k = (cos X_k, -sin X_k, t_k cos X_k, -t_k sin X_k),
                        b_k = ox_k cos X_k - oy_k sin X_k

with X_k the measured bearing. Its error, r_k sin(X_k - beta_k), is correlated with a_k
(both carry the noise of X_k), which biases least squares. The instrumental variables
g_k = a_k evaluated at the bearings beta_hat_k that the current estimate predicts are
correlated with a_k but not with the noise, so

    theta <- (sum_k w_k g_k a_k^T)^-1 sum_k w_k g_k b_k,  w_k = 1 / r_hat_k^2

removes the bias to first order (w_k: the pseudo-linear error has standard deviation
r_k sigma, so these are the weights of the maximum-likelihood fit). The iteration starts from
the N-bearings solution (``nbearings``) and runs ``iterations`` times (Dogancay, "Bias
compensation for the bearings-only pseudolinear target track estimator", IEEE Trans. Signal
Processing 54(1), 2006; "Passive emitter localization using weighted instrumental
variables", Signal Processing, 2004). Its fixed point is the maximum-likelihood fit: measured
on the default scenario at sigma 1 deg, after 10 passes the range now agrees with ``lm``'s to
3e-5 on 99 % of the tracks (after 5: 1e-4; after 3: 6e-3). Every track is solved at once:
the 4 x 4 systems are stacked and solved by ``np.linalg.solve``, columns scaled to unit norm
(metres and m/s mix). A system whose scaled condition number exceeds 1 / ``rcond`` leaves
the track's estimate NaN (``converged`` False).
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param
from tma.families.bearings2d.contract import Bearings, Solution, TargetMotion
from tma.families.bearings2d.estimators.base import BearingsConfig, BearingsEstimator
from tma.families.bearings2d.estimators.nbearings import NBearings
from tma.families.bearings2d.model import relative_position


@dataclass
class Config(BearingsConfig):
    iterations: int = param(10, "instrumental-variable passes after the N-bearings start",
                            "[1, 1000]")
    rcond: float = param(1e-12, "a scaled IV system with 1 / condition number below this is "
                         "singular", "(0, 1)")


def pseudo_linear_terms(t, own_x, own_y, measured_rad):
    """cos X, sin X and the right-hand side b = ox cos X - oy sin X of the pseudo-linear
    equations at the measured bearings X (n, K), and the (K, 3) matrix [1, t, t^2]."""
    c, s = np.cos(measured_rad), np.sin(measured_rad)
    return c, s, own_x * c - own_y * s, np.stack([np.ones_like(t), t, t * t], axis=1)


def iv_system(theta, t, own_x, own_y, terms, use):
    """The weighted IV normal system ``M theta = v`` at ``theta`` (n, 4): M (n, 4, 4) and v
    (n, 4). ``terms``: ``pseudo_linear_terms``; ``use`` (n, K) masks the bearings taken.

    With a = (c, -s, t c, -t s), g = (c^, -s^, t c^, -t s^) (c = cos X, c^ = cos beta_hat,
    ...), every entry of M = sum w g a^T is a sum of w c^ c, w c^ s, w s^ c or w s^ s times
    1, t or t^2: six matrix products with [1, t, t^2] instead of (n, K, 4) arrays.
    """
    c, s, b, powers = terms
    dx, dy = relative_position(theta, t, own_x, own_y)
    with np.errstate(divide="ignore", invalid="ignore"):
        w_over_r = np.where(use, (dx * dx + dy * dy) ** -1.5, 0.0)  # w / r, w = 1 / r^2
    c_hat, s_hat = w_over_r * dy, w_over_r * dx  # w cos(beta_hat), w sin(beta_hat)
    cc, cs, sc, ss = ((c_hat * c) @ powers, (c_hat * s) @ powers, (s_hat * c) @ powers,
                      (s_hat * s) @ powers)
    cb, sb = (c_hat * b) @ powers[:, :2], (s_hat * b) @ powers[:, :2]
    M = np.stack([
        np.stack([cc[:, 0], -cs[:, 0], cc[:, 1], -cs[:, 1]], axis=-1),
        np.stack([-sc[:, 0], ss[:, 0], -sc[:, 1], ss[:, 1]], axis=-1),
        np.stack([cc[:, 1], -cs[:, 1], cc[:, 2], -cs[:, 2]], axis=-1),
        np.stack([-sc[:, 1], ss[:, 1], -sc[:, 2], ss[:, 2]], axis=-1),
    ], axis=1)
    v = np.column_stack([cb[:, 0], -sb[:, 0], cb[:, 1], -sb[:, 1]])
    return M, v


def solve_scaled(M, v, rcond):
    """Solve the stacked systems ``M x = v`` with the unknowns scaled so that every column of
    M has unit norm; NaN where a scaled system's 1 / condition number is below ``rcond``."""
    scale = np.sqrt(np.einsum("nij,nij->nj", M, M))
    finite = np.isfinite(M).all(axis=(1, 2)) & np.isfinite(v).all(axis=1) & (scale > 0).all(1)
    scale = np.where(finite[:, None], scale, 1.0)
    Ms = np.where(finite[:, None, None], M / scale[:, None, :], np.eye(4))
    singular_values = np.linalg.svd(Ms, compute_uv=False)
    good = finite & (singular_values[:, -1] > rcond * singular_values[:, 0])
    Ms[~good] = np.eye(4)
    x = np.linalg.solve(Ms, np.where(good[:, None], v, 0.0)[..., None])[..., 0]
    return np.where(good[:, None], x / scale, np.nan)


class InstrumentalVariable(BearingsEstimator):
    Config = Config

    def solve(self, bearings: Bearings, motion: TargetMotion) -> Solution:
        cfg = self.config
        t, own_x, own_y, measured_rad, valid = (bearings.t, bearings.own_x, bearings.own_y,
                                                bearings.measured, bearings.valid)
        n = measured_rad.shape[0]
        theta = NBearings(NBearings.Config(rcond=cfg.rcond)).solve(bearings, motion).theta
        use = np.ones(measured_rad.shape, dtype=bool) if valid is None else valid
        terms = pseudo_linear_terms(t, own_x, own_y, measured_rad)
        for _ in range(cfg.iterations):
            theta = solve_scaled(*iv_system(theta, t, own_x, own_y, terms, use), cfg.rcond)
        converged = np.isfinite(theta).all(axis=1)
        return Solution(theta=theta, converged=converged,
                        stop_reason=np.where(converged, 0, -1).astype(np.int64),
                        n_f_evals=np.full(n, np.nan), n_iter=np.full(n, float(cfg.iterations)))
