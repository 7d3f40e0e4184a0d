"""A component as a bank over range: what its range is, where one Gaussian about its mode
cannot say.

After several manoeuvres the bearings bind a target's range loosely, and the velocity
changes' prior pulls the mode near (nearer trajectories need smaller changes): the component
of a target's true manoeuvres, refined to its MAP trajectory, put one 34.2 km away at
5.1 +- 3 km (issue 36). A bank of the same component refined under tight priors at ranges
across the span, each weighed by its evidence, holds the range the bearings and the prior
leave (Peach, "Bearings-only tracking using a set of range-parameterised extended Kalman
filters", IEE Proc. Radar Sonar Navig. 142(2), 1995, for a constant-velocity target; here
each band is the manoeuvring component refined to its MAP trajectory). The bands lie along
the family of trajectories bearings alone cannot tell apart: the one it starts from, its
positions and velocities relative to own-ship's scaled; their priors, each weighed by its
sds squared, add up to one flat in the state, as the diffuse one of
``manoeuvre_components.component`` nearly is. Held to importance sampling of the posterior
they stand for by ``tests/families/bearings2d/test_bearings2d_range_bank.py``.

A diagnostic for now (``make bench ARGS="--only own_model"``, ``docs/manoeuvres.md``): the
answers of ``lm`` rest on one Gaussian per component.
"""

import math

import numpy as np

from tma.families.bearings2d.manoeuvre_components import component

BANK_RANGES_M = (1000.0, 120000.0)  # the span of the bands (m)
BANK_RATIO = 1.15  # each band's range over the one before
BAND_SD = 0.1  # each band's prior sd over its range (position) and relative speed (velocity)


def bank_ranges(span_m=BANK_RANGES_M, ratio=BANK_RATIO) -> np.ndarray:
    """The bands' ranges (m): geometric over ``span_m``, ``ratio`` apart."""
    lo, hi = span_m
    return np.geomspace(lo, hi, int(math.log(hi / lo) / math.log(ratio)) + 1)


def band_prior_sd(range_m, relative_speed_m_s, band_sd=BAND_SD) -> tuple[float, float]:
    """A band's prior sd per position and velocity axis (m, m/s): ``band_sd`` times its
    range and its relative speed, at least 1 m and 0.1 m/s."""
    return max(band_sd * range_m, 1.0), max(band_sd * relative_speed_m_s, 0.1)


def range_bank(t, own_x, own_y, measured_rad, levels, sigma_rad, start, ranges=None,
               band_sd=BAND_SD):
    """The component of process levels ``levels`` (``component``'s) as a bank over range:
    per band range r_b (``bank_ranges``, m), ``start`` (K, 4: m, m/s) scaled about own-ship by
    a = r_b / (its range at the first epoch), positions and velocities relative to
    own-ship's (the family of trajectories bearings alone cannot tell apart), refined under a
    prior about its first state of sd ``band_sd`` times the scaled relative position and
    velocity (per axis; at least 1 m and 0.1 m/s); the bands weighed by their evidence times
    their prior's sds squared, so that their priors add up to one flat in the state (as the
    diffuse one of ``component`` nearly is); returns the bank's mean and covariance at the
    last epoch (4,; (4, 4): m, m/s). Bands whose fit fails are left out; all failing: NaN."""
    t = np.asarray(t, dtype=float)
    own = np.column_stack([own_x, own_y]).astype(float)
    own_v = np.gradient(own, t, axis=0)
    start = np.asarray(start, dtype=float)
    relative, relative_v = start[:, :2] - own, start[:, 2:] - own_v
    r0, s0 = math.hypot(*relative[0]), math.hypot(*relative_v[0])
    logw, means, covs = [], [], []
    for r_b in (bank_ranges() if ranges is None else ranges):
        a = r_b / r0
        band = np.column_stack([own + a * relative, own_v + a * relative_v])
        sd = band_prior_sd(r_b, a * s0, band_sd)
        loglik, mean, cov, _ = component(t, own_x, own_y, measured_rad, band[0], levels,
                                         sigma_rad, start=band, prior_sd=sd)
        if np.isfinite(loglik) and np.isfinite(cov).all():
            logw.append(loglik + 2.0 * math.log(sd[0]) + 2.0 * math.log(sd[1]))
            means.append(mean)
            covs.append(cov)
    if not logw:
        return np.full(4, np.nan), np.full((4, 4), np.nan)
    w = np.exp(np.asarray(logw) - max(logw))
    w /= w.sum()
    means, covs = np.asarray(means), np.asarray(covs)
    mean = w @ means
    spread = means - mean
    return mean, np.einsum("b,bij->ij", w, covs) + np.einsum("b,bi,bj->ij", w, spread, spread)
