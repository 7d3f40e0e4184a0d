"""Scenario ``bearings2d``: a constant-velocity target observed by a manoeuvring own-ship;
with ``target.*``, targets that manoeuvre or wander like ships (``target_motion.py``).

See ``docs/families.md``. x east, y north (m); bearings clockwise from north,
degrees in config and log. Each shard draws its targets and its noise from
``SeedSequence(seed, spawn_key=(shard,))``, so a shard's content depends neither on the number
of workers nor on sigma: datasets at different sigma share targets and standardised noise
(common random numbers), which makes the success-rate curves smooth in sigma.

Outliers (``outliers.prob`` > 0): each bearing is, independently with probability ``prob``,
replaced by a wild reading drawn uniformly on the circle [0, 360) deg (a false detection that
carries no information about the target). Which bearings and their values come from the
shard's own child stream ``SeedSequence(seed, spawn_key=(shard, OUTLIER_STREAM))``, drawn for
every bearing whatever ``prob`` (a bearing is replaced when its uniform draw is below
``prob``): the targets and noise do not change with ``prob`` (``prob`` = 0 leaves a dataset
byte for byte as without the option) and the outliers at a smaller ``prob`` are a subset of
those at a larger one (common random numbers along the outlier axis too).

Every log declares the targets' motion model it was made with (``BearingsLog.
accel_psd_m2_s3``: 0 for constant velocity) unless the targets manoeuvre or
``target.declared`` is false: estimators then treat it as a recording. Targets that move
(``target.moving``) have as truth their state at the last bearing: ``x0_m``... ``vy_m_s``
are the straight line through it, ``course_deg``, ``speed_m_s`` their values then, and the
truth adds ``manoeuvring``, the last manoeuvre's ``manoeuvre_start_s``,
``manoeuvre_end_s``, ``course_change_deg`` (signed, > 0 right) and ``speed_change_rel``, and
``n_manoeuvres``, how many started within the observation.
"""

from dataclasses import dataclass

import numpy as np

from tma.ais.recording import RealPairs
from tma.config import param, require
from tma.families.bearings2d import real_motion, target_motion
from tma.families.bearings2d.log import BearingsLog, read_bearings_log, write_bearings_log
from tma.families.bearings2d.target_motion import TargetConfig
from tma.io import arrow
from tma.maths.angles import bearing_from_north, course_from_velocity, wrap_to_pi
from tma.maths.path import LegPath, leg_config
from tma.runtime.sharding import shard_rng, shard_track_ids
from tma.scenario import ScenarioConfig

FAMILY = "bearings2d"
OUTLIER_STREAM = 1  # spawn-key element of the outlier stream under the shard's (shard,)
MANOEUVRE, WANDER = target_motion.MANOEUVRE_STREAM, target_motion.WANDER_STREAM


# a straight leg {course_deg, duration_s} or a turn {turn_to_deg, rate_deg_s, direction}
LegConfig = leg_config("course_deg", "duration_s", "turn_to_deg", "rate_deg_s", "direction")


def _default_legs():
    return [
        LegConfig(course_deg=0.0, duration_s=180.0),
        LegConfig(turn_to_deg=270.0, rate_deg_s=0.5, direction="left"),
        LegConfig(course_deg=270.0, duration_s=300.0),
        LegConfig(turn_to_deg=90.0, rate_deg_s=0.5, direction="right"),
        LegConfig(course_deg=90.0, duration_s=180.0),
    ]


@dataclass
class ObserverConfig:
    start_x_m: float = param(0.0, "own-ship's position x at t = 0 (m east)")
    start_y_m: float = param(0.0, "own-ship's position y at t = 0 (m north)")
    speed_m_s: float = param(5.0, "own-ship's speed (m/s)", "(0, 1e4)")
    legs: list[LegConfig] = param(doc="own-ship's legs (tma.maths.path)", factory=_default_legs)


@dataclass
class PopulationConfig:
    """Uniform population of true targets, relative to the observer at t = 0."""

    initial_bearing_deg: float = param(0.0, "every target's bearing from own-ship at t = 0 "
                                       "(deg)")
    distance_min_m: float = param(5000.0, "nearest distance at t = 0 (m)", "(0, 1e9)")
    distance_max_m: float = param(50000.0, "farthest distance at t = 0 (m)", "(0, 1e9)")
    course_min_deg: float = param(0.0, "smallest course (deg)")
    course_max_deg: float = param(180.0, "largest course (deg)")
    speed_min_m_s: float = param(5.0, "slowest speed (m/s)", "[0, 1e4)")
    speed_max_m_s: float = param(15.0, "fastest speed (m/s)", "[0, 1e4)")


