"""A nearly-constant-velocity (NCV) target seen through bearings: the batch estimate of its
state now, with one-sigma errors that include the target's unmodelled motion.

Motion model (Bar-Shalom, Li and Kirubarajan, "Estimation with Applications to Tracking and
Navigation", Wiley 2001, sec. 6.2.2, the "continuous white noise acceleration" model): per
axis, position and velocity driven by white acceleration of power spectral density q
(m^2/s^3), so that over T seconds

    F = [[1, T], [0, 1]],  Q = q [[T^3 / 3, T^2 / 2], [T^2 / 2, T]].

q = 0 is the constant-velocity target of ``model.py``; a real ship wanders off a straight
line by about sqrt(q T^3 / 3) metres over T seconds.

State s_k = (x, y, vx, vy) at each bearing epoch (m, m/s; x east, y north). The estimate is
the maximum a posteriori trajectory given the bearings (noise sigma) and the NCV prior,
found by Gauss-Newton from a constant-velocity solution: the iterated extended Kalman
smoother (Bell, "The iterated Kalman smoother as a Gauss-Newton method", SIAM J. Optim.
4(3), 1994), each pass a Kalman filter linearised about the current trajectory and a
Rauch-Tung-Striebel smoother, with a step halved until the MAP cost falls. These passes
give the first state a wide prior about the constant-velocity start (``PRIOR_RANGES``
times its range, ``PRIOR_SPEED_M_S`` per velocity axis), kept fixed over the passes and in
the cost, so little that the answer is the bearings' and q's.

About the MAP trajectory a last pass, a square-root information filter started from no
information at all (exactly diffuse: Bierman, "Factorization Methods for Discrete
Sequential Estimation", Academic Press 1977), gives the state at the track's last bearing
and its covariance (at the last epoch the smoother is the filter), and the innovations nu_k
with their variances S_k. Under the model e_k = nu_k / sqrt(S_k) are independent N(0, 1)
(with q = 0 they are the recursive residuals of Brown, Durbin and Evans, "Techniques for
testing the constancy of regression relationships over time", JRSS B 37(2), 1975): the
sequence the fit tests read (``status``). The few that resolve a direction the earlier
bearings left undetermined (the diffuse ones, about one per state dimension: S above
``MAX_S`` in a pass with q = 0, since process noise does not change which they are) are
left out. A covariance-form pass would not do: a prior centred on the
answer, however wide, shrinks the early innovations and makes the sequence look smoother
than white (the trend test then rejects at a third of its level).

Everything runs in units of the bearing noise: R = 1, Q = (q / sigma^2) Q1, covariances
divided by sigma^2. With sigma unknown it is estimated from the innovations and the fit
repeated with it.

q is not estimated from the bearings: measured on simulated NCV targets, the likelihood of
q of one track is nearly flat over two decades (the target's wander trades against its
range), and a q fitted to a manoeuvre absorbs it and hides it from the trend test. It is
declared (a simulation knows it), set (``estimator.accel_psd_m2_s3``) or, for a recorded
log, a value measured on real ships (``RECORDED_ACCEL_PSD``).
"""

import math

import numpy as np

from tma.families.bearings2d.model import atan2, bearing_residuals
from tma.maths.angles import wrap_angle
from tma.runtime.jit import njit

MAX_S = 1e4  # an innovation variance (in noise variances) above this: a diffuse one
# q (m^2/s^3) for a log that declares none (a recording): the Solent AIS tracks of
# tests/data/ais fitted from their positions give 1e-4..2e-3 for vessels holding course and
# speed (harbour traffic; ocean-going ships are steadier, and this is then conservative)
RECORDED_ACCEL_PSD = 1e-3
PRIOR_RANGES = 10.0  # prior position sd: this many times the start's range (diffuse)
PRIOR_SPEED_M_S = 100.0  # prior velocity sd per axis (diffuse for ships)
MIN_PRIOR_M = 1000.0  # prior position sd at least this
STEP_HALVINGS = 8  # halvings of a Gauss-Newton step whose MAP cost does not fall


@njit(error_model="numpy")
def step_noise(t, lo, hi, lam, Q):
    """``Q[k]`` = lam Q1(t_k - t_(k-1)) per axis, (q_pp, q_pv, q_vv) = lam (T^3 / 3, T^2 / 2,
    T), for the steps into epochs lo + 1..hi (``Q[lo]``: none): white acceleration of
    level ``lam`` (units of the noise variance)."""
    for j in range(3):
        Q[lo, j] = 0.0
    for k in range(lo + 1, hi + 1):
        T = t[k] - t[k - 1]
        Q[k, 0] = lam * T * T * T / 3.0
        Q[k, 1] = lam * T * T / 2.0
        Q[k, 2] = lam * T


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


