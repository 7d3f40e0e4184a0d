"""Constant-velocity and coordinated-turn motion on the state (x, vx, y, vy, omega).

x east, y north (m), velocities m/s, omega the turn rate in rad/s, positive
counter-clockwise (a left turn). Batched over the leading axis.
"""

import numpy as np

SMALL_TURN = 1e-6  # |omega T| below this uses the series expansions


def _turn_terms(omega, T):
    """sin(wT)/w, (1 - cos wT)/w and their derivatives in w (series near w = 0)."""
    wT = omega * T
    small = np.abs(wT) < SMALL_TURN
    w = np.where(small, 1.0, omega)
    s, c = np.sin(wT), np.cos(wT)
    a = np.where(small, T - omega**2 * T**3 / 6, s / w)
    b = np.where(small, omega * T**2 / 2, (1 - c) / w)
    da = np.where(small, -omega * T**3 / 3, (wT * c - s) / w**2)
    db = np.where(small, T**2 / 2 - omega**2 * T**4 / 8, (wT * s - (1 - c)) / w**2)
    return a, b, da, db, s, c


def coordinated_turn(state, T):
    """Propagate (n, 5) states over T; returns the new states and the Jacobians (n, 5, 5)."""
    x, vx, y, vy, omega = state.T
    a, b, da, db, s, c = _turn_terms(omega, T)
    new = np.column_stack([x + a * vx - b * vy, c * vx - s * vy,
                           y + b * vx + a * vy, s * vx + c * vy, omega])
    jac = np.zeros((state.shape[0], 5, 5))
    jac[:, 0, 0] = jac[:, 2, 2] = jac[:, 4, 4] = 1.0
    jac[:, 0, 1], jac[:, 0, 3], jac[:, 0, 4] = a, -b, da * vx - db * vy
    jac[:, 1, 1], jac[:, 1, 3], jac[:, 1, 4] = c, -s, -T * (s * vx + c * vy)
    jac[:, 2, 1], jac[:, 2, 3], jac[:, 2, 4] = b, a, db * vx + da * vy
    jac[:, 3, 1], jac[:, 3, 3], jac[:, 3, 4] = s, c, T * (c * vx - s * vy)
    return new, jac


def constant_velocity(T):
    """Transition (5, 5) of constant velocity; omega is carried unchanged (unused)."""
    F = np.eye(5)
    F[0, 1] = F[2, 3] = T
    return F


def white_acceleration_noise(T, accel_psd, omega_psd=0.0):
    """Process noise (5, 5) of continuous white acceleration (psd in m^2/s^3 per axis) and a
    random-walk turn rate (psd in rad^2/s^3)."""
    block = accel_psd * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
    Q = np.zeros((5, 5))
    Q[np.ix_([0, 1], [0, 1])] = block
    Q[np.ix_([2, 3], [2, 3])] = block
    Q[4, 4] = omega_psd * T
    return Q
