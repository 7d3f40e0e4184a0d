"""``lm``: maximum-likelihood TMA by Marquardt's Levenberg-Marquardt, batched over tracks.

Minimises F(theta) = sum_k wrap(X_k - f_k(theta))^2 (rad^2) per track with its own lambda:
A = H + lambda diag(H), H = J^T J; a trial step whose F rises, or whose A is not positive
definite, multiplies lambda by ``lambda_up``; an accepted step multiplies it by
``lambda_down``; a track stops when an accepted step lowers F by less than ``f_tol_rad2``.
Every pass makes one fused evaluation of F, J^T J and J^T r at each still-active track's trial
point (accepted and rejected alike; n_f_evals counts it once), so the per-track sequence is
exactly the scalar algorithm's while the work stays vectorised: the evaluation runs in
cache-sized chunks of tracks, the bookkeeping over every still-active track of the shard.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import require
from tma.families.bearings2d.estimators.base import BearingsConfig, BearingsEstimator
from tma.families.bearings2d.model import BearingTerms
from tma.linalg import jacobi_scaled_eigh, solve_shifted

# Stop reasons recorded per track.
STOP_F_TOL, STOP_MAX_ITER, STOP_LAMBDA_MAX = 0, 1, 2


@dataclass
class Config(BearingsConfig):
    name: str = "lm"
    # Prior guess: target at this bearing/distance from own-ship at t = 0 with this
    # course/speed. initial_bearing_deg = null uses each track's first measured bearing.
    initial_bearing_deg: float | None = 0.0
    initial_distance_m: float = 25000.0
    initial_course_deg: float = 90.0
    initial_speed_m_s: float = 10.0
    lambda0: float = 10.0
    lambda_up: float = 10.0
    lambda_down: float = 0.1
    f_tol_rad2: float = 1e-10
    max_iter: int = 200  # accepted steps
    lambda_max: float = 1e16  # a track whose lambda exceeds this stops (stalled)
    pd_rtol: float = 1e-12  # A is positive definite if its smallest scaled eigenvalue > this
    block_tracks: int = 64  # tracks per chunk of the fused evaluation (cache-sized)

    def __post_init__(self):
        super().__post_init__()
        w = "estimator 'lm'"
        b = self.initial_bearing_deg
        require(b is None or -360 <= b <= 360, w,
                f"initial_bearing_deg must be null or in [-360, 360], got {b}")
        require(0 < self.initial_distance_m < 1e9, w,
                f"initial_distance_m must lie in (0, 1e9) m, got {self.initial_distance_m}")
        require(-360 <= self.initial_course_deg <= 360, w,
                f"initial_course_deg must lie in [-360, 360], got {self.initial_course_deg}")
        require(0 <= self.initial_speed_m_s < 1e4, w,
                f"initial_speed_m_s must lie in [0, 1e4) m/s, got {self.initial_speed_m_s}")
        require(0 < self.lambda0 < self.lambda_max, w, "lambda0 must lie in (0, lambda_max)")
        require(self.lambda_up > 1, w, "lambda_up must exceed 1")
        require(0 < self.lambda_down < 1, w, "lambda_down must lie in (0, 1)")
        require(self.f_tol_rad2 > 0, w, "f_tol_rad2 must be positive")
        require(self.max_iter > 0, w, "max_iter must be positive")
        require(0 < self.pd_rtol < 1, w, "pd_rtol must lie in (0, 1)")
        require(self.block_tracks >= 1, w, "block_tracks must be positive")


def initial_theta(cfg: Config, t, own_x, own_y, measured_rad, first):
    """Prior guess (n_tracks, 4) placed relative to own-ship at t = 0."""
    n = measured_rad.shape[0]
    if cfg.initial_bearing_deg is None:
        bearing = measured_rad[np.arange(n), first]
    else:
        bearing = np.full(n, np.deg2rad(cfg.initial_bearing_deg))
    course, speed = np.deg2rad(cfg.initial_course_deg), cfg.initial_speed_m_s
    ox0 = np.interp(0.0, t, own_x)
    oy0 = np.interp(0.0, t, own_y)
    d = cfg.initial_distance_m
    return np.column_stack([
        ox0 + d * np.sin(bearing), oy0 + d * np.cos(bearing),
        np.full(n, speed * np.sin(course)), np.full(n, speed * np.cos(course)),
    ])


class LevenbergMarquardt(BearingsEstimator):
    name = "lm"
    Config = Config

    def solve(self, t, own_x, own_y, measured_rad, valid, first) -> dict:
        cfg = self.config
        n = measured_rad.shape[0]
        terms = BearingTerms(t, own_x, own_y, measured_rad, valid)
        out = {
            "theta": initial_theta(cfg, t, own_x, own_y, measured_rad, first),
            "n_f_evals": np.zeros(n, dtype=np.int64),
            "n_iter": np.zeros(n, dtype=np.int64),
            "stop_reason": np.full(n, -1, dtype=np.int64),
            "cost_rad2": np.zeros(n),
            "jtj": np.zeros((n, 4, 4)),
        }
        self._iterate(terms, np.arange(n), out)
        out["converged"] = out["stop_reason"] == STOP_F_TOL
        return out

    def _evaluate(self, terms, theta, rows):
        """F, H, g at ``theta`` for tracks ``rows``, in cache-sized chunks of tracks (the
        per-pass bookkeeping stays vectorised over every active track of the shard)."""
        size = self.config.block_tracks
        if rows.size <= size:
            return terms(theta, rows)
        parts = [terms(theta[i:i + size], rows[i:i + size]) for i in range(0, rows.size, size)]
        return tuple(np.concatenate(p) for p in zip(*parts, strict=True))

    def _iterate(self, terms, rows, out):
        """Marquardt iterations for the tracks ``rows``; results written into ``out``."""
        cfg = self.config
        theta = out["theta"][rows]
        cost, H, g = self._evaluate(terms, theta, rows)
        n = rows.size
        n_f_evals = np.ones(n, dtype=np.int64)
        n_iter = np.zeros(n, dtype=np.int64)
        lam = np.full(n, cfg.lambda0)
        stop = np.full(n, -1, dtype=np.int64)
        w, V, d = jacobi_scaled_eigh(H)
        active = np.arange(n)

        while active.size:
            # Step 4: raise lambda until A = H + lambda diag(H) is positive definite (the scaled
            # A has eigenvalues w + lambda, so no refactorisation is needed).
            wa = w[active]
            floor = cfg.pd_rtol * np.maximum(wa[:, -1], 1.0)
            not_pd = wa[:, 0] + lam[active] <= floor
            while np.any(not_pd):
                lam[active[not_pd]] *= cfg.lambda_up
                not_pd &= wa[:, 0] + lam[active] <= floor

            trial = theta[active] + solve_shifted(wa, V[active], d[active], g[active], lam[active])
            trial_cost, trial_H, trial_g = self._evaluate(terms, trial, rows[active])
            n_f_evals[active] += 1
            decrease = cost[active] - trial_cost
            accepted = decrease >= 0  # NaN (a non-finite trial) counts as rejected

            acc, rej = active[accepted], active[~accepted]
            theta[acc], cost[acc] = trial[accepted], trial_cost[accepted]
            H[acc], g[acc] = trial_H[accepted], trial_g[accepted]
            w[acc], V[acc], d[acc] = jacobi_scaled_eigh(H[acc])
            lam[acc] *= cfg.lambda_down
            n_iter[acc] += 1
            lam[rej] *= cfg.lambda_up

            stop[acc[decrease[accepted] < cfg.f_tol_rad2]] = STOP_F_TOL
            stop[active[(stop[active] < 0) & (n_iter[active] >= cfg.max_iter)]] = STOP_MAX_ITER
            stop[active[(stop[active] < 0) & (lam[active] > cfg.lambda_max)]] = STOP_LAMBDA_MAX
            active = active[stop[active] < 0]

        out["theta"][rows] = theta
        out["n_f_evals"][rows] = n_f_evals
        out["n_iter"][rows] = n_iter
        out["stop_reason"][rows] = stop
        out["cost_rad2"][rows] = cost
        out["jtj"][rows] = H