@njit(error_model="numpy")
def _householder(A, rows, cols):
    """Upper-triangularise the leading ``rows`` x ``cols`` block of ``A`` in place by
    Householder reflections applied to every column of A (the right-hand side too)."""
    ncol = A.shape[1]
    for j in range(min(rows, cols)):
        norm = 0.0
        for i in range(j, rows):
            norm += A[i, j] * A[i, j]
        norm = math.sqrt(norm)
        if norm == 0.0:
            continue
        alpha = -norm if A[j, j] > 0.0 else norm
        v0 = A[j, j] - alpha
        vnorm2 = v0 * v0
        for i in range(j + 1, rows):
            vnorm2 += A[i, j] * A[i, j]
        if vnorm2 == 0.0:
            continue
        for c in range(j + 1, ncol):
            dot = v0 * A[j, c]
            for i in range(j + 1, rows):
                dot += A[i, j] * A[i, c]
            f = 2.0 * dot / vnorm2
            A[j, c] -= f * v0
            for i in range(j + 1, rows):
                A[i, c] -= f * A[i, j]
        A[j, j] = alpha
        for i in range(j + 1, rows):
            A[i, j] = 0.0


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def _srif(t, ox, oy, z, w, weighted, lo, hi, nom, Q, e, S, R, r):
    """Square-root information filter (Bierman, "Factorization Methods for Discrete
    Sequential Estimation", 1977) over epochs lo..hi, linearised about ``nom``, from no
    prior information at all (exactly diffuse), R = 1, process noise ``Q[k]`` (K, 3) on the
    step into epoch k. Writes the standardised
    innovations ``e`` and their variances ``S`` (inf for a bearing that brought a direction
    the earlier ones left undetermined; NaN where no bearing) and leaves the information
    array (R upper triangular, r) of the last epoch: P = R^-1 R^-T, state R^-1 r.

    A bearing's row [h, z~] is rotated into [R, r] (Givens); its last element is then the
    innovation over sqrt(S) and the product of the rotations' cosines is 1 / sqrt(S) (the
    conversion factor of QR least squares)."""
    A = np.zeros((8, 9))
    row = np.empty(5)
    for i in range(4):
        r[i] = 0.0
        for j in range(4):
            R[i, j] = 0.0
    for k in range(lo, hi + 1):
        if k > lo:
            T = t[k] - t[k - 1]
            # R F^-1: columns 2, 3 take -T times columns 0, 1 (stays upper triangular)
            for i in range(4):
                R[i, 2] -= T * R[i, 0]
                R[i, 3] -= T * R[i, 1]
            if Q[k, 0] > 0.0:
                # x = F^-1 (x' - L u), u ~ N(0, I): rows [I, 0 | 0] and
                # [-R F^-1 L, R F^-1 | r] in the unknowns (u, x'), triangularised
                l11 = math.sqrt(Q[k, 0])
                l21 = Q[k, 1] / l11
                l22 = math.sqrt(max(Q[k, 2] - l21 * l21, 0.0))
                for i in range(8):
                    for j in range(9):
                        A[i, j] = 0.0
                for i in range(4):
                    A[i, i] = 1.0
                    # L is [[l11 I, 0], [l21 I, l22 I]] in the order (x, y, vx, vy)
                    A[4 + i, 0] = -(R[i, 0] * l11 + R[i, 2] * l21)
                    A[4 + i, 1] = -(R[i, 1] * l11 + R[i, 3] * l21)
                    A[4 + i, 2] = -R[i, 2] * l22
                    A[4 + i, 3] = -R[i, 3] * l22
                    for j in range(4):
                        A[4 + i, 4 + j] = R[i, j]
                    A[4 + i, 8] = r[i]
                _householder(A, 8, 8)
                for i in range(4):
                    r[i] = A[4 + i, 8]
                    for j in range(4):
                        R[i, j] = A[4 + i, 4 + j]
        if weighted and not w[k] > 0.0:
            e[k], S[k] = np.nan, np.nan
            continue
        dx, dy = nom[k, 0] - ox[k], nom[k, 1] - oy[k]
        inv_r2 = 1.0 / (dx * dx + dy * dy)
        res = wrap_angle(z[k] - atan2(dx, dy))
        row[0], row[1], row[2], row[3] = dy * inv_r2, -dx * inv_r2, 0.0, 0.0
        row[4] = res + row[0] * nom[k, 0] + row[1] * nom[k, 1]
        gamma = 1.0
        for j in range(4):
            if row[j] == 0.0:
                continue
            rho = math.hypot(R[j, j], row[j])
            c, s = R[j, j] / rho, row[j] / rho
            for col in range(j, 4):
                a, b = R[j, col], row[col]
                R[j, col] = c * a + s * b
                row[col] = c * b - s * a
            a, b = r[j], row[4]
            r[j] = c * a + s * b
            row[4] = c * b - s * a
            gamma *= c
        if gamma != 0.0:
            e[k], S[k] = row[4] * (1.0 if gamma > 0.0 else -1.0), 1.0 / (gamma * gamma)
        else:
            e[k], S[k] = 0.0, np.inf


