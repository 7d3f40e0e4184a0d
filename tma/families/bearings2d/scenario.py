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

Several platforms (``observers``, issue 39): instead of the one own-ship (``observer``), a list
of named platforms, each moving on its own legs or fixed (no legs: a buoy, a shore station at
its start position), each taking bearings every ``sample_period_s`` from its
``time_offset_s`` (asynchronous reports) to the end of its path (a fixed one: ``duration_s``,
or the end of the longest path of the moving ones). ``observing`` picks which of them take
bearings in a dataset (names joined by ``+``, the first the reference; null: all, in their
order): the one axis along which datasets of one, two or more platforms are made from one
declared geometry. The targets are those of the same seed without observers (the shard's
first stream draws them, relative to the first declared observer at t = 0); each declared
platform's noise comes from its own stream ``SeedSequence(seed, spawn_key=(shard,
PLATFORM_STREAM, k))`` (k its index in ``observers``), so a platform's bearings are the same
whichever others observe with it (common random numbers between one and two platforms).
Several observing platforms write a log of several platforms (``BearingsLog.platform``), its
epochs ordered by (time, platform); one writes a log of one own-ship.
"""

import re
from dataclasses import dataclass

import numpy as np

from tma.ais.recording import RealPairs
from tma.config import Form, param, require
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
PLATFORM_STREAM = 4  # spawn-key element of the platforms' noise: (shard, PLATFORM_STREAM, k)
MAX_EPOCHS = 1e7  # bearing epochs of one log (every platform's)


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


def _name_problem(value) -> str | None:
    return None if re.fullmatch(r"[A-Za-z0-9_-]+", str(value)) else ""


PLATFORM_NAME = Form("a name of letters, digits, _ and - (a buoy, ship2)", _name_problem)


@dataclass
class PlatformConfig:
    """One of several platforms taking bearings (``Config.observers``): moving on its legs
    from its start position, or fixed there (no legs: a buoy, a shore station)."""

    name: str = param("platform", "the platform's name (in the log's tma.platforms and in "
                      "observing)", form=PLATFORM_NAME)
    start_x_m: float = param(0.0, "position x at t = 0 (m east)")
    start_y_m: float = param(0.0, "position y at t = 0 (m north)")
    speed_m_s: float = param(5.0, "speed on its legs (m/s)", "(0, 1e4)")
    legs: list[LegConfig] = param(doc="its legs (tma.maths.path); none: fixed at its start "
                                  "position", factory=list)
    sample_period_s: float | None = param(None, "its bearings every ... s; null: the "
                                          "scenario's sample_period_s", "(0, inf)")
    time_offset_s: float = param(0.0, "its first bearing at this time (s): asynchronous "
                                 "reports", "[0, 1e7)")
    duration_s: float | None = param(None, "a fixed platform's bearings up to this time (s); "
                                     "null: to the end of the longest moving platform's path",
                                     "(0, 1e7)")


@dataclass
class PopulationConfig:
    """Uniform population of true targets, relative to the observer at t = 0 (the first of
    ``observers`` when given)."""

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
    # added with several platforms (issue 39): unhashed while unused, so that datasets
    # without them keep their names and bytes
    observers: list[PlatformConfig] = param(
        doc="several platforms instead of the one observer (module docstring); empty: the "
        "observer alone", factory=list, unhashed_default=True)
    observing: str | None = param(
        None, "the observers that take bearings, their names joined by + (the first the "
        "reference); null: every one of observers", unhashed_default=True)

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
        require(duration / self.sample_period_s < MAX_EPOCHS, where,
                "the observer path holds more than 1e7 bearing epochs")
        if self.observers or self.observing is not None:
            check_observers(self)


def check_observers(cfg: Config):
    """What relates the observers' fields: distinct names, ``observing`` naming them,
    ``observer`` and ``real`` left alone, every platform's bearing times known."""
    where, names = cfg.where, [o.name for o in cfg.observers]
    require(bool(names), where, "observing names observers, but observers is empty")
    require(len(set(names)) == len(names), where,
            f"observers' names must be distinct, got {', '.join(names)}")
    require(cfg.real.file is None, where, "real.file gives own-ship from AIS; leave "
            "observers empty")
    require(cfg.observer == ObserverConfig(), where, "observer.* is the one own-ship of a "
            "scenario without observers: give each observer its own position and legs")
    used = observing(cfg)
    unknown = [u for u in used if u not in names]
    require(not unknown, where, f"observing={cfg.observing}: {', '.join(unknown)} is not "
            f"among the observers ({', '.join(names)})")
    require(len(set(used)) == len(used), where, f"observing={cfg.observing} names a platform "
            "twice")
    moving = [o for o in cfg.observers if o.legs]
    for o in cfg.observers:
        require(not (o.legs and o.duration_s is not None), where, f"observer {o.name}: "
                "duration_s is for a fixed platform; a moving one's legs give its time")
        require(bool(o.legs or moving or o.duration_s is not None), where,
                f"observer {o.name} is fixed and no observer moves: give its duration_s")
    end = observation_end_s(cfg)
    n_epochs = 0.0
    for o in cfg.observers:
        stop = platform_end_s(o, end)
        require(o.time_offset_s <= stop, where, f"observer {o.name}: time_offset_s "
                f"{o.time_offset_s:g} s is after its last bearing time {stop:g} s")
        n_epochs += (stop - o.time_offset_s) / (o.sample_period_s or cfg.sample_period_s)
    require(n_epochs < MAX_EPOCHS, where, "the observers take more than 1e7 bearing epochs")


