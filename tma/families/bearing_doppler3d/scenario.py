"""Scenario ``bearing_doppler3d``: an AUV tracked by 8 fixed hydrophones (bearing + Doppler).

See ``docs/families.md``. This module holds the config (defaults and
validation), the shards and the logs; the model it simulates (``AuvModel.simulate``: truth by
Euler-Maruyama at ``truth_step_s``, readings every ``obs_period_s`` from t = 0 to
``duration_s``) is ``tma.families.bearing_doppler3d.model``. ``no_doppler`` drops the
frequency readings (bearings alone). Each shard draws the initial states, the driving noise
and the observation noise (Doppler noise is drawn even without Doppler, so both variants share
truth and angle noise) from ``SeedSequence(seed, spawn_key=(shard,))``.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.bearing_doppler3d.log import (
    HydrophoneLog,
    read_hydrophone_log,
    write_hydrophone_log,
)
from tma.families.bearing_doppler3d.model import STATE_NAMES, AuvModel, model_record
from tma.io import arrow
from tma.runtime.sharding import shard_rng, shard_track_ids
from tma.scenario import ScenarioConfig

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

    position_mean_m: list[float] = param(doc="mean position X, Y, Z (m)",
                                         factory=lambda: [0.0, 20000.0, -1000.0])
    # the filters start from this distribution's covariance: every variance positive
    position_sd_m: list[float] = param(doc="position standard deviations (m)", each="(0, inf)",
                                       factory=lambda: [1000.0, 1000.0, 100.0])
    speed_min_m_s: float = param(5.0, "smallest speed (m/s)", "(0, inf)")
    speed_max_m_s: float = param(12.0, "largest speed (m/s); above speed_min_m_s", "(0, inf)")
    heading_mean_rad: float = param(-np.pi / 2, "mean heading (rad)")
    heading_sd_rad: float = param(0.1, "heading standard deviation (rad)", "(0, inf)")
    accel_min_m_s2: float = param(-0.2, "smallest a (m/s^2)")
    accel_max_m_s2: float = param(0.2, "largest a (m/s^2); above accel_min_m_s2")


@dataclass
class Config(ScenarioConfig):
    family: str = FAMILY
    n_tracks: int = 10000  # test paths
    no_doppler: bool = param(False, "drop the Doppler readings (bearings alone)")
    duration_s: float = param(100.0, "T, the observation time (s)", "(0, inf)")
    obs_period_s: float = param(1.0, "time between readings (s)", "(0, inf)")
    truth_step_s: float = param(1e-3, "Euler-Maruyama step of the truth (s)", "(0, inf)")
    filter_step_s: float = param(1e-2, "the filters' Euler prediction step (s)", "(0, inf)")
    lam: float = param(0.01, "decay rate of the acceleration a (1/s)", "[0, inf)")
    nu: float = param(0.0, "mean-reversion level of a (m/s^2)")
    mu: float = param(0.01, "diffusion of a (m/s^2/sqrt(s))", "[0, inf)")
    sensors_m: list[list[float]] = param(doc="hydrophone positions [x, y, z] (m)",
                                         factory=_sensors)
    omega0_hz: float = param(20.0, "emitted frequency (Hz)", "(0, inf)")
    sound_speed_m_s: float = param(1500.0, "speed of sound (m/s)", "(0, inf)")
    sd_angle: float = param(0.017452406437283512, "noise standard deviation of the elevation "
                            "sine and bearing cosine (sin(1 deg))", "(0, 1]")
    sd_doppler_hz: float = param(0.005, "Doppler noise standard deviation (Hz)", "(0, inf)")
    initial: InitialConfig = param(doc="initial distribution of the AUV",
                                   factory=InitialConfig)
    seed: int = 20260104
    shard_size: int = 2500

    def __post_init__(self):
        super().__post_init__()
        w = self.where
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
        # an Euler step of da = -lam a dt must not overshoot zero
        require(self.lam * max(self.truth_step_s, self.filter_step_s) < 1, w,
                "lam x max(truth_step_s, filter_step_s) must be < 1")
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
        require(i.speed_min_m_s < i.speed_max_m_s, w,
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

