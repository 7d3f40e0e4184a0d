"""Shared pieces of the ``radar2d`` trackers: the contract between the base and a tracker
(``Scans`` in, a ``Solution`` out of ``solve``), scan-period checks and the alpha-beta
recursion.

State per run: position (x, y) and velocity (vx, vy), m and m/s, x east, y north. Trackers
return per-scan arrays (n_runs, n_scans); a scan without a plot (NaN) is skipped: the filter
predicts through it and updates nothing. Each run gets a ``status``, the tracker's own
verdict: ``ok``, or ``divergent`` when its estimate is non-finite at any scan from the run's
first plot on (a wrecked filter, or a tracker that cannot start from the plots it got). (Whether
the track was kept, against the truth, is the metrics' ``track_lost``.)
"""

from dataclasses import dataclass, field

import numpy as np

from tma.config import param
from tma.errors import InputError
from tma.estimator import Estimates, Estimator, EstimatorConfig
from tma.families.radar2d.log import RadarLog

STATUSES = ("ok", "divergent")  # a run's status in its estimates: the tracker's verdict


@dataclass
class RadarConfig(EstimatorConfig):
    """What every ``radar2d`` tracker's config holds."""

    scan_period_s: float | None = param(None, "scan period (s); null: the log's (if set, it "
                                        "must agree with the log)", "(0, inf)")


def scan_period(log: RadarLog, configured: float | None) -> float:
    """The log's (uniform) scan period; a configured period must agree with it."""
    dt = np.diff(log.t_s)
    tau = float(np.median(dt))
    if np.any(np.abs(dt - tau) > 1e-6 * tau):
        raise InputError(f"scan times are not uniform (intervals {dt.min():g}..{dt.max():g} s): "
                         "mark a missed scan by a null plot instead of dropping it")
    if configured is not None and abs(configured - tau) > 1e-6 * tau:
        raise InputError(f"scan_period_s = {configured:g} s in the config contradicts the log's "
                         f"scan period of {tau:g} s")
    return tau


def growing_gains(k):
    """Growing-memory alpha-beta gains after k measurements (k >= 2)."""
    k = np.asarray(k, float)
    return 2 * (2 * k - 1) / (k * (k + 1)), 6 / (k * (k + 1))


def alpha_beta_step(pos, vel, k, z, tau, k_max=None):
    """One scan: predict over ``tau``, then update with plots ``z`` (n, 2) where finite.

    ``k`` counts processed plots (0 = not initialised). The first plot initialises
    (position = z, velocity = 0); later ones use the growing-memory gains with
    k = min(k + 1, k_max) (fixed gains once k reaches ``k_max``: a memory of k_max scans).
    Returns new ``(pos, vel, k)``; the inputs are not modified.
    """
    pos = pos + vel * tau
    has = np.all(np.isfinite(z), axis=1)
    k_new = np.where(has, k + 1, k)
    if k_max is not None:
        k_new = np.minimum(k_new, k_max)
    init = has & (k == 0)
    upd = has & (k > 0)
    alpha, beta = growing_gains(np.maximum(k_new, 2))
    r = np.where(upd[:, None], z - pos, 0.0)
    pos = np.where(init[:, None], z, pos + alpha[:, None] * r)
    vel = np.where(init[:, None], 0.0, vel + (beta / tau)[:, None] * r)
    return pos, vel, k_new


def initial_state(n):
    """Not yet initialised: position unknown (NaN) until the first plot, k = 0."""
    return np.full((n, 2), np.nan), np.zeros((n, 2)), np.zeros(n, dtype=np.int64)


def alpha_beta_window(plots, tau):
    """Growing-memory alpha-beta over a window of scans (n, w, 2) from a fresh start: the
    least-squares straight line through the window's plots, evaluated at its last scan."""
    pos, vel, k = initial_state(plots.shape[0])
    for s in range(plots.shape[1]):
        pos, vel, k = alpha_beta_step(pos, vel, k, plots[:, s, :], tau)
    return pos, vel


def run_status(plots, position, velocity) -> np.ndarray:
    """``ok`` or ``divergent`` per run (see the module docstring)."""
    has = np.isfinite(plots).all(axis=2)  # (n, n_scans)
    started = np.cumsum(has, axis=1) > 0
    finite = np.isfinite(position).all(axis=2) & np.isfinite(velocity).all(axis=2)
    bad = (started & ~finite).any(axis=1) | ~has.any(axis=1)
    return np.where(bad, "divergent", "ok")


@dataclass(frozen=True)
class Scans:
    """One shard's radar scans as every tracker takes them: scan times ``t_s`` (K,, s), the
    uniform scan period ``tau_s`` (s), the plots ``plots_m`` (n, K, 2: x east, y north, m;
    NaN where a scan has no plot) and the radar's ``sensor`` record (``tma.sensor``, see
    ``log.py``: its noise, ``cartesian`` with ``sigma_m`` or ``polar``)."""

    t_s: np.ndarray
    tau_s: float
    plots_m: np.ndarray
    sensor: dict

    @property
    def n_tracks(self) -> int:
        return self.plots_m.shape[0]


@dataclass(frozen=True)
class Solution:
    """What ``solve`` returns: each run's estimated ``position_m`` and ``velocity_m_s`` at
    every scan (n, K, 2: x, y east and north), and its own per-scan output ``columns`` (its
    ``outputs``, e.g. the selected memory ``m``), each (n, K)."""

    position_m: np.ndarray
    velocity_m_s: np.ndarray
    columns: dict = field(default_factory=dict)


class RadarEstimator(Estimator):
    """Base of the ``radar2d`` trackers; subclasses implement ``solve``. Every output carries
    per run and scan the state (``x_m``, ``y_m``, ``vx_m_s``, ``vy_m_s``), the scan time
    ``t_s`` and the run's ``status``."""

    conformance_scenario = {"seed": 3}
    family = "radar2d"

    def estimate(self, log: RadarLog) -> Estimates:
        """The ``Estimates`` of every run of ``log``: ``read``, ``solve``, the columns."""
        scans = self.read(log)
        # extreme (valid) noise settings can overflow a run's covariance: flagged, not raised
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            solution = self.solve(scans)
        pos, vel = solution.position_m, solution.velocity_m_s
        return Estimates({
            "x_m": pos[..., 0], "y_m": pos[..., 1], "vx_m_s": vel[..., 0], "vy_m_s": vel[..., 1],
            **solution.columns,
            "t_s": np.broadcast_to(scans.t_s, pos.shape[:2]).copy(),
            "status": run_status(scans.plots_m, pos, vel)})

    def read(self, log: RadarLog) -> Scans:
        """The scans of ``log``; refuses scan times that are not uniform or that contradict
        ``scan_period_s``."""
        return Scans(log.t_s, scan_period(log, self.config.scan_period_s), log.plots_m,
                     log.sensor)

    def solve(self, scans: Scans) -> Solution:
        """The tracker's own step: its ``Solution`` from the ``scans``."""
        raise NotImplementedError
