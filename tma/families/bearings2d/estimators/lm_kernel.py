"""The compiled Marquardt loop of ``lm``, one track at a time over the tracks of a shard.

Per track: A = H + lambda diag(H) with H = J^T J, scaled to unit diagonal (D = sqrt(diag H),
so the definiteness test and the solve do not depend on units, metres vs m/s): the scaled H
is decomposed once per accepted step (cyclic Jacobi rotations; A's scaled eigenvalues are
then w + lambda, so a new lambda needs no new factorisation). Every pass makes one fused
evaluation of F, H and g at the trial point (``model.track_terms``), accepted or rejected.
"""

import math

import numpy as np

from tma.families.bearings2d.model import atan2, track_terms
from tma.maths.angles import TWO_PI
from tma.runtime.jit import njit

# Stop reasons recorded per track.
STOP_F_TOL, STOP_MAX_ITER, STOP_LAMBDA_MAX = 0, 1, 2
MAX_SWEEPS = 50  # Jacobi sweeps (4x4: converged after 4-6; the cap only stops a NaN input)
EPS2 = np.finfo(float).eps ** 2
TINY_LAMBDA = float(np.finfo(float).tiny)  # a lambda that underflowed to 0 restarts here


@njit(error_model="numpy")
def rotate(A, V, p, q):
    """One Jacobi rotation annihilating A[p, q] of the symmetric 4x4 ``A`` (A <- R^T A R,
    V <- V R), if |A[p, q]| exceeds eps times the geometric mean of A[p, p] and A[q, q] (the
    threshold under which a cold start keeps small eigenvalues to high relative accuracy).
    Returns whether it rotated."""
    apq = A[p, q]
    if not apq * apq > EPS2 * abs(A[p, p] * A[q, q]):
        return False
    alpha, beta = A[q, q] - A[p, p], 2.0 * apq
    # tan of the smaller of the two annihilating angles
    root = math.sqrt(alpha * alpha + beta * beta)
    t = beta / (alpha + root) if alpha >= 0.0 else beta / (alpha - root)
    sec = math.sqrt(t * t + 1.0)
    s, tau = t / sec, t / (1.0 + sec)  # sin and tan(angle / 2) = s / (1 + cos)
    h = t * apq
    A[p, p] -= h
    A[q, q] += h
    A[p, q] = A[q, p] = 0.0
    for r in range(4):
        if r != p and r != q:
            arp, arq = A[r, p], A[r, q]
            A[r, p] = A[p, r] = arp - s * (arq + tau * arp)
            A[r, q] = A[q, r] = arq + s * (arp - tau * arq)
        vrp, vrq = V[r, p], V[r, q]
        V[r, p] = vrp - s * (vrq + tau * vrp)
        V[r, q] = vrq + s * (vrp - tau * vrq)
    return True


@njit(error_model="numpy")
def scaled_eigh(H, w, V, d, warm, A, B):
    """Eigen-decompose D^-1 H D^-1 (D = diag(d), d = sqrt(diag H), 1 where that is 0) of a
    symmetric 4x4 ``H`` into eigenvalues ``w`` (unsorted) and eigenvector columns ``V``.

    Cyclic Jacobi in the parallel order (the two rotations of each step touch disjoint rows,
    so their latencies overlap) until a sweep makes no rotation. ``warm``: start from the
    eigenvectors already in ``V`` (those of the previous H of the same track, nearly
    diagonalising this one: 2-3 sweeps instead of 4-5). ``A``, ``B``: 4x4 work arrays.
    """
    for i in range(4):
        d[i] = math.sqrt(H[i, i]) if H[i, i] > 0.0 else 1.0
    for i in range(4):
        for j in range(4):
            A[i, j] = H[i, j] / (d[i] * d[j])
    if warm:  # A <- V^T A V
        for i in range(4):
            for j in range(4):
                acc = 0.0
                for k in range(4):
                    acc += A[i, k] * V[k, j]
                B[i, j] = acc
        for i in range(4):
            for j in range(i, 4):
                acc = 0.0
                for k in range(4):
                    acc += V[k, i] * B[k, j]
                A[i, j] = A[j, i] = acc
    else:
        for i in range(4):
            for j in range(4):
                V[i, j] = 1.0 if i == j else 0.0
    for _ in range(MAX_SWEEPS):
        rotated = rotate(A, V, 0, 1) | rotate(A, V, 2, 3)
        rotated |= rotate(A, V, 0, 2) | rotate(A, V, 1, 3)
        rotated |= rotate(A, V, 0, 3) | rotate(A, V, 1, 2)
        if not rotated:
            break
    for i in range(4):
        w[i] = A[i, i]


