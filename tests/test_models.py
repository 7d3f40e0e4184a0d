"""The bearings model: analytic Jacobian vs finite differences, normal equations, wrapping."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tma.angles import wrap_to_180, wrap_to_pi
from tma.models.bearings2d import (
    bearing_jacobian,
    bearing_residuals,
    normal_equations,
    predicted_bearings,
    wrap_residual,
)


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
