"""Scenario ``radar2d``: a small fast boat turning sharply in front of a coastal radar.

See ``docs/families.md``. The vessel starts at the origin heading +x (east) at
``speed_m_s`` and follows ``legs`` (straight, then a left turn of radius 300 m, then
straight). Scans every ``scan_period_s``; each Monte Carlo run is one track with its own
measurement noise: isotropic Cartesian (``sigma_m`` per axis) or ``polar`` (range and
bearing noise at a radar at ``radar_xy_m``, converted to Cartesian plots).
"""

from dataclasses import dataclass

import numpy as np

from tma.ais.recording import RealWindows
from tma.config import param, require
from tma.errors import ConfigError
from tma.families.radar2d import real_motion
from tma.families.radar2d.log import RadarLog, read_radar_log, write_radar_log
from tma.io import arrow
from tma.maths.path import LegPath, leg_config
from tma.runtime.sharding import shard_rng, shard_track_ids
from tma.scenario import ScenarioConfig

FAMILY = "radar2d"
# Sanity bounds: every run's scans are held in memory at once; a coastal radar's horizon is
# tens of km, so a path of a million km is a typo, and one that overflows float64 is worse.
MAX_SCANS = 100_000
MAX_PATH_M = 1e9


# {duration_s} straight on, or {turn_radius_m, duration_s, direction}
LegConfig = leg_config("duration_s", "course_deg", "turn_radius_m", "direction")


def _default_legs():
    return [LegConfig(duration_s=45.0),
            LegConfig(turn_radius_m=300.0, duration_s=45.0, direction="left"),
            LegConfig(duration_s=30.0)]


@dataclass
class Config(ScenarioConfig):
    family: str = FAMILY
    n_tracks: int = 1000  # Monte Carlo runs
    speed_m_s: float = param(10.0, "the vessel's speed (m/s)", "(0, inf)")
    initial_course_deg: float = param(90.0, "its course at t = 0 (deg clockwise from north: 90 "
                                      "heads +x)", "[-360, 360]")
    legs: list[LegConfig] = param(doc="the vessel's legs (tma.maths.path)", factory=_default_legs)
    scan_period_s: float = param(3.0, "radar scan period (s)", "(0, inf)")
    noise: str = param("cartesian", "plot noise: isotropic cartesian, or polar at the radar",
                       choices=("cartesian", "polar"))
    sigma_m: float = param(10.0, "cartesian noise: standard deviation per axis (m)",
                           "(0, inf)")
    radar_xy_m: list[float] = param(doc="polar noise: the radar's position x, y (m)",
                                    factory=lambda: [0.0, -4000.0])
    range_sd_m: float = param(6.0, "polar noise: range standard deviation (m)", "(0, inf)")
    bearing_sd_deg: float = param(0.18, "polar noise: bearing standard deviation (deg)",
                                  "(0, inf)")
    seed: int = 20260103
    shard_size: int = 500
    real: RealWindows = param(doc="the vessel from an AIS recording instead (real_motion.py)",
                              factory=RealWindows)

    def __post_init__(self):
        super().__post_init__()
        w = self.where
        require(len(self.radar_xy_m) == 2, w, "radar_xy_m needs two values (x, y)")
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # checked just below
                duration = vessel_path(self).duration_s
        except ConfigError as exc:
            raise ConfigError(f"{w}: {exc}") from None
        require(self.speed_m_s * duration <= MAX_PATH_M, w,
                f"speed_m_s x the legs' duration must be <= {MAX_PATH_M:g} m")
        # the IMM starts from the two-point line of the first two plots, then filters
        require(2 * self.scan_period_s <= duration <= MAX_SCANS * self.scan_period_s, w,
                f"the legs must last 2 to {MAX_SCANS} x scan_period_s (3 scans or more)")


def label(cfg: Config) -> str:
    if cfg.real.file is not None:
        return real_motion.label(cfg)
    return f"v{cfg.speed_m_s:g}-{cfg.noise}-n{cfg.n_tracks}"


def vessel_path(cfg: Config) -> LegPath:
    return LegPath(0.0, 0.0, cfg.speed_m_s, cfg.legs, cfg.initial_course_deg)


def scan_times(cfg: Config, path: LegPath) -> np.ndarray:
    n = int(np.floor(path.duration_s / cfg.scan_period_s + 1e-9)) + 1
    return np.arange(n) * cfg.scan_period_s


def sensor_metadata(cfg: Config) -> dict:
    return {"noise": cfg.noise, "sigma_m": cfg.sigma_m, "radar_x_m": cfg.radar_xy_m[0],
            "radar_y_m": cfg.radar_xy_m[1], "range_sd_m": cfg.range_sd_m,
            "bearing_sd_deg": cfg.bearing_sd_deg}


def simulate_shard(cfg: Config, shard_index: int):
    if cfg.real.file is not None:  # real vessel motion from AIS (real_motion.py)
        return real_motion.simulate_shard(cfg, shard_index, sensor_metadata(cfg))
    track_id = shard_track_ids(cfg, shard_index)
    n = track_id.size
    rng = shard_rng(cfg, shard_index)
    path = vessel_path(cfg)
    t = scan_times(cfg, path)
    x, y = path.position(t)
    noise = rng.standard_normal((n, t.size, 2))
    if cfg.noise == "cartesian":
        plots = np.stack([x, y], axis=-1) + cfg.sigma_m * noise
    else:
        rx, ry = cfg.radar_xy_m
        rng_m = np.hypot(x - rx, y - ry) + cfg.range_sd_m * noise[..., 0]
        bearing = np.arctan2(x - rx, y - ry) + np.deg2rad(cfg.bearing_sd_deg) * noise[..., 1]
        plots = np.stack([rx + rng_m * np.sin(bearing), ry + rng_m * np.cos(bearing)], axis=-1)
    log = RadarLog(t, track_id, plots, sensor_metadata(cfg),
                   cfg.epoch_ns)
    course = path.course(t)
    truth = arrow.table({
        "track_id": np.repeat(track_id, t.size), "step": np.tile(np.arange(t.size), n),
        "t_s": np.tile(t, n), "x_m": np.tile(x, n), "y_m": np.tile(y, n),
        "vx_m_s": np.tile(cfg.speed_m_s * np.sin(course), n),
        "vy_m_s": np.tile(cfg.speed_m_s * np.cos(course), n),
    })
    return log, truth


def write_log(path, log: RadarLog, metadata=None) -> int:
    return write_radar_log(path, log, metadata)


def read_log(path) -> RadarLog:
    return read_radar_log(path)
