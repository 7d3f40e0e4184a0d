"""An AIS recording as the real motion of simulated scenarios (scenario option group
``real``): read once per process, its ships on one plane, the pairs or windows a family uses.

The plane is the tangent plane at the median position of the recording's reports and its
clock starts at the first whole UTC minute of the recording (``AisRecording``); the sensors
are simulated on it as in the family's own scenario. A family's scenario declares its group
(``RealPairs`` for an own-ship and its targets, ``RealWindows`` for targets before a fixed
sensor) and, when ``real.file`` is set, simulates its shards from it (its ``real_motion``
module); the dataset's name carries the recording's sha256, so another recording under the
same path is another dataset.
"""

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the pairs' search (and the AIS readers it needs) loads where it is used:
    # every command registers the config group RealPairs, few read a recording
    from tma.ais.pairs import Pair, PairRules
from tma.config import param
from tma.errors import ConfigError
from tma.io.atomic import sha256_file
from tma.maths.angles import course_from_velocity

MINUTE_NS = 60 * 10**9
SMOOTH_S = 30.0  # windows: speed and course from the mean velocity over this span (s)


@dataclass(frozen=True)
class AisRecording:
    """A recording's ships (``PlaneTrack`` by MMSI) on its plane (``origin_deg``) and clock
    (``epoch_ns``, UTC ns of t = 0)."""

    path: str
    sha256: str
    origin_deg: tuple[float, float]
    epoch_ns: int
    ships: dict


def recording_of(path) -> AisRecording:
    """The recording at ``path`` (read once per process and content)."""
    path = Path(str(path))
    if not path.is_file():
        raise ConfigError(f"real.file={path}: no such file (an AIS recording: decoded position "
                          "reports or NMEA; tests/data/ais/positions.csv.gz is one)")
    return _load(str(path), sha256_file(path))