@njit(error_model="numpy")
def _invert_upper(R, Rinv):
    """Inverse of the upper triangular 4x4 ``R`` into ``Rinv``; False if singular."""
    for i in range(4):
        if not abs(R[i, i]) > 0.0:
            return False
    for j in range(4):
        for i in range(4):
            Rinv[i, j] = 0.0
        Rinv[j, j] = 1.0 / R[j, j]
        for i in range(j - 1, -1, -1):
            s = 0.0
            for m in range(i + 1, j + 1):
                s += R[i, m] * Rinv[m, j]
            Rinv[i, j] = -s / R[i, i]
    return True


@njit(error_model="numpy")
def start_track(i, t, lo, hi, theta, nom, state, P_last, e):
    """Blank track i's outputs (its state, covariance and innovations NaN until written) and
    set ``nom`` over lo..hi to its constant-velocity line ``theta[i]``: how every per-track
    kernel starts a track."""
    for k in range(e.shape[1]):
        e[i, k] = np.nan
    for a in range(4):
        state[i, a] = np.nan
        for b in range(4):
            P_last[i, a, b] = np.nan
    for k in range(lo, hi + 1):
        nom[k, 0] = theta[i, 0] + theta[i, 2] * t[k]
        nom[k, 1] = theta[i, 1] + theta[i, 3] * t[k]
        nom[k, 2] = theta[i, 2]
        nom[k, 3] = theta[i, 3]


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def finish_track(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, noisy, state, P_last, e, cost,
                 nu, S, S0, R, r, Rinv, none):
    """About the MAP trajectory ``nom`` of track i under the process noise ``Q`` (K, 3;
    ``noisy``: any step has some; ``none``: zeros of Q's shape), the exactly diffuse
    square-root information pass (``_srif``): writes the state at the last bearing and its
    covariance (units of s^2; NaN if singular), the normalised innovations ``e`` (the
    diffuse ones left out) and the squared bearing residuals of ``nom`` (rad^2): how every
    per-track kernel ends a track."""
    # the diffuse bearings are those of the information structure, which process noise
    # does not change (a pass with q = 0 finds them; with q > 0 every variance is larger
    # and, for a tiny sigma, all would pass MAX_S)
    if noisy:
        _srif(t, ox, oy, z, w, weighted, lo, hi, nom, none, nu, S0, R, r)
    _srif(t, ox, oy, z, w, weighted, lo, hi, nom, Q, nu, S, R, r)
    for k in range(lo, hi + 1):
        if nu[k] == nu[k] and (S0[k] if noisy else S[k]) <= MAX_S:
            e[i, k] = nu[k]
    if _invert_upper(R, Rinv):
        for c in range(4):
            v = 0.0
            for d in range(c, 4):
                v += Rinv[c, d] * r[d]
            state[i, c] = v
            for d in range(4):
                v = 0.0
                for m in range(max(c, d), 4):
                    v += Rinv[c, m] * Rinv[d, m]
                P_last[i, c, d] = v
    cost[i] = _bearing_cost(ox, oy, z, w, weighted, lo, hi, nom)


@njit(error_model="numpy")
def blank_path(i, path, path_cov):
    """Track i's trajectory and its covariances NaN until written."""
    for k in range(path.shape[1]):
        path[i, k, 0] = path[i, k, 1] = np.nan
    for k in range(path_cov.shape[1]):
        for j in range(3):
            path_cov[i, k, j] = np.nan


