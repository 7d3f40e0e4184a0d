"""The extended Kalman filter and smoother of a nearly-constant-velocity target over its
bearings (``ncv.py`` states the model), compiled, in units of the bearing noise: the
per-step process noise, the predict and update steps, the filter linearised about a nominal
trajectory, the Rauch-Tung-Striebel smoother and the smoothed positions' covariances, the
bearings' and the maximum a posteriori costs, and the Gauss-Newton passes of the iterated
Kalman smoother (Bell, SIAM J. Optim. 4(3), 1994) that find the MAP trajectory."""

import math

import numpy as np

from tma.families.bearings2d.model import atan2
from tma.maths.angles import wrap_angle
from tma.runtime.jit import njit

STEP_HALVINGS = 8  # halvings of a Gauss-Newton step whose MAP cost does not fall

@njit(error_model="numpy")
def step_noise(t, lo, hi, lam, Q):
    """``Q[k]`` = lam Q1(t_k - t_(k-1)) per axis, (q_pp, q_pv, q_vv) = lam (T^3 / 3, T^2 / 2,
    T), for the steps into epochs lo + 1..hi (``Q[lo]``: none): white acceleration of
    level ``lam`` (units of the noise variance)."""
    for j in range(3):
        Q[lo, j] = 0.0
    for k in range(lo + 1, hi + 1):
        white_step(lam, t[k] - t[k - 1], Q[k])


@njit(error_model="numpy")
def white_step(lam, T, Qk):
    """``Qk`` = lam (T^3 / 3, T^2 / 2, T): white acceleration of level ``lam`` over a step
    of ``T`` seconds, per axis (q_pp, q_pv, q_vv)."""
    Qk[0] = lam * T * T * T / 3.0
    Qk[1] = lam * T * T / 2.0
    Qk[2] = lam * T


@njit(error_model="numpy")
def _predict(m, P, T, Qk, mp, Pp):
    """mp = F m, Pp = F P F^T + Q for the 4-state (x, y, vx, vy), Q per axis the 2 x 2
    ``Qk`` = (q_pp, q_pv, q_vv) of the step (``step_noise``)."""
    mp[0] = m[0] + T * m[2]
    mp[1] = m[1] + T * m[3]
    mp[2] = m[2]
    mp[3] = m[3]
    # F P F^T with F = [[I, T I], [0, I]] written out
    for i in range(4):
        for j in range(4):
            Pp[i, j] = P[i, j]
    for j in range(4):  # rows: P' = F P
        Pp[0, j] += T * P[2, j]
        Pp[1, j] += T * P[3, j]
    for i in range(4):  # columns: (F P) F^T
        Pp[i, 0] += T * Pp[i, 2]
        Pp[i, 1] += T * Pp[i, 3]
    q3, q2, q1 = Qk[0], Qk[1], Qk[2]
    Pp[0, 0] += q3
    Pp[1, 1] += q3
    Pp[0, 2] += q2
    Pp[2, 0] += q2
    Pp[1, 3] += q2
    Pp[3, 1] += q2
    Pp[2, 2] += q1
    Pp[3, 3] += q1


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def _update(m, P, z, nom, ox, oy, h, kg, tmp, A):
    """Kalman update of (m, P) with the bearing z (rad) linearised about ``nom`` (R = 1,
    Joseph form; ``h``, ``kg``, ``tmp``, ``A``: work arrays); returns (nu, S). Written out
    for a bearing's row, two nonzeros, in the innermost loop of the manoeuvre mixture: the
    other filters' updates (mpekf, imm, ekf, srekf) differ in their rows and forms."""
    dx, dy = nom[0] - ox, nom[1] - oy
    inv_r2 = 1.0 / (dx * dx + dy * dy)
    h[0], h[1] = dy * inv_r2, -dx * inv_r2
    r = wrap_angle(z - atan2(dx, dy))  # wrap(z - h(nom)) - H (m - nom)
    nu = r - h[0] * (m[0] - nom[0]) - h[1] * (m[1] - nom[1])
    S = 1.0
    for i in range(4):
        tmp[i] = P[i, 0] * h[0] + P[i, 1] * h[1]  # P H^T
    S += h[0] * tmp[0] + h[1] * tmp[1]
    for i in range(4):
        kg[i] = tmp[i] / S
        m[i] += kg[i] * nu
    # Joseph: (I - K H) P (I - K H)^T + K K^T; A = (I - K H) P first
    for i in range(4):
        for j in range(4):
            A[i, j] = P[i, j] - kg[i] * (h[0] * P[0, j] + h[1] * P[1, j])
    for i in range(4):
        for j in range(4):
            P[i, j] = (A[i, j] - (A[i, 0] * h[0] + A[i, 1] * h[1]) * kg[j]) + kg[i] * kg[j]
    for i in range(4):
        for j in range(i):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v
    return nu, S