@functools.lru_cache(maxsize=4)
def _load(path: str, sha256: str) -> AisRecording:
    from tma.ais.reports import read_reports
    from tma.ais.tracks import vessel_tracks

    reports = read_reports(path)
    origin = (float(np.median(reports.lat_deg)), float(np.median(reports.lon_deg)))
    epoch = -(-int(reports.t_ns.min()) // MINUTE_NS) * MINUTE_NS  # the first whole minute
    ships = {m: v.on_plane(origin, epoch) for m, v in vessel_tracks(reports).items()}
    return AisRecording(path, sha256, origin, epoch,
                        {m: s for m, s in ships.items() if s.t_s.size >= 2})


@dataclass
class RealPairs:
    """Own-ship and target from an AIS recording (``tma.ais.pairs``): shard k is pair k
    (cycling), its tracks Monte Carlo draws of the sensor's noise."""

    file: str | None = param(None, "an AIS recording (decoded reports or NMEA) whose ships "
                             "replace the simulated own-ship and targets (tma.ais.pairs); null: "
                             "simulated motion")
    window_s: float = param(1200.0, "each pair's observation (s)", "[300, 86400]")
    min_turn_deg: float = param(45.0, "own-ship turns by at least this over the window (deg)",
                                "[0, 3600]")
    min_range_m: float = param(1000.0, "the target stays at least this far (m)", "[0, 1e6)")
    max_range_m: float = param(19000.0, "and at most this far (m)", "(0, 1e6]")
    max_gap_own_s: float = param(60.0, "longest gap in own-ship's AIS over the window (s)",
                                 "(0, 3600]")
    max_gap_target_s: float = param(90.0, "longest gap in the target's AIS (s)", "(0, 3600]")

    def rules(self) -> "PairRules":
        from tma.ais.pairs import PairRules

        return PairRules(self.window_s, self.min_turn_deg, self.min_range_m, self.max_range_m,
                         self.max_gap_own_s, self.max_gap_target_s)


def pairs_of(real: RealPairs) -> tuple[AisRecording, list["Pair"]]:
    """The recording of ``real.file`` and its pairs under ``real``'s rules (ConfigError when
    there is none)."""
    rec = recording_of(real.file)
    found = _pairs(rec.path, rec.sha256, real.rules())
    if not found:
        raise ConfigError(f"real.file={real.file}: no own-ship turns by {real.min_turn_deg:g} deg "
                          f"within {real.window_s:g} s with a target {real.min_range_m:g}-"
                          f"{real.max_range_m:g} m away (real.* sets the rules)")
    return rec, found


@functools.lru_cache(maxsize=8)
def _pairs(path: str, sha256: str, rules: "PairRules") -> list["Pair"]:
    from tma.ais.pairs import find_pairs

    return find_pairs(_load(path, sha256).ships, rules)


def label_of(file) -> str:
    """The part of a dataset's name that says which recording: ``real-<sha256[:8]>``."""
    return f"real-{recording_of(file).sha256[:8]}"


# -- targets before a fixed sensor ------------------------------------------------------------

@dataclass
class RealWindows:
    """Targets from an AIS recording before a fixed sensor at (``sensor_lat``,
    ``sensor_lon``): every window of ``window_s`` (back to back, from the recording's first
    whole minute) in which a vessel is underway, within ``max_range_m`` and reported without
    a gap over ``max_gap_s``; run k is window k (cycling), with its own noise."""

    file: str | None = param(None, "an AIS recording (decoded reports or NMEA) whose vessels "
                             "replace the simulated one (tma.ais.recording); null: simulated "
                             "motion")
    window_s: float = param(120.0, "each run's window (s)", "[10, 86400]")
    sensor_lat: float | None = param(None, "the sensor's latitude (deg, WGS84); null: the "
                                     "median of the recording's reports", "[-90, 90]")
    sensor_lon: float | None = param(None, "the sensor's longitude (deg); null: as sensor_lat",
                                     "[-180, 180]")
    max_range_m: float = param(15000.0, "the vessel stays within this range of the sensor (m)",
                               "(0, 1e6]")
    max_gap_s: float = param(30.0, "longest gap in the vessel's AIS over the window (s)",
                             "(0, 3600]")
    min_speed_m_s: float = param(1.0, "the vessel is underway: its mean speed over any 30 s "
                                 "of the window is at least this (m/s)", "[0, 1e3)")
    turn_deg: float = param(20.0, "a window whose course (30-s mean velocities) changes by more "
                            "is a turn (deg)", "(0, 3600]")


@dataclass(frozen=True)
class Window:
    """One vessel over [t0_s, t0_s + duration_s] on the recording's clock; its course change
    over the window (deg, the range of the unwrapped course of its 30-s mean velocities)."""

    mmsi: int
    t0_s: float
    duration_s: float
    course_change_deg: float


def windows_of(real: RealWindows, scan_period_s: float) -> tuple[AisRecording, list[Window],
                                                                  np.ndarray]:
    """The recording, its windows under ``real``'s rules on a scan grid of ``scan_period_s``,
    and the sensor's position (m) on the recording's plane."""
    rec = recording_of(real.file)
    if (real.sensor_lat is None) != (real.sensor_lon is None):
        raise ConfigError("real.sensor_lat and real.sensor_lon go together: give both or neither")
    found, sensor = _windows(rec.path, rec.sha256, real.window_s, real.sensor_lat,
                             real.sensor_lon, real.max_range_m, real.max_gap_s,
                             real.min_speed_m_s, scan_period_s)
    if not found:
        raise ConfigError(f"real.file={real.file}: no vessel is underway within "
                          f"{real.max_range_m:g} m of the sensor for {real.window_s:g} s without "
                          f"an AIS gap over {real.max_gap_s:g} s (real.* sets the rules)")
    return rec, found, sensor


@functools.lru_cache(maxsize=8)
def _windows(path, sha256, window_s, lat, lon, max_range_m, max_gap_s, min_speed, scan_period_s):
    from tma.maths.geo import geodetic_to_local

    rec = _load(path, sha256)
    sensor = (np.zeros(2) if lat is None else
              np.array([float(v) for v in geodetic_to_local(lat, lon, rec.origin_deg)]))
    t_last = max(s.t_s[-1] for s in rec.ships.values())
    starts = np.arange(0.0, t_last - window_s + 1e-6, window_s)
    steps = scan_period_s * np.arange(int(np.floor(window_s / scan_period_s + 1e-9)) + 1)
    found = []
    for ship in rec.ships.values():
        for t0 in starts:
            if ship.max_gap(t0, t0 + window_s) > max_gap_s:
                continue
            x, y = ship.at(t0 + steps)
            if np.hypot(x - sensor[0], y - sensor[1]).max() > max_range_m:
                continue
            mid = t0 + steps[(steps >= SMOOTH_S / 2) & (steps <= window_s - SMOOTH_S / 2)]
            vx, vy = ship.mean_velocity(mid - SMOOTH_S / 2, mid + SMOOTH_S / 2)
            if not mid.size or np.hypot(vx, vy).min() < min_speed:
                continue
            course = np.unwrap(course_from_velocity(vx, vy))
            found.append(Window(ship.mmsi, float(t0), float(window_s),
                                float(np.degrees(course.max() - course.min()))))
    found.sort(key=lambda w: (w.t0_s, w.mmsi))
    return found, sensor