@njit(error_model="numpy")
def solve_shifted(w, V, d, g, lam, coeff, out):
    """``out`` = (H + lam diag(H))^-1 g from ``scaled_eigh(H)``: D^-1 V (w + lam)^-1 V^T D^-1 g
    (``coeff``: a work array of 4)."""
    for i in range(4):
        acc = 0.0
        for j in range(4):
            acc += V[j, i] * (g[j] / d[j])
        coeff[i] = acc / (w[i] + lam)
    for i in range(4):
        acc = 0.0
        for j in range(4):
            acc += V[i, j] * coeff[j]
        out[i] = acc / d[i]


@njit(error_model="numpy", depends=(track_terms,))
def marquardt(theta, t, ox, oy, measured, weight, weighted, lambda0, lambda_up,
              lambda_down, f_tol, max_iter, lambda_max, pd_rtol,
              n_f_evals, n_iter, stop, cost, jtj):
    """Marquardt iterations for every track (row) of ``theta`` (n, 4), in place; per track
    the counters, stop reason, F (rad^2) and J^T J at the result go into the output arrays.

    A trial step whose F rises (or is NaN), or whose A is not positive definite (smallest
    scaled eigenvalue of A at most ``pd_rtol`` times max(largest, 1)), multiplies lambda by
    ``lambda_up``; an accepted step multiplies it by ``lambda_down``; a track stops when an
    accepted step lowers F by less than ``f_tol``, after ``max_iter`` accepted steps, or
    when lambda exceeds ``lambda_max``.
    """
    H, Ht = np.empty((4, 4)), np.empty((4, 4))
    g, gt = np.empty(4), np.empty(4)
    w, V, d = np.empty(4), np.empty((4, 4)), np.empty(4)
    step, trial, coeff = np.empty(4), np.empty(4), np.empty(4)
    A, B = np.empty((4, 4)), np.empty((4, 4))  # work arrays of scaled_eigh
    for i in range(theta.shape[0]):
        x = theta[i]
        w_row = weight[i] if weighted else measured[i]  # an unread placeholder
        F = track_terms(x, t, ox, oy, measured[i], w_row, weighted, H, g)
        scaled_eigh(H, w, V, d, False, A, B)
        n_f, n_acc, lam, reason = 1, 0, lambda0, -1
        while reason < 0:
            w_min, w_max = w.min(), w.max()
            floor = pd_rtol * (w_max if w_max > 1.0 else 1.0)
            while w_min + lam <= floor:
                lam = lam * lambda_up if lam > 0.0 else TINY_LAMBDA
            solve_shifted(w, V, d, g, lam, coeff, step)
            for j in range(4):
                trial[j] = x[j] + step[j]
            F_trial = track_terms(trial, t, ox, oy, measured[i], w_row, weighted, Ht, gt)
            n_f += 1
            decrease = F - F_trial
            if decrease >= 0.0:  # NaN (a non-finite trial) counts as rejected
                x[:] = trial
                F = F_trial
                H[:] = Ht
                g[:] = gt
                scaled_eigh(H, w, V, d, True, A, B)
                lam *= lambda_down
                n_acc += 1
                if decrease < f_tol:
                    reason = STOP_F_TOL
            else:
                lam *= lambda_up
            if reason < 0 and n_acc >= max_iter:
                reason = STOP_MAX_ITER
            if reason < 0 and lam > lambda_max:
                reason = STOP_LAMBDA_MAX
        n_f_evals[i], n_iter[i], stop[i], cost[i] = n_f, n_acc, reason, F
        jtj[i] = H


# Robust losses of ``marquardt_robust``: rho(u) ~ u^2 near 0, u = r / s; tuning constants c
# (in units of s) for 95 % efficiency under Gaussian noise.
LOSS_SQUARED, LOSS_HUBER, LOSS_CAUCHY = 0, 1, 2
LOSSES = {"squared": LOSS_SQUARED, "huber": LOSS_HUBER, "cauchy": LOSS_CAUCHY}
TUNING = {"squared": math.inf, "huber": 1.345, "cauchy": 2.385}


@njit(error_model="numpy")
def rho_omega(u, loss, c):
    """rho(u) and the IRLS weight omega = rho'(u) / (2 u): squared u^2 (omega 1); Huber u^2
    for |u| <= c, else 2 c |u| - c^2 (omega c / |u|); Cauchy c^2 log(1 + (u/c)^2) (omega
    1 / (1 + (u/c)^2))."""
    if loss == LOSS_HUBER:
        au = abs(u)
        if au <= c:
            return u * u, 1.0
        return 2.0 * c * au - c * c, c / au
    if loss == LOSS_CAUCHY:
        q = (u / c) * (u / c)
        return c * c * math.log1p(q), 1.0 / (1.0 + q)
    return u * u, 1.0


