"""A target that may manoeuvre: its state now, averaged over when and how often it did.

Motion model. Between manoeuvres the target is nearly at constant velocity (``ncv.py``: white
random acceleration of spectral density q per axis). Manoeuvres (turns, speed changes) start
at the times of a Poisson process of rate lambda, any number of them; each changes the
velocity by dv, drawn N(0, s^2 I) per axis, over its duration D (a burst of white
acceleration of density s^2 / D). Seen from the bearings after it, a manoeuvre is a shock at
its centre of covariance s^2 (D^2 / 12, 0, 1) per axis (position, cross term, velocity: the
velocity change, and the bend of the path about a sudden change at its centre), applied at
one epoch. A turn by phi at speed v changes the velocity by 2 v sin(phi / 2): s is set from
the targets' speeds and turns (``ManoeuvrePrior``), not from one track's fit.

Inference: Bayesian model averaging over the manoeuvres the target made in the window. Time
is cut into cells of ``step_s`` seconds; a component is a set of manoeuvres, at most one per
cell, each with one of the durations; its prior is the Poisson probability of exactly those.
The components are found level by level (0, 1, 2, ... manoeuvres), each level extending the
``BASES`` most probable components of the one below by one manoeuvre anywhere: every cell
and duration at once, from one backward pass after the base's Kalman filter (``shocks.py``:
the exact Bayes factor of the bearings linearised about the base's trajectory, and the
state at the last bearing with it), so that a level costs a few filter passes whatever the
number of cells. The ``KEEP`` most probable extensions of a level join the mixture, its
``REFINE`` most probable are refined to their maximum a posteriori trajectory (``ncv._fit``:
the iterated Kalman smoother) and linearised there (Laplace). The search goes deeper as long
as a level holds more than ``STOP_MASS`` of the mixture's mass; what it leaves out is
computed: the screened mass of the extensions not kept, and beyond the last level the tail
of the levels' masses (geometric, at the ratio of the last two), as ``p_omitted``, the
share of the posterior the answer does not hold (so an answer that leaves out much can be
refused instead of stated). (Madigan and Raftery's Occam's window, JASA 89(428), 1994,
with the window's omitted mass measured.)

The answer is the mixture's mean and covariance at the last bearing (within plus between
components), widened by ``mixture_tails.tail_scale`` so that its 95 % ellipsoid holds 95 %
of the mixture; with lambda = 0 the mixture is the no-manoeuvre component alone:
``ncv.smooth``'s answer.
"""

import math
from dataclasses import dataclass

import numpy as np

from tma.families.bearings2d.mixture_tails import tail_points, tail_scale
from tma.families.bearings2d.ncv import (
    MAX_PASSES,
    MIN_PRIOR_M,
    MIN_SIGMA_RAD,
    PRIOR_RANGES,
    PRIOR_SPEED_M_S,
    _filter,
    _fit,
    _predict,
    filter_on,
    finish_track,
    in_units,
    smooth,
    start_track,
)
from tma.families.bearings2d.shocks import (
    backward_pass,
    shift_posterior,
    shock_posterior,
    state_with_shock,
)
from tma.runtime.jit import njit

# manoeuvres assumed of a recording's targets (which declares none), measured from the AIS
# positions of the vessels underway in two recordings, the Solent and New York Harbor
# (tests/data/ais/motion_stats.py, docs/manoeuvres.md): 9.6 an hour (turns over 15 deg,
# speed changes over 25 %, stops and starts), velocity changes of 4.6 m/s RMS per axis,
# durations 88 / 119 / 181 s (quartiles)
RECORDED_RATE_PER_H = 10.0
RECORDED_DV_M_S = 4.6
RECORDED_DURATIONS_S = (75.0, 120.0, 230.0)
MAX_LEVEL = 6  # manoeuvres in one component at most
MIN_LEVELS = 3  # levels searched whatever their mass (two manoeuvres may explain what one
# cannot: a level's mass says little of the next one's)
BASES = 3  # components of a level the next level extends
KEEP = 64  # extensions of a level kept in the mixture
SIZES = (0.5, 1.0, 2.0)  # a manoeuvre's velocity change: these times the prior's sd, alike
REFINE = 2  # of which refined to their MAP trajectory
LOG_STOP = math.log(1e-3)  # a level holding less of the mixture's mass ends the search
LOG_SCREEN = math.log(1e-2)  # an extension screened below this share of the mass is left out
REFINE_TOL_M = 0.1  # a refinement stops when no position moves more than this (m)
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


