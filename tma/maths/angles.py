"""Angle conventions: bearings and courses clockwise from north, radians inside the code."""

import numpy as np

from tma.runtime.jit import njit

TWO_PI = 2.0 * np.pi


def wrap_residual(angle_rad):
    """Wrap to [-pi, pi] by the nearest multiple of 2 pi (cheaper than a float modulo; the
    two conventions differ only at exactly +-pi, where a squared residual is the same): the
    difference of two bearings. Numpy arrays or numbers; ``wrap_angle`` is the same function
    compiled, for the kernels."""
    return angle_rad - TWO_PI * np.rint(angle_rad * (1.0 / TWO_PI))


wrap_angle = njit(inline="always")(wrap_residual)


def wrap_to_pi(angle_rad):
    """Wrap angles (radians) to [-pi, pi)."""
    return (np.asarray(angle_rad) + np.pi) % TWO_PI - np.pi


def wrap_to_180(angle_deg):
    """Wrap angles (degrees) to [-180, 180)."""
    return (np.asarray(angle_deg) + 180.0) % 360.0 - 180.0


def bearing_from_north(dx_m, dy_m):
    """Bearing (radians, clockwise from north) of the vector (dx east, dy north)."""
    return np.arctan2(dx_m, dy_m)


def course_from_velocity(vx_m_s, vy_m_s):
    """Course (radians in [0, 2pi), clockwise from north) of a velocity (vx east, vy north)."""
    return np.arctan2(vx_m_s, vy_m_s) % TWO_PI


def crossing_angle_deg(bearing_a_rad, bearing_b_rad):
    """The acute angle (deg, 0-90) between two lines of sight of bearings ``a`` and ``b``
    (rad): 0 where they are parallel (the platforms in line with the target), 90 where they
    are square."""
    d = np.abs(np.degrees(np.asarray(bearing_a_rad) - np.asarray(bearing_b_rad))) % 180.0
    return np.minimum(d, 180.0 - d)
