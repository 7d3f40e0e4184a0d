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
``BASES`` most probable components of the one below by one manoeuvre anywhere. Every cell and
duration is screened at once, from one backward pass after the base's Kalman filter
(``shocks.py``: the Bayes factor of the burst taken as a shock at its centre, and the state
at the last bearing with it, for the bearings linearised about the base's trajectory), so
that a level costs a few filter passes whatever the number of cells. The extensions that
weigh (above ``LOG_SCREEN`` of the mixture's mass) are then evaluated exactly, the burst as
it is (``manoeuvre_components._extension``: the base's filter run again over the burst
alone, the bearings after it through the backward pass); the lighter ones are pooled into
one Gaussian of their moments. The ``KEEP`` most probable extensions of a level join the
mixture; its most probable is refined to its maximum a posteriori trajectory (``kalman._fit``:
the iterated Kalman smoother) and linearised there (Laplace), the next ``REFINE`` - 1 (those
whose screened weight is above ``LOG_REFINE`` of its refined one) by ``REFINE_PASSES`` pass of
that smoother from the base's trajectory. The search goes
at least ``MIN_LEVELS`` deep and on while a level holds more than ``LOG_STOP`` of the
mixture's mass, up to ``MAX_LEVEL``. (Madigan and Raftery's Occam's window, JASA 89(428),
1994, with the window's omitted mass measured.)

A level's bases reach few of its sets: where manoeuvres are many and the bearings barely
show them, the sets of two, three or more such manoeuvres number in the thousands, and
counting the reached ones alone said a third of the prior's count where the bearings show
none (30 an hour). The sets of manoeuvres the bearings neither show nor rule out
(``UNSEEN_NATS``) that no base reaches are counted instead (``_unreached``: each reached
one stands for its share of them), and beyond the last level searched their levels go on by
the same count into the pool of light extensions; the sets of manoeuvres the bearings show
are the search's alone (on targets drawn from the model at 10 an hour it weighs 2.2
manoeuvres where they made 3.3; counting those too overcounts against Bayesian model
averaging by hand). What is still left out, the extensions not kept and the levels
beyond (geometric, at the ratio of the last two) where no unseen manoeuvres were found, is
``p_omitted``, the share of the posterior the answer does not hold.

The answer is the mixture's mean and covariance at the last bearing (within plus between
components), widened by ``mixture_tails.tail_scale`` so that its 95 % ellipsoid holds 95 %
of the mixture; with lambda = 0 the mixture is the no-manoeuvre component alone:
``ncv.smooth``'s answer.
"""

import dataclasses
import math

import numpy as np

from tma.families.bearings2d.kalman import _filter, _fit, smoothed_positions
from tma.families.bearings2d.manoeuvre_components import (  # noqa: F401 (component: tests)
    REFINE_TOL_M,
    _component_noise,
    _extension,
    _insert,
    _laplace,
    _logaddexp,
    _pool,
    component,
)
from tma.families.bearings2d.manoeuvre_prior import (  # noqa: F401 (the prior's home is there)
    RECORDED_MANOEUVRES,
    ManoeuvrePrior,
    cell_priors,
    window_s,
)
from tma.families.bearings2d.mixture_tails import (
    INTERVAL_LEVELS,
    quantity_intervals,
    tail_points,
    tail_scale,
)
from tma.families.bearings2d.ncv import (
    MAX_PASSES,
    MIN_PRIOR_M,
    MIN_SIGMA_RAD,
    PRIOR_RANGES,
    PRIOR_SPEED_M_S,
    MotionFit,
    blank_path,
    finish_track,
    in_units,
    smooth,
    start_track,
)
from tma.families.bearings2d.shocks import backward_pass, shock_posterior, state_with_shock
from tma.runtime.jit import njit

MAX_LEVEL = 6  # manoeuvres in one component at most
MIN_LEVELS = 3  # levels searched whatever their mass (two manoeuvres may explain what one
# cannot: a level's mass says little of the next one's)
BASES = 3  # components of a level the next level extends
KEEP = 64  # extensions of a level kept in the mixture
REFINE = 6  # of which refined: the most probable to its MAP trajectory (or the next, where
# that fit fails), the rest whose screened weight is above LOG_REFINE of its refined one by
# REFINE_PASSES passes of the iterated smoother from the base's trajectory
REFINE_PASSES = 1
LOG_REFINE = math.log(1e-2)
LOG_STOP = math.log(1e-3)  # a level holding less of the mixture's mass ends the search
LOG_SCREEN = math.log(1e-2)  # an extension screened below this share of the mass is left out
UNSEEN_NATS = 0.5  # an extension whose screened log Bayes factor is b adds a manoeuvre the
# bearings neither show nor rule out to the degree exp(-b^2 / (2 UNSEEN_NATS^2)): the sets
# of those no base reaches are counted so (``_unreached``)
MAX_TAIL = 20  # manoeuvres counted beyond the search, at most


@njit(error_model="numpy")
def _from_earlier_base(cells, bases, bi, b, nb, code):
    """Whether the set of base ``b``'s ``nb`` manoeuvres and ``code`` is also an extension
    of a base before it in ``bases[:bi]`` (one of the set's subsets of ``nb``): each set is
    weighed from the first base that reaches it, so that no mass is counted twice."""
    for bj in range(bi):
        inside = True
        for m in range(nb):
            v = cells[bases[bj], m]
            found = v == code
            for mm in range(nb):
                found |= cells[b, mm] == v
            inside &= found
        if inside:
            return True
    return False


@njit(error_model="numpy")
def _log1m_exp(x):
    """log(1 - e^x) for x <= 0 (-inf at 0)."""
    return math.log(-math.expm1(x)) if x < 0.0 else -np.inf


@njit(error_model="numpy")
def _unreached(below, base_mass, extended, level, reached):
    """The log factor by which the sets of ``level`` that add an unseen manoeuvre
    (``UNSEEN_NATS``) are scaled for those no base reaches (0: none missing); ``below``: the
    level below's log mass, ``base_mass`` its bases' and ``extended`` the sum over the bases
    of w_b F_b (F_b: the base's unseen extensions' weights over its own), ``reached`` the
    log mass of those extensions the bases reach.

    A set of L manoeuvres extends each of its L subsets of L - 1, so L M_L is the sum over
    the level below of w_S F_S. The bases are a handful of the level below's sets: taking
    their mean F for every set of it, M_L = M_(L-1) F / L, exact where the bearings say
    nothing of the manoeuvres (every F_S alike, the levels' masses the Poisson prior's), and
    an undercount where the level below holds a manoeuvre the bearings show (its sets
    without it are light, though they extend to heavy ones). Against Bayesian model
    averaging by hand over every set of up to three manoeuvres, the count is within 0.04
    (``test_bearings2d_manoeuvre_model.py``); where the bearings show nothing, it is the
    prior's."""
    if level < 2 or not reached > -np.inf or not base_mass > -np.inf:
        return 0.0  # (the first level: the one base reaches every set)
    return max(below + extended - base_mass - math.log(level) - reached, 0.0)


@njit(error_model="numpy", depends=(_from_earlier_base, _filter, _fit, finish_track,
                                         start_track, backward_pass,
                                         shock_posterior, state_with_shock, tail_scale,
                                         quantity_intervals,
                                         _extension, blank_path, smoothed_positions,
                                         _unreached, _log1m_exp))
def mixture_tracks(t, ox, oy, measured, weight, weighted, first, last, theta, q, taus, starts,
                   ends, durations, burst, p_none, epochs, shocks, scale2, p0_pos, max_iter, tol_m,
                   state, P_last, e, cost, passes, p_manoeuvre, p_omitted, n_manoeuvres, u,
                   u_q95, widen, now_x, now_y, levels, intervals, path, path_cov):
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
    posterior mean number of manoeuvres, the tail factor ``widen``, the ``intervals`` (n, 3,
    len(levels)) of range from ``now_x``, ``now_y`` (n,), course and speed now
    (``mixture_tails.quantity_intervals``) and the most probable
    refined component's positions ``path`` (n, K, 2; NaN outside the track) with, where
    ``path_cov`` has epochs (n, K, 3), their smoothed covariances under that component's
    manoeuvres (``kalman.smoothed_positions``, units of s^2)."""
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
    # a level's light sets that add an unseen manoeuvre, pooled apart (scaled by _unreached)
    lvl_mean, lvl_cov, lvl_count = np.empty(4), np.empty((4, 4)), np.empty(1)
    log_unseen_c = np.zeros(C)  # the log degree a set's last manoeuvre is unseen
    for i in range(n):
        lo, hi = first[i], last[i]
        z, w = measured[i], (weight[i] if weighted else measured[i])
        start_track(i, t, lo, hi, theta, noms[0], state, P_last, e)
        cost[i], p_manoeuvre[i], p_omitted[i], n_manoeuvres[i] = np.nan, np.nan, np.nan, np.nan
        widen[i] = 1.0
        intervals[i] = np.nan
        blank_path(i, path, path_cov)
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
        lvl_pooled, log_unseen = -np.inf, -np.inf  # (log_unseen: the last level's mean F)
        stopped = False
        while level < L:
            level += 1
            start = used
            previous_mass = level_mass
            lvl_pooled, lvl_omitted = -np.inf, -np.inf  # of the unseen extensions
            seen = -np.inf  # the mass of the other light extensions
            reached, extended, base_mass = -np.inf, -np.inf, -np.inf  # (_unreached)
            for bi in range(n_bases):
                b = bases[bi]
                nb = count[b]
                log_f = -np.inf  # the base's unseen extensions' weights over its own
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
                        log_u = -0.5 * (lbf / UNSEEN_NATS) ** 2  # (its degree unseen)
                        log_f = _logaddexp(log_f, log_pn[cj] + lbf + log_u)
                        if _from_earlier_base(cells, bases, bi, b, nb, cj * D + d):
                            continue  # that set's mass is counted once, from that base
                        lw = logw[b] + log_pn[cj] + lbf
                        reached = _logaddexp(reached, lw + log_u)
                        log_seen = _log1m_exp(log_u)  # (the rest of its weight)
                        if not lw > total + LOG_SCREEN:
                            # too light to weigh one by one: pooled into one Gaussian by
                            # their screened weights and states (their moments)
                            if lw > -np.inf:
                                state_with_shock(mf[hi], Pf[hi], W[k], dmean, dcov,
                                                 math.sqrt(s2), means[C], covs[C])
                                for a in range(4):  # (in m, m/s)
                                    for bb in range(4):
                                        covs[C, a, bb] *= s2
                                # (its unseen part apart: scaled once the level is done)
                                lvl_pooled = _pool(lvl_mean, lvl_cov, lvl_pooled, lw + log_u,
                                                   means[C], covs[C], nb + 1, lvl_count)
                                if log_seen > -np.inf:
                                    seen = _logaddexp(seen, lw + log_seen)
                                    pooled = _pool(pool_mean, pool_cov, pooled, lw + log_seen,
                                                   means[C], covs[C], nb + 1, pool_count)
                            continue
                        _insert(cells, b, nb, cj * D + d, C)
                        count[C] = nb + 1
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
                        c = used
                        if used - start >= KEEP:  # the level keeps its KEEP most probable
                            c, worst = start, logw[start]
                            for cc in range(start + 1, used):
                                if logw[cc] < worst:
                                    c, worst = cc, logw[cc]
                            if lw <= worst:
                                lvl_omitted = _logaddexp(lvl_omitted, lw + log_u)
                                seen = _logaddexp(seen, lw + log_seen)
                                omitted = _logaddexp(omitted, lw + log_seen)
                                continue
                            lvl_omitted = _logaddexp(lvl_omitted, worst + log_unseen_c[c])
                            part = worst + _log1m_exp(log_unseen_c[c])
                            seen = _logaddexp(seen, part)
                            omitted = _logaddexp(omitted, part)
                        else:
                            used += 1
                        count[c] = nb + 1
                        for m in range(nb + 1):
                            cells[c, m] = cells[C, m]
                        logw[c], slot[c], parent[c], log_unseen_c[c] = lw, -1, b, log_u
                        for a in range(4):
                            means[c, a] = means[C, a]
                            for bb in range(4):
                                covs[c, a, bb] = covs[C, a, bb]
                extended = _logaddexp(extended, logw[b] + log_f)
                base_mass = _logaddexp(base_mass, logw[b])
            # the sets of unseen manoeuvres no base reaches, counted by scaling those reached
            shift = _unreached(level_mass, base_mass, extended, level, reached)
            if base_mass > -np.inf:
                log_unseen = extended - base_mass
            if lvl_pooled > -np.inf:
                pooled = _pool(pool_mean, pool_cov, pooled, lvl_pooled + shift, lvl_mean,
                               lvl_cov, lvl_count[0], pool_count)
            omitted = _logaddexp(omitted, lvl_omitted + shift)
            # the level's mass: its light sets' here, its kept ones' once refined
            level_mass = _logaddexp(_logaddexp(seen, lvl_pooled + shift), lvl_omitted + shift)
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
            # (an extension's weight and state are the base's linearisation's: after a large
            # manoeuvre they rank it poorly, and the next level's bases are chosen among the
            # refined; one pass from the base's trajectory re-ranks five more at the cost of
            # one pass each, which the long logs' many manoeuvres need: flagged 15 % -> 5 %.
            # The answer's trajectory (trend test, residuals, drawn path) is the most probable
            # refined component's, one pass or to convergence: on 30-minute logs drawn from
            # the model itself, 3.8 % flagged, and 8.1 % with it refined on to convergence)
            first_w = -np.inf  # the level's fully refined one's weight (none yet)
            for f in range(min(REFINE, used - start)):
                c = order[f]
                if first_w > -np.inf and logw[c] < first_w + LOG_REFINE:
                    break
                _component_noise(t, lo, hi, q[i], taus[i], durations, burst[i], cells[c],
                                 count[c], Q)
                noms[filled] = noms[slot[parent[c]]]
                lp = log_none
                for m in range(count[c]):
                    lp += log_pn[cells[c, m] // D]
                whole = first_w == -np.inf  # (to its MAP trajectory, else one pass)
                if _fit(t, ox, oy, z, w, weighted, lo, hi, noms[filled], Q, prior, p0,
                        max_iter if whole else REFINE_PASSES, tol_m, mf, Pf, Pp, nu, S, ms,
                        trial) < 0:
                    logw[c] = -np.inf
                    continue
                logw[c] = lp + _laplace(t, ox, oy, z, w, weighted, lo, hi, noms[filled], Q,
                                        prior, p0, s2, mf, Pf, Pp, nu, S, means[c], covs[c])
                if whole:
                    first_w = logw[c]
                slot[c] = filled
                filled += 1
            for c in range(start, used):
                if shift > 0.0:  # (each stands for itself and the unreached share)
                    logw[c] += math.log1p(math.exp(log_unseen_c[c]) * math.expm1(shift))
                total = _logaddexp(total, logw[c])
                level_mass = _logaddexp(level_mass, logw[c])
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
        if (not stopped or level_mass - total >= LOG_STOP) and lvl_pooled > -np.inf \
                and log_unseen > -np.inf:
            # the levels beyond the last, of unseen manoeuvres: by the same count
            # (_unreached), F falling as the sets fill the open cells, held in the pool
            # with the last level's unseen sets' moments
            n_open = 0
            for c in range(J):
                n_open += log_pn[c] > -np.inf
            lv, m = level, level_mass
            while lv < min(MAX_TAIL, n_open):
                lv += 1
                m += log_unseen + math.log((n_open - lv + 1) / (n_open - level + 1)) \
                    - math.log(lv)
                pooled = _pool(pool_mean, pool_cov, pooled, m, lvl_mean, lvl_cov, lv,
                               pool_count)
                if m - _logaddexp(total, pooled) < LOG_STOP:
                    break
            if lv == MAX_TAIL < n_open and m - _logaddexp(total, pooled) >= LOG_STOP:
                omitted = _logaddexp(omitted, m)  # (as much again beyond, at most)
        elif not stopped or level_mass - total >= LOG_STOP:
            # the levels beyond the last: geometric at the ratio of the last two (all of
            # the last level's mass again when the masses do not fall)
            ratio = min(level_mass - previous_mass, 0.0)
            beyond = level_mass + (ratio - _log1m_exp(ratio) if ratio < 0.0 else 0.0)
            omitted = _logaddexp(omitted, beyond)
        pool_slot = -1
        if pooled > -np.inf:  # the pooled light extensions: one component (slot C - 1:
            # used is at most 1 + L KEEP)
            c = pool_slot = used
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
            # (the pool: its sets' mean count)
            mean_count += weights[c] * (pool_count[0] if c == pool_slot else count[c])
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
        quantity_intervals(weights, means, covs, used, s2, now_x[i], now_y[i], levels,
                           intervals[i])
        p_manoeuvre[i] = 1.0 - weights[0] / mass
        n_manoeuvres[i] = mean_count / mass
        p_omitted[i] = (1.0 / (1.0 + math.exp(math.log(mass) + top - omitted))
                        if omitted > -np.inf else 0.0)
        # the innovations (trend test) and residuals: the most probable refined component's
        nom = noms[slot[best]]
        _component_noise(t, lo, hi, q[i], taus[i], durations, burst[i], cells[best],
                         count[best], Q)
        finish_track(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, True, state, P_last, e,
                     cost, nu, S, S0, R, r, Rinv, none)
        smoothed_positions(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf,
                           Pp, nu, S, path, path_cov)
        for a in range(4):  # (finish_track wrote that component's own state)
            state[i, a] = m0[a]
            for b in range(4):
                P_last[i, a, b] = P0[a, b] * widen[i]


def mixture(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd,
            prior: ManoeuvrePrior, sigma_rad, path_cov=False, now_xy=None) -> MotionFit:
    """The state at each track's last bearing under NCV wander ``accel_psd`` (m^2/s^3, (n,)
    or scalar) and the manoeuvres of ``prior``, from the constant-velocity start
    ``theta_cv`` (n, 4): its ``ncv.MotionFit`` with the mixture's own
    ``p_manoeuvre`` (the posterior probability of a manoeuvre since the first bearing),
    ``p_omitted`` (the share of the posterior the mixture leaves out), ``n_manoeuvres``
    (their posterior mean number), ``tail_scale`` (the factor its covariance was widened
    by, ``mixture_tails.tail_scale``), ``intervals`` (n, 3, 4: the central intervals of
    range from ``now_xy`` (two (n,) arrays, m; None: own-ship at the last bearing), course and
    speed now that hold 68.3 and 95.4 %, ``mixture_tails.quantity_intervals``) and ``path_m``
    (n, K, 2: the most probable
    trajectory's positions, NaN outside the track); with ``path_cov``, ``path_cov_m2`` (n, K,
    3: their smoothed covariances xx, xy, yy in m^2 under that trajectory's manoeuvres).

    ``sigma_rad`` (n,): the bearing noise, NaN where unknown: then estimated as
    ``ncv.smooth`` does without manoeuvres."""
    n, K = measured_rad.shape
    sigma = np.asarray(sigma_rad, dtype=float)
    if prior.rate_per_h == 0:  # no manoeuvres: the nearly-constant-velocity answer itself
        out = smooth(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd,
                     sigma, path_cov=path_cov)
        return dataclasses.replace(out, p_manoeuvre=np.zeros(n), tail_scale=np.ones(n),
                                   p_omitted=np.zeros(n), n_manoeuvres=np.zeros(n))
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
                                                  last, theta_cv, q, sigma).sigma2)
    sigma2 = np.maximum(sigma2, MIN_SIGMA_RAD**2)
    taus, starts, ends, p_none, epochs, shocks = cell_priors(prior, t, first, last)
    durations = np.asarray(prior.durations_s, dtype=float)
    burst = prior.dv_m_s**2 / durations[None, :] / sigma2[:, None]
    out = {"state": np.empty((n, 4)), "cov": np.empty((n, 4, 4)),
           "innovations": np.empty((n, K)), "cost_rad2": np.empty(n),
           "passes": np.zeros(n, dtype=np.int64), "p_manoeuvre": np.empty(n),
           "p_omitted": np.empty(n), "n_manoeuvres": np.empty(n), "tail_scale": np.ones(n),
           "intervals": np.empty((n, 3, len(INTERVAL_LEVELS))), "path_m": np.empty((n, K, 2))}
    now_x, now_y = ((np.asarray(own_x, float)[last], np.asarray(own_y, float)[last])
                    if now_xy is None else now_xy)
    if path_cov:
        out["path_cov_m2"] = np.empty((n, K, 3))
    mixture_tracks(t, np.ascontiguousarray(own_x, float), np.ascontiguousarray(own_y, float),
                   np.ascontiguousarray(measured_rad, float), weight, weighted, first, last,
                   theta0, q / sigma2, taus, starts, ends, durations, burst, p_none, epochs,
                   shocks / sigma2[:, None, None, None], sigma2, p0_pos, MAX_PASSES,
                   REFINE_TOL_M, out["state"], out["cov"],
                   out["innovations"], out["cost_rad2"], out["passes"], out["p_manoeuvre"],
                   out["p_omitted"], out["n_manoeuvres"], *tail_points(), out["tail_scale"],
                   np.ascontiguousarray(now_x, float), np.ascontiguousarray(now_y, float),
                   np.array(INTERVAL_LEVELS), out["intervals"], out["path_m"],
                   out.get("path_cov_m2", np.empty((n, 0, 3))))
    return in_units(out, sigma2, t[last], theta_cv)