def start_cells(t_first, t_last, step_s):
    """Cells of ``step_s`` over each track's window: their bounds (n, J) each, clipped to the
    window (J cells over the longest)."""
    span = float(np.max(t_last - t_first)) if np.size(t_first) else 0.0
    J = max(int(math.ceil(span / step_s - 1e-9)), 1)
    lo = t_first[:, None] + step_s * np.arange(J)
    hi = np.minimum(lo + step_s, t_last[:, None])
    return lo, np.maximum(hi, lo)


def manoeuvre_options(prior: ManoeuvrePrior):
    """The manoeuvres a cell may hold, equally likely: every duration of ``prior`` with every
    size, its velocity change's sd per axis ``prior.dv_m_s`` times ``SIZES`` (turns of 20
    to 120 deg change the velocity by 0.35 to 1.7 times the speed: a velocity change is
    heavier-tailed than one Gaussian); durations (s) and sds (m/s), (O,) each."""
    D = np.asarray(prior.durations_s, dtype=float)
    sizes = prior.dv_m_s * np.asarray(SIZES)
    return np.repeat(D, sizes.size), np.tile(sizes, D.size)


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
    D, dv = manoeuvre_options(prior)
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


@njit(error_model="numpy")
def _component_noise(t, lo, hi, q, taus, durations, burst, cells, count, Q):
    """The process noise of a component: white acceleration ``q`` on every step plus, for
    each of its ``count`` manoeuvres (``cells``: cell * D + duration), a burst of density
    ``burst[d]`` over [taus[cell], taus[cell] + durations[d]], each step taking its share
    (units of s^2)."""
    D = durations.size
    for j in range(3):
        Q[lo, j] = 0.0
    for k in range(lo + 1, hi + 1):
        ta, tb = t[k - 1], t[k]
        extra = 0.0
        for m in range(count):
            c, d = cells[m] // D, cells[m] % D
            extra += burst[d] * max(min(tb, taus[c] + durations[d]) - max(ta, taus[c]), 0.0)
        T = tb - ta
        lam = q + extra / T
        Q[k, 0] = lam * T * T * T / 3.0
        Q[k, 1] = lam * T * T / 2.0
        Q[k, 2] = lam * T


@njit(error_model="numpy", depends=(_filter,))
def _laplace(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, s2, mf, Pf, Pp, nu, S,
             mean, cov):
    """The Kalman filter linearised about ``nom``: writes the state at ``hi`` and its
    covariance (units of s^2) and returns the log likelihood of the bearings,
    -1/2 sum(nu^2 / (s^2 S) + log S), up to a constant common to every component."""
    _filter(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf, Pp, nu, S)
    loglik = 0.0
    for k in range(lo, hi + 1):
        if nu[k] == nu[k]:
            loglik -= 0.5 * (nu[k] * nu[k] / (s2 * S[k]) + math.log(S[k]))
    for a in range(4):
        mean[a] = mf[hi, a]
        for b in range(4):
            cov[a, b] = Pf[hi, a, b]
    return loglik


@njit(error_model="numpy")
def _logaddexp(a, b):
    if a == -np.inf:
        return b
    if b == -np.inf:
        return a
    top = max(a, b)
    return top + math.log(math.exp(a - top) + math.exp(b - top))


@njit(error_model="numpy")
def _same_set(cells, c1, n1, c2, n2):
    """Whether components c1 and c2 hold the same manoeuvres (``cells`` kept sorted)."""
    if n1 != n2:
        return False
    for m in range(n1):
        if cells[c1, m] != cells[c2, m]:
            return False
    return True


