"""The component of a target's known manoeuvres, for checks on simulated targets whose
manoeuvres are drawn from the model itself (``target.manoeuvres.shape=burst``): how far the
component, with no search, holds the truth, as it is and stated through log-polar
coordinates (``log_polar.py``). Issue 36; ``make bench ARGS="--only own_model"``."""

import numpy as np

from tma.families.bearings2d.log_polar import log_polar_statement
from tma.families.bearings2d.manoeuvre_components import burst_levels, component
from tma.families.bearings2d.metrics import THETA
from tma.families.bearings2d.mixture_tails import tail_points
from tma.families.bearings2d.scenario import MANOEUVRE
from tma.families.bearings2d.target_motion import burst_plan
from tma.runtime.sharding import shard_rng


def known_manoeuvres_nees(t, own_x, own_y, measured_rad, sigma_rad, theta, start, duration,
                          dv_m_s) -> tuple[float, float]:
    """The 4D normalised errors, at the last epoch, of the component of one target's known
    manoeuvres (``start``, ``duration``: (slots,), s, inf: none; ``burst_levels``), refined
    to its MAP trajectory from the straight line ``theta`` (x0, y0, vx, vy: m, m/s, through
    the true state at the last epoch, as the truth states it) and linearised there, as the
    mixture's components are (the Laplace approximation alone, with no search), and of that
    Gaussian stated through log-polar coordinates about own-ship at the last epoch
    (``log_polar.log_polar_statement``); inf where the fit fails."""
    x0, y0, vx, vy = theta
    line = np.column_stack([x0 + vx * t, y0 + vy * t, np.full(t.size, vx),
                            np.full(t.size, vy)])
    _, mean, cov, _ = component(t, own_x, own_y, measured_rad, line[0],
                                burst_levels(t, start, duration, dv_m_s), sigma_rad,
                                start=line)
    if not np.isfinite(cov).all():
        return np.inf, np.inf
    own_p = np.array([own_x[-1], own_y[-1]])
    own_v = (own_p - np.array([own_x[-2], own_y[-2]])) / (t[-1] - t[-2])
    stated = log_polar_statement(mean, cov, own_p, own_v, *tail_points())
    return tuple(float((m - line[-1]) @ np.linalg.solve(c, m - line[-1]))
                 for m, c in ((mean, cov), stated))


def true_manoeuvres_nees(dataset, rows) -> np.ndarray:
    """``known_manoeuvres_nees`` (rows, 2) of the targets ``rows`` of a simulated dataset of
    one shard whose manoeuvres are bursts: their bursts drawn again from the shard's
    manoeuvre stream (``target_motion.burst_plan`` makes its first draws; a ValueError if
    the counts drawn are not the truth's)."""
    cfg = dataset.config
    if len(dataset.logs) != 1 or cfg.target.manoeuvres.shape != "burst":
        raise ValueError("true_manoeuvres_nees: a dataset of one shard (shard_size=n_tracks) "
                         "whose manoeuvres are bursts (target.manoeuvres.shape=burst)")
    log = dataset.logs[0]
    t = np.asarray(log.t_s, dtype=float)
    prior = log.manoeuvres
    count, start, duration = burst_plan(cfg.target.manoeuvres, prior, t, cfg.n_tracks,
                                        shard_rng(cfg, 0, MANOEUVRE))
    if not np.array_equal(count, dataset.truth.n_manoeuvres):
        raise ValueError("true_manoeuvres_nees: the bursts drawn again are not the dataset's")
    truth = dataset.truth[list(THETA)].to_numpy()  # (one shard: rows in the log's order)
    return np.array([known_manoeuvres_nees(t, log.own_x_m, log.own_y_m,
                                           np.deg2rad(log.bearing_deg[i]),
                                           np.deg2rad(log.sigma_deg), truth[i], start[:, i],
                                           duration[:, i], prior.dv_m_s) for i in rows],
                    dtype=float).reshape(-1, 2)
