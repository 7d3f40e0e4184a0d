"""``lm``: maximum-likelihood TMA by Marquardt's Levenberg-Marquardt, one track at a time in
compiled code (``marquardt.py``) over the tracks of a shard.

Minimises F(theta) = sum_k wrap(X_k - f_k(theta))^2 (rad^2) per track with its own lambda:
A = H + lambda diag(H), H = J^T J; a trial step whose F rises, or whose A is not positive
definite, multiplies lambda by ``lambda_up``; an accepted step multiplies it by
``lambda_down``; a track stops when an accepted step lowers F by less than ``f_tol_rad2``.
Every pass makes one fused evaluation of F, J^T J and J^T r at the trial point (accepted and
rejected alike; n_f_evals counts it once).

``loss=huber|cauchy`` fits robustly (the same ``marquardt.marquardt``, its loss a parameter):
F_rho = sum s^2 rho(r/s), iteratively reweighted inside the Marquardt loop (H = J^T Omega J,
g = J^T Omega r, omega = rho'(u) / (2u), a step accepted when F_rho falls; c = 1.345 s for Huber,
2.385 s for Cauchy). The scale s is the log's nominal sigma (``scale=sigma``), or with
``scale=mad`` (or no nominal sigma > 0) 1.4826 median |r| at the first start, re-estimated
twice at the robust solution (each a new pass from there). The covariance is the sandwich
s^2 A^-1 B A^-1 (A = sum psi'(u) j j^T, B = sum psi(u)^2 j j^T, psi = rho' / 2), stored
as the information ``jtj`` = A B^-1 A with ``sigma_used`` = s so that every reader's
jtj^-1 sigma^2 is it; the fit test is
``status.robust_fit_p`` on the bearings within c. ``cost_rad2`` stays the sum of squared
residuals; ``cost_robust_rad2`` is F_rho, ``n_downweighted`` the bearings beyond c.
``loss=squared`` (the default) runs the plain kernel exactly as before.

``starts=K`` > 1 runs K initial distances per track in one kernel call: ``initial_distance_m``
and K - 1 geometric between ``start_min_m`` and ``start_max_m`` (the default scenario's
population, 5-50 km); each track keeps the start of lowest F (F_rho when robust; the earliest
of those within ``f_tol_rad2`` of it), its index in ``start_won``; ``n_f_evals`` then
counts every start's evaluations, ``n_iter`` and ``stop_reason`` are the winner's.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.bearings2d.contract import Bearings, Solution, TargetMotion
from tma.families.bearings2d.estimated_path import RECORDED_POINTS
from tma.families.bearings2d.estimators.base import GROSS_SIGMAS, BearingsConfig, BearingsEstimator
from tma.families.bearings2d.marquardt import (
    LOSSES,
    STOP_F_TOL,
    TUNING,
    MarquardtSettings,
    fit_starts,
)
from tma.families.bearings2d.model import BearingTerms, bearing_jacobian, bearing_residuals
from tma.families.bearings2d.status import noiseless_fit_p, robust_fit_p, runs_test_p
from tma.maths.linalg import scaled_inverse

SCALES = ("sigma", "mad")
MAD_TO_SD = 1.4826  # sd of a normal over its median absolute deviation
MIN_SCALE_RAD = 1e-10  # floor of a MAD scale (a noiseless fit has residuals ~ round-off)
MAX_STARTS = 64
MAD_PASSES = 2  # re-estimations of a MAD scale at the solution


@dataclass
class Config(BearingsConfig):
    # Prior guess: target at this bearing/distance from own-ship at t = 0 with this
    # course/speed.
    initial_bearing_deg: float | None = param(0.0, "initial guess: bearing from own-ship at "
                                              "t = 0 (deg); null: each track's first bearing",
                                              "[-360, 360]")
    initial_distance_m: float = param(25000.0, "initial guess: distance at t = 0 (m)",
                                      "(0, 1e9)")
    initial_course_deg: float = param(90.0, "initial guess: course (deg)", "[-360, 360]")
    initial_speed_m_s: float = param(10.0, "initial guess: speed (m/s)", "[0, 1e4)")
    lambda0: float = param(10.0, "initial Marquardt lambda; below lambda_max", "(0, inf)")
    lambda_up: float = param(10.0, "lambda's factor after a rejected step", "(1, inf)")
    lambda_down: float = param(0.1, "lambda's factor after an accepted step", "(0, 1)")
    f_tol_rad2: float = param(1e-10, "stop when F falls by less than this (rad^2)", "(0, inf)")
    max_iter: int = param(200, "accepted steps at most", "[1, inf)")
    lambda_max: float = param(1e16, "a track whose lambda exceeds this stops (stalled)",
                              "(0, inf)")
    pd_rtol: float = param(1e-12, "A is positive definite if its smallest scaled eigenvalue "
                           "exceeds this", "(0, 1)")
    loss: str = param("squared", "loss of the residuals", choices=LOSSES)
    scale: str = param("sigma", "robust scale s: sigma (nominal) or mad (from the residuals)",
                       choices=SCALES)
    starts: int = param(1, "initial distances per track; the lowest F wins",
                        f"[1, {MAX_STARTS}]")
    start_min_m: float = param(5000.0, "nearest extra start (m; geometric up to start_max_m)",
                               "(0, 1e9)")
    start_max_m: float = param(50000.0, "farthest extra start (m)", "(0, 1e9)")
    path_points: int = param(0, "the trajectory each answer rests on, for the plots and the "
                             "map: at most this many of its points per track in the side "
                             "table path (0: none; a recording's default 200)", "[0, 100000]")

    def __post_init__(self):
        super().__post_init__()
        w = self.where
        require(self.lambda0 < self.lambda_max, w, "lambda0 must lie in (0, lambda_max)")
        require(self.start_min_m <= self.start_max_m, w,
                "start_min_m and start_max_m must satisfy 0 < start_min_m <= start_max_m < 1e9"
                f" m, got {self.start_min_m}, {self.start_max_m}")


def start_distances(cfg: Config) -> np.ndarray:
    """The ``starts`` initial distances (m): ``initial_distance_m``, then ``starts`` - 1
    geometric from ``start_min_m`` to ``start_max_m`` (one extra start: ``start_min_m``)."""
    extra = np.geomspace(cfg.start_min_m, cfg.start_max_m, cfg.starts - 1)
    return np.concatenate([[cfg.initial_distance_m], extra])


def initial_theta(cfg: Config, t, own_x, own_y, measured_rad, first, distance_m=None):
    """Prior guess (n_tracks, 4) placed relative to own-ship at t = 0, at ``distance_m``
    (default ``initial_distance_m``)."""
    n = measured_rad.shape[0]
    if cfg.initial_bearing_deg is None:
        bearing = measured_rad[np.arange(n), first]
    else:
        bearing = np.full(n, np.deg2rad(cfg.initial_bearing_deg))
    course, speed = np.deg2rad(cfg.initial_course_deg), cfg.initial_speed_m_s
    ox0 = np.interp(0.0, t, own_x)
    oy0 = np.interp(0.0, t, own_y)
    d = cfg.initial_distance_m if distance_m is None else distance_m
    return np.column_stack([
        ox0 + d * np.sin(bearing), oy0 + d * np.cos(bearing),
        np.full(n, speed * np.sin(course)), np.full(n, speed * np.cos(course)),
    ])


def mad_scale(residuals, valid):
    """1.4826 median |r| over each track's bearings (rad), floored at ``MIN_SCALE_RAD``."""
    a = np.abs(residuals) if valid is None else np.where(valid, np.abs(residuals), np.nan)
    return np.maximum(MAD_TO_SD * np.nanmedian(a, axis=1), MIN_SCALE_RAD)


