"""How real vessels move over a window, and the pairs of them a bearings-only scenario uses.

Rules (those of the Solent cases, ``tests/data/ais/build_cases.py``; angles in degrees
clockwise from north, SI units, positions on one plane of the recording):

- the *motion samples* of a vessel over [t0, t1] are its centred ``VELOCITY_SPAN_S`` (120 s)
  mean velocities every ``SAMPLE_S`` (10 s) from t0 + 60 s to t1 - 60 s; a sample has a
  course only where its speed is at least ``MIN_SPEED_M_S`` (1 m/s);
- ``course_change_deg``: total course change, the sum over the runs of samples with a course
  of the range of their unwrapped course, plus across each stop the course difference from
  before to after it; ``speed_change_frac`` = (max - min) / mean speed; ``course_dev_deg`` and
  ``speed_dev_frac``: the largest deviation from the mean course and speed;
- a target is **manoeuvring** when its course changes by more than 20 deg or its speed by
  more than 30 %, it is underway at 80 % of the samples, its last sample has a course and
  it settled (course within 6 deg, speed within 10 % of the last sample's) 180 s or more
  before the window's end; **steady** when underway throughout, within 10 deg of its mean
  course and 20 % of its mean speed; otherwise it is not used;
- a **pair** is an own-ship underway at half the samples or more that turns by
  ``PairRules.min_turn_deg`` (45) or more over the window, and a target of either class
  ``min_range_m``-``max_range_m`` from it at every bearing time (every 5 s), with no report
  gap over ``max_gap_own_s`` (60 s) or ``max_gap_target_s`` (90 s); windows start on every
  whole minute and last ``window_s``. Of the windows of one (own-ship, target), the one with
  the largest own-ship turn is kept (ties: the earlier); pairs are ordered by start time,
  own-ship MMSI, target MMSI.
"""

from dataclasses import dataclass

import numpy as np

from tma.ais.tracks import PlaneTrack
from tma.maths.angles import course_from_velocity, wrap_to_180, wrap_to_pi

VELOCITY_SPAN_S = 120.0
SAMPLE_S = 10.0
MIN_SPEED_M_S = 1.0
STEADY_COURSE_DEG, STEADY_SPEED_FRAC = 10.0, 0.20
MANOEUVRE_COURSE_DEG, MANOEUVRE_SPEED_FRAC = 20.0, 0.30
SETTLE_COURSE_DEG, SETTLE_SPEED_FRAC = 6.0, 0.10
MIN_LAST_LEG_S = 180.0
MIN_TARGET_MOVING_FRAC, MIN_OWN_MOVING_FRAC = 0.8, 0.5
RANGE_STEP_S = 5.0  # the range rule is checked at these bearing times
START_STEP_S = 60.0


@dataclass(frozen=True)
class Motion:
    """Motion samples of one vessel over a window: times (s), course (deg, NaN below
    ``MIN_SPEED_M_S``), speed (m/s)."""

    t: np.ndarray
    course_deg: np.ndarray
    speed_m_s: np.ndarray

    @property
    def course_change_deg(self) -> float:
        ok = np.flatnonzero(np.isfinite(self.course_deg))
        if len(ok) < 2:
            return float("nan")
        runs = np.split(ok, np.flatnonzero(np.diff(ok) > 1) + 1)
        total = 0.0
        for i, run in enumerate(runs):
            u = np.degrees(np.unwrap(np.radians(self.course_deg[run])))
            total += float(u.max() - u.min())
            if i:
                step = self.course_deg[run[0]] - self.course_deg[runs[i - 1][-1]]
                total += abs(wrap_to_180(step))
        return total

    @property
    def course_dev_deg(self) -> float:
        c = np.radians(self.course_deg[np.isfinite(self.course_deg)])
        if len(c) == 0:
            return float("nan")
        mean = np.arctan2(np.sin(c).mean(), np.cos(c).mean())
        return float(np.degrees(np.max(np.abs(wrap_to_pi(c - mean)))))

    @property
    def speed_dev_frac(self) -> float:
        mean = float(np.mean(self.speed_m_s))
        return float(np.max(np.abs(self.speed_m_s - mean)) / mean) if mean > 0 else 0.0

    @property
    def moving_frac(self) -> float:
        return float(np.mean(np.isfinite(self.course_deg)))

    @property
    def speed_change_frac(self) -> float:
        mean = float(np.mean(self.speed_m_s))
        return float((self.speed_m_s.max() - self.speed_m_s.min()) / mean) if mean > 0 else 0.0