@njit(error_model="numpy")
def _chol_solve(A, b, L, y):
    """Solve A y = b for symmetric positive definite 4x4 ``A`` (Cholesky into ``L``);
    False when A is not positive definite."""
    for i in range(4):
        for j in range(i + 1):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if not s > 0.0:
                    return False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    for i in range(4):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    for i in range(3, -1, -1):
        s = y[i]
        for k in range(i + 1, 4):
            s -= L[k, i] * y[k]
        y[i] = s / L[i, i]
    return True


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def filter_on(t, ox, oy, z, w, weighted, k0, hi, nom, Q, m, P, mf, Pf, Pp, nu, S):
    """The Kalman filter of ``_filter`` over epochs k0..hi from the state (``m``, ``P``:
    updated in place) filtered at k0 - 1 (predicted into k0 first) or, with k0 < 1, from
    the prediction at k0 = -k0 itself. Writes mf, Pf, Pp, nu, S over those epochs."""
    mp = np.empty(4)
    h, kg, tmp, A = np.zeros(4), np.empty(4), np.empty(4), np.empty((4, 4))
    first = -k0 if k0 < 1 else k0
    for i in range(4):
        for j in range(4):
            Pp[first, i, j] = P[i, j]
    for k in range(first, hi + 1):
        if k > first or k0 >= 1:
            _predict(m, P, t[k] - t[k - 1], Q[k], mp, Pp[k])
            for i in range(4):
                m[i] = mp[i]
                for j in range(4):
                    P[i, j] = Pp[k, i, j]
        if (not weighted) or w[k] > 0.0:
            nu[k], S[k] = _update(m, P, z[k], nom[k], ox[k], oy[k], h, kg, tmp, A)
        else:
            nu[k], S[k] = np.nan, np.nan
        for i in range(4):
            mf[k, i] = m[i]
            for j in range(4):
                Pf[k, i, j] = P[i, j]


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def _filter(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf, Pp, nu, S):
    """Kalman filter over epochs lo..hi linearised about ``nom`` (K, 4); filtered means and
    covariances, predicted covariances (index k: the prediction into k; at lo the prior's)
    and the innovations (NaN where no bearing). ``Q`` (K, 3): the process noise of the step
    into each epoch (``Q[k]``: from k - 1 to k, ``step_noise``); ``p0``: the diffuse prior's
    (position, velocity) variances about ``prior`` (4,)."""
    m, P = np.empty(4), np.zeros((4, 4))
    for i in range(4):
        m[i] = prior[i]
    P[0, 0] = P[1, 1] = p0[0]
    P[2, 2] = P[3, 3] = p0[1]
    filter_on(t, ox, oy, z, w, weighted, -lo, hi, nom, Q, m, P, mf, Pf, Pp, nu, S)


@njit(error_model="numpy")
def _smooth(t, lo, hi, mf, Pf, Pp, ms):
    """Rauch-Tung-Striebel means: ms_k = mf_k + Pf_k F^T Pp_{k+1}^-1 (ms_{k+1} - F mf_k).
    False when a predicted covariance is not positive definite."""
    d, y, L = np.empty(4), np.empty(4), np.empty((4, 4))
    for i in range(4):
        ms[hi, i] = mf[hi, i]
    for k in range(hi - 1, lo - 1, -1):
        T = t[k + 1] - t[k]
        d[0] = ms[k + 1, 0] - (mf[k, 0] + T * mf[k, 2])
        d[1] = ms[k + 1, 1] - (mf[k, 1] + T * mf[k, 3])
        d[2] = ms[k + 1, 2] - mf[k, 2]
        d[3] = ms[k + 1, 3] - mf[k, 3]
        if not _chol_solve(Pp[k + 1], d, L, y):
            return False
        # F^T y = (y0, y1, T y0 + y2, T y1 + y3)
        f0, f1, f2, f3 = y[0], y[1], T * y[0] + y[2], T * y[1] + y[3]
        for i in range(4):
            ms[k, i] = mf[k, i] + Pf[k, i, 0] * f0 + Pf[k, i, 1] * f1 + Pf[k, i, 2] * f2 \
                + Pf[k, i, 3] * f3
    return True