@njit(error_model="numpy", depends=(atan2, wrap_angle, start_track, step_noise, finish_track,
                                     smoothed_positions))
def smooth_tracks(t, ox, oy, measured, weight, weighted, first, last, theta, lam, scale2,
                  p0_pos, max_iter, tol_m, state, P_last, e, cost, passes, path, path_cov):
    """Per track i: the NCV MAP trajectory from the constant-velocity ``theta[i]`` with
    lam[i] = q / s^2 (``scale2[i]`` = s^2, rad^2: the noise variance the units refer to;
    ``max_iter`` 0: about the constant-velocity line itself, no iteration), then its
    exactly diffuse square-root information pass (``finish_track``). Writes the state at
    the last bearing (4,) and its covariance in units of s^2 (NaN if singular), the
    innovations over the root of their variance in units of s^2 (``e``, rad: sd s under
    the model; NaN where no bearing and for the diffuse ones), the squared bearing residuals
    of the trajectory (rad^2), the Gauss-Newton passes (-1: a covariance was not positive
    definite) and the trajectory's positions ``path`` (n, K, 2, m; NaN outside the track and
    where the fit failed) with, where ``path_cov`` has epochs, their smoothed covariances
    (``smoothed_positions``)."""
    n, K = measured.shape
    nom = np.empty((K, 4))
    mf, ms, trial = np.empty((K, 4)), np.empty((K, 4)), np.empty((K, 4))
    Pf, Pp = np.empty((K, 4, 4)), np.empty((K, 4, 4))
    nu, S, S0 = np.empty(K), np.empty(K), np.empty(K)
    R, r, Rinv = np.empty((4, 4)), np.empty(4), np.empty((4, 4))
    p0, prior = np.empty(2), np.empty(4)
    Q, none = np.empty((K, 3)), np.zeros((K, 3))  # per step: this track's noise; none
    for i in range(n):
        lo, hi = first[i], last[i]
        z, w = measured[i], (weight[i] if weighted else measured[i])
        start_track(i, t, lo, hi, theta, nom, state, P_last, e)
        cost[i] = np.nan
        blank_path(i, path, path_cov)
        p0[0] = p0_pos[i] * p0_pos[i] / scale2[i]
        p0[1] = PRIOR_SPEED_M_S * PRIOR_SPEED_M_S / scale2[i]
        step_noise(t, lo, hi, lam[i], Q)
        prior[:] = nom[lo]
        made = _fit(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, max_iter, tol_m,
                    mf, Pf, Pp, nu, S, ms, trial)
        passes[i] = made
        if made < 0:
            continue
        finish_track(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, lam[i] > 0.0, state,
                     P_last, e, cost, nu, S, S0, R, r, Rinv, none)
        smoothed_positions(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf,
                           Pp, nu, S, path, path_cov)


MAX_PASSES = 30  # Gauss-Newton passes
# the motion fit assumes at least this bearing noise (rad; 1e-3 deg, finer than any bearing
# sensor): with a noiseless log, q / sigma^2 would be numerically infinite
MIN_SIGMA_RAD = float(np.deg2rad(1e-3))
TOL_M = 1e-3  # a pass moving no position by more than this (m) ends the iteration


def theta_of_state(state, P, t_now):
    """theta = (x0, y0, vx, vy) of the straight line through the state (x, y, vx, vy) at
    ``t_now`` (extrapolated back to t = 0: what every ``bearings2d`` output holds), and its
    covariance A P A^T."""
    A = np.broadcast_to(np.eye(4), P.shape).copy()
    A[:, 0, 2] = A[:, 1, 3] = -t_now
    theta = np.einsum("nij,nj->ni", A, state)
    return theta, A @ P @ np.swapaxes(A, 1, 2)


def in_units(out, sigma2, t_now, theta_cv):
    """A kernel's ``out`` (covariance and innovations in units of the noise variance) in
    physical units under ``sigma2`` (rad^2, (n,)), with ``theta``/``cov_theta`` of the state
    at ``t_now`` (n,) and NaN for the tracks without a constant-velocity start."""
    out["cov"] *= sigma2[:, None, None]
    out["innovations"] = out["innovations"] / np.sqrt(sigma2)[:, None]
    out["theta"], out["cov_theta"] = theta_of_state(out["state"], out["cov"], t_now)
    out["sigma2"] = sigma2
    if "path_cov_m2" in out:
        out["path_cov_m2"] *= sigma2[:, None, None]
    fail = ~np.isfinite(theta_cv).all(axis=1)
    for key in ("state", "cov", "innovations", "theta", "cov_theta", "path_m", "path_cov_m2"):
        if key in out:
            out[key][fail] = np.nan
    return out


