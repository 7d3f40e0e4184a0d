"""The compiled Marquardt loop of ``lm`` and ``last_leg``, one track at a time over the tracks
of a shard, and the one way they call it (``fit_starts``: every track from several starts,
each keeping its best, ``best_start``).

Per track: A = H + lambda diag(H) with H = J^T J (J^T Omega J for a robust loss), scaled to
unit diagonal (D = sqrt(diag H),
so the definiteness test and the solve do not depend on units, metres vs m/s): the scaled H
is decomposed once per accepted step (cyclic Jacobi rotations; A's scaled eigenvalues are
then w + lambda, so a new lambda needs no new factorisation). Every pass makes one fused
evaluation of F, H and g at the trial point (``model.track_terms``), accepted or rejected.
"""

import math
from dataclasses import dataclass

import numpy as np

from tma.families.bearings2d.model import (  # noqa: F401 (the losses, imported from here)
    LOSS_CAUCHY,
    LOSS_HUBER,
    LOSS_SQUARED,
    LOSSES,
    TUNING,
    track_terms,
)
from tma.runtime.jit import njit

MAX_INT = np.iinfo(np.int64).max
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
def marquardt(theta, t, ox, oy, measured, weight, weighted, lambda0, lambda_up, lambda_down,
              f_tol, max_iter, lambda_max, pd_rtol, n_f_evals, n_iter, stop, cost, jtj,
              loss=LOSS_SQUARED, c=math.inf, scale=None):
    """Marquardt iterations for every track (row) of ``theta`` (n, 4), in place, on the cost
    of ``loss`` (``model.track_terms``: the squared loss, or a robust one with tuning
    constant ``c`` and bearing scale ``scale[i]`` (rad) per row, iteratively reweighted
    inside the loop: the weights are re-evaluated at every trial point); per track the
    counters, stop reason, F (rad^2) and the normal matrix H at the result go into the
    output arrays.

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
        s = 1.0 if scale is None else scale[i]
        w_row = weight[i] if weighted else measured[i]  # an unread placeholder
        F = track_terms(x, t, ox, oy, measured[i], w_row, weighted, H, g, loss, c, s)
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
            F_trial = track_terms(trial, t, ox, oy, measured[i], w_row, weighted, Ht, gt, loss,
                                  c, s)
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
        if jtj is not None:
            jtj[i] = H


@dataclass(frozen=True)
class MarquardtSettings:
    """The loop's settings (``lm.Config`` states each): the first lambda, its factors after
    a rejected and an accepted step, the F tolerance (rad^2), the accepted steps at most,
    the largest lambda and the definiteness threshold."""

    lambda0: float
    lambda_up: float
    lambda_down: float
    f_tol_rad2: float
    max_iter: int
    lambda_max: float
    pd_rtol: float

    @classmethod
    def of(cls, cfg) -> "MarquardtSettings":
        """The settings an estimator's config holds (``lm.Config`` and its subclasses)."""
        return cls(float(cfg.lambda0), float(cfg.lambda_up), float(cfg.lambda_down),
                   float(cfg.f_tol_rad2), min(int(cfg.max_iter), MAX_INT),
                   float(cfg.lambda_max), float(cfg.pd_rtol))


def _tiled(array, k):
    """``array`` repeated ``k`` times along its first axis (a 0-row placeholder as it is)."""
    return array if k == 1 or array.shape[0] == 0 else np.tile(array, (k, 1))


def best_start(cost, k, tol):
    """Index (n,) of the start of lowest cost per track (NaN counts as +inf), from ``cost``
    of the ``k`` starts stacked start-major (k * n,): the earliest start within ``tol`` of
    the lowest (starts reaching one minimum differ by about the F tolerance)."""
    cost = np.where(np.isnan(cost), np.inf, cost).reshape(k, -1)
    return np.argmax(cost <= cost.min(axis=0) + tol, axis=0)


def _pick(values, won, k):
    """Rows of ``values`` (k * n, ...) stacked start-major: the winning start's per track."""
    n = won.size
    return values.reshape(k, n, *values.shape[1:])[won, np.arange(n)]


def fit_starts(settings: MarquardtSettings, starts, t, ox, oy, measured, weight, weighted,
               loss="squared", scale=None) -> dict:
    """Marquardt from ``starts`` (k * n, 4: k starts of the n tracks of ``measured``, stacked
    start-major; ``weight``: each bearing's weight, n x K, read when ``weighted``), on the
    squared cost or on a robust ``loss`` with the bearing ``scale`` per track (n,, rad), each
    track keeping its best start (``best_start``). Returns by name ``theta`` (n, 4),
    ``n_f_evals`` (summed over the starts), ``n_iter``, ``stop_reason`` and the cost at the
    result: ``cost_rad2`` with ``jtj`` (the normal matrix) for the squared loss,
    ``cost_robust_rad2`` for a robust one; with several starts, ``start_won``."""
    n = measured.shape[0]
    k, m = (starts.shape[0] // n if n else 1), starts.shape[0]  # (no track: nothing to fit)
    robust = loss != "squared"
    cost_key = "cost_robust_rad2" if robust else "cost_rad2"
    out = {"theta": np.array(starts, dtype=float), "n_f_evals": np.zeros(m, dtype=np.int64),
           "n_iter": np.zeros(m, dtype=np.int64),
           "stop_reason": np.full(m, -1, dtype=np.int64), cost_key: np.zeros(m)}
    if not robust:
        out["jtj"] = np.zeros((m, 4, 4))
    s = settings
    common = (out["theta"], np.ascontiguousarray(t, float), np.ascontiguousarray(ox, float),
              np.ascontiguousarray(oy, float), _tiled(np.ascontiguousarray(measured, float), k),
              _tiled(weight, k), weighted, s.lambda0, s.lambda_up, s.lambda_down, s.f_tol_rad2,
              s.max_iter, s.lambda_max, s.pd_rtol, out["n_f_evals"], out["n_iter"],
              out["stop_reason"], out[cost_key])
    if robust:
        marquardt(*common, None, LOSSES[loss], TUNING[loss], np.tile(scale, k))
    else:
        marquardt(*common, out["jtj"])
    if k == 1:
        return out
    won = best_start(out[cost_key], k, s.f_tol_rad2)
    total = out["n_f_evals"].reshape(k, -1).sum(axis=0)
    out = {key: _pick(value, won, k) for key, value in out.items()}
    out["n_f_evals"] = total
    out["start_won"] = won.astype(np.int64)
    return out