@njit(error_model="numpy", depends=(_filter, _chol_solve))
def smoothed_positions(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf, Pp,
                       nu, S, path, path_cov):
    """Write the positions of the trajectory ``nom`` (its MAP, m) into ``path[i]`` (K, 2) and,
    where ``path_cov`` has epochs (n, K, 3; none: only the positions), their smoothed
    covariances about it (x x, x y, y y, units of s^2): the Kalman filter linearised about
    ``nom`` under the same process noise ``Q`` and prior as the fit, then the
    Rauch-Tung-Striebel recursion P_k = Pf_k + C_k (P_(k+1) - Pp_(k+1)) C_k^T,
    C_k = Pf_k F^T Pp_(k+1)^-1 (Bar-Shalom, Li and Kirubarajan 2001, sec. 8.6): the
    linearised posterior of each epoch's position given every bearing. NaN where a predicted
    covariance is not positive definite. ``mf``..``S``: the filter's scratch. (Not P - P N P
    from ``shocks.backward_pass``: under the diffuse prior the early predicted covariances
    exceed the posterior's by ten orders, and the difference cancels to noise.)"""
    for k in range(lo, hi + 1):
        path[i, k, 0], path[i, k, 1] = nom[k, 0], nom[k, 1]
    if path_cov.shape[1] == 0:
        return
    _filter(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf, Pp, nu, S)
    Ps, D, B, G, L, col, y = (np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)),
                              np.empty((4, 4)), np.empty((4, 4)), np.empty(4), np.empty(4))
    for a in range(4):
        for b in range(4):
            Ps[a, b] = Pf[hi, a, b]
    path_cov[i, hi, 0], path_cov[i, hi, 1], path_cov[i, hi, 2] = Ps[0, 0], Ps[0, 1], Ps[1, 1]
    for k in range(hi - 1, lo - 1, -1):
        T = t[k + 1] - t[k]
        for b in range(4):  # B = F Pf_k (F = [[I, T I], [0, I]])
            B[0, b] = Pf[k, 0, b] + T * Pf[k, 2, b]
            B[1, b] = Pf[k, 1, b] + T * Pf[k, 3, b]
            B[2, b] = Pf[k, 2, b]
            B[3, b] = Pf[k, 3, b]
        for b in range(4):  # C_k^T = Pp_(k+1)^-1 F Pf_k, column by column
            for a in range(4):
                col[a] = B[a, b]
            if not _chol_solve(Pp[k + 1], col, L, y):
                for kk in range(lo, k + 1):
                    for j in range(3):
                        path_cov[i, kk, j] = np.nan
                return
            for a in range(4):
                G[b, a] = y[a]  # G = C_k
        for a in range(4):
            for b in range(4):
                D[a, b] = Ps[a, b] - Pp[k + 1, a, b]
        for a in range(4):  # Ps = Pf_k + G D G^T
            for b in range(4):
                v = 0.0
                for c in range(4):
                    gd = 0.0
                    for e in range(4):
                        gd += G[a, e] * D[e, c]
                    v += gd * G[b, c]
                B[a, b] = Pf[k, a, b] + v
        for a in range(4):
            for b in range(4):
                Ps[a, b] = 0.5 * (B[a, b] + B[b, a])
        path_cov[i, k, 0], path_cov[i, k, 1], path_cov[i, k, 2] = Ps[0, 0], Ps[0, 1], Ps[1, 1]


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def _bearing_cost(ox, oy, z, w, weighted, lo, hi, s):
    """Sum of squared wrapped bearing residuals (rad^2) of the trajectory ``s`` (K, 4)."""
    c = 0.0
    for k in range(lo, hi + 1):
        if (not weighted) or w[k] > 0.0:
            r = wrap_angle(z[k] - atan2(s[k, 0] - ox[k], s[k, 1] - oy[k]))
            c += r * r
    return c


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def _map_cost(t, ox, oy, z, w, weighted, lo, hi, s, Q, prior, p0):
    """MAP cost (units of sigma^2): squared bearing residuals, the process term of each
    step with noise ``Q[k]`` (K, 3: the step into epoch k; none where zero) and the diffuse
    prior about ``prior`` (4,)."""
    c = _bearing_cost(ox, oy, z, w, weighted, lo, hi, s)
    for k in range(lo, hi):
        q11, q12, q22 = Q[k + 1, 0], Q[k + 1, 1], Q[k + 1, 2]
        det = q11 * q22 - q12 * q12
        if q11 > 0.0 and det > 0.0:
            T = t[k + 1] - t[k]
            a11, a12, a22 = q22 / det, -q12 / det, q11 / det  # the 2 x 2 inverse
            for axis in range(2):
                dp = s[k + 1, axis] - s[k, axis] - T * s[k, axis + 2]
                dv = s[k + 1, axis + 2] - s[k, axis + 2]
                c += a11 * dp * dp + 2.0 * a12 * dp * dv + a22 * dv * dv
    for i in range(4):
        e = s[lo, i] - prior[i]
        c += e * e / p0[0 if i < 2 else 1]
    return c


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def _fit(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, max_iter, tol_m, mf, Pf,
         Pp, nu, S, ms, trial):
    """Gauss-Newton (iterated smoother) from ``nom`` (K, 4, updated in place to the MAP
    trajectory) under the process noise ``Q`` (K, 3) and the diffuse prior about ``prior``
    (4,) at epoch lo; returns the passes made (-1: a covariance was not positive
    definite)."""
    cost = _map_cost(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0)
    passes = 0
    for _ in range(max_iter):
        _filter(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf, Pp, nu, S)
        passes += 1
        if not _smooth(t, lo, hi, mf, Pf, Pp, ms):
            return -1
        step = 1.0
        accepted = False
        for _h in range(STEP_HALVINGS + 1):
            for k in range(lo, hi + 1):
                for i in range(4):
                    trial[k, i] = nom[k, i] + step * (ms[k, i] - nom[k, i])
            new = _map_cost(t, ox, oy, z, w, weighted, lo, hi, trial, Q, prior, p0)
            if new <= cost:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        change = 0.0
        for k in range(lo, hi + 1):
            for i in range(2):
                change = max(change, abs(trial[k, i] - nom[k, i]))
            for i in range(4):
                nom[k, i] = trial[k, i]
        cost = new
        if change <= tol_m:
            break
    return passes
