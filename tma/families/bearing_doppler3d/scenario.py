"""Scenario ``bearing_doppler3d``: an AUV tracked by 8 fixed hydrophones (bearing + Doppler).

See ``../shared/specs/bearing_doppler3d.md``. This module holds the config (defaults and
validation), the shards and the logs; the model it simulates (``AuvModel.simulate``: truth by
Euler-Maruyama at ``truth_step_s``, readings every ``obs_period_s`` from t = 0 to
``duration_s``) is ``tma.families.bearing_doppler3d.model``. ``no_doppler`` drops the
frequency readings (bearings alone). Each shard draws the initial states, the driving noise
and the observation noise (Doppler noise is drawn even without Doppler, so both variants share
truth and angle noise) from ``SeedSequence(seed, spawn_key=(shard,))``.
"""

from dataclasses import dataclass, field

import numpy as np

from tma.config import require
from tma.families.bearing_doppler3d.log import (
    HydrophoneLog,
    read_hydrophone_log,
    write_hydrophone_log,
)
from tma.families.bearing_doppler3d.model import STATE_NAMES, AuvModel, model_record
from tma.io import arrow
from tma.scenario import ScenarioConfig
from tma.sharding import shard_rng, shard_track_ids

FAMILY = "bearing_doppler3d"
# Sanity bounds on step counts: a shard's epochs, and its Euler-Maruyama normals per epoch,
# are held in memory at once.
MAX_EPOCHS = 100_000
MAX_STEPS_PER_EPOCH = 100_000


def _sensors():
    return [[x, y, z] for x, y in ((-10000.0, 0.0), (10000.0, 0.0), (-5000.0, 1000.0),
                                   (5000.0, 1000.0)) for z in (-25.0, -50.0)]


@dataclass
class InitialConfig:
    """Initial distribution (``model.InitialDistribution``): Gaussian position, uniform speed,
    Gaussian heading, uniform a."""

    position_mean_m: list[float] = field(default_factory=lambda: [0.0, 20000.0, -1000.0])
    position_sd_m: list[float] = field(default_factory=lambda: [1000.0, 1000.0, 100.0])
    speed_min_m_s: float = 5.0
    speed_max_m_s: float = 12.0
    heading_mean_rad: float = -np.pi / 2
    heading_sd_rad: float = 0.1
    accel_min_m_s2: float = -0.2
    accel_max_m_s2: float = 0.2


