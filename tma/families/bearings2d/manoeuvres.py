"""A target that may manoeuvre: its state now, averaged over when and how often it did.

Motion model. Between manoeuvres the target is nearly at constant velocity (``ncv.py``: white
random acceleration of spectral density q per axis). Manoeuvres (turns, speed changes) start
at the times of a Poisson process of rate lambda; each changes the velocity by dv, drawn
N(0, s^2 I) per axis, spread evenly over its duration D (a burst of white acceleration of
density s^2 / D on top of q). A turn by phi at speed v changes the velocity by 2 v sin(phi /
2): s is set from the targets' speeds and turns (``ManoeuvrePrior``), not from one track's
fit (a fit that the manoeuvre misled would shrink it where it matters most).

Inference: Bayesian model averaging over the manoeuvres the target made in the window. A
component is a set of manoeuvres, each starting at the centre of a cell of ``step_s``
seconds with one of the durations D_d; its prior is the Poisson probability of exactly
those, exp(-lambda T) prod (lambda cell / n_D). The components are found as Occam's window
finds models (Madigan and Raftery, JASA 89(428), 1994): none; every single manoeuvre; a
second manoeuvre anywhere besides each of the ``TOP_SINGLES`` most probable single ones;
a third besides the most probable pair. Components left out are those far less probable
than the ones kept. (A "last manoeuvre" model with the earlier ones as extra white noise,
the moment-matched alternative, was tried and rejected: a turn is one large jump, which
white noise of the same variance makes improbable, so the model would explain an early turn
as the last manoeuvre and rule out a later one; 60 % of its ok tracks were consistent where
this reaches the nominal 95 %, ``docs/manoeuvres.md``.)

Each component is an NCV model with a step-dependent process level (``_levels``). Its
likelihood is that of the bearings linearised about a nominal trajectory: the Kalman
filter's (``ncv._filter``) innovations under a weak prior on the first state about the
no-manoeuvre solution, the same for every component. Every component is first screened
about the trajectory of the component it extends (the no-manoeuvre solution for single
manoeuvres); the ``REFINE`` most probable of each level are refined to their maximum a
posteriori trajectory (``ncv._fit``: the iterated Kalman smoother, Gauss-Newton) and
linearised there (Laplace). Screening about a nearby trajectory is accurate for the
components the bearings do not single out (their trajectories hardly differ), and those
they do single out are refined.

The answer is the mixture's mean and covariance at the last bearing (within plus between
components), so a manoeuvre the bearings cannot rule out widens the errors by what it could
have done, at its posterior probability. With lambda = 0 the mixture is the no-manoeuvre
component alone: ``ncv.smooth``'s answer, which ``mixture`` then returns.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np

from tma.families.bearings2d.ncv import (
    MAX_PASSES,
    MAX_S,
    MIN_PRIOR_M,
    MIN_SIGMA_RAD,
    PRIOR_RANGES,
    PRIOR_SPEED_M_S,
    TOL_M,
    _bearing_cost,
    _filter,
    _fit,
    _srif,
    in_units,
    smooth,
    start_track,
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
MAX_MANOEUVRES = 3  # in one component
TOP_SINGLES = 3  # single manoeuvres a second one is sought beside
REFINE = 3  # components of each level refined to their MAP trajectory
REFINE_TOL_M = 0.1  # a refinement stops when no position moves more than this (m)
@functools.cache
def tail_points() -> tuple[np.ndarray, float]:
    """Fixed standard-normal points of the state's four dimensions, not random (the same
    bytes whatever the shards): a Halton set's first four coordinates give each its
    direction, the fifth its radius at chi-square(4) quantiles (the tails, which decide, as
    well as the core); and their 95 % quantile of |u|^2 (about chi-square(4)'s 9.49).
    Built when first needed: scipy.stats loads only then."""
    from scipy.stats import chi2, norm, qmc

    halton = qmc.Halton(d=5, scramble=False).random(1025)[1:]
    directions = norm.ppf(halton[:, :4])
    points = np.ascontiguousarray(directions / np.linalg.norm(directions, axis=1, keepdims=True)
                                  * np.sqrt(chi2.ppf(halton[:, 4:], 4)))
    return points, float(np.quantile(np.sum(points**2, axis=1), 0.95, method="inverted_cdf"))


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


def start_cells(t_first, t_last, step_s):
    """Cells of ``step_s`` over each track's window: their bounds (n, J) each, clipped to the
    window (J cells over the longest)."""
    span = float(np.max(t_last - t_first)) if np.size(t_first) else 0.0
    J = max(int(math.ceil(span / step_s - 1e-9)), 1)
    lo = t_first[:, None] + step_s * np.arange(J)
    hi = np.minimum(lo + step_s, t_last[:, None])
    return lo, np.maximum(hi, lo)


def log_priors(prior: ManoeuvrePrior, t_first, t_last):
    """Per track: log exp(-lambda T), the prior of no manoeuvre in the window (n,), the
    start time of each cell's manoeuvre (its centre, (n, J)) and log(lambda x cell / n_D)
    (n, J), the prior factor of a manoeuvre in that cell with one of the n_D durations: a
    component's log prior is the first plus one of these per manoeuvre. A cell outside a
    track's window has -inf."""
    lam = prior.rate_per_s
    a, b = start_cells(t_first, t_last, prior.step_s)
    with np.errstate(divide="ignore"):
        each = np.log(lam * (b - a)) - math.log(len(prior.durations_s))
    return -lam * (t_last - t_first), 0.5 * (a + b), each


@njit(error_model="numpy")
def _levels(t, lo, hi, q, taus, durations, bursts, count, lam):
    """Process level of each step into epoch k of lo..hi: ``q`` plus, for each of the first
    ``count`` manoeuvres, ``bursts[m]`` over [taus[m], taus[m] + durations[m]] by its share
    of the step (units of the noise variance)."""
    for k in range(lo + 1, hi + 1):
        a, b = t[k - 1], t[k]
        extra = 0.0
        for m in range(count):
            extra += bursts[m] * max(min(b, taus[m] + durations[m]) - max(a, taus[m]), 0.0)
        lam[k] = q + extra / (b - a)
    lam[lo] = q


@njit(error_model="numpy", depends=(_filter,))
def _screen(t, ox, oy, z, w, weighted, lo, hi, nom, lam, prior, p0, s2, mf, Pf, Pp, nu, S,
            mean, cov):
    """The Kalman filter linearised about ``nom`` under the levels ``lam``: writes the state
    at ``hi`` and its covariance (units of s^2 = ``s2``, rad^2) and returns the log
    likelihood of the bearings, -1/2 sum(nu^2 / (s^2 S) + log S), up to a constant common
    to every component (the prior, the same for all, and n log s)."""
    _filter(t, ox, oy, z, w, weighted, lo, hi, nom, lam, prior, p0, mf, Pf, Pp, nu, S)
    loglik = 0.0
    for k in range(lo, hi + 1):
        if nu[k] == nu[k]:
            loglik -= 0.5 * (nu[k] * nu[k] / (s2 * S[k]) + math.log(S[k]))
    for a in range(4):
        mean[a] = mf[hi, a]
        for b in range(4):
            cov[a, b] = Pf[hi, a, b]
    return loglik


@njit(error_model="numpy", depends=(_fit, _screen))
def _refine(t, ox, oy, z, w, weighted, lo, hi, nom, lam, prior, p0, s2, max_iter, tol_m, mf,
            Pf, Pp, nu, S, ms, trial, mean, cov):
    """``_screen`` about the MAP trajectory, found by Gauss-Newton from ``nom`` (updated in
    place): the Laplace approximation. -inf if a covariance was not positive definite."""
    if _fit(t, ox, oy, z, w, weighted, lo, hi, nom, lam, prior, p0, max_iter, tol_m, mf, Pf,
            Pp, nu, S, ms, trial) < 0:
        return -np.inf
    return _screen(t, ox, oy, z, w, weighted, lo, hi, nom, lam, prior, p0, s2, mf, Pf, Pp,
                   nu, S, mean, cov)


@njit(error_model="numpy")
def _top(values, count, k, out):
    """Indices of the ``k`` largest finite ``values[:count]`` into ``out``; returns how many."""
    found = 0
    for _ in range(k):
        best, best_v = -1, -np.inf
        for c in range(count):
            v = values[c]
            if v > best_v:
                taken = False
                for f in range(found):
                    taken |= out[f] == c
                if not taken:
                    best, best_v = c, v
        if best < 0:
            break
        out[found] = best
        found += 1
    return found


@njit(error_model="numpy")
def _tail_scale(weights, means, covs, used, mean, P, s2, u, u_q95):
    """The factor (>= 1) by which the mixture's covariance ``P`` (units of ``s2``) must grow
    for its 95 % ellipsoid about ``mean`` to hold 95 % of the mixture (``weights`` of the
    first ``used`` components, ``means`` in m and m/s, ``covs`` in units of ``s2``): the
    95 % weighted quantile of the normalised error of the points ``means[c] + sqrt(s2) L_c
    u`` (``u``: fixed standard-normal points, L_c L_c^T = ``covs[c]``) over ``u_q95``, the
    points' own 95 % quantile of |u|^2 (so a single Gaussian gets exactly 1)."""
    N = u.shape[0]
    Pinv = np.linalg.inv(P)
    total = 0.0
    for c in range(used):
        total += weights[c]
    d = np.empty(used * N)
    w = np.empty(used * N)
    count = 0
    x, L = np.empty(4), np.empty((4, 4))
    for c in range(used):
        if not weights[c] > 1e-9 * total:
            continue
        vals, vecs = np.linalg.eigh(covs[c])
        for a in range(4):
            for b in range(4):
                L[a, b] = vecs[a, b] * math.sqrt(max(vals[b], 0.0))
        for k in range(N):
            for a in range(4):
                v = (means[c, a] - mean[a]) / math.sqrt(s2)
                for b in range(4):
                    v += L[a, b] * u[k, b]
                x[a] = v
            q = 0.0
            for a in range(4):
                for b in range(4):
                    q += x[a] * Pinv[a, b] * x[b]
            d[count], w[count] = q, weights[c] / N
            count += 1
    order = np.argsort(d[:count])
    level = 0.95 * total
    acc = 0.0
    for k in order:
        acc += w[k]
        if acc >= level:
            scale = d[k] / u_q95
            return scale if scale > 1.0 + 1e-9 else 1.0
    return 1.0


@njit(error_model="numpy", depends=(_screen, _refine, _levels, _top, _srif, _bearing_cost,
                                         _tail_scale, start_track))
def mixture_tracks(t, ox, oy, measured, weight, weighted, first, last, theta, q, dv2, taus,
                   durations, log_none, log_each, scale2, p0_pos, max_iter, tol_m, state,
                   P_last, e, cost, passes, p_manoeuvre, tau_map, u, u_q95, tail_scale):
    """Per track i the mixture of the module docstring: wander ``q`` and manoeuvres of
    velocity variance ``dv2`` (m^2/s^3, m^2/s^2: (n,)), candidate starts ``taus`` (n, J),
    ``durations`` (D,), the priors ``log_none`` (n,) and ``log_each`` (n, J)
    (``log_priors``), the noise variance ``scale2`` (n,) the units refer to (rad^2). Writes
    the mixture's state at the last bearing (n, 4) and its covariance in units of s^2, the
    innovations of its most probable component (as ``ncv.smooth_tracks``), that component's
    squared bearing residuals (rad^2), the Gauss-Newton passes of the no-manoeuvre component
    (-1: failed), the posterior probability of a manoeuvre in the window, and the most
    probable component's last start (NaN: none)."""
    n, K = measured.shape
    J, D = taus.shape[1], durations.size
    JD = J * D
    C = 1 + JD * (1 + TOP_SINGLES + 1)  # none, singles, pairs, triples
    M = MAX_MANOEUVRES
    mf, ms, trial = np.empty((K, 4)), np.empty((K, 4)), np.empty((K, 4))
    Pf, Pp = np.empty((K, 4, 4)), np.empty((K, 4, 4))
    nu, S, nu0, S0 = np.empty(K), np.empty(K), np.empty(K), np.empty(K)
    R, r = np.empty((4, 4)), np.empty(4)
    lam, none = np.empty(K), np.zeros(K)
    p0, prior = np.empty(2), np.empty(4)
    # the components: their manoeuvres (cell * D + duration), count, log weight, base
    # (the component whose trajectory screened it), refined trajectory slot, moments
    cells = np.empty((C, M), dtype=np.int64)
    count = np.empty(C, dtype=np.int64)
    logw = np.empty(C)
    slot = np.empty(C, dtype=np.int64)
    parent = np.empty(C, dtype=np.int64)
    means, covs = np.empty((C, 4)), np.empty((C, 4, 4))
    noms = np.empty((1 + 3 * REFINE, K, 4))  # MAP trajectories: none, then refined ones
    seen = np.zeros((JD, JD), dtype=np.bool_)
    btau, bdur, bq = np.empty(M), np.empty(M), np.empty(M)
    chosen = np.empty(max(TOP_SINGLES, REFINE), dtype=np.int64)
    for i in range(n):
        lo, hi = first[i], last[i]
        z, w = measured[i], (weight[i] if weighted else measured[i])
        start_track(i, t, lo, hi, theta, noms[0], state, P_last, e)
        cost[i], p_manoeuvre[i], tau_map[i] = np.nan, np.nan, np.nan
        s2 = scale2[i]
        p0[0] = p0_pos[i] * p0_pos[i] / s2
        p0[1] = PRIOR_SPEED_M_S * PRIOR_SPEED_M_S / s2
        for a in range(4):
            prior[a] = noms[0, lo, a]
        qi = q[i] / s2
        # component 0: no manoeuvre
        _levels(t, lo, hi, qi, btau, bdur, bq, 0, lam)
        passes[i] = _fit(t, ox, oy, z, w, weighted, lo, hi, noms[0], lam, prior, p0, max_iter,
                         tol_m, mf, Pf, Pp, nu, S, ms, trial)
        if passes[i] < 0:
            continue
        logw[0] = log_none[i] + _screen(t, ox, oy, z, w, weighted, lo, hi, noms[0], lam,
                                        prior, p0, s2, mf, Pf, Pp, nu, S, means[0], covs[0])
        count[0], slot[0] = 0, 0
        used, filled = 1, 1
        seen[:, :] = False
        for level in range(1, M + 1):
            # bases: the component(s) this level extends by one manoeuvre
            if level == 1:
                n_bases, chosen[0] = 1, 0
            else:
                n_bases = 0
                for c in range(used):  # the most probable refined of the level below
                    if count[c] == level - 1 and slot[c] >= 0:
                        n_bases += 1
                n_bases = min(n_bases, TOP_SINGLES if level == 2 else 1)
                tmp = np.full(used, -np.inf)
                for c in range(used):
                    if count[c] == level - 1 and slot[c] >= 0:
                        tmp[c] = logw[c]
                n_bases = _top(tmp, used, n_bases, chosen)
            start = used
            for bi in range(n_bases):
                base = chosen[bi]
                nb = count[base]
                for cd in range(JD):
                    j = cd // D
                    if not log_each[i, j] > -np.inf:
                        continue
                    clash = False
                    for m in range(nb):
                        clash |= cells[base, m] // D == j
                    if clash:
                        continue
                    if level == 2:  # a pair found from either of its single manoeuvres once
                        other = cells[base, 0]
                        if seen[min(other, cd), max(other, cd)]:
                            continue
                        seen[min(other, cd), max(other, cd)] = True
                    c = used
                    used += 1
                    count[c], slot[c], parent[c] = nb + 1, -1, base
                    for m in range(nb):
                        cells[c, m] = cells[base, m]
                    cells[c, nb] = cd
                    lp = log_none[i]
                    for m in range(nb + 1):
                        jm, dm = cells[c, m] // D, cells[c, m] % D
                        btau[m], bdur[m], bq[m] = taus[i, jm], durations[dm], dv2[i] / (
                            durations[dm] * s2)
                        lp += log_each[i, jm]
                    _levels(t, lo, hi, qi, btau, bdur, bq, nb + 1, lam)
                    logw[c] = lp + _screen(t, ox, oy, z, w, weighted, lo, hi,
                                           noms[slot[base]], lam, prior, p0, s2, mf, Pf, Pp,
                                           nu, S, means[c], covs[c])
            if used == start:
                break
            # refine the most probable of this level about their own MAP trajectories
            tmp = np.full(used, -np.inf)
            for c in range(start, used):
                tmp[c] = logw[c]
            for f in range(_top(tmp, used, REFINE, chosen)):
                c = chosen[f]
                lp = log_none[i]
                for m in range(count[c]):
                    jm, dm = cells[c, m] // D, cells[c, m] % D
                    btau[m], bdur[m], bq[m] = taus[i, jm], durations[dm], dv2[i] / (
                        durations[dm] * s2)
                    lp += log_each[i, jm]
                _levels(t, lo, hi, qi, btau, bdur, bq, count[c], lam)
                noms[filled] = noms[slot[parent[c]]]
                loglik = _refine(t, ox, oy, z, w, weighted, lo, hi, noms[filled], lam, prior,
                                 p0, s2, max_iter, tol_m, mf, Pf, Pp, nu, S, ms, trial,
                                 means[c], covs[c])
                logw[c] = lp + loglik
                slot[c] = filled if loglik > -np.inf else -1
                filled += 1
        # the mixture
        best, best_logw = 0, logw[0]
        for c in range(used):
            if logw[c] > best_logw and slot[c] >= 0:
                best, best_logw = c, logw[c]
        top = logw[0]
        for c in range(used):
            top = max(top, logw[c])
        total = 0.0
        for c in range(used):
            logw[c] = math.exp(logw[c] - top) if logw[c] > -np.inf else 0.0
            total += logw[c]
        for a in range(4):
            v = 0.0
            for c in range(used):
                if logw[c] > 0.0:
                    v += logw[c] * means[c, a]
            state[i, a] = v / total
        for a in range(4):
            for b in range(4):
                v = 0.0
                for c in range(used):
                    if logw[c] > 0.0:  # (covariances in units of s^2, as the output)
                        v += logw[c] * (covs[c, a, b] + (means[c, a] - state[i, a])
                                        * (means[c, b] - state[i, b]) / s2)
                P_last[i, a, b] = v / total
        # a heavy-tailed mixture holds less than 95 % in the 95 % ellipsoid of its moments:
        # the errors stated are those of the Gaussian (same mean and shape) that holds it
        tail_scale[i] = _tail_scale(logw, means, covs, used, state[i], P_last[i], s2, u,
                                   u_q95)
        for a in range(4):
            for b in range(4):
                P_last[i, a, b] *= tail_scale[i]
        p_manoeuvre[i] = 1.0 - logw[0] / total
        if count[best] > 0:
            latest = -np.inf
            for m in range(count[best]):
                latest = max(latest, taus[i, cells[best, m] // D])
            tau_map[i] = latest
        # the trend test's innovations: the most probable refined component's, diffuse
        # (ncv.smooth_tracks)
        nom = noms[slot[best]]
        for m in range(count[best]):
            jm, dm = cells[best, m] // D, cells[best, m] % D
            btau[m], bdur[m], bq[m] = taus[i, jm], durations[dm], dv2[i] / (durations[dm] * s2)
        _levels(t, lo, hi, qi, btau, bdur, bq, count[best], lam)
        _srif(t, ox, oy, z, w, weighted, lo, hi, nom, none, nu0, S0, R, r)
        _srif(t, ox, oy, z, w, weighted, lo, hi, nom, lam, nu, S, R, r)
        for k in range(lo, hi + 1):
            if nu[k] == nu[k] and S0[k] <= MAX_S:
                e[i, k] = nu[k]
        cost[i] = _bearing_cost(ox, oy, z, w, weighted, lo, hi, nom)


def mixture(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd,
            prior: ManoeuvrePrior, sigma_rad):
    """The state at each track's last bearing under NCV wander ``accel_psd`` (m^2/s^3, (n,)
    or scalar) and the manoeuvres of ``prior``, from the constant-velocity start
    ``theta_cv`` (n, 4), as ``ncv.smooth`` returns it (``state``, ``cov``, ``theta``,
    ``cov_theta``, ``innovations``, ``sigma2``, ``cost_rad2``, ``passes``) plus
    ``p_manoeuvre`` (the posterior probability of a manoeuvre since the first bearing),
    ``manoeuvre_s`` (the latest start of the most probable component; NaN: none) and
    ``tail_scale`` (the factor its covariance was widened by, ``_tail_scale``).

    ``sigma_rad`` (n,): the bearing noise, NaN where unknown: then estimated as
    ``ncv.smooth`` does without manoeuvres."""
    n, K = measured_rad.shape
    sigma = np.asarray(sigma_rad, dtype=float)
    if prior.rate_per_h == 0:  # no manoeuvres: the nearly-constant-velocity answer itself
        out = smooth(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd,
                     sigma)
        return {**out, "p_manoeuvre": np.zeros(n), "manoeuvre_s": np.full(n, np.nan)}
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
    dv2 = np.full(n, prior.dv_m_s**2)
    log_none, taus, log_each = log_priors(prior, t[first], t[last])
    if known.all():
        sigma2 = sigma**2
    else:  # the no-manoeuvre fit's estimate: a manoeuvre can only inflate it (conservative);
        # the components' innovations would shrink it (they fit the noise with manoeuvres)
        sigma2 = np.where(known, sigma**2, smooth(t, own_x, own_y, measured_rad, valid, first,
                                                  last, theta_cv, q, sigma)["sigma2"])
    sigma2 = np.maximum(sigma2, MIN_SIGMA_RAD**2)
    out = {"state": np.empty((n, 4)), "cov": np.empty((n, 4, 4)),
           "innovations": np.empty((n, K)), "cost_rad2": np.empty(n),
           "passes": np.zeros(n, dtype=np.int64), "p_manoeuvre": np.empty(n),
           "manoeuvre_s": np.empty(n), "tail_scale": np.ones(n)}
    mixture_tracks(t, np.ascontiguousarray(own_x, float), np.ascontiguousarray(own_y, float),
                   np.ascontiguousarray(measured_rad, float), weight, weighted, first, last,
                   theta0, q, dv2, np.ascontiguousarray(taus),
                   np.asarray(prior.durations_s, dtype=float), np.ascontiguousarray(log_none),
                   np.ascontiguousarray(log_each), sigma2, p0_pos, MAX_PASSES, REFINE_TOL_M,
                   out["state"], out["cov"], out["innovations"], out["cost_rad2"],
                   out["passes"], out["p_manoeuvre"], out["manoeuvre_s"], *tail_points(),
                   out["tail_scale"])
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
    work = [np.empty((K, 4)), np.empty((K, 4, 4)), np.empty((K, 4, 4)), np.empty(K),
            np.empty(K), np.empty((K, 4)), np.empty((K, 4))]
    mean, cov = np.empty(4), np.empty((4, 4))
    loglik = _refine(t, np.ascontiguousarray(own_x, float), np.ascontiguousarray(own_y, float),
                     np.ascontiguousarray(measured_rad, float), np.empty(0), False, 0, K - 1,
                     nom, np.asarray(levels, dtype=float) / s2, prior, p0, s2, MAX_PASSES,
                     TOL_M, *work, mean, cov)
    return loglik, mean, cov * s2, nom
