"""The shared pieces of the bearings-only estimators: settings, the contract between the base
and an estimator (``Bearings`` and ``TargetMotion`` in, a ``Solution`` out of ``solve``), and
the per-track status and one-sigma errors every output carries.

``BearingsEstimator.estimate`` runs three named steps: ``read`` (the log's bearings as the
estimators take them, checked), ``solve`` (the estimator's own, typed), ``judge`` (the
targets' motion fitted about the solution, the noise and trend tests, the status, the
columns)."""

import dataclasses
from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.errors import InputError
from tma.estimator import Estimates, Estimator, EstimatorConfig
from tma.families.bearings2d import estimated_path, manoeuvres, ncv
from tma.families.bearings2d.bearing_noise import differenced_sigma
from tma.families.bearings2d.contract import Bearings, JudgedFit, Solution, TargetMotion
from tma.families.bearings2d.end_bearing import end_bearing
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.manoeuvre_prior import RECORDED_MANOEUVRES, window_start
from tma.families.bearings2d.model import BearingTerms
from tma.families.bearings2d.ncv import RECORDED_ACCEL_PSD
from tma.families.bearings2d.platforms import observer_now, reference_index
from tma.families.bearings2d.status import (
    MIN_RANGE_M,
    assess,
    noise_fit,
    range_rel_sd,
    trend_test_p,
    two_sided_chi2_p,
)
from tma.maths.linalg import scaled_inverse

BLOCK_TRACKS = 64
# what the manoeuvre mixture says of each answer (ncv.MotionFit), output in this order
MIXTURE_COLUMNS = ("p_manoeuvre", "tail_scale", "p_omitted", "n_manoeuvres")
GROSS_SIGMAS = 5.0  # a robust fit's outliers: bearings this many sigma off (Gaussian: 6e-7)


def evaluate_in_blocks(terms: BearingTerms, theta, block=BLOCK_TRACKS):
    """F(theta) (rad^2), J^T J and the gradient J^T r per track, evaluated in cache-sized
    blocks of tracks."""
    n = theta.shape[0]
    cost, jtj, g = np.empty(n), np.empty((n, 4, 4)), np.empty((n, 4))
    for start in range(0, n, block):
        rows = np.arange(start, min(start + block, n))
        cost[rows], jtj[rows], g[rows] = terms(theta[rows], rows)
    return cost, jtj, g


MOTION_TESTS = ("auto", "on", "off")


@dataclass
class BearingsConfig(EstimatorConfig):
    """Settings every bearings-only estimator shares: what it needs, the targets' motion it
    assumes, and how its per-track ``status`` is decided (``tma.families.bearings2d.status``)."""

    min_bearings: int = param(5, "bearings a track needs (4 unknowns)", "[4, inf)")
    max_range_rel_sd: float = param(0.2, "unobservable above this range sd / range",
                                    "(0, inf)")
    max_course_sd_deg: float = param(30.0, "position_only above this course sd (deg), for "
                                     "targets that may wander or manoeuvre (where the target "
                                     "is heading is then not determined)", "(0, 360]")
    max_speed_rel_sd: float = param(0.5, "position_only above this speed sd / speed, for "
                                    "targets that may wander or manoeuvre (where the target "
                                    "is heading is then not determined)", "(0, inf)")
    fit_alpha: float = param(1e-3, "poor_fit below this p-value of the noise test (chi-square)",
                             "(0, 1)")
    singular_rcond: float = param(1e-12, "J^T J is singular at or below this scaled "
                                  "eigenvalue ratio", "(0, 1)")
    accel_psd_m2_s3: float | None = param(
        None, "the targets' random acceleration, spectral density per axis (m^2/s^3; 0: "
        "constant velocity); null: the log's declared one, else (a recording) real-ship "
        "motion, ncv.RECORDED_ACCEL_PSD", "[0, 1e6)")
    manoeuvre_rate_per_h: float | None = param(
        None, "the targets' manoeuvres per hour (Poisson; 0: none); null: the log's declared "
        "ones, else (a recording) real-ship manoeuvres, manoeuvres.RECORDED_MANOEUVRES",
        "[0, 1000]")
    manoeuvre_dv_m_s: float | None = param(
        None, "a manoeuvre's velocity change, sd per axis (m/s), where the targets manoeuvre; "
        "null: the log's declared one, else (a recording) manoeuvre_prior.RECORDED_DV_M_S",
        "(0, 1000]")
    manoeuvre_durations_s: list[float] | None = param(
        None, "the durations a manoeuvre's velocity change is spread over (s, equal prior "
        "weights), where the targets manoeuvre; null: the log's declared ones, else (a "
        "recording) manoeuvre_prior.RECORDED_DURATIONS_S", each="(0, 86400]")
    motion_prior_scale: float = param(1.0, "the targets' assumed random acceleration and "
                                      "manoeuvre rate times this (1: as declared or assumed; "
                                      "to measure what a wrong prior does)", "(0, 1e6)")
    motion_test: str = param("auto", "the trend test of the residual sequence (status "
                             "manoeuvring): auto runs it on a log that declares its targets' "
                             "motion or its noise not (a recording)", choices=MOTION_TESTS)
    motion_alpha: float = param(1e-3, "manoeuvring below this p-value of the trend test",
                                "(0, 1)")
    motion_terms: int = param(8, "cosines of the trend test's smooth bias (1: a constant bias)",
                              "[1, 64]")
    reference_platform: str | None = param(
        None, "the platform range and bearing now are given from, in a log of several "
        "(ships, buoys, stations); null: the first", None)

    def __post_init__(self):
        super().__post_init__()
        require(self.manoeuvre_durations_s is None or len(self.manoeuvre_durations_s) > 0,
                self.where, "manoeuvre_durations_s must be null or a list of one duration "
                "(s) or more, got []")


