"""A Gaussian stated through log-polar coordinates (``log_polar.py``): the coordinates against
their inverse, the statement against its linear limit and against Monte Carlo."""

import numpy as np
import pytest

from tma.families.bearings2d.log_polar import (
    from_log_polar,
    log_polar_statement,
    to_log_polar,
)
from tma.families.bearings2d.metrics import NEES_95
from tma.families.bearings2d.mixture_tails import tail_points

OWN_P, OWN_V = np.array([300.0, -200.0]), np.array([4.0, 3.0])
MEAN = np.array([9000.0, 16000.0, -6.0, 2.5])


def test_log_polar_coordinates_invert():
    states = MEAN + np.random.default_rng(1).normal(0, [3000, 3000, 5, 5], (100, 4))
    u = to_log_polar(states, OWN_P, OWN_V)
    np.testing.assert_allclose(from_log_polar(u, OWN_P, OWN_V), states, rtol=1e-12, atol=1e-9)
    d = MEAN[:2] - OWN_P
    assert u[0, 0] == pytest.approx(np.arctan2(*(states[0, :2] - OWN_P)))  # clockwise from N
    assert to_log_polar(MEAN, OWN_P, OWN_V)[1] == pytest.approx(np.log(np.hypot(*d)))


@pytest.mark.parametrize("where", [MEAN, np.r_[OWN_P + [0.0, -18000.0], MEAN[2:]]],
                         ids=["north-north-east", "due south"])
def test_a_narrow_gaussian_is_stated_as_it_is(where):
    """Where the mapping is linear over the Gaussian (100 m at 18 km), the statement is the
    Gaussian itself: mean within a metre, covariance within 2 %; also due south of own-ship,
    where the bearing steps across +-pi."""
    cov = np.diag([100.0, 80.0, 0.05, 0.04]) ** 2
    mean, stated = log_polar_statement(where, cov, OWN_P, OWN_V, *tail_points())
    np.testing.assert_allclose(mean, where, atol=1.0)
    np.testing.assert_allclose(np.sqrt(np.diag(stated)), np.sqrt(np.diag(cov)), rtol=0.02)


def test_a_wide_range_is_stated_as_the_log_polar_gaussian_it_maps():
    """A range known to 30 %: the statement's mean lies farther out than the Cartesian mean,
    and its 95 % ellipsoid holds 94-96 % of 200,000 Monte Carlo draws of the same log-polar
    Gaussian mapped back (the Cartesian Gaussian itself holds less of them)."""
    los = (MEAN[:2] - OWN_P) / np.hypot(*(MEAN[:2] - OWN_P))
    r = np.hypot(*(MEAN[:2] - OWN_P))
    pos = np.outer(los, los) * (0.3 * r) ** 2 + np.eye(2) * 150.0**2
    cov = np.zeros((4, 4))
    cov[:2, :2], cov[2:, 2:] = pos, np.eye(2) * 1.5**2
    cov[:2, 2:] = cov[2:, :2] = 0.8 * (0.3 * r) * 1.5 * np.outer(los, los)  # range, its rate
    mean, stated = log_polar_statement(MEAN, cov, OWN_P, OWN_V, *tail_points())
    assert (mean[:2] - MEAN[:2]) @ los > 0.02 * r  # skewed away from own-ship
    # the same log-polar Gaussian, drawn at random
    step = 1e-6 * np.sqrt(np.diag(cov))
    jac = np.column_stack([(to_log_polar(MEAN + np.eye(4)[k] * step[k], OWN_P, OWN_V)
                            - to_log_polar(MEAN - np.eye(4)[k] * step[k], OWN_P, OWN_V))
                           / (2 * step[k]) for k in range(4)])
    draws = from_log_polar(np.random.default_rng(5).multivariate_normal(
        to_log_polar(MEAN, OWN_P, OWN_V), jac @ cov @ jac.T, 200_000), OWN_P, OWN_V)

    def held(m, c):
        e = draws - m
        return np.mean(np.einsum("ij,jk,ik->i", e, np.linalg.inv(c), e) <= NEES_95)

    assert 0.94 <= held(mean, stated) <= 0.96
    assert held(MEAN, cov) < held(mean, stated)