def observing(cfg: Config) -> list[str]:
    """The names of the observers that take bearings, the reference first."""
    if cfg.observing is None:
        return [o.name for o in cfg.observers]
    return cfg.observing.split("+")


def _path_of(o) -> LegPath:
    return LegPath(o.start_x_m, o.start_y_m, o.speed_m_s, o.legs)


def observation_end_s(cfg: Config) -> float | None:
    """The end of the longest moving observer's path (s); None when every one is fixed."""
    ends = [_path_of(o).duration_s for o in cfg.observers if o.legs]
    return max(ends) if ends else None


def platform_end_s(o: PlatformConfig, end_s: float | None) -> float:
    """Platform ``o``'s last possible bearing time (s): its path's end, or a fixed one's
    ``duration_s`` (None: ``end_s``, the longest path's)."""
    if o.legs:
        return _path_of(o).duration_s
    return o.duration_s if o.duration_s is not None else end_s


def label(cfg: Config) -> str:
    if cfg.real.file is not None:
        return real_motion.label(cfg)
    outliers = f"-out{cfg.outliers.prob:g}" if cfg.outliers.prob > 0 else ""
    if cfg.observers:
        outliers = f"-{'.'.join(observing(cfg))}{outliers}"  # a plain file name: no +
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


def platform_epochs(cfg: Config):
    """The bearing epochs of the observing platforms (``observing``), ordered by (time,
    platform): ``(t_s, x_m, y_m, platform, declared)``, ``platform`` the index into
    ``observing``, ``declared`` the index into ``observers`` of each platform (in
    ``observing`` order)."""
    end = observation_end_s(cfg)
    index = {o.name: k for k, o in enumerate(cfg.observers)}
    declared = [index[name] for name in observing(cfg)]
    parts = []
    for j, k in enumerate(declared):
        o = cfg.observers[k]
        period = o.sample_period_s or cfg.sample_period_s
        stop = platform_end_s(o, end)
        t = o.time_offset_s + np.arange(
            int(np.floor((stop - o.time_offset_s) / period + 1e-9)) + 1) * period
        if o.legs:
            x, y = _path_of(o).position(np.minimum(t, stop))  # the last one may pass by 1e-9
        else:
            x, y = np.full(t.size, o.start_x_m), np.full(t.size, o.start_y_m)
        parts.append((t, x, y, np.full(t.size, j, dtype=np.int64)))
    t, x, y, platform = (np.concatenate(p) for p in zip(*parts, strict=True))
    order = np.lexsort((platform, t))
    return t[order], x[order], y[order], platform[order], declared


def platform_noise(cfg: Config, shard_index: int, n: int, platform, declared) -> np.ndarray:
    """Standard normal noise (n, n_epochs) of the epochs of ``platform``: each platform's from
    its own stream (``PLATFORM_STREAM``, its index in ``observers``: module docstring)."""
    noise = np.empty((n, platform.size))
    for j, k in enumerate(declared):
        mine = platform == j  # its epochs, in time order
        noise[:, mine] = shard_rng(cfg, shard_index, (PLATFORM_STREAM, k)).standard_normal(
            (n, int(mine.sum())))
    return noise


def simulate_shard(cfg: Config, shard_index: int):
    """Simulate one shard: ``(BearingsLog, truth pyarrow.Table)``."""
    if cfg.real.file is not None:  # real ship motion from AIS (real_motion.py)
        return real_motion.simulate_shard(cfg, shard_index, with_outliers)
    track_id = shard_track_ids(cfg, shard_index)
    n = track_id.size
    rng = shard_rng(cfg, shard_index)
    platform = names = None
    if cfg.observers:  # several platforms (module docstring)
        t, own_x, own_y, platform, declared = platform_epochs(cfg)
        first = cfg.observers[0]
        start = (first.start_x_m, first.start_y_m)
        if len(declared) > 1:
            names = tuple(cfg.observers[k].name for k in declared)
    else:
        path = observer_path(cfg)
        t = epochs(cfg, path)
        own_x, own_y = path.position(t)
        start = (own_x[0], own_y[0])

    pop = cfg.population
    distance = rng.uniform(pop.distance_min_m, pop.distance_max_m, n)
    course = np.deg2rad(rng.uniform(pop.course_min_deg, pop.course_max_deg, n))
    speed = rng.uniform(pop.speed_min_m_s, pop.speed_max_m_s, n)
    noise = (platform_noise(cfg, shard_index, n, platform, declared) if cfg.observers
             else rng.standard_normal((n, t.size)))

    p0 = np.deg2rad(pop.initial_bearing_deg)
    x0, y0 = start[0] + distance * np.sin(p0), start[1] + distance * np.cos(p0)
    vx, vy = speed * np.sin(course), speed * np.cos(course)
    moving = cfg.target.moving
    if moving:
        # the targets' paths on their own grid: from t = 0, one time per instant (several
        # platforms may take bearings at one time, the first as late as its offset)
        grid, at = (t, slice(None)) if platform is None else _time_grid(t)
        x, y, v_end, last = target_motion.target_paths(
            cfg.target, x0, y0, course, speed, grid, shard_rng(cfg, shard_index, MANOEUVRE),
            shard_rng(cfg, shard_index, WANDER),
            target_motion.declared_prior(cfg.target.manoeuvres, rms_speed(pop))
            if cfg.target.manoeuvres.shape == "burst" else None)
        x, y = x[:, at], y[:, at]
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
        platform=None if names is None else platform, platforms=names,
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


def _time_grid(t):
    """The distinct times of ``t`` from 0 (s), and where each of ``t`` is among them."""
    grid = np.unique(np.concatenate([[0.0], t]))
    return grid, np.searchsorted(grid, t)


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