def smooth(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd, sigma_rad,
           iterate=True, path_cov=False):
    """The NCV MAP state at each track's last bearing from the constant-velocity start
    ``theta_cv`` (n, 4), with q = ``accel_psd`` (m^2/s^3, (n,)); ``iterate`` False keeps the
    constant-velocity line itself (only its innovations and covariance are computed).

    ``sigma_rad``: the known bearing noise (n,); NaN where unknown: then sigma^2 is
    estimated from the innovations and the fit repeated with it (twice: q is absolute, so
    q / sigma^2 changes with the estimate; the first pass starts from the residual RMS of
    ``theta_cv``). Returns a dict: ``state`` (n, 4) and ``cov`` (n, 4, 4) at the last bearing
    (NaN where singular), ``innovations`` (n, K) normalised by sigma (NaN where none, and
    the diffuse ones), ``sigma2`` (rad^2) used, ``cost_rad2`` (squared bearing residuals of
    the trajectory), ``passes`` (Gauss-Newton passes; -1: failed) and ``path_m`` (n, K, 2:
    the MAP trajectory's positions, m; NaN outside the track); with ``path_cov``,
    ``path_cov_m2`` (n, K, 3: their smoothed covariances xx, xy, yy in m^2,
    ``smoothed_positions``)."""
    n, K = measured_rad.shape
    sigma = np.asarray(sigma_rad, dtype=float)
    known = np.isfinite(sigma)
    weighted = valid is not None
    weight = valid.astype(float) if weighted else np.empty((0, 0))
    start_range = np.hypot(theta_cv[:, 0] + theta_cv[:, 2] * t[first] - own_x[first],
                           theta_cv[:, 1] + theta_cv[:, 3] * t[first] - own_y[first])
    p0_pos = np.maximum(PRIOR_RANGES * np.nan_to_num(start_range, nan=0.0), MIN_PRIOR_M)
    args = (np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(own_x, float),
            np.ascontiguousarray(own_y, float), np.ascontiguousarray(measured_rad, float),
            weight, weighted, np.asarray(first, np.int64), np.asarray(last, np.int64),
            np.ascontiguousarray(np.nan_to_num(theta_cv), float))
    if known.all():
        sigma2, rounds = sigma**2, 1
    else:  # start from the constant-velocity fit's residual RMS
        r = bearing_residuals(np.nan_to_num(theta_cv), t, own_x, own_y, measured_rad, valid)
        count = np.maximum(valid.sum(axis=1) if weighted else K, 5) - 4
        sigma2, rounds = np.where(known, sigma**2, np.einsum("nk,nk->n", r, r) / count), 3
    q = np.broadcast_to(np.asarray(accel_psd, dtype=float), (n,))
    for round_ in range(rounds):
        scale2 = np.maximum(sigma2, MIN_SIGMA_RAD**2)
        out = {"state": np.empty((n, 4)), "cov": np.empty((n, 4, 4)),
               "innovations": np.empty((n, K)), "cost_rad2": np.empty(n),
               "passes": np.zeros(n, dtype=np.int64), "path_m": np.empty((n, K, 2))}
        # the covariances of the trajectory: in the last round only (the others' are not kept)
        covs = np.empty((n, K if path_cov and round_ == rounds - 1 else 0, 3))
        smooth_tracks(*args, q / scale2, scale2, p0_pos, MAX_PASSES if iterate else 0, TOL_M,
                      out["state"], out["cov"], out["innovations"], out["cost_rad2"],
                      out["passes"], out["path_m"], covs)
        if covs.shape[1]:
            out["path_cov_m2"] = covs
        e2 = out["innovations"] ** 2  # rad^2: mean s^2 under the model
        count = np.sum(np.isfinite(e2), axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            estimated = np.nansum(e2, axis=1) / count
        if round_ < rounds - 1:
            sigma2 = np.where(known, sigma2, estimated)
    sigma2 = np.where(known, scale2, np.where(count > 0, estimated, scale2))
    return in_units(out, sigma2, t[last], theta_cv)
