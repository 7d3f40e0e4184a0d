"""Bearings-only measurement model of a constant-velocity target in the plane.

State ``theta = (x0, y0, vx, vy)``: target position (m) at the dataset's t = 0 and velocity
(m/s), x east, y north. The bearing at time t from own-ship (ox, oy) is
``atan2(x0 + vx t - ox, y0 + vy t - oy)``, radians clockwise from north. Arrays are batched
over tracks: ``theta`` is ``(n_tracks, 4)``, times and own-ship ``(n_epochs,)`` shared by the
shard, measurements ``(n_tracks, n_epochs)``. ``valid`` is a boolean mask of the same shape
(False where a track has no bearing), or None when every bearing is present.
"""

import math

import numpy as np

from tma.angles import bearing_from_north, wrap_angle, wrap_residual
from tma.jit import njit

THETA_COLUMNS = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")


def _masked(values, valid):
    return values if valid is None else np.where(valid, values, 0.0)


def relative_position(theta, t_s, own_x_m, own_y_m):
    """Target minus own-ship position, each ``(n_tracks, n_epochs)``."""
    dx = theta[:, 0, None] + theta[:, 2, None] * t_s - own_x_m
    dy = theta[:, 1, None] + theta[:, 3, None] * t_s - own_y_m
    return dx, dy


def predicted_bearings(theta, t_s, own_x_m, own_y_m):
    """Bearings (rad) predicted by ``theta``, ``(n_tracks, n_epochs)``."""
    return bearing_from_north(*relative_position(theta, t_s, own_x_m, own_y_m))


def bearing_residuals(theta, t_s, own_x_m, own_y_m, measured_rad, valid):
    """Wrapped residuals ``wrap(measured - predicted)``, zero where not ``valid``."""
    r = wrap_residual(measured_rad - predicted_bearings(theta, t_s, own_x_m, own_y_m))
    return _masked(r, valid)


def bearing_cost(theta, t_s, own_x_m, own_y_m, measured_rad, valid):
    """F(theta) = sum of squared wrapped residuals (rad^2) per track."""
    r = bearing_residuals(theta, t_s, own_x_m, own_y_m, measured_rad, valid)
    return np.einsum("ij,ij->i", r, r)


def _partials(dx, dy, valid):
    """a = d(bearing)/d(x) = dy / r^2 and b = d(bearing)/d(y) = -dx / r^2 (masked)."""
    inv_r2 = 1.0 / (dx * dx + dy * dy)
    return _masked(dy * inv_r2, valid), _masked(-dx * inv_r2, valid)


def bearing_jacobian(theta, t_s, own_x_m, own_y_m, valid):
    """Analytic Jacobian d(bearing)/d(theta), ``(n_tracks, n_epochs, 4)``: columns
    ``(a, b, a t, b t)`` with a, b the partials w.r.t. target x and y."""
    a, b = _partials(*relative_position(theta, t_s, own_x_m, own_y_m), valid)
    return np.stack([a, b, a * t_s, b * t_s], axis=-1)


def normal_equations(theta, t_s, own_x_m, own_y_m, measured_rad, valid):
    """Residuals r, ``H = J^T J`` (n, 4, 4) and ``g = J^T r`` (n, 4) without forming J.

    With J = (a, b, a t, b t), every entry of H is a sum of a^2, ab or b^2 weighted by 1, t
    or t^2, i.e. three matrix products with the (n_epochs, 3) matrix [1, t, t^2].
    """
    dx, dy = relative_position(theta, t_s, own_x_m, own_y_m)
    r = _masked(wrap_residual(measured_rad - bearing_from_north(dx, dy)), valid)
    a, b = _partials(dx, dy, valid)
    powers = np.stack([np.ones_like(t_s), t_s, t_s * t_s], axis=1)
    aa, ab, bb = (a * a) @ powers, (a * b) @ powers, (b * b) @ powers
    ar, br = (a * r) @ powers[:, :2], (b * r) @ powers[:, :2]
    H = np.empty((theta.shape[0], 4, 4))
    H[:, 0, 0], H[:, 0, 1], H[:, 0, 2], H[:, 0, 3] = aa[:, 0], ab[:, 0], aa[:, 1], ab[:, 1]
    H[:, 1, 1], H[:, 1, 2], H[:, 1, 3] = bb[:, 0], ab[:, 1], bb[:, 1]
    H[:, 2, 2], H[:, 2, 3], H[:, 3, 3] = aa[:, 2], ab[:, 2], bb[:, 2]
    iu = np.triu_indices(4, 1)
    H[:, iu[1], iu[0]] = H[:, iu[0], iu[1]]
    g = np.column_stack([ar[:, 0], br[:, 0], ar[:, 1], br[:, 1]])
    return r, H, g


