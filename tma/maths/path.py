"""A platform's path made of straight legs and constant-rate turns at constant speed,
integrated exactly (own-ship of ``bearings2d``, the vessel of ``radar2d``).

Conventions: x east, y north (m), time in s, course clockwise from north. A turn at rate
omega (rad/s) and speed V is a circular arc of radius V/omega; positions on it come from the
closed-form integral, so position is continuous and the radius exact (no Euler drift).

Leg forms: ``{course_deg, duration_s}`` (straight; without ``course_deg`` it keeps the
current course), ``{turn_to_deg, rate_deg_s, direction}`` and
``{turn_radius_m, duration_s, direction}`` (turns; ``direction`` is ``left`` or ``right``).
"""

import sys
from dataclasses import dataclass, make_dataclass

import numpy as np

from tma.config import param
from tma.errors import ConfigError

# Every key a leg may have (the module docstring's forms): its type, meaning and values.
LEG_KEYS = {
    "course_deg": (float | None, param(None, "course of a straight leg (deg clockwise from "
                                       "north); null: keep the current course", "[-360, 360]")),
    "duration_s": (float | None, param(None, "duration of a straight leg or of a turn of given "
                                       "radius (s)", "(0, 1e7)")),
    "turn_to_deg": (float | None, param(None, "course a turn ends on (deg)", "[-360, 360]")),
    "rate_deg_s": (float | None, param(None, "turn rate of a turn to a course (deg/s)",
                                       "(0, 1e7)")),
    "turn_radius_m": (float | None, param(None, "radius of a turn of given duration (m)",
                                          "(0, inf)")),
    "direction": (str | None, param(None, "direction of a turn", choices=("left", "right"))),
}


def leg_config(*keys: str) -> type:
    """The config dataclass of one leg, with the keys (of ``LEG_KEYS``, in this order) that
    a family's paths use, each None unless given: the one leg config of every scenario (a
    family lists only its keys, so its configs and their hashes hold no key it never
    uses). ``build_segments`` reads it and checks what the keys make."""
    cls = make_dataclass("LegConfig", [(key, *LEG_KEYS[key]) for key in keys])
    cls.__module__ = sys._getframe(1).f_globals["__name__"]  # the family's: picklable there
    return cls


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
    """Turn a leg list (see the module docstring) into exact segments. A leg without its own
    course starts from the previous leg's final course (or ``initial_course_deg``)."""
    if speed_m_s <= 0:
        raise ConfigError(f"path speed must be positive, got {speed_m_s} m/s")
    segments, t, x, y = [], 0.0, float(start_x_m), float(start_y_m)
    course = None if initial_course_deg is None else np.deg2rad(initial_course_deg)
    for i, leg in enumerate(legs):
        turn_to = _leg_value(leg, "turn_to_deg") is not None
        radius = _leg_value(leg, "turn_radius_m")
        if turn_to and radius is not None:
            raise ConfigError(f"legs[{i}]: give turn_to_deg or turn_radius_m, not both")
        if turn_to or radius is not None:
            if course is None:
                raise ConfigError(f"legs[{i}]: a turn needs a preceding course")
            direction = _leg_value(leg, "direction")
            if direction not in ("left", "right"):
                raise ConfigError(f"legs[{i}].direction must be 'left' or 'right'")
            sign = 1.0 if direction == "right" else -1.0
            if turn_to:
                rate_deg = _leg_value(leg, "rate_deg_s")
                if rate_deg is None or rate_deg <= 0:
                    raise ConfigError(f"legs[{i}].rate_deg_s must be positive")
                target = np.deg2rad(_leg_value(leg, "turn_to_deg"))
                angle = (sign * (target - course)) % (2 * np.pi)  # turn angle that way
                rate = sign * np.deg2rad(rate_deg)
                duration = angle / abs(rate)
            else:
                duration = _leg_value(leg, "duration_s")
                if radius <= 0 or duration is None or duration <= 0:
                    raise ConfigError(f"legs[{i}]: turn_radius_m and duration_s must be positive")
                rate = sign * speed_m_s / radius
        else:
            duration = _leg_value(leg, "duration_s")
            if duration is None or duration <= 0:
                raise ConfigError(f"legs[{i}].duration_s must be positive, got {duration}")
            if _leg_value(leg, "course_deg") is not None:
                course = np.deg2rad(_leg_value(leg, "course_deg"))
            elif course is None:
                raise ConfigError(f"legs[{i}]: the first leg needs course_deg")
            rate = 0.0
        seg = Segment(t, x, y, course, float(duration), rate)
        segments.append(seg)
        x, y = _positions_on(seg, speed_m_s, np.array([duration]))
        x, y, t = float(x[0]), float(y[0]), t + duration
        course = course + rate * duration
    if not segments:
        raise ConfigError("legs: a path needs at least one leg")
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


class LegPath:
    """Exact path at constant speed. ``position(t)`` for any times within [0, duration]."""

    def __init__(self, start_x_m, start_y_m, speed_m_s, legs, initial_course_deg=None):
        self.speed_m_s = float(speed_m_s)
        self.segments = build_segments(start_x_m, start_y_m, speed_m_s, legs, initial_course_deg)
        self._t0 = np.array([s.t0_s for s in self.segments])
        last = self.segments[-1]
        self.duration_s = last.t0_s + last.duration_s

    def position(self, t_s):
        """Own-ship (x, y) in metres at times ``t_s`` (array), each in [0, duration]."""
        t_s = np.asarray(t_s, dtype=float)
        if np.any(t_s < 0) or np.any(t_s > self.duration_s * (1 + 1e-12)):
            raise ConfigError(f"path times must lie in [0, {self.duration_s:g}] s")
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