@dataclass
class OriginConfig:
    """WGS84 position (deg) of the local plane's origin (x = y = 0); null: none. With one,
    each log carries it and own-ship as ``foxglove.LocationFix`` (Foxglove's Map panel)."""

    lat: float | None = param(None, "latitude of the origin (deg)", "(-90, 90)")
    lon: float | None = param(None, "longitude of the origin (deg)", "[-180, 180]")


@dataclass
class OutlierConfig:
    """Share ``prob`` of bearings replaced by draws uniform on the circle (module docstring)."""

    prob: float = param(0.0, "share of the bearings replaced by draws uniform on the circle",
                        "[0, 1]")


@dataclass
class Config(ScenarioConfig):
    family: str = FAMILY
    n_tracks: int = 10000  # targets in the dataset
    sigma_deg: float = param(0.5, "bearing noise standard deviation (deg)", "[0, 90)")
    seed: int = 20260101
    shard_size: int = 2000  # tracks per MCAP shard (and per estimation task)
    sample_period_s: float = param(2.0, "bearings at t = 0, dt, ..., the end of the observer "
                                   "path (s)", "(0, inf)")
    observer: ObserverConfig = param(doc="the own-ship", factory=ObserverConfig)
    population: PopulationConfig = param(doc="the targets", factory=PopulationConfig)
    origin: OriginConfig = param(doc="the local plane's WGS84 origin", factory=OriginConfig)
    outliers: OutlierConfig = param(doc="wild bearings", factory=OutlierConfig)
    target: TargetConfig = param(doc="how the targets move beyond constant velocity "
                                 "(manoeuvres, wander), and whether the log says so",
                                 factory=TargetConfig)
    real: RealPairs = param(doc="own-ship and targets from an AIS recording instead "
                            "(real_motion.py)", factory=RealPairs)

    def __post_init__(self):
        super().__post_init__()
        where = self.where
        target_motion.check(self.target, where)
        real_motion.check(self)
        require((self.origin.lat is None) == (self.origin.lon is None), where,
                "origin.lat and origin.lon must be given together (or both null)")
        p = self.population
        require(p.distance_min_m <= p.distance_max_m, where,
                "population distances must satisfy 0 < distance_min_m <= distance_max_m < 1e9")
        require(p.speed_min_m_s <= p.speed_max_m_s, where,
                "population speeds must satisfy 0 <= speed_min_m_s <= speed_max_m_s < 1e4")
        require(p.course_min_deg <= p.course_max_deg, where,
                "population.course_min_deg must not exceed course_max_deg")
        duration = sum(leg.duration_s or 0.0 for leg in self.observer.legs)
        require(duration / self.sample_period_s < 1e7, where,
                "the observer path holds more than 1e7 bearing epochs")


def label(cfg: Config) -> str:
    if cfg.real.file is not None:
        return real_motion.label(cfg)
    outliers = f"-out{cfg.outliers.prob:g}" if cfg.outliers.prob > 0 else ""
    target = cfg.target
    motion = "".join([f"-q{target.accel_psd_m2_s3:g}" if target.accel_psd_m2_s3 > 0 else "",
                      f"-man{target.manoeuvres.prob:g}" if target.manoeuvres.prob > 0 else "",
                      f"-man{target.manoeuvres.rate_per_h:g}ph"
                      if target.manoeuvres.rate_per_h > 0 else "",
                      "" if target.declared else "-undeclared"])
    return f"sigma{cfg.sigma_deg:g}{outliers}{motion}-n{cfg.n_tracks}"


def observer_path(cfg: Config) -> LegPath:
    o = cfg.observer
    return LegPath(o.start_x_m, o.start_y_m, o.speed_m_s, o.legs)


def epochs(cfg: Config, path: LegPath) -> np.ndarray:
    """Bearing times t = 0, dt, ..., up to the end of the observer path (s)."""
    n = int(np.floor(path.duration_s / cfg.sample_period_s + 1e-9)) + 1
    return np.arange(n) * cfg.sample_period_s


