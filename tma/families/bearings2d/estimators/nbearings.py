"""``nbearings``: the "N bearings" pseudo-linear least-squares TMA (direct, not iterative).

phi0 = the track's first measured bearing is taken as the target's bearing at t0; unknowns
(r0, vx, vy). Each later bearing phi_i gives one linear row (nautical form):

    r0 sin(phi_i - phi0) - vx dt_i cos(phi_i) + vy dt_i sin(phi_i)
        = -(dx_i cos(phi_i) - dy_i sin(phi_i))

with dt_i = t_i - t0 and (dx_i, dy_i) the own-ship displacement since t0. Ordinary least
squares per track (batched normal equations, column-scaled); then the target position at t0
is own(t0) + r0 (sin phi0, cos phi0), moved back to the dataset's t = 0 with (vx, vy). Biased
by the noise of phi0: that is the point of the comparison with ``lm``.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param
from tma.families.bearings2d.contract import Bearings, Solution, TargetMotion
from tma.families.bearings2d.estimators.base import BearingsConfig, BearingsEstimator
from tma.maths.linalg import jacobi_scaled_eigh, solve_shifted


@dataclass
class Config(BearingsConfig):
    rcond: float = param(1e-12, "the scaled normal matrix with eigenvalues below rcond x max "
                         "is singular", "(0, 1)")


class NBearings(BearingsEstimator):
    Config = Config
    honest_errors = False  # biased by the noise of its first bearing: never ok, approximate

    def solve(self, bearings: Bearings, motion: TargetMotion) -> Solution:
        t, own_x, own_y, measured_rad, valid, first = (
            bearings.t, bearings.own_x, bearings.own_y, bearings.measured, bearings.valid,
            bearings.first)
        n = measured_rad.shape[0]
        rows = np.arange(n)
        phi0 = measured_rad[rows, first][:, None]
        t0 = t[first][:, None]
        dt = t - t0
        dx, dy = own_x - own_x[first][:, None], own_y - own_y[first][:, None]
        use = np.arange(t.size) > first[:, None]
        if valid is not None:
            use &= valid
        sin_phi, cos_phi = np.sin(measured_rad), np.cos(measured_rad)
        design = np.stack([np.sin(measured_rad - phi0), -dt * cos_phi, dt * sin_phi], axis=-1)
        design *= use[..., None]
        rhs = np.where(use, -(dx * cos_phi - dy * sin_phi), 0.0)
        normal = np.einsum("nki,nkj->nij", design, design)
        w, V, d = jacobi_scaled_eigh(normal)
        singular = w[:, 0] <= self.config.rcond * w[:, -1]
        x = solve_shifted(w, V, d, np.einsum("nki,nk->ni", design, rhs), np.zeros(n))
        x[singular] = np.nan
        r0, vx, vy = x[:, 0], x[:, 1], x[:, 2]
        t0 = t0[:, 0]
        x0 = own_x[first] + r0 * np.sin(phi0[:, 0]) - vx * t0
        y0 = own_y[first] + r0 * np.cos(phi0[:, 0]) - vy * t0
        return Solution(theta=np.column_stack([x0, y0, vx, vy]), converged=~singular,
                        stop_reason=np.where(singular, -1, 0).astype(np.int64),
                        n_f_evals=np.full(n, np.nan), n_iter=np.full(n, np.nan))
