"""A component's Gaussian stated through log-polar coordinates about the observer.

Bearings-only information fixes the bearing well and the range poorly, and what it leaves of
the range is long-tailed away from the observer: a Gaussian in Cartesian coordinates (the
Laplace approximation of each component of ``manoeuvres.py``) is symmetric about its mode,
and after manoeuvres its far side holds too little (issue 36: the component of a target's
true manoeuvres is 82 % consistent after two, its misses nearer than the truth). The modified
polar coordinates of Aidala and Hammel ("Utilization of modified polar coordinates for
bearings-only tracking", IEEE Trans. Automatic Control 28(3), 1983) separate what the bearings
determine from what they do not; here with log range for inverse range: u = (bearing, log
range, bearing rate, range rate / range) of the target relative to the observer (rad, log m,
rad/s, 1/s). The same Gaussian, carried into u by its Jacobian at the mean and mapped back
through fixed quasi-random points, is a banana along the line of sight with a log-normal
range: its mean lies farther out, and its covariance, widened so that its 95 % ellipsoid
holds 95 % of the points, holds the far side.

A diagnostic for now (``make bench ARGS="--only own_model"``, ``docs/manoeuvres.md``): the
answers of ``lm`` are stated in Cartesian coordinates.
"""

import numpy as np

from tma.maths.angles import wrap_to_pi


def to_log_polar(state, own_p, own_v):
    """u (..., 4) of Cartesian states (..., 4: x, y, vx, vy; m, m/s) relative to the
    observer at ``own_p`` (2,; m) moving at ``own_v`` (2,; m/s): bearing clockwise from
    north (rad), log range (log m), bearing rate (rad/s), range rate over range (1/s)."""
    state = np.asarray(state, dtype=float)
    dx, dy = state[..., 0] - own_p[0], state[..., 1] - own_p[1]
    vx, vy = state[..., 2] - own_v[0], state[..., 3] - own_v[1]
    r = np.hypot(dx, dy)
    s, c = dx / r, dy / r
    return np.stack([np.arctan2(dx, dy), np.log(r), (vx * c - vy * s) / r,
                     (vx * s + vy * c) / r], axis=-1)


def from_log_polar(u, own_p, own_v):
    """The Cartesian states (..., 4) of log-polar ``u`` (..., 4; ``to_log_polar``)."""
    u = np.asarray(u, dtype=float)
    bearing, r = u[..., 0], np.exp(u[..., 1])
    s, c = np.sin(bearing), np.cos(bearing)
    return np.stack([own_p[0] + r * s, own_p[1] + r * c,
                     own_v[0] + r * (u[..., 3] * s + u[..., 2] * c),
                     own_v[1] + r * (u[..., 3] * c - u[..., 2] * s)], axis=-1)


def log_polar_statement(mean, cov, own_p, own_v, points, points_q95):
    """The Gaussian (``mean`` (4,), ``cov`` (4, 4); m, m/s) stated through log-polar
    coordinates: N(u(mean), J cov J^T), J u's Jacobian at ``mean`` (central differences), its
    standard-normal ``points`` (N, 4; ``mixture_tails.tail_points``, whose 95 % quantile of
    |u|^2 is ``points_q95``) mapped back to Cartesian; returns their mean and covariance, the
    covariance widened (never narrowed) so that its 95 % ellipsoid holds 95 % of them."""
    mean = np.asarray(mean, dtype=float)
    step = 1e-6 * np.maximum(np.sqrt(np.diag(cov)), 1e-9)
    jacobian = np.empty((4, 4))
    for k in range(4):
        delta = np.zeros(4)
        delta[k] = step[k]
        d = to_log_polar(mean + delta, own_p, own_v) - to_log_polar(mean - delta, own_p, own_v)
        d[0] = wrap_to_pi(d[0])  # (a bearing due south steps across +-pi)
        jacobian[:, k] = d / (2 * step[k])
    cov_u = jacobian @ cov @ jacobian.T
    vals, vecs = np.linalg.eigh(0.5 * (cov_u + cov_u.T))
    root = vecs * np.sqrt(np.maximum(vals, 0.0))
    cloud = from_log_polar(to_log_polar(mean, own_p, own_v) + points @ root.T, own_p, own_v)
    centre = cloud.mean(axis=0)
    spread = np.cov(cloud.T)
    d2 = np.einsum("ij,jk,ik->i", cloud - centre, np.linalg.inv(spread), cloud - centre)
    widen = max(float(np.quantile(d2, 0.95, method="inverted_cdf")) / points_q95, 1.0)
    return centre, spread * widen
