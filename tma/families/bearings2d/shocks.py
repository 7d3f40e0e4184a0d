"""What the bearings say about a sudden change of the target's state at any epoch, for every
epoch at once: one backward pass after a Kalman filter (``kalman._filter``).

A shock is an extra N(0, Delta) added to the predicted state at epoch k (per axis Delta =
(d_pp, d_pv, d_vv): position, cross term, velocity; the order of the state is (x, y, vx,
vy)). For the bearings linearised about the filter's trajectory the log-likelihood of a
fixed shift u of that state is exactly quadratic, g_k^T u - 1/2 u^T G_k u, with the score
g_k and information G_k of the backward recursion of de Jong ("Smoothing and interpolation
with the state-space model", JASA 84(408), 1989: r_(k-1), N_(k-1)); de Jong and Penzer
("Diagnosing shocks in time series", JASA 93(442), 1998) test shocks with them. So, with no
further filter pass:

- the Bayes factor of the shock: |I + G Delta|^(-1/2) exp(1/2 g^T Delta (I + G Delta)^-1 g);
- the shock's posterior: mean Delta (I + G Delta)^-1 g, covariance Delta (I + G Delta)^-1;
- the state at the last epoch, hi: the filter's mean plus W_k times the shock's posterior
  mean, its covariance plus W_k (shock's covariance) W_k^T, where W_k is the sensitivity of
  the filtered state at hi to a shift of the predicted state at k (W_hi = I - K_hi h^T,
  W_k = W_(k+1) F (I - K_k h^T)).

Everything is in the filter's units: covariances over the noise variance s^2, innovations
over s (``inv_s``).
"""

import math

import numpy as np

from tma.runtime.jit import njit


@njit(error_model="numpy")
def backward_pass(t, ox, oy, lo, hi, nom, Pp, nu, S, inv_s, g, G, W):
    """After ``kalman._filter`` over lo..hi about ``nom`` (predicted covariances ``Pp``,
    innovations ``nu`` in rad, NaN where no bearing, and their variances ``S``): for each
    epoch k the score ``g[k]`` (4,), information ``G[k]`` (4, 4) and sensitivity ``W[k]``
    (4, 4) of the module docstring (``inv_s``: 1 / s, rad^-1)."""
    a, B, h, Kg, C, WF = (np.empty(4), np.empty((4, 4)), np.empty(4), np.empty(4),
                          np.empty((4, 4)), np.empty((4, 4)))
    for k in range(hi, lo - 1, -1):
        if k == hi:
            for i in range(4):
                a[i] = 0.0
                for j in range(4):
                    B[i, j] = 0.0
                    WF[i, j] = 1.0 if i == j else 0.0
        else:  # a = F^T g_(k+1), B = F^T G_(k+1) F, WF = W_(k+1) F; F = [[I, T I], [0, I]]
            T = t[k + 1] - t[k]
            a[0], a[1] = g[k + 1, 0], g[k + 1, 1]
            a[2], a[3] = T * g[k + 1, 0] + g[k + 1, 2], T * g[k + 1, 1] + g[k + 1, 3]
            for i in range(4):
                for j in range(4):
                    B[i, j] = G[k + 1, i, j]
                    WF[i, j] = W[k + 1, i, j]
            for i in range(4):
                B[2, i] += T * B[0, i]
                B[3, i] += T * B[1, i]
            for i in range(4):
                B[i, 2] += T * B[i, 0]
                B[i, 3] += T * B[i, 1]
                WF[i, 2] += T * WF[i, 0]
                WF[i, 3] += T * WF[i, 1]
        if not nu[k] == nu[k]:  # no bearing at k
            for i in range(4):
                g[k, i] = a[i]
                for j in range(4):
                    G[k, i, j] = B[i, j]
                    W[k, i, j] = WF[i, j]
            continue
        dx, dy = nom[k, 0] - ox[k], nom[k, 1] - oy[k]
        inv_r2 = 1.0 / (dx * dx + dy * dy)
        h[0], h[1], h[2], h[3] = dy * inv_r2, -dx * inv_r2, 0.0, 0.0
        for i in range(4):
            Kg[i] = (Pp[k, i, 0] * h[0] + Pp[k, i, 1] * h[1]) / S[k]
        ka = 0.0
        for i in range(4):
            ka += Kg[i] * a[i]
        for i in range(4):
            g[k, i] = h[i] * nu[k] * inv_s / S[k] + a[i] - h[i] * ka
        # C = B (I - K h^T); G_k = (I - h K^T) C + h h^T / S; W_k = WF (I - K h^T)
        for i in range(4):
            bk, wk = 0.0, 0.0
            for j in range(4):
                bk += B[i, j] * Kg[j]
                wk += WF[i, j] * Kg[j]
            for j in range(4):
                C[i, j] = B[i, j] - bk * h[j]
                W[k, i, j] = WF[i, j] - wk * h[j]
        for j in range(4):
            kc = 0.0
            for i in range(4):
                kc += Kg[i] * C[i, j]
            for i in range(4):
                G[k, i, j] = C[i, j] - h[i] * kc + h[i] * h[j] / S[k]
        for i in range(4):
            for j in range(i):
                v = 0.5 * (G[k, i, j] + G[k, j, i])
                G[k, i, j] = v
                G[k, j, i] = v


