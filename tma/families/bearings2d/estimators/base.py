"""The shared pieces of the bearings-only estimators: settings, the per-track status and
one-sigma errors every output carries, and F / J^T J at a solution."""

from dataclasses import dataclass

import numpy as np

from tma.config import param
from tma.errors import InputError
from tma.estimator import Estimator, EstimatorConfig
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.model import BearingTerms, bearing_residuals
from tma.families.bearings2d.status import assess, runs_test_p

BLOCK_TRACKS = 64


def evaluate_in_blocks(terms: BearingTerms, theta, block=BLOCK_TRACKS):
    """F(theta) (rad^2) and J^T J per track, evaluated in cache-sized blocks of tracks."""
    n = theta.shape[0]
    cost, jtj = np.empty(n), np.empty((n, 4, 4))
    for start in range(0, n, block):
        rows = np.arange(start, min(start + block, n))
        cost[rows], jtj[rows], _ = terms(theta[rows], rows)
    return cost, jtj


@dataclass
class BearingsConfig(EstimatorConfig):
    """Settings every bearings-only estimator shares: what it needs, and how its per-track
    ``status`` is decided (``tma.families.bearings2d.status``)."""

    min_bearings: int = param(5, "bearings a track needs (4 unknowns)", "[4, inf)")
    max_range_rel_sd: float = param(0.5, "unobservable above this range sd / range",
                                    "(0, inf)")
    fit_alpha: float = param(1e-3, "poor_fit below this p-value (chi-square, or runs test)",
                             "(0, 1)")
    singular_rcond: float = param(1e-12, "J^T J is singular at or below this scaled "
                                  "eigenvalue ratio", "(0, 1)")


class BearingsEstimator(Estimator):
    """Base of estimators over ``bearings2d`` logs; subclasses implement ``solve``. Every
    output carries per track its kinematics now (at the last bearing), their one-sigma
    errors and a ``status`` (see ``bearings_status``)."""

    family = "bearings2d"
    conformance_scenario = {"sigma_deg": 0.5, "seed": 3}

    def estimate(self, log: BearingsLog) -> dict:
        """Estimate theta for every track of ``log``; returns output columns by name."""
        t, ox, oy = log.t_s, log.own_x_m, log.own_y_m
        measured = np.deg2rad(log.bearing_deg)
        valid = np.isfinite(measured)
        n_bearings = valid.sum(axis=1)
        few = n_bearings < self.config.min_bearings
        if np.any(few):
            ids = ", ".join(str(i) for i in log.track_id[few][:10])
            raise InputError(
                f"{self.name}: tracks {ids} have fewer than {self.config.min_bearings} bearings "
                f"(min {n_bearings.min()}); 4 parameters (x0, y0, vx, vy) need more"
            )
        measured = np.where(valid, measured, 0.0)
        last = valid.shape[1] - 1 - np.argmax(valid[:, ::-1], axis=1)
        first = np.argmax(valid, axis=1)
        if valid.all():
            valid = None  # every bearing present: skip masking in the hot loops
        self.log_sigma_deg = log.sigma_deg  # the log's nominal noise (None: unknown), for solve
        out = self.solve(t, ox, oy, measured, valid, first)
        theta = out.pop("theta")
        if "cost_rad2" in out:  # iterative estimators know F and J^T J at their solution
            cost, jtj = out.pop("cost_rad2"), out.pop("jtj")
        else:
            cost, jtj = evaluate_in_blocks(BearingTerms(t, ox, oy, measured, valid), theta)
        # a fit with its own noise scale and fit test (robust lm) passes both on to assess
        sigma2, fit_p = out.pop("sigma2_rad2", None), out.pop("fit_p", None)
        runs_p = None
        if log.sigma_deg is None and fit_p is None:
            residuals = bearing_residuals(theta, t, ox, oy, measured, valid)
            runs_p = runs_test_p(residuals, valid)
        trust = assess(theta, cost, jtj, n_bearings, out["converged"], t[last], ox[last],
                       oy[last], log.sigma_deg, runs_p, self.config, sigma2=sigma2, fit_p=fit_p)
        columns = {
            "x0_m": theta[:, 0], "y0_m": theta[:, 1], "vx_m_s": theta[:, 2], "vy_m_s": theta[:, 3],
            **out,
            "cost_rad2": cost,
            "n_bearings": n_bearings.astype(np.int64),
            "t_last_s": t[last], "own_x_last_m": ox[last], "own_y_last_m": oy[last],
            **trust,
        }
        for i in range(4):
            for j in range(i, 4):
                columns[f"jtj_{i}{j}"] = jtj[:, i, j]
        return columns

    def solve(self, t, own_x, own_y, measured_rad, valid, first) -> dict:
        """``valid``: mask or None (all present); ``first``: index of each track's first
        bearing; ``self.log_sigma_deg`` is the log's nominal noise. Returns ``theta`` (n, 4),
        optionally ``cost_rad2`` and ``jtj`` at theta, ``sigma2_rad2`` and ``fit_p`` (a noise
        scale and fit test of the estimator's own, replacing the nominal ones in the status),
        and estimator-specific columns."""
        raise NotImplementedError
