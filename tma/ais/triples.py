"""Triples of real vessels: a target and two platforms that take its bearings, their lines of
sight crossing (bearings-only TMA from two platforms, issue 39).

Rules (angles in degrees clockwise from north, SI units, positions on one plane of the
recording; the target's classes and motion samples those of ``tma.ais.pairs``):

- the **target** is steady or manoeuvring over the window (``tma.ais.pairs.classify``), with
  no report gap over ``TripleRules.max_gap_target_s``;
- each **platform** is another vessel, ``min_range_m``-``max_range_m`` (1-15 km) from the
  target at every time of the window's grid (every ``grid_s``, 10 s, both ends included), with
  no report gap over ``max_gap_platform_s``; it need not move, let alone turn;
- the two platforms' **lines of sight cross**: the acute angle between the bearings from
  each platform to the target (``crossing_angle_deg``) lies in ``min_cross_deg``-
  ``max_cross_deg`` (40-89) at some time of the grid;
- windows start on every whole minute (of the recording's clock) and last ``window_s``; of
  the windows of one target and one (unordered) pair of platforms the earliest is kept.

Selection (``select``, deterministic): each target's candidates are ranked by start time
(then the platforms' MMSIs); all targets' first candidates come before any second one, and so
on (ties: start time, target MMSI, platforms' MMSIs); a candidate is accepted while its
target has fewer than ``max_per_target`` triples and each platform has taken part in fewer
than ``max_per_platform``. Within a triple the platforms are ordered by MMSI: the first is
the reference (``Triple.platforms[0]``).
"""

from dataclasses import dataclass

import numpy as np

from tma.ais.pairs import START_STEP_S, classify, motion
from tma.ais.tracks import PlaneTrack
from tma.maths.angles import bearing_from_north, crossing_angle_deg


@dataclass(frozen=True)
class TripleRules:
    """What makes a target and two platforms a triple (module docstring)."""

    window_s: float = 1200.0
    min_range_m: float = 1000.0
    max_range_m: float = 15000.0
    max_gap_platform_s: float = 60.0
    max_gap_target_s: float = 90.0
    min_cross_deg: float = 40.0
    max_cross_deg: float = 89.0
    grid_s: float = 10.0
    max_per_target: int = 3
    max_per_platform: int = 6


@dataclass(frozen=True)
class Triple:
    """A target seen from two platforms (MMSIs; ``platforms[0]`` the reference) over [t0_s,
    t0_s + duration_s] (s on the recording's clock); the target's class; the largest crossing
    angle of the lines of sight over the window's grid (deg, acute)."""

    target_mmsi: int
    platforms: tuple[int, int]
    t0_s: float
    duration_s: float
    kind: str
    max_cross_deg: float


def find_triples(ships: dict[int, PlaneTrack], rules: TripleRules,
                 first_start_s: float = 0.0) -> list[Triple]:
    """Every (target, pair of platforms) of ``ships`` that meets ``rules`` in some window
    starting at ``first_start_s`` + k minutes, its earliest window each, ordered by start
    time, target and platforms."""
    if not ships:
        return []
    t_last = max(s.t_s[-1] for s in ships.values())
    starts = np.arange(first_start_s, t_last - rules.window_s + 1e-6, START_STEP_S)
    grid = rules.grid_s * np.arange(int(np.floor(rules.window_s / rules.grid_s + 1e-9)) + 1)
    found: dict[tuple[int, int, int], Triple] = {}
    for t0 in starts:
        t1 = t0 + rules.window_s
        covered = {m: s for m, s in ships.items()
                   if s.max_gap(t0, t1) <= max(rules.max_gap_platform_s, rules.max_gap_target_s)}
        where = {m: s.at(t0 + grid) for m, s in covered.items()}
        for target in covered.values():
            if target.max_gap(t0, t1) > rules.max_gap_target_s:
                continue
            kind = classify(motion(target, t0, t1), t1)
            if kind is None:
                continue
            tx, ty = where[target.mmsi]
            near, bearings = [], []
            for m, (x, y) in where.items():
                if m == target.mmsi or covered[m].max_gap(t0, t1) > rules.max_gap_platform_s:
                    continue
                r = np.hypot(tx - x, ty - y)
                if r.min() >= rules.min_range_m and r.max() <= rules.max_range_m:
                    near.append(m)
                    bearings.append(bearing_from_north(tx - x, ty - y))
            if len(near) < 2:
                continue
            b = np.array(bearings)
            cross = crossing_angle_deg(b[:, None, :], b[None, :, :])  # (P, P, grid)
            crossing = ((cross >= rules.min_cross_deg) & (cross <= rules.max_cross_deg)).any(-1)
            for i, j in zip(*np.nonzero(np.triu(crossing, 1)), strict=True):
                a, c = sorted((near[i], near[j]))
                key = (target.mmsi, a, c)
                if key not in found:
                    found[key] = Triple(target.mmsi, (a, c), float(t0), float(rules.window_s),
                                        kind, float(cross[i, j].max()))
    return sorted(found.values(), key=lambda s: (s.t0_s, s.target_mmsi, s.platforms))


def select(triples: list[Triple], rules: TripleRules) -> list[Triple]:
    """The triples ``select`` keeps of ``find_triples``' (module docstring), ordered by start
    time, target and platforms."""
    rank: dict[int, int] = {}
    ranked = []
    for s in sorted(triples, key=lambda s: (s.target_mmsi, s.t0_s, s.platforms)):
        rank[s.target_mmsi] = rank.get(s.target_mmsi, -1) + 1
        ranked.append((rank[s.target_mmsi], s))
    per_target: dict[int, int] = {}
    per_platform: dict[int, int] = {}
    kept = []
    for _, s in sorted(ranked, key=lambda r: (r[0], r[1].t0_s, r[1].target_mmsi,
                                              r[1].platforms)):
        if per_target.get(s.target_mmsi, 0) >= rules.max_per_target or any(
                per_platform.get(p, 0) >= rules.max_per_platform for p in s.platforms):
            continue
        kept.append(s)
        per_target[s.target_mmsi] = per_target.get(s.target_mmsi, 0) + 1
        for p in s.platforms:
            per_platform[p] = per_platform.get(p, 0) + 1
    return sorted(kept, key=lambda s: (s.t0_s, s.target_mmsi, s.platforms))
