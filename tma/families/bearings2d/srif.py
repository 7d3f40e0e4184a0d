"""The square-root information filter (Bierman, "Factorization Methods for Discrete
Sequential Estimation", Academic Press 1977) of a nearly-constant-velocity target over its
bearings, started from no information at all (exactly diffuse), compiled: Householder
triangularisation, the filter's pass about a nominal trajectory (its innovations and their
variances) and the inverse of its upper-triangular information factor (``ncv.py`` states
the model and why the diffuse start)."""

import math

import numpy as np

from tma.families.bearings2d.model import atan2
from tma.maths.angles import wrap_angle
from tma.runtime.jit import njit

MAX_S = 1e4  # an innovation variance (in noise variances) above this: a diffuse one

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
