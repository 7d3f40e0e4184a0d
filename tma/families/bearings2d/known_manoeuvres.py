"""The component of a target's known manoeuvres, for checks on simulated targets whose
manoeuvres are drawn from the model itself (``target.manoeuvres.shape=burst``): how far the
component, with no search, holds the truth, as it is and in the statements that may replace
it (``log_polar.py``, ``range_bank.py``). Issue 36; ``make bench ARGS="--only own_model"``."""

import numpy as np

from tma.families.bearings2d.log_polar import log_polar_statement
from tma.families.bearings2d.manoeuvre_components import burst_levels, component
from tma.families.bearings2d.mixture_tails import tail_points
from tma.families.bearings2d.range_bank import range_bank


def known_manoeuvres_nees(t, own_x, own_y, measured_rad, sigma_rad, theta, start, duration,
                          dv_m_s, log_polar: bool = False, over_range: bool = False) -> float:
    """The 4D normalised error, at the last epoch, of the component of one target's known
    manoeuvres (``start``, ``duration``: (slots,), s, inf: none; ``burst_levels``), refined
    to its MAP trajectory from the straight line ``theta`` (x0, y0, vx, vy: m, m/s, through
    the true state at the last epoch, as the truth states it) and linearised there, as the
    mixture's components are: the Laplace approximation alone, with no search (inf where
    the fit fails). ``log_polar``: that Gaussian stated through log-polar coordinates about
    own-ship at the last epoch (``log_polar.log_polar_statement``); ``over_range``: the
    component as a bank over range instead (``range_bank.range_bank``)."""
    if log_polar and over_range:
        raise ValueError("known_manoeuvres_nees: log_polar and over_range are two statements "
                         "of the component; ask for one of them")
    x0, y0, vx, vy = theta
    line = np.column_stack([x0 + vx * t, y0 + vy * t, np.full(t.size, vx),
                            np.full(t.size, vy)])
    levels = burst_levels(t, start, duration, dv_m_s)
    if over_range:
        mean, cov = range_bank(t, own_x, own_y, measured_rad, levels, sigma_rad, line)
    else:
        _, mean, cov, _ = component(t, own_x, own_y, measured_rad, line[0], levels, sigma_rad,
                                    start=line)
    if not np.isfinite(cov).all():
        return np.inf
    if log_polar:
        own_p = np.array([own_x[-1], own_y[-1]])
        own_v = (own_p - np.array([own_x[-2], own_y[-2]])) / (t[-1] - t[-2])
        mean, cov = log_polar_statement(mean, cov, own_p, own_v, *tail_points())
    error = mean - line[-1]
    return float(error @ np.linalg.solve(cov, error))