@njit(error_model="numpy", fastmath={"contract"}, depends=(atan2,))
def robust_terms(theta, t, ox, oy, measured, weight, weighted, loss, c, s, H, g):
    """F_rho = sum_k s^2 rho(r_k / s) (rad^2) of one track at ``theta`` (4,), with H = J^T
    Omega J and g = J^T Omega r (Omega = diag omega_k at theta) written into ``H``, ``g``: the
    IRLS normal equations, whose step lowers F_rho for a large enough lambda. ``weighted``:
    ``weight`` 0 drops a missing bearing. r_k and J as in ``model.track_terms``."""
    x0, y0, vx, vy = theta[0], theta[1], theta[2], theta[3]
    F = aa0 = aa1 = aa2 = ab0 = ab1 = ab2 = bb0 = bb1 = bb2 = ar0 = ar1 = br0 = br1 = 0.0
    inv_s = 1.0 / s
    for k in range(t.size):
        if weighted and weight[k] == 0.0:
            continue
        tk = t[k]
        dx = x0 + vx * tk - ox[k]
        dy = y0 + vy * tk - oy[k]
        r = measured[k] - atan2(dx, dy)
        r -= TWO_PI * np.rint(r * (1.0 / TWO_PI))
        rho, omega = rho_omega(r * inv_s, loss, c)
        F += s * s * rho
        inv_r2 = 1.0 / (dx * dx + dy * dy)
        a = dy * inv_r2
        b = dx * inv_r2  # minus d bearing / dy: the signs are restored below
        oa, ob = omega * a, omega * b
        aa, ab, bb, ar, br = oa * a, oa * b, ob * b, oa * r, ob * r
        t2 = tk * tk
        aa0 += aa
        aa1 += aa * tk
        aa2 += aa * t2
        ab0 += ab
        ab1 += ab * tk
        ab2 += ab * t2
        bb0 += bb
        bb1 += bb * tk
        bb2 += bb * t2
        ar0 += ar
        ar1 += ar * tk
        br0 += br
        br1 += br * tk
    H[0, 0], H[0, 1], H[0, 2], H[0, 3] = aa0, -ab0, aa1, -ab1
    H[1, 1], H[1, 2], H[1, 3] = bb0, -ab1, bb1
    H[2, 2], H[2, 3], H[3, 3] = aa2, -ab2, bb2
    for i in range(4):
        for j in range(i):
            H[i, j] = H[j, i]
    g[0], g[1], g[2], g[3] = ar0, -br0, ar1, -br1
    return F


@njit(error_model="numpy", depends=(robust_terms,))
def marquardt_robust(theta, t, ox, oy, measured, weight, weighted, loss, c, scale, lambda0,
                     lambda_up, lambda_down, f_tol, max_iter, lambda_max, pd_rtol,
                     n_f_evals, n_iter, stop, cost):
    """``marquardt`` on the robust cost F_rho (``robust_terms``) of every row of ``theta``,
    with bearing scale ``scale[i]`` (rad) per row: iteratively reweighted least squares
    inside the Marquardt loop (the weights are re-evaluated at every trial point; a step is
    accepted when F_rho falls). F_rho at the result goes into ``cost``."""
    H, Ht = np.empty((4, 4)), np.empty((4, 4))
    g, gt = np.empty(4), np.empty(4)
    w, V, d = np.empty(4), np.empty((4, 4)), np.empty(4)
    step, trial, coeff = np.empty(4), np.empty(4), np.empty(4)
    A, B = np.empty((4, 4)), np.empty((4, 4))
    for i in range(theta.shape[0]):
        x, s = theta[i], scale[i]
        w_row = weight[i] if weighted else measured[i]  # an unread placeholder
        F = robust_terms(x, t, ox, oy, measured[i], w_row, weighted, loss, c, s, H, g)
        scaled_eigh(H, w, V, d, False, A, B)
        n_f, n_acc, lam, reason = 1, 0, lambda0, -1
        while reason < 0:
            w_min, w_max = w.min(), w.max()
            floor = pd_rtol * (w_max if w_max > 1.0 else 1.0)
            while w_min + lam <= floor:
                lam = lam * lambda_up if lam > 0.0 else TINY_LAMBDA
            solve_shifted(w, V, d, g, lam, coeff, step)
            for j in range(4):
                trial[j] = x[j] + step[j]
            F_trial = robust_terms(trial, t, ox, oy, measured[i], w_row, weighted, loss, c, s,
                                   Ht, gt)
            n_f += 1
            decrease = F - F_trial
            if decrease >= 0.0:  # NaN (a non-finite trial) counts as rejected
                x[:] = trial
                F = F_trial
                H[:] = Ht
                g[:] = gt
                scaled_eigh(H, w, V, d, True, A, B)
                lam *= lambda_down
                n_acc += 1
                if decrease < f_tol:
                    reason = STOP_F_TOL
            else:
                lam *= lambda_up
            if reason < 0 and n_acc >= max_iter:
                reason = STOP_MAX_ITER
            if reason < 0 and lam > lambda_max:
                reason = STOP_LAMBDA_MAX
        n_f_evals[i], n_iter[i], stop[i], cost[i] = n_f, n_acc, reason, F