@njit(error_model="numpy")
def shift_posterior(g, G, delta0, Delta, A, rhs, mean, cov):
    """A change of the predicted state's distribution from N(m, P) to N(m + ``delta0``,
    P + ``Delta``) (``Delta`` (4, 4) any symmetric matrix that keeps P + Delta positive,
    ``delta0`` in units of s): the log Bayes factor of the bearings that the score ``g``
    and information ``G`` summarise, g^T d - 1/2 d^T G d - 1/2 log|I + G Delta| + 1/2 g'^T
    Delta (I + G Delta)^-1 g' with g' = g - G d, d = ``delta0``; and the shift's posterior
    (``mean``, units of s; ``cov``, units of s^2), d + Delta (I + G Delta)^-1 g' and
    Delta (I + G Delta)^-1. -inf where I + G Delta is not positive (numerically)."""
    gp = np.empty(4)
    lin = 0.0
    for i in range(4):
        v = 0.0
        for j in range(4):
            v += G[i, j] * delta0[j]
        gp[i] = g[i] - v
        lin += g[i] * delta0[i] - 0.5 * delta0[i] * v
    for i in range(4):
        for j in range(4):
            v = 0.0
            for m in range(4):
                v += G[i, m] * Delta[m, j]
            A[i, j] = v + (1.0 if i == j else 0.0)
            rhs[i, j] = 1.0 if i == j else 0.0
        rhs[i, 4] = gp[i]
    logdet, sign = 0.0, 1.0  # LU with partial pivoting: A X = [I | g']
    for c in range(4):
        p, best = c, abs(A[c, c])
        for r in range(c + 1, 4):
            if abs(A[r, c]) > best:
                p, best = r, abs(A[r, c])
        if not best > 0.0:
            return -np.inf
        if p != c:
            sign = -sign
            for j in range(4):
                A[c, j], A[p, j] = A[p, j], A[c, j]
            for j in range(5):
                rhs[c, j], rhs[p, j] = rhs[p, j], rhs[c, j]
        if A[c, c] < 0.0:
            sign = -sign
        logdet += math.log(abs(A[c, c]))
        for r in range(c + 1, 4):
            f = A[r, c] / A[c, c]
            for j in range(c, 4):
                A[r, j] -= f * A[c, j]
            for j in range(5):
                rhs[r, j] -= f * rhs[c, j]
    if sign < 0.0:
        return -np.inf
    for c in range(3, -1, -1):
        for j in range(5):
            v = rhs[c, j]
            for m in range(c + 1, 4):
                v -= A[c, m] * rhs[m, j]
            rhs[c, j] = v / A[c, c]
    quad = 0.0
    for i in range(4):
        for j in range(5):
            v = 0.0
            for m in range(4):
                v += Delta[i, m] * rhs[m, j]
            if j == 4:
                mean[i] = delta0[i] + v
                quad += gp[i] * v
            else:
                cov[i, j] = v
    for i in range(4):
        for j in range(i):
            v = 0.5 * (cov[i, j] + cov[j, i])
            cov[i, j] = v
            cov[j, i] = v
    return lin - 0.5 * logdet + 0.5 * quad


@njit(error_model="numpy")
def shock_posterior(g, G, d, A, rhs, mean, cov):
    """The shock of covariance Delta (per axis ``d``) on a state of score ``g`` and
    information ``G`` (``backward_pass``): returns the log Bayes factor (-inf where
    I + G Delta is not positive, numerically) and writes the shock's posterior ``mean`` (4,;
    in units of s: times s for metres) and ``cov`` (4, 4; units of s^2). ``A`` (4, 4),
    ``rhs`` (4, 5): work arrays. (``shift_posterior`` with no mean shift.)"""
    Delta = np.zeros((4, 4))
    for a in range(2):  # Delta = [[d_pp I, d_pv I], [d_pv I, d_vv I]]
        Delta[a, a], Delta[a, a + 2] = d[0], d[1]
        Delta[a + 2, a], Delta[a + 2, a + 2] = d[1], d[2]
    return shift_posterior(g, G, np.zeros(4), Delta, A, rhs, mean, cov)


@njit(error_model="numpy")
def state_with_shock(m_hi, P_hi, Wk, mean, cov, s, out_mean, out_cov):
    """The state at the last epoch given a shock at k: ``m_hi`` + ``Wk`` (s ``mean``) (m,
    m/s) and ``P_hi`` + ``Wk`` ``cov`` ``Wk``^T (units of s^2)."""
    for i in range(4):
        v = m_hi[i]
        for j in range(4):
            v += Wk[i, j] * mean[j] * s
        out_mean[i] = v
    for i in range(4):
        for j in range(4):
            v = P_hi[i, j]
            for a in range(4):
                wa = Wk[i, a]
                if wa == 0.0:
                    continue
                for b in range(4):
                    v += wa * cov[a, b] * Wk[j, b]
            out_cov[i, j] = v
