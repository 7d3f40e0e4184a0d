"""What a target's manoeuvres are believed to be before the bearings (``ManoeuvrePrior``), the
one measured on real ships for a recording (``RECORDED_MANOEUVRES``), and the cells of time
and durations a manoeuvre may take, with their priors: the model
``manoeuvres.py`` averages over (its docstring says how)."""

import math
from dataclasses import dataclass

import numpy as np

# manoeuvres assumed of a recording's targets (which declares none), measured from the AIS
# positions of the vessels underway in two recordings, the Solent and New York Harbor
# (tests/data/ais/motion_stats.py, docs/manoeuvres.md): 9.6 an hour (turns over 15 deg,
# speed changes over 25 %, stops and starts), velocity changes of 4.6 m/s RMS per axis,
# durations 88 / 119 / 181 s (quartiles)
RECORDED_RATE_PER_H = 10.0
RECORDED_DV_M_S = 4.6
RECORDED_DURATIONS_S = (75.0, 120.0, 230.0)
WINDOW_MANOEUVRES = 3.0  # the answer rests on the span of this many manoeuvres (expected)...
MIN_WINDOW_S = 1200.0  # ...or of this much time (s), whichever is longer


@dataclass(frozen=True)
class ManoeuvrePrior:
    """What a target's manoeuvres are believed to be, before the bearings (module docstring).

    ``rate_per_h``: manoeuvres per hour (Poisson); ``dv_m_s``: the velocity change's sd per
    axis (m/s); ``durations_s``: the durations averaged over (equal prior weights);
    ``step_s``: the grid of candidate start times (s)."""

    rate_per_h: float
    dv_m_s: float
    durations_s: tuple[float, ...]
    step_s: float = 60.0

    @property
    def rate_per_s(self) -> float:
        return self.rate_per_h / 3600.0

    def scaled(self, factor: float) -> "ManoeuvrePrior":
        """The same prior with ``factor`` times the rate."""
        return ManoeuvrePrior(self.rate_per_h * factor, self.dv_m_s, self.durations_s,
                              self.step_s)


RECORDED_MANOEUVRES = ManoeuvrePrior(RECORDED_RATE_PER_H, RECORDED_DV_M_S,
                                     RECORDED_DURATIONS_S)


def window_s(prior: ManoeuvrePrior) -> float:
    """How far back (s) an answer under ``prior`` rests on: the span in which the target is
    expected to make ``WINDOW_MANOEUVRES`` manoeuvres, at least ``MIN_WINDOW_S``. Earlier
    bearings would say little more of the target now (its manoeuvres since cut the
    trajectory into legs the bearings tie loosely) and would need more manoeuvres than the
    search weighs; the answer says from when it holds (``leg_start_s``)."""
    return max(MIN_WINDOW_S, WINDOW_MANOEUVRES / prior.rate_per_s if prior.rate_per_h > 0
               else np.inf)


def window_start(t, first, last, prior: ManoeuvrePrior) -> np.ndarray:
    """Per track the index of the first bearing the answer rests on (``window_s`` before its
    last bearing ``last``, not before its first ``first``; ``t`` the log's epochs, s)."""
    return np.maximum(first, np.searchsorted(t, t[last] - window_s(prior), side="left"))


def start_cells(t_first, t_last, step_s):
    """Cells of ``step_s`` over each track's window: their bounds (n, J) each, clipped to the
    window (J cells over the longest)."""
    span = float(np.max(t_last - t_first)) if np.size(t_first) else 0.0
    J = max(int(math.ceil(span / step_s - 1e-9)), 1)
    lo = t_first[:, None] + step_s * np.arange(J)
    hi = np.minimum(lo + step_s, t_last[:, None])
    return lo, np.maximum(hi, lo)


def cell_priors(prior: ManoeuvrePrior, t, first, last):
    """Per track and cell (n, J): the manoeuvre's start (the cell's centre, s), the first epoch
    after it (where a filter from the start takes it in) and the prior probability of no
    manoeuvre in it, exp(-lambda cell) (1: a cell outside the window);
    per track, cell and duration D (n, J, D): the epoch its shock is screened at (the first
    at or after the burst's centre, at most the track's last; -1: a cell outside the window)
    and that shock (n, J, D, 3: per axis, m^2, m^2/s and m^2/s^2): a burst of density
    s^2 / D over D changes the velocity by N(0, s^2) and puts the position at its end
    N(0, s^2 D^2 / 12) off that of a sudden change at its centre, uncorrelated (a burst
    under way at the last bearing: as far as it went)."""
    a, b = start_cells(t[first], t[last], prior.step_s)
    tau = 0.5 * (a + b)
    inside = (b > a) & (last > first)[:, None]
    D, dv = np.asarray(prior.durations_s, dtype=float), prior.dv_m_s
    seen = np.clip((t[last][:, None, None] - tau[:, :, None]) / D, 0.0, 1.0)  # (n, J, D)
    centre = tau[:, :, None] + 0.5 * seen * D
    epoch = np.clip(np.searchsorted(t, centre), (first + 1)[:, None, None],
                    last[:, None, None])
    # the shock at the centre, carried to that epoch (x' = x + T' v: the same for any grid
    # of epochs, bearings or none, between them)
    lag = t[epoch] - centre
    pp, vv = (dv**2 * seen) * (seen * D) ** 2 / 12.0, dv**2 * seen
    shock = np.stack([pp + lag * lag * vv, lag * vv, vv], axis=-1)
    after = np.clip(np.searchsorted(t, tau, side="right"), (first + 1)[:, None],
                    last[:, None]).astype(np.int64)
    end = np.clip(np.searchsorted(t, tau[:, :, None] + D, side="left"), after[:, :, None],
                  last[:, None, None]).astype(np.int64)
    return (tau, after, end, np.where(inside, np.exp(-prior.rate_per_s * (b - a)), 1.0),
            np.where(inside[..., None], epoch, -1).astype(np.int64), shock)


def burst_step_noise(t, start, duration, dv_m_s):
    """Per target and step into each epoch of ``t`` (n, K - 1), the noise that white
    acceleration of density dv^2 / D per axis over each burst [start, start + D] (``start``,
    ``duration``: (slots, n), s; inf: none, sorted) adds to that step, exactly for the part of
    each burst within it: position (m^2), position-velocity (m^2/s) and velocity (m^2/s^2)
    per axis. A burst of no duration or no size adds nothing. The estimators' manoeuvre: the
    simulator draws it (``target_motion.burst_deviations``), and a component of known
    manoeuvres takes its velocity term over the step (``manoeuvre_components.burst_levels``)."""
    n = start.shape[1]
    t0, t1 = t[:-1], t[1:]
    pp, pv, vv = (np.zeros((n, t.size - 1)) for _ in range(3))
    for j in range(start.shape[0]):
        live = np.isfinite(start[j])
        if not live.any():  # (sorted: no later slot has one either)
            break
        a = np.clip(np.where(live, start[j], t[-1])[:, None], t0, t1)
        b = np.clip(np.where(live, start[j] + duration[j], t[-1])[:, None], t0, t1)
        sized = live & (duration[j] > 0) & (dv_m_s > 0)  # (0, not 0 / 0)
        density = np.where(sized, dv_m_s**2 / np.where(sized, duration[j], 1.0), 0.0)[:, None]
        pp += density * ((t1 - a) ** 3 - (t1 - b) ** 3) / 3
        pv += density * ((t1 - a) ** 2 - (t1 - b) ** 2) / 2
        vv += density * (b - a)
    return pp, pv, vv