def simulate_shard(cfg: Config, shard_index: int):
    """Simulate one shard: ``(BearingsLog, truth pyarrow.Table)``."""
    if cfg.real.file is not None:  # real ship motion from AIS (real_motion.py)
        return real_motion.simulate_shard(cfg, shard_index, with_outliers)
    track_id = shard_track_ids(cfg, shard_index)
    n = track_id.size
    rng = shard_rng(cfg, shard_index)
    path = observer_path(cfg)
    t = epochs(cfg, path)
    own_x, own_y = path.position(t)

    pop = cfg.population
    distance = rng.uniform(pop.distance_min_m, pop.distance_max_m, n)
    course = np.deg2rad(rng.uniform(pop.course_min_deg, pop.course_max_deg, n))
    speed = rng.uniform(pop.speed_min_m_s, pop.speed_max_m_s, n)
    noise = rng.standard_normal((n, t.size))

    p0 = np.deg2rad(pop.initial_bearing_deg)
    x0, y0 = own_x[0] + distance * np.sin(p0), own_y[0] + distance * np.cos(p0)
    vx, vy = speed * np.sin(course), speed * np.cos(course)
    moving = cfg.target.moving
    if moving:
        x, y, v_end, last = target_motion.target_paths(
            cfg.target, x0, y0, course, speed, t, shard_rng(cfg, shard_index, MANOEUVRE),
            shard_rng(cfg, shard_index, WANDER))
        true_bearing = bearing_from_north(x - own_x, y - own_y)
    else:
        true_bearing = bearing_from_north(
            x0[:, None] + vx[:, None] * t - own_x, y0[:, None] + vy[:, None] * t - own_y
        )
    measured = wrap_to_pi(true_bearing + np.deg2rad(cfg.sigma_deg) * noise)
    if cfg.outliers.prob > 0:
        measured = with_outliers(measured, cfg, shard_index)

    origin = cfg.origin
    log = BearingsLog(
        t_s=t, own_x_m=own_x, own_y_m=own_y, track_id=track_id,
        bearing_deg=np.rad2deg(measured) % 360.0, sigma_deg=cfg.sigma_deg,
        epoch_utc_ns=cfg.epoch_ns,
        origin_deg=None if origin.lat is None else (origin.lat, origin.lon),
        accel_psd_m2_s3=cfg.target.declared_psd(),
        manoeuvres=cfg.target.declared_manoeuvres(rms_speed(pop)),
    )
    columns = {"track_id": track_id, "x0_m": x0, "y0_m": y0, "vx_m_s": vx, "vy_m_s": vy}
    if moving:  # the state at the last bearing, as the straight line through it
        vx, vy = v_end[:, 0], v_end[:, 1]
        columns = {"track_id": track_id, "x0_m": x[:, -1] - vx * t[-1],
                   "y0_m": y[:, -1] - vy * t[-1], "vx_m_s": vx, "vy_m_s": vy}
        course, speed = course_from_velocity(vx, vy), np.hypot(vx, vy)
    truth = arrow.table({
        **columns,
        "distance0_m": distance,
        "course_deg": np.rad2deg(course), "speed_m_s": speed,
        **({"manoeuvring": ~np.isnan(last["manoeuvre_start_s"]), **last} if moving else {}),
    })
    return log, truth


def rms_speed(pop: PopulationConfig) -> float:
    """The root mean square of the targets' speed, uniform in [min, max] (m/s)."""
    a, b = pop.speed_min_m_s, pop.speed_max_m_s
    return float(np.sqrt((a * a + a * b + b * b) / 3.0))


def with_outliers(measured_rad, cfg: Config, shard_index: int) -> np.ndarray:
    """``measured_rad`` (n_tracks, n_epochs) with each bearing replaced, with probability
    ``cfg.outliers.prob``, by a draw uniform on [-pi, pi)."""
    rng = shard_rng(cfg, shard_index, OUTLIER_STREAM)
    replaced = rng.random(measured_rad.shape) < cfg.outliers.prob
    wild = rng.uniform(-np.pi, np.pi, measured_rad.shape)
    return np.where(replaced, wild, measured_rad)


def write_log(path, log: BearingsLog, metadata=None) -> int:
    """Write a shard's bearing log as MCAP; returns the message count."""
    return write_bearings_log(path, log, metadata)


def read_log(path) -> BearingsLog:
    """Read a shard's bearing log (validated)."""
    return read_bearings_log(path)
