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