class BearingTerms:
    """Fused evaluation of F, H = J^T J and g = J^T r at many trial points (the LM hot path):
    the measured bearings (rad) and the weight of each (1 present, 0 missing), each call
    running the compiled ``track_terms`` per track."""

    def __init__(self, t_s, own_x_m, own_y_m, measured_rad, valid):
        self.t = np.ascontiguousarray(t_s, dtype=float)
        self.ox = np.ascontiguousarray(own_x_m, dtype=float)
        self.oy = np.ascontiguousarray(own_y_m, dtype=float)
        self.measured = np.ascontiguousarray(measured_rad, dtype=float)
        self.weighted = valid is not None
        # without a mask the kernels never read the weights: a placeholder of the right type
        self.weight = valid.astype(float) if self.weighted else np.empty((0, 0))

    def __call__(self, theta, rows):
        """``(F, H, g)`` for ``theta`` (k, 4) of tracks ``rows`` (index array, length k)."""
        k = theta.shape[0]
        F, H, g = np.empty(k), np.empty((k, 4, 4)), np.empty((k, 4))
        rows_terms(np.ascontiguousarray(theta, dtype=float), np.asarray(rows, dtype=np.int64),
                   self.t, self.ox, self.oy, self.measured, self.weight, self.weighted,
                   F, H, g)
        return F, H, g


# fdlibm s_atan.c: atan(x) = x - x (s1 + s2) on |x| < 7/16 (error < 1 ulp), and atan(1/2),
# atan(1) split into high and low parts for the reduced intervals.
AT0, AT1, AT2, AT3 = (3.33333333333329318027e-01, -1.99999999998764832476e-01,
                      1.42857142725034663711e-01, -1.11111104054623557880e-01)
AT4, AT5, AT6, AT7 = (9.09088713343650656196e-02, -7.69187620504482999495e-02,
                      6.66107313738753120669e-02, -5.83357013379057348645e-02)
AT8, AT9, AT10 = (4.97687799461593236017e-02, -3.65315727442169155270e-02,
                  1.62858201153657823623e-02)
ATAN_HALF_HI, ATAN_HALF_LO = 4.63647609000806093515e-01, 2.26987774529616870924e-17
ATAN_ONE_HI, ATAN_ONE_LO = 7.85398163397448278999e-01, 3.06161699786838301793e-17


@njit(error_model="numpy", fastmath={"contract"})
def atan2(y, x):
    """atan2(y, x) in [-pi, pi] within 1 ulp of libm's, written so that a loop over it
    vectorises (libm's is an opaque call per element, ~6x slower in the LM loop).

    fdlibm's atan on z = min(|y|, |x|) / max(|y|, |x|) in [0, 1] (reduced on [7/16, 11/16)
    about 1/2 and on [11/16, 1] about 1 with a single division), then mapped to the octant.
    Finite arguments only; atan2(+-0, -0) is +-0 here, +-pi in libm (the direction of a zero
    vector is undefined either way).
    """
    ay, ax = abs(y), abs(x)
    num, den = min(ay, ax), max(ay, ax)
    if 16.0 * num < 7.0 * den:
        p, q, hi, lo = num, den, 0.0, 0.0
    elif 16.0 * num < 11.0 * den:
        p, q, hi, lo = 2.0 * num - den, 2.0 * den + num, ATAN_HALF_HI, ATAN_HALF_LO
    else:
        p, q, hi, lo = num - den, num + den, ATAN_ONE_HI, ATAN_ONE_LO
    w = p / (q if q > 0.0 else 1.0)
    z = w * w
    v = z * z
    s1 = z * (AT0 + v * (AT2 + v * (AT4 + v * (AT6 + v * (AT8 + v * AT10)))))
    s2 = v * (AT1 + v * (AT3 + v * (AT5 + v * (AT7 + v * AT9))))
    a = hi - ((w * (s1 + s2) - lo) - w)
    a = 0.5 * math.pi - a if ay > ax else a
    a = math.pi - a if x < 0.0 else a
    return math.copysign(a, y)