class BearingsEstimator(Estimator):
    """Base of estimators over ``bearings2d`` logs; subclasses implement ``solve``. Every
    output carries per track its kinematics now (at the last bearing), their one-sigma
    errors, a ``status`` (see ``status.py``), from when the solution holds
    (``leg_start_s``), the target motion it assumed (``accel_psd_m2_s3``; with manoeuvres,
    ``manoeuvre_rate_per_h`` and ``p_manoeuvre``) and the trend test's p-value
    (``motion_p_value``, NaN where not run).

    ``models_motion``: the estimator can follow a target that is not at constant velocity
    (its ``Config`` then declares ``path_points``, the side table ``path`` it keeps):
    its constant-velocity fit is refined to the maximum a posteriori state under the targets'
    motion (``ncv.smooth``; with manoeuvres, ``manoeuvres.mixture``), whose covariance
    includes that motion; for a robust fit (``loss`` huber|cauchy) on the bearings no more
    than ``GROSS_SIGMAS`` off its constant-velocity line and off the motion fit (outliers,
    not wander). One that cannot follow such a target reports ``approximate`` there, as does
    one whose errors are not honest by construction (``honest_errors`` False).
    ``tests_motion``: the trend test runs even where the log declares its targets' motion
    (``last_leg``)."""

    family = "bearings2d"
    models_motion = False
    honest_errors = True
    tests_motion = False  # runs the trend test even where the log declares its motion
    several_platforms = True  # takes each bearing from its own platform (BearingsLog.platform)
    conformance_scenario = {"sigma_deg": 0.5, "seed": 3}

    def estimate(self, log: BearingsLog) -> Estimates:
        """The ``Estimates`` of every track of ``log``: ``read``, ``solve``, ``judge``."""
        bearings, motion = self.read(log), self.motion(log)
        return self.judge(bearings, motion, self.solve(bearings, motion), log)

    def read(self, log: BearingsLog) -> Bearings:
        """The bearings of ``log`` in radians, the missing ones masked; refuses a track with
        fewer than ``min_bearings``."""
        measured = np.deg2rad(log.bearing_deg)
        valid = np.isfinite(measured)
        n_bearings = valid.sum(axis=1)
        few = n_bearings < self.config.min_bearings
        if np.any(few):
            ids = ", ".join(str(i) for i in log.track_id[few][:10])
            raise InputError(
                f"{self.name}: tracks {ids} have fewer than {self.config.min_bearings} "
                f"bearings (min {n_bearings.min()}); 4 parameters (x0, y0, vx, vy) need more"
            )
        if log.platforms is not None and not self.several_platforms:
            raise InputError(f"{self.name}: the log's bearings come from {log.n_platforms} "
                             f"platforms ({', '.join(log.platforms)}); {self.name} needs one "
                             "own-ship: use lm, last_leg, iv or nbearings")
        reference = reference_index(log.platforms, self.config.reference_platform, self.name)
        last = valid.shape[1] - 1 - np.argmax(valid[:, ::-1], axis=1)
        now_x, now_y = observer_now(log.t_s, log.own_x_m, log.own_y_m, log.platform,
                                    reference, last)
        return Bearings(t=log.t_s, own_x=log.own_x_m, own_y=log.own_y_m,
                        measured=np.where(valid, measured, 0.0),
                        valid=None if valid.all() else valid, first=np.argmax(valid, axis=1),
                        last=last, n_bearings=n_bearings, sigma_deg=log.sigma_deg,
                        now_x=now_x, now_y=now_y, platform=log.platform,
                        platforms=log.platforms, reference=reference)

    def motion(self, log: BearingsLog) -> TargetMotion:
        """The targets' motion the outputs assume: the random acceleration q (m^2/s^3) and
        the manoeuvres' prior (rate, velocity change, durations), each as set, else as the
        log declares, else (a recording, which declares nothing) real-ship motion; q and the
        rate scaled by ``motion_prior_scale``."""
        cfg = self.config
        recorded = log.accel_psd_m2_s3 is None
        q = cfg.accel_psd_m2_s3
        if q is None:
            q = RECORDED_ACCEL_PSD if recorded else log.accel_psd_m2_s3
        prior = RECORDED_MANOEUVRES if recorded else log.manoeuvres
        if cfg.manoeuvre_rate_per_h is not None:
            prior = dataclasses.replace(prior or RECORDED_MANOEUVRES,
                                        rate_per_h=cfg.manoeuvre_rate_per_h)
        if prior is not None and cfg.manoeuvre_dv_m_s is not None:
            prior = dataclasses.replace(prior, dv_m_s=cfg.manoeuvre_dv_m_s)
        if prior is not None and cfg.manoeuvre_durations_s is not None:
            prior = dataclasses.replace(prior,
                                        durations_s=tuple(cfg.manoeuvre_durations_s))
        if prior is not None:
            prior = prior.scaled(cfg.motion_prior_scale)
        return TargetMotion(q * cfg.motion_prior_scale,
                            prior if prior and prior.rate_per_h > 0 else None)

    def solve(self, bearings: Bearings, motion: TargetMotion) -> Solution:
        """The estimator's own step: its ``Solution`` from the ``bearings``, under the targets'
        ``motion`` where it needs it."""
        raise NotImplementedError

    def judge(self, bearings: Bearings, motion: TargetMotion, solution: Solution,
              log: BearingsLog) -> Estimates:
        """The ``Estimates`` of ``solution``, in four steps: ``_noise_fit`` (the fit at the
        solution and the noise test), ``_follow`` (the targets' motion fitted about it,
        ``models_motion``, and the trend test), ``status.assess`` (the status and one-sigma
        errors, with ``end_bearing``'s guard) and ``_columns``."""
        b = bearings
        fit = self._noise_fit(b, solution)
        self._follow(b, motion, solution, log, fit)
        approximate = np.full(fit.theta.shape[0], not self.honest_errors)
        approximate |= motion.moving and not self.models_motion
        t, last = b.t, b.last
        trust = assess(fit.theta, fit.jtj, fit.sigma2, fit.fit_p, fit.motion_p, fit.converged,
                       approximate, t[last], b.now_x, b.now_y, self.config,
                       motion_tested=fit.tested, undetermined=fit.undetermined,
                       moving=motion.moving, tail_scale=fit.tail_scale,
                       intervals=fit.intervals)
        # where the log's own last bearings point now, for status.not_an_answer's rule
        trust.update(self._end_bearing(b, np.sqrt(fit.sigma2)))
        return self._columns(b, motion, solution, log, fit, trust)

    def _noise_fit(self, b: Bearings, solution: Solution) -> JudgedFit:
        """The fit at the solution (F and J^T J, computed where the solver has none), the
        bearings it rests on, and the noise scale and fit test (the solver's own for a robust
        fit)."""
        theta = solution.theta
        if solution.cost_rad2 is not None:  # iterative estimators know F and J^T J there
            cost, jtj = solution.cost_rad2, solution.jtj
        else:
            cost, jtj, _ = evaluate_in_blocks(
                BearingTerms(b.t, b.own_x, b.own_y, b.measured, b.valid), theta)
        n_bearings, valid = b.n_bearings, b.valid
        if solution.bearings_used is not None:  # a fit of part of each track (last_leg)
            n_bearings, valid = solution.bearings_used.sum(axis=1), solution.bearings_used
        # a fit with its own noise scale and fit test (robust lm): its scale, its test, and
        # of the bearings the ones it kept
        sigma2, fit_p = solution.sigma2_rad2, solution.fit_p
        own_fit_test = fit_p is not None
        if fit_p is None:
            sigma2, fit_p = noise_fit(cost, n_bearings - 4, b.sigma_deg)
        n = theta.shape[0]
        sigma2 = np.broadcast_to(np.asarray(sigma2, dtype=float), (n,))
        return JudgedFit(theta=theta, converged=solution.converged, cost=cost, jtj=jtj,
                         sigma2=sigma2, fit_p=fit_p, own_fit_test=own_fit_test,
                         n_bearings=n_bearings,
                         use=valid if solution.inliers is None else solution.inliers,
                         start=b.first, tested=np.zeros(n, dtype=bool),
                         motion_p=np.full(n, np.nan), p_manoeuvre=np.full(n, np.nan),
                         tail_scale=np.ones(n), p_omitted=np.full(n, np.nan),
                         n_manoeuvres=np.full(n, np.nan), undetermined=np.zeros(n, dtype=bool),
                         intervals=np.full((n, 3, 4), np.nan))

    def _follow(self, b: Bearings, motion: TargetMotion, solution: Solution,
                log: BearingsLog, fit: JudgedFit):
        """The targets' motion fitted about the solution (``models_motion``: ``ncv.smooth``,
        with manoeuvres ``manoeuvres.mixture`` over the recent window the answer rests on),
        its trajectory kept for the plots (``path_points``), and the trend test of the
        innovations; updates ``fit``."""
        cfg = self.config
        t, ox, oy, first, last = b.t, b.own_x, b.own_y, b.first, b.last
        n = fit.theta.shape[0]
        undeclared = log.accel_psd_m2_s3 is None or b.sigma_deg is None
        test = cfg.motion_test == "on" or (cfg.motion_test == "auto"
                                           and (undeclared or self.tests_motion))
        test &= b.sigma_deg != 0  # a noiseless sensor: any misfit fails its own test
        # residuals below any sensor's noise (a noiseless log, declared or not) have no
        # pattern to test: round-off has one
        fit.tested = np.full(n, test) & (np.sqrt(fit.sigma2) >= ncv.MIN_SIGMA_RAD)
        follows = motion.moving and self.models_motion
        q, prior = motion.accel_psd_m2_s3, motion.manoeuvres
        # the trajectory the answer rests on, for the plots and the map (a recording's
        # default; lm's path_points): the side table path (estimated_path)
        points = cfg.path_points if self.models_motion else 0
        if not (follows or test):
            return
        # without manoeuvres, a track whose range the constant-velocity fit leaves
        # undetermined stays so: wander could only widen it (and its MAP would shrink range
        # to fit noise); its innovations for the trend test are those about the fit's line.
        # A manoeuvre can explain what a constant-velocity fit leaves undetermined: with
        # them, every track with an estimate (and then whether own-ship's motion determines
        # the range of the answer, below)
        follow = np.zeros(n, dtype=bool)
        if follows and prior is not None:
            follow = np.isfinite(fit.theta).all(axis=1)
            # the answer rests on the recent past, where the manoeuvres it weighs are few
            # enough to be weighed (manoeuvre_prior.window_start): from when it holds
            fit.start = window_start(t, first, last, prior)
            if np.any(fit.start > first):
                inside = np.arange(t.size)[None, :] >= fit.start[:, None]
                fit.use = inside if fit.use is None else fit.use & inside
                fit.n_bearings = fit.use.sum(axis=1)
        elif follows:
            follow = range_rel_sd(fit.theta, fit.jtj, fit.sigma2, t[last], b.now_x, b.now_y,
                                  cfg.singular_rcond) <= cfg.max_range_rel_sd
        innovations = np.full(b.measured.shape, np.nan)
        leg_start = self._leg_start(t, fit.start, solution)
        for rows, iterate in ((np.flatnonzero(follow), True), (np.flatnonzero(~follow), False)):
            if rows.size == 0 or not (iterate or test):
                continue
            motion_fit = self._motion_fit(b, fit.use, fit.theta, rows, q if follows else 0.0,
                                          prior if follows else None, fit.sigma2, iterate,
                                          b.sigma_deg is None and iterate, fit.own_fit_test,
                                          fit.start[rows], path_cov=iterate and points > 0)
            innovations[rows] = motion_fit.innovations
            if iterate and points > 0:
                fit.paths.append(estimated_path.path_table(
                    log.track_id[rows], t, motion_fit.path_m, motion_fit.path_cov_m2,
                    motion_fit.cov[:, :2, :2], np.searchsorted(t, leg_start[rows]), points))
            for key in (*MIXTURE_COLUMNS, "intervals"):  # (a mixture's own: None from
                if getattr(motion_fit, key) is not None:  # ncv.smooth)
                    getattr(fit, key)[rows] = getattr(motion_fit, key)
            if iterate:
                fit.theta, fit.cost, fit.jtj, fit.sigma2, fit.fit_p = (
                    np.array(v, dtype=float)
                    for v in (fit.theta, fit.cost, fit.jtj, fit.sigma2, fit.fit_p))
                (fit.theta[rows], fit.cost[rows], fit.jtj[rows], fit.sigma2[rows],
                 fit.fit_p[rows]) = self._followed(motion_fit, b.sigma_deg, fit.fit_p[rows])
                # the answer is the motion fit's: its own convergence (the constant-
                # velocity start over the whole log may stop at max_iter on a target that
                # manoeuvred for hours, and only starts it)
                fit.converged = fit.converged.copy()
                fit.converged[rows] = motion_fit.passes >= 0
        if test:
            fit.motion_p = np.where(fit.tested,
                                    trend_test_p(innovations, t, cfg.motion_terms), np.nan)
        if follows and prior is not None:
            # no target manoeuvre makes range observable, only own-ship's: the bearings'
            # information on a constant-velocity target at the answer must determine it
            _, jtj_cv, _ = evaluate_in_blocks(
                BearingTerms(t, ox, oy, b.measured, fit.use), fit.theta)
            fit.undetermined = ~(range_rel_sd(fit.theta, jtj_cv, fit.sigma2, t[last],
                                              b.now_x, b.now_y, cfg.singular_rcond)
                                 <= cfg.max_range_rel_sd)
            if log.accel_psd_m2_s3 is None:  # a recording: an answer collapsed onto own-ship
                # (a target riding with it fits a straight own-ship's bearings) determines
                # no range, and its trend test nothing (status.not_an_answer's MIN_RANGE_M)
                now = fit.theta[:, :2] + fit.theta[:, 2:] * t[last][:, None]
                fit.undetermined |= np.hypot(now[:, 0] - b.now_x,
                                             now[:, 1] - b.now_y) < MIN_RANGE_M
            # there no one-sigma error can be given (the prior's would pretend one): the
            # estimate is no answer (status.not_an_answer)
            fit.jtj = np.where(fit.undetermined[:, None, None], np.nan, fit.jtj)

    def _columns(self, b: Bearings, motion: TargetMotion, solution: Solution,
                 log: BearingsLog, fit: JudgedFit, trust: dict) -> Estimates:
        """The output columns by name and the side table ``path`` (``path_points``)."""
        t, last = b.t, b.last
        theta, n = fit.theta, fit.theta.shape[0]
        q, prior = motion.accel_psd_m2_s3, motion.manoeuvres
        columns = {
            "x0_m": theta[:, 0], "y0_m": theta[:, 1], "vx_m_s": theta[:, 2], "vy_m_s": theta[:, 3],
            "n_f_evals": solution.n_f_evals, "n_iter": solution.n_iter,
            "stop_reason": solution.stop_reason, "converged": fit.converged,
            **solution.columns,
            "cost_rad2": fit.cost,
            "n_bearings": fit.n_bearings.astype(np.int64),
            "t_last_s": t[last], "own_x_last_m": b.now_x, "own_y_last_m": b.now_y,
            **trust,
            "leg_start_s": self._leg_start(t, fit.start, solution),
            "accel_psd_m2_s3": np.full(n, float(q) if self.models_motion else 0.0),
            "motion_p_value": fit.motion_p,
        }
        if prior is not None and self.models_motion:  # (not in the constant-velocity runs)
            columns["manoeuvre_rate_per_h"] = np.full(n, prior.rate_per_h)
            columns.update({key: getattr(fit, key) for key in MIXTURE_COLUMNS})
        for i in range(4):
            for j in range(i, 4):
                columns[f"jtj_{i}{j}"] = fit.jtj[:, i, j]
        path = self.models_motion and self.config.path_points > 0
        return Estimates(columns, {"path": estimated_path.joined(fit.paths, log.track_id.dtype)}
                         if path else {})

    @staticmethod
    def _end_bearing(b: Bearings, sigma_rad) -> dict:
        """Where the log's own last bearings point at each track's last bearing time
        (``end_bearing``): from the reference platform's bearings alone when there are
        several (the answer's bearing now is read from it); NaN for a track it took fewer
        than two of."""
        if b.platform is None:
            return end_bearing(b.t, b.measured, b.valid, b.last, sigma_rad)
        valid = np.ones(b.measured.shape, dtype=bool) if b.valid is None else b.valid
        mine = valid & (b.platform == b.reference)[None, :]
        has = mine.sum(axis=1) >= 2
        last_mine = mine.shape[1] - 1 - np.argmax(mine[:, ::-1], axis=1)
        rows = np.flatnonzero(has)
        out = {k: np.full(has.size, np.nan) for k in ("end_bearing_deg", "end_bearing_sd_deg")}
        if rows.size:
            part = end_bearing(b.t, b.measured[rows], mine[rows], last_mine[rows],
                               np.broadcast_to(sigma_rad, has.shape)[rows],
                               at_s=b.t[b.last[rows]])
            for k, v in part.items():
                out[k][rows] = v
        return out

    @staticmethod
    def _leg_start(t, start, solution: Solution):
        """From when each track's answer holds (s): its first bearing ``start`` in the fit,
        or later where the solution rests on a later leg (``Solution.leg_start_s``)."""
        return t[start] if solution.leg_start_s is None else np.maximum(solution.leg_start_s,
                                                                         t[start])

    @staticmethod
    def _motion_fit(b: Bearings, use, theta, rows, q, prior, sigma2, iterate, sigma_unknown,
                    robust, first, path_cov=False):
        """The motion fit of tracks ``rows``: ``ncv.smooth`` (``iterate`` False: about their
        constant-velocity line), or with a manoeuvre ``prior`` ``manoeuvres.mixture``, from
        each track's bearing ``first``; a robust fit's (``robust``) bearings more than
        ``GROSS_SIGMAS`` off the motion fit are outliers: dropped, and fitted again.
        ``path_cov``: with the covariances of its trajectory's positions (``path_cov_m2``)."""
        part = None if use is None else use[rows]
        sigma_rad = np.full(rows.size, np.nan) if sigma_unknown else np.sqrt(sigma2[rows])
        if sigma_unknown and prior is not None:
            # the mixture weighs manoeuvres against the noise: a noise measured by a fit
            # without them would be inflated by every one it left out (bearing_noise)
            sigma_rad = differenced_sigma(b.t, b.measured[rows],
                                          None if part is None else part, b.platform)

        def fit_of(part):
            args = (b.t, b.own_x, b.own_y, b.measured[rows], part, first, b.last[rows],
                    theta[rows], q)
            if prior is None or not iterate:
                return ncv.smooth(*args, sigma_rad, iterate=iterate, path_cov=path_cov)
            return manoeuvres.mixture(*args, prior, sigma_rad, path_cov=path_cov,
                                      now_xy=(b.now_x[rows], b.now_y[rows]))

        fit = fit_of(part)
        wild = np.abs(np.nan_to_num(fit.innovations)) > GROSS_SIGMAS
        if iterate and robust and wild.any():
            fit = fit_of((np.ones(wild.shape, dtype=bool) if part is None else part) & ~wild)
        return fit

    @staticmethod
    def _followed(fit, sigma_deg, fit_p):
        """theta, F, J^T J, sigma^2 and the noise test of the NCV state ``fit``
        (``ncv.smooth``): J^T J is the information sigma^2 C^-1 of its covariance C (so that
        C is what every reader computes as J^T J^-1 sigma^2); the noise test is the
        two-sided chi-square of its normalised innovations when sigma is known (none when
        unknown: a robust fit's own test judged the constant-velocity fit, which a wandering
        target fails; below ``ncv.MIN_SIGMA_RAD``, the constant-velocity fit's)."""
        sigma2 = fit.sigma2
        info, _ = scaled_inverse(fit.cov_theta, 1e-14)
        info *= sigma2[:, None, None]
        if sigma_deg is not None and np.deg2rad(sigma_deg) >= ncv.MIN_SIGMA_RAD:
            e2 = fit.innovations ** 2
            count = np.sum(np.isfinite(e2), axis=1)
            fit_p = np.where(count > 0,
                             two_sided_chi2_p(np.maximum(count, 1), np.nansum(e2, axis=1)),
                             np.nan)
        elif sigma_deg is None:
            fit_p = np.full(sigma2.size, np.nan)
        return fit.theta, fit.cost_rad2, info, sigma2, fit_p