@dataclass
class Config(ScenarioConfig):
    family: str = FAMILY
    n_tracks: int = 10000  # test paths
    no_doppler: bool = False
    duration_s: float = 100.0  # T
    obs_period_s: float = 1.0
    truth_step_s: float = 1e-3  # Euler-Maruyama
    filter_step_s: float = 1e-2  # the filters' Euler prediction step
    lam: float = 0.01  # 1/s
    nu: float = 0.0
    mu: float = 0.01
    sensors_m: list[list[float]] = field(default_factory=_sensors)
    omega0_hz: float = 20.0
    sound_speed_m_s: float = 1500.0
    sd_angle: float = 0.017452406437283512  # sin(1 deg), on xi and eta
    sd_doppler_hz: float = 0.005
    initial: InitialConfig = field(default_factory=InitialConfig)
    seed: int = 20260104
    shard_size: int = 2500

    def __post_init__(self):
        super().__post_init__()
        w = self.where
        for name in ("duration_s", "obs_period_s", "truth_step_s", "filter_step_s",
                     "omega0_hz", "sound_speed_m_s", "sd_angle", "sd_doppler_hz"):
            require(getattr(self, name) > 0, w, f"{name} must be positive")
        # whole numbers of steps: the simulation and the filters round step counts silently
        for num, den in (("duration_s", "obs_period_s"), ("obs_period_s", "truth_step_s"),
                         ("obs_period_s", "filter_step_s")):
            ratio = getattr(self, num) / getattr(self, den)
            require(round(ratio) >= 1 and abs(ratio - round(ratio)) < 1e-9 * ratio, w,
                    f"{num} must be a whole multiple of {den}")
        require(self.duration_s <= MAX_EPOCHS * self.obs_period_s, w,
                f"duration_s / obs_period_s must be <= {MAX_EPOCHS}")
        require(self.obs_period_s <= MAX_STEPS_PER_EPOCH * self.truth_step_s, w,
                f"obs_period_s / truth_step_s must be <= {MAX_STEPS_PER_EPOCH}")
        require(self.lam >= 0, w, "lam must be >= 0 (the acceleration decays)")
        # an Euler step of da = -lam a dt must not overshoot zero
        require(self.lam * max(self.truth_step_s, self.filter_step_s) < 1, w,
                "lam x max(truth_step_s, filter_step_s) must be < 1")
        require(self.mu >= 0, w, "mu must be >= 0")
        require(self.sd_angle <= 1, w, "sd_angle must be <= 1 (the std of a sine or cosine)")
        # the Doppler reading is a frequency near omega0; the training bundle stores it in
        # float32 (relative resolution 6e-8), which must resolve its noise
        require(1e-5 * self.omega0_hz <= self.sd_doppler_hz <= self.omega0_hz, w,
                "sd_doppler_hz must lie in [1e-5, 1] x omega0_hz")
        # omega = omega0 / (1 + V/C) needs |V| < C
        require(self.sound_speed_m_s > self.initial.speed_max_m_s, w,
                "sound_speed_m_s must exceed initial.speed_max_m_s")
        require(len(self.sensors_m) >= 1 and all(len(s) == 3 for s in self.sensors_m), w,
                "sensors_m: a non-empty list of [x, y, z]")
        i = self.initial
        require(len(i.position_mean_m) == 3 and len(i.position_sd_m) == 3, w,
                "initial.position_mean_m and initial.position_sd_m need 3 values (X, Y, Z)")
        # the filters start from this distribution's covariance: every variance positive
        require(min(i.position_sd_m) > 0 and i.heading_sd_rad > 0, w,
                "initial.position_sd_m and initial.heading_sd_rad must be positive")
        require(0 < i.speed_min_m_s < i.speed_max_m_s, w,
                "need 0 < initial.speed_min_m_s < initial.speed_max_m_s")
        require(i.accel_min_m_s2 < i.accel_max_m_s2, w,
                "need initial.accel_min_m_s2 < initial.accel_max_m_s2")


def label(cfg: Config) -> str:
    return f"{'bearings' if cfg.no_doppler else 'doppler'}-n{cfg.n_tracks}"


def simulation_key(cfg: Config, shard_index: int) -> dict:
    """What a shard's random draws depend on: datasets differing only in ``no_doppler`` share
    truth and noise, so the simulate stage computes such shards once (``simulate_raw``)."""
    return {"config": {**model_record(cfg), "no_doppler": None, "n_tracks": cfg.n_tracks,
                       "seed": cfg.seed, "shard_size": cfg.shard_size}, "shard": shard_index}


def simulate_raw(cfg: Config, shard_index: int):
    """Truth and the full (Doppler included) readings of a shard."""
    n = shard_track_ids(cfg, shard_index).size
    return AuvModel.from_record(model_record(cfg)).simulate(n, shard_rng(cfg, shard_index))


def from_raw(cfg: Config, shard_index: int, raw):
    """The shard's log and truth table from ``simulate_raw``'s output."""
    truth, obs = raw
    n = truth.shape[0]
    record = model_record(cfg)
    model = AuvModel.from_record(record)
    track_id = shard_track_ids(cfg, shard_index)
    t = model.epochs()
    log = HydrophoneLog(t, track_id, model.select_readings(obs), record,
                        cfg.epoch_ns)
    table = {"track_id": np.repeat(track_id, t.size), "step": np.tile(np.arange(t.size), n),
             "t_s": np.tile(t, n)}
    for i, name in enumerate(STATE_NAMES):
        table[name] = truth[..., i].ravel()
    return log, arrow.table(table)


def simulate_shard(cfg: Config, shard_index: int):
    return from_raw(cfg, shard_index, simulate_raw(cfg, shard_index))


def write_log(path, log: HydrophoneLog, metadata=None) -> int:
    return write_hydrophone_log(path, log, metadata)


def read_log(path) -> HydrophoneLog:
    return read_hydrophone_log(path)