# Losses of the residuals: rho(u) ~ u^2 near 0, u = r / s; tuning constants c (in units of s)
# for 95 % efficiency under Gaussian noise.
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


# reassoc lets the 14 sums vectorise (their order is then LLVM's), contract fuses multiply-adds;
# atan2 is compiled apart, without reassoc, so its careful evaluation order stays.
@njit(error_model="numpy", fastmath={"reassoc", "contract"}, depends=(rho_omega, wrap_angle))
def track_terms(theta, t, ox, oy, measured, weight, weighted, H, g, loss=LOSS_SQUARED,
                c=math.inf, s=1.0):
    """F = sum_k s^2 rho(r_k / s) (rad^2; the squared loss: sum r_k^2) of one track at
    ``theta`` (4,); H = J^T Omega J (4, 4) and g = J^T Omega r (4,) written into ``H`` and
    ``g`` (Omega = diag omega_k, ``rho_omega``; 1 for the squared loss: J^T J and J^T r),
    the IRLS normal equations, whose step lowers F for a large enough damping.

    r_k = wrap(X_k - atan2(dx_k, dy_k)), X the measured bearing (rad); with J = (a, b, a t,
    b t), a = d bearing / dx = dy / rho^2 and b = d bearing / dy = -dx / rho^2, every entry
    of H is a sum of omega a^2, omega ab, omega b^2 times 1, t or t^2. ``weighted``:
    multiply each residual and partial by ``weight`` (0 for a missing bearing).
    """
    x0, y0, vx, vy = theta[0], theta[1], theta[2], theta[3]
    F = aa0 = aa1 = aa2 = ab0 = ab1 = ab2 = bb0 = bb1 = bb2 = ar0 = ar1 = br0 = br1 = 0.0
    robust = loss != LOSS_SQUARED  # loop-invariant: the squared loop is compiled apart
    inv_s = 1.0 / s
    for k in range(t.size):
        tk = t[k]
        dx = x0 + vx * tk - ox[k]
        dy = y0 + vy * tk - oy[k]
        r = wrap_angle(measured[k] - atan2(dx, dy))
        inv_r2 = 1.0 / (dx * dx + dy * dy)
        if weighted:
            r *= weight[k]
            inv_r2 *= weight[k]
        a = dy * inv_r2
        b = dx * inv_r2  # minus d bearing / dy: the signs are restored below
        if robust:
            rho, omega = rho_omega(r * inv_s, loss, c)
            F += s * s * rho
            aa, ab, bb, ar, br = omega * a * a, omega * a * b, omega * b * b, omega * a * r, \
                omega * b * r
        else:
            F += r * r
            aa, ab, bb, ar, br = a * a, a * b, b * b, a * r, b * r
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


@njit()
def rows_terms(theta, rows, t, ox, oy, measured, weight, weighted, F, H, g):
    """``track_terms`` for tracks ``rows`` at ``theta`` (k, 4) into F (k,), H (k, 4, 4),
    g (k, 4)."""
    for i in range(rows.size):
        row = rows[i]
        w_row = weight[row] if weighted else measured[row]  # an unread placeholder
        F[i] = track_terms(theta[i], t, ox, oy, measured[row], w_row, weighted, H[i], g[i])