def sandwich_information(residuals, jac, scale, loss):
    """A B^-1 A per track (n, 4, 4): the inverse of the sandwich covariance A^-1 B A^-1 s^2
    over s^2, with A = sum psi'(u) j j^T, B = sum psi(u)^2 j j^T, u = r / s, psi = rho' / 2
    (Gauss-Newton A: the curvature of the bearings themselves is left out). NaN where B is
    numerically singular."""
    c = TUNING[loss]
    u = residuals / scale[:, None]
    if loss == "huber":
        inside = np.abs(u) <= c
        psi, dpsi = np.where(inside, u, c * np.sign(u)), inside.astype(float)
    else:  # cauchy
        q = 1.0 + (u / c) ** 2
        psi, dpsi = u / q, (2.0 - q) / (q * q)
    A = np.einsum("nk,nki,nkj->nij", dpsi, jac, jac)
    B = np.einsum("nk,nki,nkj->nij", psi * psi, jac, jac)
    B_inv, singular = scaled_inverse(B, 1e-14)
    info = A @ B_inv @ A
    info = 0.5 * (info + np.swapaxes(info, 1, 2))
    return np.where(singular[:, None, None], np.nan, info)


class LevenbergMarquardt(BearingsEstimator):
    Config = Config
    models_motion = True  # a target that is not at constant velocity: the NCV MAP state
    # present when starts > 1 / when the loss is robust (the default run adds none)
    outputs = ("start_won", "cost_robust_rad2", "n_downweighted")
    # every output present (the side table path: empty on the conformance log, whose
    # targets hold course and speed as it declares)
    conformance_config = {"starts": 2, "loss": "huber", "path_points": 50}
    # the trajectory each answer rests on (path_points > 0, a recording's default), which
    # the plots and the map draw (estimated_path)
    side_tables = ("path",)
    # a recording has no prior on the bearing of its targets (the simulated one, north): start
    # from each track's first bearing unless the command line says otherwise; its contacts
    # are drawn, along the trajectory each answer rests on
    recorded_defaults = {"initial_bearing_deg": None, "path_points": RECORDED_POINTS}

    def solve(self, bearings: Bearings, motion: TargetMotion) -> Solution:
        return self.solution(self.fit(bearings))

    def solution(self, out: dict) -> Solution:
        """The ``Solution`` of a fit's fields by name (``fit``), its outputs as columns."""
        columns = {k: out.pop(k) for k in self.outputs if k in out}
        return Solution(**out, columns=columns)

    def fit(self, bearings: Bearings) -> dict:
        """The Marquardt fit of every track from its starts: the ``Solution``'s fields and
        the outputs, by name."""
        cfg = self.config
        t, own_x, own_y, measured_rad, valid, first, sigma = (
            bearings.t, bearings.own_x, bearings.own_y, bearings.measured, bearings.valid,
            bearings.first, bearings.sigma_deg)
        terms = BearingTerms(t, own_x, own_y, measured_rad, valid)
        starts = np.concatenate([initial_theta(cfg, t, own_x, own_y, measured_rad, first, d)
                                 for d in start_distances(cfg)])
        if cfg.loss != "squared" and cfg.scale == "sigma" and sigma is not None and sigma > 0:
            scale = np.full(measured_rad.shape[0], np.deg2rad(sigma))
            out = self._robust(terms, starts, scale)
        elif cfg.loss == "squared":
            out = self._squared(terms, starts)
        else:  # scale from the residuals at the first start, then twice at the solution
            n = measured_rad.shape[0]
            r = bearing_residuals(starts[:n], t, own_x, own_y, measured_rad, valid)
            out = self._robust(terms, starts, mad_scale(r, valid))
            for _ in range(MAD_PASSES):
                r = bearing_residuals(out["theta"], t, own_x, own_y, measured_rad, valid)
                scale = mad_scale(r, valid)
                again = self._robust(terms, out["theta"], scale)
                again["n_f_evals"] += out["n_f_evals"]
                if "start_won" in out:
                    again["start_won"] = out["start_won"]
                out = again
        out["converged"] = out["stop_reason"] == STOP_F_TOL
        if cfg.loss != "squared":
            self._robust_columns(out, t, own_x, own_y, measured_rad, valid, scale, sigma)
        return out

    def _squared(self, terms, theta):
        """The squared-loss Marquardt fit from every start (stacked start-major)."""
        return fit_starts(MarquardtSettings.of(self.config), theta, terms.t, terms.ox,
                          terms.oy, terms.measured, terms.weight, terms.weighted)

    def _robust(self, terms, theta, scale):
        """The robust fit from every start (stacked start-major; ``scale`` per track)."""
        return fit_starts(MarquardtSettings.of(self.config), theta, terms.t, terms.ox,
                          terms.oy, terms.measured, terms.weight, terms.weighted,
                          self.config.loss, scale)

    def _robust_columns(self, out, t, own_x, own_y, measured_rad, valid, scale, sigma):
        """At the robust solution: the plain F, the sandwich information as ``jtj``, the
        bearings beyond c, the bearings kept, and sigma^2 = s^2 and the fit test (the
        ``Solution``'s own noise scale and test)."""
        loss = self.config.loss
        theta = out["theta"]
        r = bearing_residuals(theta, t, own_x, own_y, measured_rad, valid)
        jac = bearing_jacobian(theta, t, own_x, own_y, valid)
        out["cost_rad2"] = np.einsum("nk,nk->n", r, r)
        out["jtj"] = sandwich_information(r, jac, scale, loss)
        beyond = np.abs(r) > TUNING[loss] * scale[:, None]
        out["n_downweighted"] = (beyond if valid is None else beyond & valid).sum(axis=1)
        kept = np.abs(r) <= GROSS_SIGMAS * scale[:, None]  # a motion fit drops outliers only
        out["inliers"] = kept if valid is None else valid & kept
        if sigma is None:
            fit_p = runs_test_p(r, valid)
        elif sigma > 0:
            fit_p = robust_fit_p(r, valid, np.deg2rad(sigma), TUNING[loss])
        else:  # declared noiseless: as the squared fit's test
            n = r.shape[1] if valid is None else valid.sum(axis=1)
            fit_p = noiseless_fit_p(out["cost_rad2"], n)
        out["sigma2_rad2"], out["fit_p"] = scale**2, fit_p
