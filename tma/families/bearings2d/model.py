"""Bearings-only measurement model of a constant-velocity target in the plane.

State ``theta = (x0, y0, vx, vy)``: target position (m) at the dataset's t = 0 and velocity
(m/s), x east, y north. The bearing at time t from own-ship (ox, oy) is
``atan2(x0 + vx t - ox, y0 + vy t - oy)``, radians clockwise from north. Arrays are batched
over tracks: ``theta`` is ``(n_tracks, 4)``, times and own-ship ``(n_epochs,)`` shared by the
shard, measurements ``(n_tracks, n_epochs)``. ``valid`` is a boolean mask of the same shape
(False where a track has no bearing), or None when every bearing is present.
"""

import numpy as np

from tma.angles import TWO_PI, bearing_from_north

THETA_COLUMNS = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")


def _masked(values, valid):
    return values if valid is None else np.where(valid, values, 0.0)


def wrap_residual(angle_rad):
    """Wrap to [-pi, pi] by the nearest multiple of 2 pi (cheaper than a float modulo; the
    two conventions differ only at exactly +-pi, where the squared residual is the same)."""
    return angle_rad - TWO_PI * np.rint(angle_rad * (1.0 / TWO_PI))


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
    """Fused evaluation of F, H = J^T J and g = J^T r at many trial points (the LM hot path).

    Precomputes sin and cos of the measured bearings once, so the wrapped residual is
    ``atan2(sin X dy - cos X dx, cos X dy + sin X dx)`` (already in (-pi, pi], no separate
    wrap). A missing bearing has weight 0: its residual is multiplied by it, because
    atan2(+-0, -0) is +-pi, not 0, whatever sin and cos are set to.
    """

    def __init__(self, t_s, own_x_m, own_y_m, measured_rad, valid):
        self.t, self.ox, self.oy = t_s, own_x_m, own_y_m
        self.sin_m, self.cos_m = np.sin(measured_rad), np.cos(measured_rad)
        self.weight = None if valid is None else valid.astype(float)
        self.powers = np.stack([np.ones_like(t_s), t_s, t_s * t_s], axis=1)

    def __call__(self, theta, rows):
        """``(F, H, g)`` for ``theta`` (k, 4) of tracks ``rows`` (index array, length k)."""
        t, k = self.t, theta.shape[0]
        if k and rows[-1] - rows[0] + 1 == k:  # contiguous rows: views, no copies
            rows = slice(int(rows[0]), int(rows[-1]) + 1)
        sin_m, cos_m = self.sin_m[rows], self.cos_m[rows]
        dx = np.multiply.outer(theta[:, 2], t)
        dx += theta[:, 0, None]
        dx -= self.ox
        dy = np.multiply.outer(theta[:, 3], t)
        dy += theta[:, 1, None]
        dy -= self.oy
        r = np.arctan2(sin_m * dy - cos_m * dx, cos_m * dy + sin_m * dx)
        inv_r2 = dx * dx
        inv_r2 += dy * dy
        np.reciprocal(inv_r2, out=inv_r2)
        if self.weight is not None:
            weight = self.weight[rows]
            r *= weight
            inv_r2 *= weight
        F = np.einsum("ij,ij->i", r, r)
        a = np.multiply(dy, inv_r2, out=dy)  # d bearing / d x
        b = np.multiply(dx, inv_r2, out=dx)  # minus d bearing / d y
        products = np.empty((5, k, t.size))
        np.multiply(a, a, out=products[0])
        np.multiply(a, b, out=products[1])
        np.multiply(b, b, out=products[2])
        np.multiply(a, r, out=products[3])
        np.multiply(b, r, out=products[4])
        sums = (products.reshape(5 * k, t.size) @ self.powers).reshape(5, k, 3)
        aa, ab, bb, ar, br = sums  # with b = -d/dy: ab, br change sign
        H = np.empty((k, 4, 4))
        H[:, 0, 0], H[:, 0, 1], H[:, 0, 2], H[:, 0, 3] = aa[:, 0], -ab[:, 0], aa[:, 1], -ab[:, 1]
        H[:, 1, 1], H[:, 1, 2], H[:, 1, 3] = bb[:, 0], -ab[:, 1], bb[:, 1]
        H[:, 2, 2], H[:, 2, 3], H[:, 3, 3] = aa[:, 2], -ab[:, 2], bb[:, 2]
        iu = np.triu_indices(4, 1)
        H[:, iu[1], iu[0]] = H[:, iu[0], iu[1]]
        g = np.column_stack([ar[:, 0], -br[:, 0], ar[:, 1], -br[:, 1]])
        return F, H, g
