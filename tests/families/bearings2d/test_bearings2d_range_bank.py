"""A component as a bank over range (``range_bank.py``) against importance sampling of the
posterior it stands for: a constant-velocity target whose range the bearings bind loosely,
under the bank's own prior (its bands' Gaussians, weighed by the square of their range)."""

import math

import numpy as np
import pytest

from tma.families.bearings2d.known_manoeuvres import known_manoeuvres_nees
from tma.families.bearings2d.manoeuvre_components import component
from tma.families.bearings2d.range_bank import band_prior_sd, bank_ranges, range_bank


def _weak_geometry(seed=3, K=121, dt=10.0, sigma_deg=0.5):
    """Own-ship north at 5 m/s turning 30 deg at a third of the time; a target 20 km away at
    4 m/s, bearings every 10 s with 0.5 deg noise: its range is bound loosely."""
    rng = np.random.default_rng(seed)
    t = np.arange(K) * dt
    heading = np.where(t < t[-1] / 3, 0.0, math.radians(30.0))
    own_v = np.column_stack([5 * np.sin(heading), 5 * np.cos(heading)])
    own = np.vstack([[0.0, 0.0], np.cumsum(own_v[:-1] * dt, axis=0)])
    start = 20000.0 * np.array([math.sin(math.radians(60)), math.cos(math.radians(60))])
    v = np.array([-4.0, -3.0])
    target = start + t[:, None] * v
    sigma = math.radians(sigma_deg)
    z = (np.arctan2(target[:, 0] - own[:, 0], target[:, 1] - own[:, 1])
         + sigma * rng.standard_normal(K))
    line = np.column_stack([target, np.tile(v, (K, 1))])
    return t, own, z, sigma, line


def _range_now(state, own_now):
    return np.hypot(state[..., 0] - own_now[0], state[..., 1] - own_now[1])


def test_the_bank_holds_the_posterior_its_bands_stand_for():
    """Range now: the bank's mean within 5 % and its sd within 20 % of importance sampling
    (400,000 draws of a Student t about the bank, exact bearings likelihood, the bank's
    prior), where one Gaussian about the mode is far off (its mean more than 20 % short)."""
    t, own, z, sigma, line = _weak_geometry()
    levels = np.zeros(t.size)  # constant velocity: the state at 0 fixes the track
    mean, cov = range_bank(t, own[:, 0], own[:, 1], z, levels, sigma, line)
    _, mode, _, _ = component(t, own[:, 0], own[:, 1], z, line[0], levels, sigma, start=line)
    T = t[-1]
    back = np.array([[1, 0, -T, 0], [0, 1, 0, -T], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    m0, P0 = back @ mean, back @ cov @ back.T
    root = np.linalg.cholesky(4.0 * 0.5 * (P0 + P0.T))
    rng = np.random.default_rng(0)
    n, df = 400_000, 3
    u = rng.standard_normal((n, 4))
    draws = m0 + (u @ root.T) / np.sqrt(rng.chisquare(df, n) / df)[:, None]
    d = np.linalg.solve(root, (draws - m0).T).T
    log_q = -0.5 * (df + 4) * np.log1p(np.sum(d**2, axis=1) / df)
    # the bank's prior: per band, N(its first state, band_prior_sd per axis), weighed by
    # those sds squared
    own_v = np.gradient(own, t, axis=0)
    relative, relative_v = line[0, :2] - own[0], line[0, 2:] - own_v[0]
    r0, s0 = math.hypot(*relative), math.hypot(*relative_v)
    log_prior = np.full(n, -np.inf)
    for r_b in bank_ranges():
        a = r_b / r0
        centre = np.r_[own[0] + a * relative, own_v[0] + a * relative_v]
        sd_p, sd_v = band_prior_sd(r_b, a * s0)
        sd = np.array([sd_p, sd_p, sd_v, sd_v])
        log_band = (2 * math.log(sd_p) + 2 * math.log(sd_v) - np.sum(np.log(sd))
                    - 0.5 * np.sum(((draws - centre) / sd) ** 2, axis=1))
        log_prior = np.logaddexp(log_prior, log_band)
    x = draws[:, None, 0] + draws[:, None, 2] * t
    y = draws[:, None, 1] + draws[:, None, 3] * t
    r = (z - np.arctan2(x - own[:, 0], y - own[:, 1]) + math.pi) % (2 * math.pi) - math.pi
    log_w = log_prior - 0.5 * np.sum(r**2, axis=1) / sigma**2 - log_q
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    assert 1.0 / np.sum(w**2) > 2000  # the reference holds: enough effective draws
    now = draws @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [T, 0, 1, 0], [0, T, 0, 1.0]])
    ranges = _range_now(now, own[-1])
    ref_mean = w @ ranges
    ref_sd = math.sqrt(w @ (ranges - ref_mean) ** 2)
    bank_mean = _range_now(mean, own[-1])
    g = (mean[:2] - own[-1]) / bank_mean
    bank_sd = math.sqrt(g @ cov[:2, :2] @ g)
    assert bank_mean == pytest.approx(ref_mean, rel=0.05)
    assert bank_sd == pytest.approx(ref_sd, rel=0.2)
    assert _range_now(mode, own[-1]) < 0.8 * ref_mean  # (where the bank is needed)


def test_the_known_manoeuvres_check_takes_one_statement():
    """Log-polar and the bank are two statements of one component: asking for both is a
    ValueError, not a silent choice."""
    t, own, z, sigma, line = _weak_geometry(K=31)
    with pytest.raises(ValueError, match="ask for one"):
        known_manoeuvres_nees(t, own[:, 0], own[:, 1], z, sigma, line[0], np.array([np.inf]),
                              np.array([0.0]), 1.0, log_polar=True, over_range=True)
