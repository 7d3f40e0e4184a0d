"""Own-ship (observer) path made of straight legs and constant-rate turns, integrated exactly.

Conventions: x east, y north (m), time in s, course clockwise from north. A turn at rate
omega (rad/s) and speed V is a circular arc of radius V/omega; positions on it come from the
closed-form integral, so position is continuous and the radius exact (no Euler drift).
"""

from dataclasses import dataclass

import numpy as np

from tma.errors import ConfigError


@dataclass(frozen=True)
class Segment:
    """One leg: start time/position/course, duration and signed turn rate (0 = straight)."""

    t0_s: float
    x0_m: float
    y0_m: float
    course0_rad: float
    duration_s: float
    rate_rad_s: float  # > 0 turns right (clockwise), < 0 left


def _leg_value(leg, key):
    return leg.get(key) if isinstance(leg, dict) else getattr(leg, key, None)


def build_segments(start_x_m, start_y_m, speed_m_s, legs, initial_course_deg=None):
    """Turn a leg list into exact segments.

    Each leg is either ``{course_deg, duration_s}`` (straight) or
    ``{turn_to_deg, rate_deg_s, direction}`` with ``direction`` ``"left"`` or ``"right"``.
    A turn starts from the previous leg's course (or ``initial_course_deg``).
    """
    if speed_m_s <= 0:
        raise ConfigError(f"observer speed must be positive, got {speed_m_s} m/s")
    segments, t, x, y = [], 0.0, float(start_x_m), float(start_y_m)
    course = None if initial_course_deg is None else np.deg2rad(initial_course_deg)
    for i, leg in enumerate(legs):
        straight = _leg_value(leg, "course_deg") is not None
        turn = _leg_value(leg, "turn_to_deg") is not None
        if straight == turn:
            raise ConfigError(
                f"observer leg {i}: give either course_deg + duration_s or "
                f"turn_to_deg + rate_deg_s + direction, got {dict(leg)!r}"
            )
        if straight:
            duration = _leg_value(leg, "duration_s")
            if duration is None or duration <= 0:
                raise ConfigError(f"observer leg {i}: duration_s must be positive")
            course, rate = np.deg2rad(_leg_value(leg, "course_deg")), 0.0
        else:
            if course is None:
                raise ConfigError(f"observer leg {i}: a turn needs a preceding course")
            rate_deg = _leg_value(leg, "rate_deg_s")
            direction = _leg_value(leg, "direction")
            if rate_deg is None or rate_deg <= 0:
                raise ConfigError(f"observer leg {i}: rate_deg_s must be positive")
            if direction not in ("left", "right"):
                raise ConfigError(f"observer leg {i}: direction must be 'left' or 'right'")
            target = np.deg2rad(_leg_value(leg, "turn_to_deg"))
            sign = 1.0 if direction == "right" else -1.0
            angle = (sign * (target - course)) % (2 * np.pi)  # turn angle in that direction
            rate = sign * np.deg2rad(rate_deg)
            duration = angle / abs(rate)
        seg = Segment(t, x, y, course, float(duration), rate)
        segments.append(seg)
        x, y = _positions_on(seg, speed_m_s, np.array([duration]))
        x, y, t = float(x[0]), float(y[0]), t + duration
        course = course + rate * duration
    if not segments:
        raise ConfigError("observer needs at least one leg")
    return segments


def _positions_on(seg, speed_m_s, tau_s):
    """Positions at times ``tau_s`` after the segment start (closed form)."""
    c0 = seg.course0_rad
    if seg.rate_rad_s == 0.0:
        step = speed_m_s * tau_s
        return seg.x0_m + step * np.sin(c0), seg.y0_m + step * np.cos(c0)
    radius = speed_m_s / seg.rate_rad_s  # signed
    c = c0 + seg.rate_rad_s * tau_s
    return (seg.x0_m + radius * (np.cos(c0) - np.cos(c)),
            seg.y0_m + radius * (np.sin(c) - np.sin(c0)))


class ObserverPath:
    """Exact own-ship path. ``position(t)`` for any times within [0, duration]."""

    def __init__(self, start_x_m, start_y_m, speed_m_s, legs):
        self.speed_m_s = float(speed_m_s)
        self.segments = build_segments(start_x_m, start_y_m, speed_m_s, legs)
        self._t0 = np.array([s.t0_s for s in self.segments])
        last = self.segments[-1]
        self.duration_s = last.t0_s + last.duration_s

    def position(self, t_s):
        """Own-ship (x, y) in metres at times ``t_s`` (array), each in [0, duration]."""
        t_s = np.asarray(t_s, dtype=float)
        if np.any(t_s < 0) or np.any(t_s > self.duration_s * (1 + 1e-12)):
            raise ConfigError(f"observer times must lie in [0, {self.duration_s:g}] s")
        which = np.clip(np.searchsorted(self._t0, t_s, side="right") - 1, 0, len(self._t0) - 1)
        x, y = np.empty_like(t_s), np.empty_like(t_s)
        for i, seg in enumerate(self.segments):
            sel = which == i
            x[sel], y[sel] = _positions_on(seg, self.speed_m_s, t_s[sel] - seg.t0_s)
        return x, y

    def course(self, t_s):
        """Course (radians, clockwise from north) at times ``t_s``."""
        t_s = np.asarray(t_s, dtype=float)
        which = np.clip(np.searchsorted(self._t0, t_s, side="right") - 1, 0, len(self._t0) - 1)
        c0 = np.array([s.course0_rad for s in self.segments])[which]
        rate = np.array([s.rate_rad_s for s in self.segments])[which]
        return (c0 + rate * (t_s - self._t0[which])) % (2 * np.pi)
