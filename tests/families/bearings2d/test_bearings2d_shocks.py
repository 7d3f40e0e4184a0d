"""``shocks.py`` against the filter it summarises: the Bayes factor of a shock, or of a
changed predicted state, and the state at the last bearing with it, each against a second
Kalman filter run with that shock in its process noise (exact for the linearised bearings)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tma.families.bearings2d import kalman, shocks


def _case(seed=1, K=150, dt=8.0):
    """Own-ship zig-zagging, a target turning halfway, bearings with 0.5 deg noise; the
    linearisation about a trajectory 50 m off the truth."""
    rng = np.random.default_rng(seed)
    t = np.arange(K) * dt
    ox = np.cumsum(np.where((t // 400) % 2 == 0, 3.5, -3.5) * dt)
    oy = t * 3.5
    tx, ty = 8000 + 3.0 * t, 12000 - 2.0 * t
    tx[K // 2:] += 4.0 * (t[K // 2:] - t[K // 2])
    sigma = math.radians(0.5)
    z = np.arctan2(tx - ox, ty - oy) + sigma * rng.standard_normal(K)
    nom = np.column_stack([tx, ty, np.gradient(tx, t), np.gradient(ty, t)]) + 50.0
    return t, ox, oy, z, sigma, nom


def _filter(t, ox, oy, z, sigma, nom, Q):
    K = t.size
    s2 = sigma**2
    out = [np.empty((K, 4)), np.empty((K, 4, 4)), np.empty((K, 4, 4)), np.empty(K),
           np.empty(K)]
    kalman._filter(t, ox, oy, z, np.empty(0), False, 0, K - 1, nom, Q, nom[0].copy(),
                np.array([1e8, 1e4]) / s2, *out)
    mf, Pf, Pp, nu, S = out
    return -0.5 * (nu**2 / (s2 * S) + np.log(S)), mf, Pf, Pp, nu, S


def _base(seed=1):
    t, ox, oy, z, sigma, nom = _case(seed)
    Q = np.zeros((t.size, 3))
    kalman.step_noise(t, 0, t.size - 1, 1e-4 / sigma**2, Q)
    ll, mf, Pf, Pp, nu, S = _filter(t, ox, oy, z, sigma, nom, Q)
    g, G, W = (np.empty((t.size, 4)), np.empty((t.size, 4, 4)), np.empty((t.size, 4, 4)))
    shocks.backward_pass(t, ox, oy, 0, t.size - 1, nom, Pp, nu, S, 1 / sigma, g, G, W)
    return (t, ox, oy, z, sigma, nom, Q), (ll, mf, Pf, Pp), (g, G, W)


@settings(max_examples=25, deadline=None)
@given(k=st.integers(1, 149), dv=st.floats(0.5, 10.0), D=st.floats(10.0, 400.0),
       lag=st.floats(0.0, 20.0))
def test_a_shocks_bayes_factor_and_state_are_the_filters_with_it(k, dv, D, lag):
    (t, ox, oy, z, sigma, nom, Q), (ll, mf, Pf, _), (g, G, W) = _base()
    s2 = sigma**2
    d = np.array([dv**2 * (D**2 / 12 + lag**2), dv**2 * lag, dv**2]) / s2
    mean, cov = np.empty(4), np.empty((4, 4))
    lbf = shocks.shock_posterior(g[k], G[k], d, np.empty((4, 4)), np.empty((4, 5)), mean, cov)
    hi_mean, hi_cov = np.empty(4), np.empty((4, 4))
    shocks.state_with_shock(mf[-1], Pf[-1], W[k], mean, cov, sigma, hi_mean, hi_cov)
    Q2 = Q.copy()
    Q2[k] += d
    ll2, mf2, Pf2, *_ = _filter(t, ox, oy, z, sigma, nom, Q2)
    assert lbf == pytest.approx(ll2.sum() - ll.sum(), abs=1e-6)
    np.testing.assert_allclose(hi_mean, mf2[-1], atol=1e-6 * np.sqrt(Pf2[-1].diagonal().max()
                                                                      * s2))
    np.testing.assert_allclose(hi_cov, Pf2[-1], rtol=1e-8, atol=1e-10 * np.abs(Pf2[-1]).max())


@pytest.mark.parametrize("k1, k2, burst", [(30, 45, 21 / 120), (70, 90, 21 / 120),
                                           (5, 20, 5 / 120), (140, 149, 10 / 60)])
def test_a_changed_predicted_state_is_the_filters_with_it(k1, k2, burst):
    """A burst over k1..k2 filtered alone, the bearings after it through the backward pass
    (``shift_posterior``): its Bayes factor and the state at the last bearing are those of a
    whole second filter."""
    (t, ox, oy, z, sigma, nom, Q), (ll, mf, Pf, Pp), (g, G, W) = _base()
    s2 = sigma**2
    Q2 = Q.copy()
    T = np.diff(t)[k1 - 1:k2]
    lam = 1e-4 / s2 + burst / s2
    Q2[k1:k2 + 1] = np.column_stack([lam * T**3 / 3, lam * T**2 / 2, lam * T])
    ll2, mf2, Pf2, *_ = _filter(t, ox, oy, z, sigma, nom, Q2)
    K = t.size
    part = [np.empty((K, 4)), np.empty((K, 4, 4)), np.empty((K, 4, 4)), np.empty(K),
            np.empty(K)]
    m, P = mf[k1 - 1].copy(), Pf[k1 - 1].copy()
    kalman.filter_on(t, ox, oy, z, np.empty(0), False, k1, k2, nom, Q2, m, P, *part)
    nu, S = part[3][k1:k2 + 1], part[4][k1:k2 + 1]
    lbf = -0.5 * np.sum(nu**2 / (s2 * S) + np.log(S)) - ll[k1:k2 + 1].sum()
    if k2 == K - 1:
        hi_mean, hi_cov = m, P
    else:
        mp, Pn, mb, Pb = np.empty(4), np.empty((4, 4)), np.empty(4), np.empty((4, 4))
        T = t[k2 + 1] - t[k2]
        kalman._predict(m.copy(), P.copy(), T, Q[k2 + 1], mp, Pn)
        kalman._predict(mf[k2].copy(), Pf[k2].copy(), T, Q[k2 + 1], mb, Pb)
        np.testing.assert_allclose(Pb, Pp[k2 + 1])
        mean, cov = np.empty(4), np.empty((4, 4))
        lbf += shocks.shift_posterior(g[k2 + 1], G[k2 + 1], (mp - mb) / sigma, Pn - Pb,
                                      np.empty((4, 4)), np.empty((4, 5)), mean, cov)
        hi_mean = mf[-1] + W[k2 + 1] @ mean * sigma
        hi_cov = Pf[-1] + W[k2 + 1] @ cov @ W[k2 + 1].T
    assert lbf == pytest.approx(ll2.sum() - ll.sum(), abs=1e-6)
    np.testing.assert_allclose(hi_mean, mf2[-1], atol=1e-3)
    np.testing.assert_allclose(hi_cov, Pf2[-1], rtol=1e-7, atol=1e-10 * np.abs(Pf2[-1]).max())


def test_a_shock_no_bearing_sees_is_its_prior():
    """No bearing after the shock (score and information zero): Bayes factor 1, and the
    shock's posterior is its prior."""
    d = np.array([4.0, 1.0, 2.0])
    mean, cov = np.empty(4), np.empty((4, 4))
    lbf = shocks.shock_posterior(np.zeros(4), np.zeros((4, 4)), d, np.empty((4, 4)),
                                 np.empty((4, 5)), mean, cov)
    assert lbf == 0.0
    np.testing.assert_array_equal(mean, 0.0)
    np.testing.assert_allclose(cov, [[4, 0, 1, 0], [0, 4, 0, 1], [1, 0, 2, 0], [0, 1, 0, 2]])
