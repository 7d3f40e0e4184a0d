"""Errors that hold a mixture's tails: the factor by which a Gaussian mixture's covariance
must grow for its 95 % ellipsoid to hold 95 % of the mixture.

A mixture of a core and wider components (what the bearings favour, and at some probability
a manoeuvre that puts the target elsewhere) holds less than 95 % in the 95 % ellipsoid of its
own mean and covariance: with 15 % of the weight in a component five times wider, in four
dimensions, that ellipsoid must grow 2.6 times. The factor is measured on fixed quasi-random
points of each component (the same bytes whatever the shards), held to Monte Carlo by the
tests.
"""

import functools
import math

import numpy as np

from tma.runtime.jit import njit


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


@njit(error_model="numpy")
def tail_scale(weights, means, covs, used, mean, P, s2, u, u_q95):
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


# The central intervals of the quantities a user reads: the probabilities a Gaussian holds
# within 1 and 2 sd (68.3 and 95.4 %), so that a single Gaussian's course and speed are
# exactly its estimate +- 1 and 2 sd, and a mixture's hold what they say however heavy its
# tails
INTERVAL_LEVELS = (0.5 * math.erfc(2.0 / math.sqrt(2.0)), 0.5 * math.erfc(1.0 / math.sqrt(2.0)),
                   0.5 * math.erfc(-1.0 / math.sqrt(2.0)), 0.5 * math.erfc(-2.0 / math.sqrt(2.0)))


@njit(error_model="numpy")
def _mixture_quantile(w, mu, sd, count, p):
    """The ``p`` quantile of the one-dimensional Gaussian mixture of the first ``count``
    weights ``w`` (summing to 1), means ``mu`` and sds ``sd`` (> 0): Newton's method on its
    distribution function, kept inside a bracket that halves where a step would leave it,
    to 1e-12 in probability (60 steps at most). NaN where a mean or sd is not finite (a
    quantity the component does not determine: no quantile of the mixture either)."""
    lo, hi = np.inf, -np.inf
    for c in range(count):
        if not (np.isfinite(mu[c]) and np.isfinite(sd[c])):
            return np.nan
        lo = min(lo, mu[c] - 9.0 * sd[c])
        hi = max(hi, mu[c] + 9.0 * sd[c])
    x = 0.5 * (lo + hi)
    for _ in range(60):
        f, d = -p, 0.0
        for c in range(count):
            u = (x - mu[c]) / sd[c]
            f += w[c] * 0.5 * math.erfc(-u / math.sqrt(2.0))
            d += w[c] * math.exp(-0.5 * u * u) / (sd[c] * math.sqrt(2.0 * math.pi))
        if abs(f) < 1e-12:
            break
        if f < 0.0:
            lo = x
        else:
            hi = x
        step = x - f / d if d > 0.0 else np.nan
        x = step if lo < step < hi else 0.5 * (lo + hi)
    return x


@njit(error_model="numpy")
def quantity_intervals(weights, means, covs, used, s2, now_x, now_y, levels, out):
    """The ``levels`` quantiles (``INTERVAL_LEVELS``) of range (m, from the point ``now_x``,
    ``now_y``), course (rad, clockwise from north; unwrapped about the course of the
    mixture's mean velocity) and speed (m/s) now under a Gaussian mixture of states (x, y
    (m), vx, vy (m/s)): ``weights`` of the first ``used`` components, ``means``, ``covs`` in
    units of ``s2``. Each component's quantities are Gaussian to first order (its mean's
    value and the sd its covariance gives through their gradient, as a single Gaussian's
    stated sd; range in its logarithm), so the mixture's are mixtures of those, and one
    component's are ``status.interval_columns``' closed form; ``out`` (3, len(levels)): rows
    range, course, speed, speed at least 0. A component with no spread in a quantity counts
    at 1e-9 of its value's scale; one at the point (range 0) or at rest (speed 0) leaves the
    quantities its gradient does not reach NaN."""
    total = 0.0
    for c in range(used):
        total += weights[c]
    w, mu, sd = np.empty(used), np.empty((3, used)), np.empty((3, used))
    vx0, vy0 = 0.0, 0.0
    for c in range(used):
        vx0 += weights[c] * means[c, 2] / total
        vy0 += weights[c] * means[c, 3] / total
    course0 = math.atan2(vx0, vy0)
    k = 0
    for c in range(used):
        if not weights[c] > 1e-9 * total:
            continue
        w[k] = weights[c]
        dx, dy = means[c, 0] - now_x, means[c, 1] - now_y
        vx, vy = means[c, 2], means[c, 3]
        r, v = math.hypot(dx, dy), math.hypot(vx, vy)
        P = covs[c]
        # gradients: range (dx, dy) / r on the position; course (vy, -vx) / v^2 and speed
        # (vx, vy) / v on the velocity
        var_r = (dx * dx * P[0, 0] + 2.0 * dx * dy * P[0, 1] + dy * dy * P[1, 1]) / (r * r)
        var_c = (vy * vy * P[2, 2] - 2.0 * vx * vy * P[2, 3] + vx * vx * P[3, 3]) / v**4
        var_s = (vx * vx * P[2, 2] + 2.0 * vx * vy * P[2, 3] + vy * vy * P[3, 3]) / (v * v)
        course = math.atan2(vx, vy) - course0
        course -= 2.0 * math.pi * math.floor((course + math.pi) / (2.0 * math.pi))
        mu[0, k], mu[1, k], mu[2, k] = math.log(r), course0 + course, v
        sd[0, k] = math.sqrt(max(var_r * s2, 0.0)) / r + 1e-9
        sd[1, k] = math.sqrt(max(var_c * s2, 0.0)) + 1e-9
        sd[2, k] = math.sqrt(max(var_s * s2, 0.0)) + 1e-9 * v
        k += 1
    kept = 0.0
    for c in range(k):
        kept += w[c]
    for c in range(k):
        w[c] /= kept
    for a in range(3):
        for j in range(levels.size):
            out[a, j] = _mixture_quantile(w, mu[a], sd[a], k, levels[j])
    for j in range(levels.size):
        out[0, j] = math.exp(out[0, j])
        out[2, j] = max(out[2, j], 0.0)