def motion(track: PlaneTrack, t0: float, t1: float) -> Motion:
    """Motion samples of ``track`` over [t0, t1] (module docstring)."""
    half = VELOCITY_SPAN_S / 2
    t = np.arange(t0 + half, t1 - half + 1e-6, SAMPLE_S)
    ve, vn = track.mean_velocity(t - half, t + half)
    speed = np.hypot(ve, vn)
    course = np.where(speed >= MIN_SPEED_M_S, np.degrees(course_from_velocity(ve, vn)), np.nan)
    return Motion(t, course, speed)


def settle_time(m: Motion) -> float:
    """The first sample of the final run of samples settled on the last one's course and
    speed."""
    ref_c, ref_v = m.course_deg[-1], m.speed_m_s[-1]
    dc = np.abs(wrap_to_180(m.course_deg - ref_c))
    settled = (dc <= SETTLE_COURSE_DEG) & (np.abs(m.speed_m_s - ref_v) <= SETTLE_SPEED_FRAC * ref_v)
    bad = np.flatnonzero(~settled)  # the last sample has a course (``classify``): settled
    return float(m.t[bad[-1] + 1]) if len(bad) else float(m.t[0])


def classify(m: Motion, t1: float) -> str | None:
    """``steady``, ``manoeuvring`` or None (module docstring)."""
    if m.course_change_deg > MANOEUVRE_COURSE_DEG or m.speed_change_frac > MANOEUVRE_SPEED_FRAC:
        if m.moving_frac < MIN_TARGET_MOVING_FRAC or not m.speed_m_s[-1] >= MIN_SPEED_M_S:
            return None
        return "manoeuvring" if t1 - settle_time(m) >= MIN_LAST_LEG_S else None
    if (m.speed_m_s.min() >= MIN_SPEED_M_S and m.course_dev_deg <= STEADY_COURSE_DEG
            and m.speed_dev_frac <= STEADY_SPEED_FRAC):
        return "steady"
    return None


@dataclass(frozen=True)
class PairRules:
    """What makes an own-ship and a target a pair (module docstring)."""

    window_s: float = 1200.0
    min_turn_deg: float = 45.0
    min_range_m: float = 1000.0
    max_range_m: float = 19000.0
    max_gap_own_s: float = 60.0
    max_gap_target_s: float = 90.0


@dataclass(frozen=True)
class Pair:
    """An own-ship and a target over [t0_s, t0_s + duration_s] (s on the recording's clock),
    the own-ship's turn (deg) and the target's class."""

    own_mmsi: int
    target_mmsi: int
    t0_s: float
    duration_s: float
    own_turn_deg: float
    kind: str


def find_pairs(ships: dict[int, PlaneTrack], rules: PairRules,
               first_start_s: float = 0.0) -> list[Pair]:
    """Every (own-ship, target) of ``ships`` that meets ``rules`` in some window starting at
    ``first_start_s`` + k minutes (the whole UTC minutes), its best window each."""
    if not ships:
        return []
    t_last = max(s.t_s[-1] for s in ships.values())
    starts = np.arange(first_start_s, t_last - rules.window_s + 1e-6, START_STEP_S)
    steps = RANGE_STEP_S * np.arange(int(round(rules.window_s / RANGE_STEP_S)) + 1)
    best: dict[tuple[int, int], Pair] = {}
    for own in ships.values():
        for t0 in starts:
            t1 = t0 + rules.window_s
            if own.max_gap(t0, t1) > rules.max_gap_own_s:
                continue
            m = motion(own, t0, t1)
            if m.moving_frac < MIN_OWN_MOVING_FRAC or not m.course_change_deg >= rules.min_turn_deg:
                continue
            turn = m.course_change_deg
            ox, oy = own.at(t0 + steps)
            for target in ships.values():
                if target.mmsi == own.mmsi or target.max_gap(t0, t1) > rules.max_gap_target_s:
                    continue
                tx, ty = target.at(t0 + steps)
                r = np.hypot(tx - ox, ty - oy)
                if not (r.min() >= rules.min_range_m and r.max() <= rules.max_range_m):
                    continue
                kind = classify(motion(target, t0, t1), t1)
                key = (own.mmsi, target.mmsi)
                if kind is not None and (key not in best or turn > best[key].own_turn_deg):
                    best[key] = Pair(own.mmsi, target.mmsi, float(t0), float(rules.window_s),
                                     float(turn), kind)
    return sorted(best.values(), key=lambda p: (p.t0_s, p.own_mmsi, p.target_mmsi))
