"""A component of the manoeuvre mixture (``manoeuvres.py``): a set of manoeuvres, its process
noise, its Laplace weight and state at the last bearing, and its extension by one more
manoeuvre evaluated from its own filter pass; the per-track kernels' small pieces."""

import math

import numpy as np

from tma.families.bearings2d.kalman import _filter, _fit, _predict, filter_on, white_step
from tma.families.bearings2d.manoeuvre_prior import burst_step_noise
from tma.families.bearings2d.ncv import (
    MAX_PASSES,
    MIN_PRIOR_M,
    PRIOR_RANGES,
    PRIOR_SPEED_M_S,
)
from tma.families.bearings2d.shocks import shift_posterior, state_with_shock
from tma.runtime.jit import njit

REFINE_TOL_M = 0.1  # a refinement stops when no position moves more than this (m)


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
        # two platforms' bearings at one time: a step of no time, no noise (not 0 / 0)
        white_step(q + extra / (tb - ta) if tb > ta else q, tb - ta, Q[k])


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


@njit(error_model="numpy", depends=(filter_on, _predict, shift_posterior, state_with_shock))
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
    state_with_shock(mf[hi], Pf[hi], W[k2 + 1], dm, dc, 1.0 / inv_s, mean, cov)
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


def component(t, own_x, own_y, measured_rad, theta_cv, levels, sigma_rad, start=None,
              prior_state=None):
    """One track's component under the process levels ``levels`` (K,: the density q_k of the
    step into each epoch, m^2/s^3), refined to its MAP trajectory from the constant-velocity
    ``theta_cv`` (4,) or the trajectory ``start`` (K, 4), with bearing noise ``sigma_rad``
    and the weak prior about ``prior_state`` (4,; default: the start at the first epoch):
    (log likelihood of the bearings, the prior integrated out, up to a constant that depends
    on sigma alone; state at the last bearing (4,), its covariance (4, 4), the MAP trajectory
    (K, 4)). What
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


def burst_levels(t, start, duration, dv_m_s):
    """The process levels (K,; m^2/s^3, ``component``'s ``levels`` without the wander) of
    one target's manoeuvres at known times: each burst (``start``, ``duration``: (slots,),
    s; inf: none) a density dv^2 / D over the share of each step into an epoch of ``t`` it
    covers, as the mixture's components take theirs. For the check of a component against
    targets whose manoeuvres are known (``target_motion.burst_plan``)."""
    t = np.asarray(t, dtype=float)
    _, _, vv = burst_step_noise(t, np.asarray(start, float)[:, None],
                                np.asarray(duration, float)[:, None], dv_m_s)
    step = np.diff(t)
    return np.r_[0.0, np.divide(vv[0], step, out=np.zeros_like(step), where=step > 0)]