@njit(error_model="numpy", depends=(filter_on, _predict, shift_posterior))
def _extension(t, ox, oy, z, w, weighted, k1, k2, hi, nom, Q, Q2, mf, Pf, Pp, g, G, W,
               suffix, s2, mf2, Pf2, Pp2, nu, S, mean, cov):
    """The log Bayes factor of a component extended by a burst over epochs k1..k2 (its
    process noise ``Q2`` there; the base's ``Q`` elsewhere) against the base, exactly for the
    bearings linearised about the base's trajectory ``nom``, and its state at ``hi`` (``mean``,
    m and m/s; ``cov``, units of s^2): the base's filter (``mf``, ``Pf``, ``Pp``) is run again
    over the burst alone, from its state at k1 - 1; the bearings after k2 come in through
    the base's backward pass (``g``, ``G``, ``W``, ``shocks.backward_pass``) as a shift of
    the predicted state at k2 + 1; ``suffix[k]``: the base's log likelihood of the bearings
    k..hi. ``mf2``, ``Pf2``, ``Pp2``, ``nu``, ``S``: the filter's scratch."""
    m, P = np.empty(4), np.empty((4, 4))
    mp, Pn = np.empty(4), np.empty((4, 4))
    for a in range(4):
        m[a] = mf[k1 - 1, a]
        for b in range(4):
            P[a, b] = Pf[k1 - 1, a, b]
    loglik = 0.0
    filter_on(t, ox, oy, z, w, weighted, k1, k2, nom, Q2, m, P, mf2, Pf2, Pp2, nu, S)
    for k in range(k1, k2 + 1):
        if nu[k] == nu[k]:
            loglik -= 0.5 * (nu[k] * nu[k] / (s2 * S[k]) + math.log(S[k]))
    loglik -= suffix[k1] - suffix[k2 + 1]
    if k2 == hi:
        for a in range(4):
            mean[a] = m[a]
            for b in range(4):
                cov[a, b] = P[a, b]
        return loglik
    # the predicted state at k2 + 1, the extension's against the base's
    T = t[k2 + 1] - t[k2]
    _predict(m, P, T, Q[k2 + 1], mp, Pn)
    base_mean = np.empty(4)
    base_mean[0] = mf[k2, 0] + T * mf[k2, 2]
    base_mean[1] = mf[k2, 1] + T * mf[k2, 3]
    base_mean[2], base_mean[3] = mf[k2, 2], mf[k2, 3]
    inv_s = 1.0 / math.sqrt(s2)
    d0, Delta = np.empty(4), np.empty((4, 4))
    for a in range(4):
        d0[a] = (mp[a] - base_mean[a]) * inv_s
        for b in range(4):
            Delta[a, b] = Pn[a, b] - Pp[k2 + 1, a, b]
    A, rhs, dm, dc = np.empty((4, 4)), np.empty((4, 5)), np.empty(4), np.empty((4, 4))
    loglik += shift_posterior(g[k2 + 1], G[k2 + 1], d0, Delta, A, rhs, dm, dc)
    Wk = W[k2 + 1]
    for a in range(4):
        v = mf[hi, a]
        for b in range(4):
            v += Wk[a, b] * dm[b] / inv_s
        mean[a] = v
    for a in range(4):
        for b in range(4):
            v = Pf[hi, a, b]
            for c in range(4):
                for e in range(4):
                    v += Wk[a, c] * dc[c, e] * Wk[b, e]
            cov[a, b] = v
    return loglik


@njit(error_model="numpy")
def _pool(mean, pcov, mass, lw, m, cov, count, mean_count):
    """Add a component of log weight ``lw``, state ``m`` and covariance ``cov`` with
    ``count`` manoeuvres to the pool of log mass ``mass``, mean ``mean`` and covariance
    ``pcov`` (the moments of the two, merged; ``mean_count[0]``: its mean count); returns
    the new log mass."""
    if not mass > -np.inf:
        for i in range(4):
            mean[i] = m[i]
            for j in range(4):
                pcov[i, j] = cov[i, j]
        mean_count[0] = count
        return lw
    new = _logaddexp(mass, lw)
    a, b = math.exp(mass - new), math.exp(lw - new)
    for i in range(4):
        for j in range(4):
            pcov[i, j] = (a * pcov[i, j] + b * cov[i, j]
                          + a * b * (mean[i] - m[i]) * (mean[j] - m[j]))
    for i in range(4):
        mean[i] = a * mean[i] + b * m[i]
    mean_count[0] = a * mean_count[0] + b * count
    return new


@njit(error_model="numpy")
def _insert(cells, b, nb, code, row):
    """Write into ``cells[row]`` the manoeuvres of component b (``nb``, sorted) with
    ``code`` added in order."""
    placed, mm = False, 0
    for m in range(nb):
        if not placed and code < cells[b, m]:
            cells[row, mm] = code
            mm += 1
            placed = True
        cells[row, mm] = cells[b, m]
        mm += 1
    if not placed:
        cells[row, mm] = code


