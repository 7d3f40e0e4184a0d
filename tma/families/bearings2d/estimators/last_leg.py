"""``last_leg``: a manoeuvring target's last leg, found and solved: ``lm`` on the bearings
after the target's last manoeuvre.

Bearings-only TMA of a manoeuvring target is usually posed leg by leg: the target holds
course and speed between manoeuvres, and each leg is solved from the own-ship geometry
during it (Le Cadre and Tremois, "Bearings-only tracking for maneuvering sources", IEEE
Trans. Aerospace and Electronic Systems 34(1), 1998, model the source as such legs). What is
followed here:

1. ``lm`` on all the track's bearings (the motion it assumes, ``accel_psd_m2_s3``, as
   ``lm``'s). A track whose residual sequence passes the trend test (``status``) is one leg:
   the answer is ``lm``'s.
2. Otherwise, the change time by likelihood over candidate times: for each tau every
   ``step_s`` that leaves ``min_leg_s`` and ``min_bearings`` on both sides, a
   constant-velocity fit to the bearings before tau and another to those from tau; with a
   common noise the most likely tau minimises F_before(tau) + F_after(tau) (the two-phase
   regression of Quandt, JASA 53, 1958; the change-point likelihood of Hinkley, Biometrika
   57(1), 1970).
3. The bearings from tau are the candidate last leg. If they fail the trend test in turn
   (tau fell within a turn, or an earlier manoeuvre was found first) step 2 is repeated on
   them, up to ``max_rounds`` times.
   With manoeuvres in the prior, all of this is within the span ``lm``'s answer rests on
   (``manoeuvres.window_s``: the last 20 minutes of a recording).
4. The leg's solution is ``lm``'s on the leg's bearings alone (``bearings_used``), with
   every output column, its status and its one-sigma errors referring to that leg:
   ``leg_start_s`` is its first bearing, and a leg the own-ship did not manoeuvre during is
   ``unobservable``, as it should be. A leg that still fails the test after the last round
   keeps status ``manoeuvring``.

Each fit takes the lowest F of its starts: the whole track's solution and the leg's first
bearing at ``start_min_m``-``start_max_m`` (geometric, ``leg_starts`` of them).
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.bearings2d import manoeuvres, ncv
from tma.families.bearings2d.bearing_noise import differenced_sigma
from tma.families.bearings2d.contract import Bearings, Solution, TargetMotion
from tma.families.bearings2d.estimators.lm import Config as LmConfig
from tma.families.bearings2d.estimators.lm import LevenbergMarquardt
from tma.families.bearings2d.manoeuvre_prior import window_start
from tma.families.bearings2d.marquardt import STOP_F_TOL, MarquardtSettings, fit_starts
from tma.families.bearings2d.status import trend_test_p


@dataclass
class Config(LmConfig):
    step_s: float = param(30.0, "candidate change times every this many seconds", "(0, 1e7)")
    min_leg_s: float = param(120.0, "a leg (before or after a change) lasts at least this long "
                             "(s)", "(0, 1e7)")
    max_rounds: int = param(3, "change searches per track (each within the last leg found)",
                            "[1, 20]")
    settle_alpha: float = param(0.2, "a leg whose constant-velocity trend test rejects at this "
                                "level starts step_s later", "(0, 1)")
    leg_starts: int = param(4, "initial distances along the leg's first bearing, besides the "
                            "track's solution", "[1, 16]")

    def __post_init__(self):
        super().__post_init__()
        require(self.loss == "squared", self.where, f"loss must be squared, got {self.loss!r}")


class LastLeg(LevenbergMarquardt):
    Config = Config
    outputs = ("start_won", "n_rounds")
    # every output present (the loss is squared; path: as lm's)
    conformance_config = {"starts": 2, "path_points": 50}
    tests_motion = True  # its legs are tested whatever the log declares

    def solve(self, bearings: Bearings, motion: TargetMotion) -> Solution:
        t, own_x, own_y, measured_rad, valid = (bearings.t, bearings.own_x, bearings.own_y,
                                                bearings.measured, bearings.valid)
        q, sigma, prior = motion.accel_psd_m2_s3, bearings.sigma_deg, motion.manoeuvres
        out = self.fit(bearings)
        n, K = measured_rad.shape
        present = np.ones((n, K), dtype=bool) if valid is None else valid
        if prior is not None and motion.moving and self.models_motion:
            # as lm's answer, the legs rest on the recent past where the mixture weighs the
            # manoeuvres (manoeuvres.window_s): a log of hours costs what its window does
            start = window_start(t, bearings.first, bearings.last, prior)
            present = present & (np.arange(K)[None, :] >= start[:, None])
        used = present.copy()
        rounds = np.zeros(n, dtype=np.int64)
        todo = np.arange(0) if self.config.motion_test == "off" else np.flatnonzero(
            self._drifting(t, own_x, own_y, measured_rad, present, out["theta"], q, sigma,
                           prior, bearings.platform))
        for _ in range(self.config.max_rounds):
            if todo.size == 0:
                break
            rounds[todo] += 1
            tau = self._change_times(t, own_x, own_y, measured_rad[todo], used[todo],
                                     out["theta"][todo])
            found = np.isfinite(tau)
            todo, tau = todo[found], tau[found]
            used[todo] &= t >= tau[:, None]
            leg = self._settle(t, own_x, own_y, measured_rad[todo], used[todo],
                               out["theta"][todo], sigma)
            used[todo] = leg.pop("used")
            out["n_f_evals"][todo] += leg.pop("n_f_evals")  # the work of every round, summed
            for key, value in leg.items():
                out[key][todo] = value
            drifting = self._drifting(t, own_x, own_y, measured_rad[todo], used[todo],
                                      out["theta"][todo], q, sigma, prior, bearings.platform)
            todo = todo[drifting]
        out["converged"] = out["stop_reason"] == STOP_F_TOL
        out.update(n_rounds=rounds, bearings_used=used, leg_start_s=t[np.argmax(used, axis=1)])
        return self.solution(out)

    def _drifting(self, t, own_x, own_y, measured, used, theta, q, sigma, prior=None,
                  platform=None):
        """Tracks whose residual sequence fails the trend test, under the wander ``q`` and
        the manoeuvres ``prior`` assumed (``sigma``: the nominal noise, deg; None: unknown:
        with manoeuvres, the bearings' own, ``bearing_noise``, over each epoch's
        ``platform``).
        With manoeuvres in the prior, the mixture already averages over when the target
        changed its motion (the Bayesian form of the change-time search below): a leg is
        sought only where the mixture's own innovations fail the test."""
        if measured.shape[0] == 0:
            return np.zeros(0, dtype=bool)
        first = np.argmax(used, axis=1)
        last = used.shape[1] - 1 - np.argmax(used[:, ::-1], axis=1)
        sigma_rad = np.full(measured.shape[0], np.nan if sigma is None else np.deg2rad(sigma))
        if prior is None or not self.models_motion:
            fit = ncv.smooth(t, own_x, own_y, measured, used, first, last, theta, q, sigma_rad,
                             iterate=q > 0)
        else:
            if sigma is None:  # as the base's motion fit weighs them (bearing_noise)
                sigma_rad = differenced_sigma(t, measured, used, platform)
            fit = manoeuvres.mixture(t, own_x, own_y, measured, used, first, last, theta, q,
                                     prior, sigma_rad)
        with np.errstate(invalid="ignore"):
            drifting = trend_test_p(fit.innovations, t, self.config.motion_terms) \
                < self.config.motion_alpha
        # below any sensor's noise (a noiseless log) the residuals are round-off: no pattern
        noisy = (sigma is None or np.deg2rad(sigma) >= ncv.MIN_SIGMA_RAD) & (
            np.sqrt(fit.sigma2) >= ncv.MIN_SIGMA_RAD)
        return drifting & noisy

    def _settle(self, t, own_x, own_y, measured, used, theta, sigma):
        """The fit of each candidate leg, its start moved on by ``step_s`` while its
        constant-velocity residual sequence still fails the trend test at ``settle_alpha``
        (the change time falls within a turn: the leg starts once the turn is over), as
        long as ``min_leg_s`` remains. Returns the fits and the bearings used."""
        cfg = self.config
        used = used.copy()
        fit = self._fit(t, own_x, own_y, measured, used, theta)
        last_t = t[used.shape[1] - 1 - np.argmax(used[:, ::-1], axis=1)]
        todo = np.arange(measured.shape[0])
        while todo.size:
            first = np.argmax(used[todo], axis=1)
            last = used.shape[1] - 1 - np.argmax(used[todo, ::-1], axis=1)
            cv = ncv.smooth(t, own_x, own_y, measured[todo], used[todo], first, last,
                            fit["theta"][todo], 0.0,
                            np.full(todo.size, np.nan if sigma is None else np.deg2rad(sigma)),
                            iterate=False)
            with np.errstate(invalid="ignore"):
                unsettled = trend_test_p(cv.innovations, t, cfg.motion_terms) \
                    < cfg.settle_alpha
            start = t[first] + cfg.step_s
            room = (last_t[todo] - start >= cfg.min_leg_s) & (
                (used[todo] & (t >= start[:, None])).sum(axis=1) >= cfg.min_bearings)
            todo, start = todo[unsettled & room], start[unsettled & room]
            if todo.size == 0:
                break
            used[todo] &= t >= start[:, None]
            again = self._fit(t, own_x, own_y, measured[todo], used[todo], fit["theta"][todo])
            fit["n_f_evals"][todo] += again.pop("n_f_evals")
            for key, value in again.items():
                fit[key][todo] = value
        fit["used"] = used
        return fit

    def _change_times(self, t, own_x, own_y, measured, used, theta):
        """The most likely change time per track (NaN where no candidate leaves two legs):
        the tau minimising F(before) + F(after) of two constant-velocity fits."""
        cfg = self.config
        n = measured.shape[0]
        lo = np.where(used.any(axis=1), t[np.argmax(used, axis=1)], np.inf)
        hi = t[used.shape[1] - 1 - np.argmax(used[:, ::-1], axis=1)]
        span = np.nanmax(np.where(np.isfinite(lo), hi - lo, 0.0), initial=0.0)
        offsets = np.arange(cfg.min_leg_s, span - cfg.min_leg_s + 1e-9, cfg.step_s)
        best, best_cost = np.full(n, np.nan), np.full(n, np.inf)
        for offset in offsets:
            tau = lo + offset
            before, after = used & (t < tau[:, None]), used & (t >= tau[:, None])
            enough = ((before.sum(1) >= cfg.min_bearings) & (after.sum(1) >= cfg.min_bearings)
                      & (hi - tau >= cfg.min_leg_s))
            if not enough.any():
                continue
            rows = np.flatnonzero(enough)
            cost = (self._fit(t, own_x, own_y, measured[rows], before[rows], theta[rows],
                              cost_only=True)
                    + self._fit(t, own_x, own_y, measured[rows], after[rows], theta[rows],
                                cost_only=True))
            better = cost < best_cost[rows]
            best[rows[better]], best_cost[rows[better]] = tau[rows[better]], cost[better]
        return best

    def _fit(self, t, own_x, own_y, measured, used, theta, cost_only=False):
        """Constant-velocity ML fits of the bearings ``used`` (rows), each from the lowest F
        of its starts: ``theta`` and the leg's first bearing at ``leg_starts`` distances."""
        cfg = self.config
        n = measured.shape[0]
        first = np.argmax(used, axis=1)
        rows = np.arange(n)
        bearing = measured[rows, first]
        ox0, oy0 = own_x[first], own_y[first]
        starts = [theta]
        for d in np.geomspace(cfg.start_min_m, cfg.start_max_m, cfg.leg_starts):
            # a target at rest at distance d along the leg's first bearing
            starts.append(np.column_stack([ox0 + d * np.sin(bearing), oy0 + d * np.cos(bearing),
                                           np.zeros(n), np.zeros(n)]))
        best = fit_starts(MarquardtSettings.of(cfg), np.nan_to_num(np.concatenate(starts)), t,
                          own_x, own_y, measured, np.ascontiguousarray(used, dtype=float), True)
        best.pop("start_won", None)
        return best["cost_rad2"] if cost_only else best
