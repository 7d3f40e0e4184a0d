"""The bearings model: analytic Jacobian vs finite differences, normal equations, wrapping,
missing bearings."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tma.families import build_estimator
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.model import (
    BearingTerms,
    bearing_cost,
    bearing_jacobian,
    bearing_residuals,
    normal_equations,
    predicted_bearings,
    wrap_residual,
)
from tma.maths.angles import wrap_to_180, wrap_to_pi


def _setup(n=50, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 1201.0, 2.0)
    ox, oy = 5.0 * t * 0.3, 5.0 * t * 0.9
    theta = np.column_stack([rng.uniform(-20e3, 20e3, n), rng.uniform(5e3, 50e3, n),
                             rng.uniform(-15, 15, n), rng.uniform(-15, 15, n)])
    return theta, t, ox, oy


def test_jacobian_matches_central_differences():
    theta, t, ox, oy = _setup()
    jac = bearing_jacobian(theta, t, ox, oy, None)
    steps = np.array([1.0, 1.0, 1e-3, 1e-3])  # m and m/s
    for i, h in enumerate(steps):
        plus, minus = theta.copy(), theta.copy()
        plus[:, i] += h
        minus[:, i] -= h
        fd = wrap_to_pi(predicted_bearings(plus, t, ox, oy)
                        - predicted_bearings(minus, t, ox, oy)) / (2 * h)
        scale = np.abs(jac[..., i]).max()
        np.testing.assert_allclose(jac[..., i], fd, rtol=0, atol=1e-6 * scale)


def test_normal_equations_equal_explicit_jacobian_products():
    theta, t, ox, oy = _setup(seed=1)
    rng = np.random.default_rng(2)
    measured = predicted_bearings(theta, t, ox, oy) + rng.normal(0, 0.01, (theta.shape[0], t.size))
    valid = rng.random(measured.shape) > 0.2
    r, H, g = normal_equations(theta, t, ox, oy, measured, valid)
    jac = bearing_jacobian(theta, t, ox, oy, valid)
    np.testing.assert_allclose(H, np.einsum("nki,nkj->nij", jac, jac), rtol=1e-12)
    np.testing.assert_allclose(g, np.einsum("nki,nk->ni", jac, r), rtol=1e-10, atol=1e-18)
    np.testing.assert_array_equal(r, bearing_residuals(theta, t, ox, oy, measured, valid))
    assert np.all(r[~valid] == 0)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4, allow_nan=False))
def test_wraps_are_consistent(angle):
    w = float(wrap_to_pi(angle))
    assert -np.pi <= w < np.pi
    assert np.isclose(np.cos(w), np.cos(angle), atol=1e-9)
    assert np.isclose(np.sin(w), np.sin(angle), atol=1e-9)
    assert abs(abs(float(wrap_residual(angle))) - abs(w)) < 1e-9 or abs(w) > np.pi - 1e-9
    assert -180 <= float(wrap_to_180(np.rad2deg(angle))) < 180


def test_bearing_convention_clockwise_from_north():
    theta = np.array([[0.0, 1000.0, 0, 0], [1000.0, 0.0, 0, 0], [-1000.0, 0.0, 0, 0]])
    b = np.rad2deg(predicted_bearings(theta, np.array([0.0]), np.zeros(1), np.zeros(1)))[:, 0]
    np.testing.assert_allclose(b, [0.0, 90.0, -90.0])


def _quadrant_case():
    """Own-ship manoeuvring near the origin, one target in each quadrant (NE, SE, SW, NW)
    and bearings missing at random epochs and over the first 100 s of two tracks."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 1201.0, 2.0)
    ox, oy = 3.0 * t, 1000.0 * np.sin(t / 200.0)
    theta = np.array([[15e3, 12e3, -4.0, 3.0], [14e3, -13e3, -2.0, 5.0],
                      [-16e3, -11e3, 6.0, 1.0], [-12e3, 17e3, 3.0, -6.0]])
    measured = predicted_bearings(theta, t, ox, oy) + rng.normal(0, 0.005, (4, t.size))
    valid = rng.random(measured.shape) > 0.3
    valid[1:3, t < 100.0] = False
    return theta, t, ox, oy, measured, valid


def test_masking_a_bearing_equals_deleting_it_in_every_quadrant():
    theta, t, ox, oy, measured, valid = _quadrant_case()
    trial = theta + np.array([300.0, -200.0, 0.5, -0.4])  # away from the minimum: g != 0
    masked = BearingTerms(t, ox, oy, np.where(valid, measured, 0.0), valid)
    F, H, g = masked(trial, np.arange(4))
    for i in range(4):
        keep = valid[i]
        Fd, Hd, gd = BearingTerms(t[keep], ox[keep], oy[keep], measured[i:i + 1, keep], None)(
            trial[i:i + 1], np.array([0]))
        np.testing.assert_allclose(F[i], Fd[0], rtol=1e-12)
        np.testing.assert_allclose(H[i], Hd[0], rtol=1e-12)
        np.testing.assert_allclose(g[i], gd[0], rtol=1e-10)
        np.testing.assert_allclose(F[i], bearing_cost(trial[i:i + 1], t, ox, oy,
                                                      measured[i:i + 1], valid[i:i + 1]),
                                   rtol=1e-12)


@pytest.mark.parametrize("name", ["lm", "nbearings"])
def test_estimates_with_missing_bearings_equal_those_without_them(name):
    theta, t, ox, oy, measured, valid = _quadrant_case()
    bearing_deg = np.where(valid, np.rad2deg(measured) % 360.0, np.nan)
    log = BearingsLog(t_s=t, own_x_m=ox, own_y_m=oy, track_id=np.arange(4),
                      bearing_deg=bearing_deg)
    estimator = build_estimator({"name": name, "initial_bearing_deg": None}
                                if name == "lm" else {"name": name})
    together = estimator.estimate(log)
    for i in range(4):
        keep = valid[i]
        alone = estimator.estimate(BearingsLog(t_s=t[keep], own_x_m=ox[keep], own_y_m=oy[keep],
                                               track_id=np.array([i]),
                                               bearing_deg=bearing_deg[i:i + 1, keep]))
        # equal up to where LM stops (F tolerance 1e-10 rad^2; round-off in the sums differs):
        # within a thousandth of the estimate's own standard deviation
        for column, sd in (("x0_m", "range_sd_m"), ("y0_m", "range_sd_m"),
                           ("vx_m_s", "speed_sd_m_s"), ("vy_m_s", "speed_sd_m_s")):
            assert abs(together[column][i] - alone[column][0]) < 1e-3 * alone[sd][0], column
        # (a recording: lm averages over manoeuvres, each refined until no position moves by
        # more than manoeuvres.REFINE_TOL_M, which the sds follow to about 1e-4)
        for column in ("cost_rad2", "range_sd_m", "course_sd_deg"):
            np.testing.assert_allclose(together[column][i], alone[column][0], rtol=1e-3)
        # nbearings is biased by design: its errors are never honest, so never ok (lm's log
        # is a recording's, whose target may manoeuvre: its heading may not be determined)
        assert together["status"][i] == alone["status"][0]
        assert together["status"][i] in (("ok", "position_only") if estimator.honest_errors
                                         else ("approximate",))
        # the residuals are those of the noise (0.005 rad): no pi^2 of a missing bearing
        assert together["cost_rad2"][i] < 4 * keep.sum() * 0.005**2