@njit(error_model="numpy", depends=(_filter, _fit, finish_track, start_track, backward_pass,
                                         shock_posterior, state_with_shock, tail_scale,
                                         _extension))
def mixture_tracks(t, ox, oy, measured, weight, weighted, first, last, theta, q, taus, starts,
                   ends, durations, burst, p_none, epochs, shocks, scale2, p0_pos, max_iter, tol_m,
                   state, P_last, e, cost, passes, p_manoeuvre, p_omitted, n_manoeuvres, u,
                   u_q95, widen, path, evidence):
    """Per track i the mixture of the module docstring: wander ``q`` (n,, units of s^2),
    each cell's manoeuvre start ``taus`` (n, J) and the epoch after it ``starts`` (n, J),
    each burst's last epoch ``ends`` (n, J, D),
    the ``durations`` (D,) and their bursts' density ``burst`` (n, D, units of s^2), each
    cell's prior probability of no manoeuvre ``p_none`` (n, J), each cell and duration's
    screening epoch ``epochs`` (n, J, D; -1: none) and shock ``shocks`` (n, J, D, 3, units
    of s^2), the noise variance ``scale2`` (n,) the units refer to (rad^2). Writes as
    ``ncv.smooth_tracks`` (the mixture's state at the last bearing and covariance in units
    of s^2; the innovations and squared bearing residuals of the most probable refined
    component; the Gauss-Newton passes of the no-manoeuvre fit, -1: failed), the posterior
    probability of a manoeuvre in the window, the share of the posterior left out, the
    posterior mean number of manoeuvres, the tail factor ``widen`` and the most probable
    refined component's positions ``path`` (n, K, 2; NaN outside the track)."""
    n, K = measured.shape
    J, D = taus.shape[1], durations.size
    C = 2 + MAX_LEVEL * KEEP
    L = MAX_LEVEL
    mf, ms, trial = np.empty((K, 4)), np.empty((K, 4)), np.empty((K, 4))
    Pf, Pp = np.empty((K, 4, 4)), np.empty((K, 4, 4))
    nu, S, S0 = np.empty(K), np.empty(K), np.empty(K)
    R, r, Rinv = np.empty((4, 4)), np.empty(4), np.empty((4, 4))
    p0, prior = np.empty(2), np.empty(4)
    Q, Q2, none = np.empty((K, 3)), np.empty((K, 3)), np.zeros((K, 3))
    g, G, W = np.empty((K, 4)), np.empty((K, 4, 4)), np.empty((K, 4, 4))
    A, rhs, dmean, dcov = np.empty((4, 4)), np.empty((4, 5)), np.empty(4), np.empty((4, 4))
    m0, P0 = np.empty(4), np.empty((4, 4))
    suffix = np.empty(K + 1)  # the base's log likelihood of the bearings k..hi
    cells = np.empty((C + 1, L), dtype=np.int64)  # (row C: the candidate being screened)
    count = np.empty(C + 1, dtype=np.int64)
    logw = np.empty(C)
    slot = np.empty(C, dtype=np.int64)
    parent = np.empty(C, dtype=np.int64)
    means, covs = np.empty((C + 1, 4)), np.empty((C + 1, 4, 4))
    mf2, Pf2, Pp2, nu2, S2 = (np.empty((K, 4)), np.empty((K, 4, 4)), np.empty((K, 4, 4)),
                              np.empty(K), np.empty(K))
    noms = np.empty((1 + L * REFINE, K, 4))
    bases = np.empty(BASES, dtype=np.int64)
    order = np.empty(C, dtype=np.int64)
    log_pn = np.empty(J)
    weights = np.empty(C)
    pool_mean, pool_cov, pool_count = np.empty(4), np.empty((4, 4)), np.empty(1)
    for i in range(n):
        lo, hi = first[i], last[i]
        z, w = measured[i], (weight[i] if weighted else measured[i])
        start_track(i, t, lo, hi, theta, noms[0], state, P_last, e)
        cost[i], p_manoeuvre[i], p_omitted[i], n_manoeuvres[i] = np.nan, np.nan, np.nan, np.nan
        widen[i] = 1.0
        for k in range(K):
            path[i, k, 0] = path[i, k, 1] = np.nan
        s2 = scale2[i]
        p0[0] = p0_pos[i] * p0_pos[i] / s2
        p0[1] = PRIOR_SPEED_M_S * PRIOR_SPEED_M_S / s2
        for a in range(4):
            prior[a] = noms[0, lo, a]
        log_none = 0.0  # the prior of no manoeuvre at all; a manoeuvre in cell c multiplies
        for c in range(J):  # it by (1 - p_none) / D / p_none
            log_none += math.log(p_none[i, c])
            log_pn[c] = (math.log((1.0 - p_none[i, c]) / D) - math.log(p_none[i, c])
                         if epochs[i, c, 0] >= 0 and p_none[i, c] < 1.0 else -np.inf)
        # component 0: no manoeuvre
        count[0], slot[0], parent[0] = 0, 0, -1
        _component_noise(t, lo, hi, q[i], taus[i], durations, burst[i], cells[0], 0, Q)
        passes[i] = _fit(t, ox, oy, z, w, weighted, lo, hi, noms[0], Q, prior, p0, max_iter,
                         tol_m, mf, Pf, Pp, nu, S, ms, trial)
        if passes[i] < 0:
            continue
        logw[0] = log_none + _laplace(t, ox, oy, z, w, weighted, lo, hi, noms[0], Q, prior,
                                      p0, s2, mf, Pf, Pp, nu, S, means[0], covs[0])
        used, filled = 1, 1
        total = logw[0]  # log of the mass the mixture holds
        omitted = -np.inf  # log of the mass it leaves out
        pooled = -np.inf  # log of the mass of the light extensions pooled
        level_mass, previous_mass = logw[0], -np.inf
        level, n_bases, bases[0] = 0, 1, 0
        stopped = False
        while level < L:
            level += 1
            start = used
            previous_mass, level_mass = level_mass, -np.inf
            for bi in range(n_bases):
                b = bases[bi]
                nb = count[b]
                nom = noms[slot[b]]
                _component_noise(t, lo, hi, q[i], taus[i], durations, burst[i], cells[b], nb, Q)
                _filter(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf, Pp, nu, S)
                backward_pass(t, ox, oy, lo, hi, nom, Pp, nu, S, 1.0 / math.sqrt(s2), g, G, W)
                suffix[hi + 1] = 0.0
                for k in range(hi, lo - 1, -1):
                    suffix[k] = suffix[k + 1] - (0.5 * (nu[k] * nu[k] / (s2 * S[k])
                                                        + math.log(S[k])) if nu[k] == nu[k]
                                                 else 0.0)
                for cj in range(J):
                    if not log_pn[cj] > -np.inf:
                        continue
                    clash = False
                    for m in range(nb):
                        clash |= cells[b, m] // D == cj
                    if clash:
                        continue
                    for d in range(D):
                        k = epochs[i, cj, d]
                        # every extension's weight at once (the burst as a shock at its
                        # centre, shocks.py); those far below the mixture's mass are left
                        # out, with that mass
                        lbf = shock_posterior(g[k], G[k], shocks[i, cj, d], A, rhs, dmean,
                                              dcov)
                        lw = logw[b] + log_pn[cj] + lbf
                        if not lw > total + LOG_SCREEN:
                            # too light to weigh one by one: pooled into one Gaussian by
                            # their screened weights and states (their moments)
                            if lw > -np.inf:
                                level_mass = _logaddexp(level_mass, lw)
                                state_with_shock(mf[hi], Pf[hi], W[k], dmean, dcov,
                                                 math.sqrt(s2), means[C], covs[C])
                                for a in range(4):  # (in m, m/s)
                                    for bb in range(4):
                                        covs[C, a, bb] *= s2
                                pooled = _pool(pool_mean, pool_cov, pooled, lw, means[C],
                                               covs[C], nb + 1, pool_count)
                            continue
                        _insert(cells, b, nb, cj * D + d, C)
                        count[C] = nb + 1
                        duplicate = False
                        for cc in range(start, used):
                            if _same_set(cells, cc, count[cc], C, nb + 1):
                                duplicate = True
                        if duplicate:
                            continue
                        # the extension exactly (the bearings linearised about the base's
                        # trajectory): its filter over the burst, the bearings after it
                        # through the base's backward pass (shocks.shift_posterior)
                        k1, k2 = starts[i, cj], ends[i, cj, d]
                        _component_noise(t, k1 - 1, k2, q[i], taus[i], durations, burst[i],
                                         cells[C], nb + 1, Q2)
                        loglik = _extension(t, ox, oy, z, w, weighted, k1, k2, hi, nom, Q, Q2,
                                            mf, Pf, Pp, g, G, W, suffix, s2, mf2, Pf2, Pp2,
                                            nu2, S2, means[C], covs[C])
                        lw = logw[b] + log_pn[cj] + loglik
                        level_mass = _logaddexp(level_mass, lw)
                        c = used
                        if used - start >= KEEP:  # the level keeps its KEEP most probable
                            c, worst = start, logw[start]
                            for cc in range(start + 1, used):
                                if logw[cc] < worst:
                                    c, worst = cc, logw[cc]
                            if lw <= worst:
                                omitted = _logaddexp(omitted, lw)
                                continue
                            omitted = _logaddexp(omitted, worst)
                        else:
                            used += 1
                        count[c] = nb + 1
                        for m in range(nb + 1):
                            cells[c, m] = cells[C, m]
                        logw[c], slot[c], parent[c] = lw, -1, b
                        for a in range(4):
                            means[c, a] = means[C, a]
                            for bb in range(4):
                                covs[c, a, bb] = covs[C, a, bb]
            if used == start:
                stopped = True
                break
            # refine the most probable of this level to their own MAP trajectories (Laplace)
            for c in range(start, used):
                order[c - start] = c
            for a in range(used - start):  # by weight, descending (insertion sort)
                for bb in range(a, 0, -1):
                    if logw[order[bb]] > logw[order[bb - 1]]:
                        order[bb], order[bb - 1] = order[bb - 1], order[bb]
                    else:
                        break
            for f in range(min(REFINE, used - start)):
                c = order[f]
                _component_noise(t, lo, hi, q[i], taus[i], durations, burst[i], cells[c],
                                 count[c], Q)
                noms[filled] = noms[slot[parent[c]]]
                lp = log_none
                for m in range(count[c]):
                    lp += log_pn[cells[c, m] // D]
                if _fit(t, ox, oy, z, w, weighted, lo, hi, noms[filled], Q, prior, p0,
                        max_iter, tol_m, mf, Pf, Pp, nu, S, ms, trial) < 0:
                    logw[c] = -np.inf
                    continue
                logw[c] = lp + _laplace(t, ox, oy, z, w, weighted, lo, hi, noms[filled], Q,
                                        prior, p0, s2, mf, Pf, Pp, nu, S, means[c], covs[c])
                slot[c] = filled
                filled += 1
            for c in range(start, used):
                total = _logaddexp(total, logw[c])
            # the next level extends the most probable refined components of this one
            n_bases = 0
            for _ in range(BASES):
                best_c, best_w = -1, -np.inf
                for c in range(start, used):
                    if slot[c] >= 0 and logw[c] > best_w:
                        taken = False
                        for bb in range(n_bases):
                            taken |= bases[bb] == c
                        if not taken:
                            best_c, best_w = c, logw[c]
                if best_c < 0:
                    break
                bases[n_bases] = best_c
                n_bases += 1
            if n_bases == 0 or (level >= MIN_LEVELS and level_mass - total < LOG_STOP):
                stopped = True
                break
        if not stopped or level_mass - total >= LOG_STOP:
            # the levels beyond the last: geometric at the ratio of the last two (all of
            # the last level's mass again when the masses do not fall)
            ratio = min(level_mass - previous_mass, 0.0)
            beyond = level_mass + (ratio - math.log(-math.expm1(ratio)) if ratio < 0.0
                                   else 0.0)
            omitted = _logaddexp(omitted, beyond)
        if pooled > -np.inf and used < C:  # the pooled light extensions: one component
            c = used
            used += 1
            logw[c], slot[c], count[c] = pooled, -1, max(int(round(pool_count[0])), 1)
            for a in range(4):
                means[c, a] = pool_mean[a]
            for a in range(4):
                for b in range(4):
                    covs[c, a, b] = pool_cov[a, b] / s2
        # the mixture
        best, best_logw = 0, logw[0]
        top = logw[0]
        for c in range(used):
            top = max(top, logw[c])
            if logw[c] > best_logw and slot[c] >= 0:
                best, best_logw = c, logw[c]
        mass, mean_count = 0.0, 0.0
        for c in range(used):
            weights[c] = math.exp(logw[c] - top) if logw[c] > -np.inf else 0.0
            mass += weights[c]
            mean_count += weights[c] * count[c]
        for a in range(4):
            v = 0.0
            for c in range(used):
                if weights[c] > 0.0:
                    v += weights[c] * means[c, a]
            m0[a] = v / mass
        for a in range(4):
            for b in range(4):
                v = 0.0
                for c in range(used):
                    if weights[c] > 0.0:  # (covariances in units of s^2, as the output)
                        v += weights[c] * (covs[c, a, b] + (means[c, a] - m0[a])
                                           * (means[c, b] - m0[b]) / s2)
                P0[a, b] = v / mass
        widen[i] = tail_scale(weights, means, covs, used, m0, P0, s2, u, u_q95)
        p_manoeuvre[i] = 1.0 - weights[0] / mass
        evidence[i] = math.log(mass) + top
        n_manoeuvres[i] = mean_count / mass
        p_omitted[i] = (1.0 / (1.0 + math.exp(math.log(mass) + top - omitted))
                        if omitted > -np.inf else 0.0)
        # the innovations (trend test) and residuals: the most probable refined component's
        nom = noms[slot[best]]
        for k in range(lo, hi + 1):
            path[i, k, 0], path[i, k, 1] = nom[k, 0], nom[k, 1]
        _component_noise(t, lo, hi, q[i], taus[i], durations, burst[i], cells[best],
                         count[best], Q)
        finish_track(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, True, state, P_last, e,
                     cost, nu, S, S0, R, r, Rinv, none)
        for a in range(4):  # (finish_track wrote that component's own state)
            state[i, a] = m0[a]
            for b in range(4):
                P_last[i, a, b] = P0[a, b] * widen[i]


def mixture(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd,
            prior: ManoeuvrePrior, sigma_rad):
    """The state at each track's last bearing under NCV wander ``accel_psd`` (m^2/s^3, (n,)
    or scalar) and the manoeuvres of ``prior``, from the constant-velocity start
    ``theta_cv`` (n, 4), as ``ncv.smooth`` returns it (``state``, ``cov``, ``theta``,
    ``cov_theta``, ``innovations``, ``sigma2``, ``cost_rad2``, ``passes``) plus
    ``p_manoeuvre`` (the posterior probability of a manoeuvre since the first bearing),
    ``p_omitted`` (the share of the posterior the mixture leaves out), ``n_manoeuvres``
    (their posterior mean number), ``tail_scale`` (the factor its covariance was widened
    by, ``mixture_tails.tail_scale``) and ``path_m`` (n, K, 2: the most probable
    trajectory's positions, NaN outside the track).

    ``sigma_rad`` (n,): the bearing noise, NaN where unknown: then estimated as
    ``ncv.smooth`` does without manoeuvres."""
    n, K = measured_rad.shape
    sigma = np.asarray(sigma_rad, dtype=float)
    if prior.rate_per_h == 0:  # no manoeuvres: the nearly-constant-velocity answer itself
        out = smooth(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd,
                     sigma)
        return {**out, "p_manoeuvre": np.zeros(n), "tail_scale": np.ones(n)}
    known = np.isfinite(sigma)
    weighted = valid is not None
    weight = valid.astype(float) if weighted else np.empty((0, 0))
    t = np.ascontiguousarray(t, dtype=float)
    first, last = np.asarray(first, np.int64), np.asarray(last, np.int64)
    theta0 = np.ascontiguousarray(np.nan_to_num(theta_cv), float)
    start_range = np.hypot(theta0[:, 0] + theta0[:, 2] * t[first] - own_x[first],
                           theta0[:, 1] + theta0[:, 3] * t[first] - own_y[first])
    p0_pos = np.maximum(PRIOR_RANGES * start_range, MIN_PRIOR_M)
    q = np.broadcast_to(np.asarray(accel_psd, dtype=float), (n,)).copy()
    if known.all():
        sigma2 = sigma**2
    else:  # the no-manoeuvre fit's estimate: a manoeuvre can only inflate it (conservative);
        # the components' innovations would shrink it (they fit the noise with manoeuvres)
        sigma2 = np.where(known, sigma**2, smooth(t, own_x, own_y, measured_rad, valid, first,
                                                  last, theta_cv, q, sigma)["sigma2"])
    sigma2 = np.maximum(sigma2, MIN_SIGMA_RAD**2)
    taus, starts, ends, p_none, epochs, shocks = cell_priors(prior, t, first, last)
    durations, dv = manoeuvre_options(prior)
    burst = dv**2 / durations[None, :] / sigma2[:, None]
    out = {"state": np.empty((n, 4)), "cov": np.empty((n, 4, 4)),
           "innovations": np.empty((n, K)), "cost_rad2": np.empty(n),
           "passes": np.zeros(n, dtype=np.int64), "p_manoeuvre": np.empty(n),
           "p_omitted": np.empty(n), "n_manoeuvres": np.empty(n), "tail_scale": np.ones(n),
           "path_m": np.empty((n, K, 2)), "log_evidence": np.full(n, np.nan)}
    mixture_tracks(t, np.ascontiguousarray(own_x, float), np.ascontiguousarray(own_y, float),
                   np.ascontiguousarray(measured_rad, float), weight, weighted, first, last,
                   theta0, q / sigma2, taus, starts, ends, durations, burst, p_none, epochs,
                   shocks / sigma2[:, None, None, None], sigma2, p0_pos, MAX_PASSES,
                   REFINE_TOL_M, out["state"], out["cov"],
                   out["innovations"], out["cost_rad2"], out["passes"], out["p_manoeuvre"],
                   out["p_omitted"], out["n_manoeuvres"], *tail_points(), out["tail_scale"],
                   out["path_m"], out["log_evidence"])
    return in_units(out, sigma2, t[last], theta_cv)


def component(t, own_x, own_y, measured_rad, theta_cv, levels, sigma_rad, start=None,
              prior_state=None):
    """One track's component under the process levels ``levels`` (K,: the density q_k of the
    step into each epoch, m^2/s^3), refined to its MAP trajectory from the constant-velocity
    ``theta_cv`` (4,) or the trajectory ``start`` (K, 4), with bearing noise ``sigma_rad``
    and the weak prior about ``prior_state`` (4,; default: the start at the first epoch):
    (log likelihood up to a constant that depends on sigma and the prior alone, state at the
    last bearing (4,), its covariance (4, 4), the MAP trajectory (K, 4)). What
    ``mixture_tracks`` computes for each component it refines, for tests and diagnosis."""
    t = np.ascontiguousarray(t, dtype=float)
    K = t.size
    s2 = sigma_rad**2
    nom = np.empty((K, 4))
    nom[:, 0] = theta_cv[0] + theta_cv[2] * t
    nom[:, 1] = theta_cv[1] + theta_cv[3] * t
    nom[:, 2:] = theta_cv[2:]
    if start is not None:
        nom[:] = start
    prior = np.array(nom[0] if prior_state is None else prior_state, dtype=float)
    start_range = math.hypot(theta_cv[0] - own_x[0], theta_cv[1] - own_y[0])
    p0 = np.array([max(PRIOR_RANGES * start_range, MIN_PRIOR_M) ** 2, PRIOR_SPEED_M_S**2]) / s2
    T = np.diff(t, prepend=t[0])
    lam = np.asarray(levels, dtype=float) / s2
    Q = np.column_stack([lam * T**3 / 3.0, lam * T**2 / 2.0, lam * T])
    Q[0] = 0.0
    work = [np.empty((K, 4)), np.empty((K, 4, 4)), np.empty((K, 4, 4)), np.empty(K),
            np.empty(K)]
    mean, cov = np.empty(4), np.empty((4, 4))
    ox, oy = np.ascontiguousarray(own_x, float), np.ascontiguousarray(own_y, float)
    z = np.ascontiguousarray(measured_rad, float)
    if _fit(t, ox, oy, z, np.empty(0), False, 0, K - 1, nom, Q, prior, p0, MAX_PASSES,
            REFINE_TOL_M, *work, np.empty((K, 4)), np.empty((K, 4))) < 0:
        return -np.inf, np.full(4, np.nan), np.full((4, 4), np.nan), nom
    loglik = _laplace(t, ox, oy, z, np.empty(0), False, 0, K - 1, nom, Q, prior, p0, s2, *work,
                      mean, cov)
    return loglik, mean, cov * s2, nom
