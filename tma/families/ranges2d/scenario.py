"""Scenario ``ranges2d``: a static ship locating itself from ranges to point landmarks.

See ``docs/families.md``. Two modes:

- ``concrete`` (default): the article's case, its ten ranges to two lighthouses, repeated as
  ``n_tracks`` identical tracks: the repeated runs of each Monte Carlo estimator (every track
  gets its own random stream in the estimators). No truth (the article gives none).
- ``population``: ``n_tracks`` ships drawn from the prior, ``n_pairs`` noisy ranges to every
  landmark each; truth in Parquet.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.ranges2d.log import RangesLog, read_ranges_log, write_ranges_log
from tma.io import arrow
from tma.runtime.sharding import shard_rng, shard_track_ids
from tma.scenario import ScenarioConfig

FAMILY = "ranges2d"
MAX_PAIRS = 100_000  # population: a shard's ranges are held in memory at once


def _landmarks():
    return [[3000.0, 0.0], [0.0, 3000.0]]


def _article_ranges():
    return [[2981.0, 2978.0, 2985.0, 3017.0, 2993.0], [2969.0, 3002.0, 2977.0, 3021.0, 2995.0]]


@dataclass
class Config(ScenarioConfig):
    family: str = FAMILY
    mode: str = param("concrete", "concrete: the article's ranges repeated n_tracks times; "
                      "population: ships drawn from the prior", choices=("concrete", "population"))
    n_tracks: int = 300  # concrete: repeated runs; population: ships
    landmarks_m: list[list[float]] = param(doc="(x, y) of each landmark (m)", factory=_landmarks)
    ranges_m: list[list[float]] = param(doc="concrete: the measured ranges to each landmark (m)",
                                        factory=_article_ranges)
    n_pairs: int = param(5, "population: ranges per landmark", f"[1, {MAX_PAIRS}]")
    sigma_m: float = param(30.0, "range noise standard deviation (m)", "(0, inf)")
    prior_mean_m: list[float] = param(doc="prior mean of the position x, y (m)",
                                      factory=lambda: [0.0, 0.0])
    prior_sd_m: list[float] = param(doc="prior standard deviation of x, y (m)", each="(0, inf)",
                                    factory=lambda: [100.0, 100.0])
    seed: int = 20260102
    shard_size: int = 50

    def __post_init__(self):
        super().__post_init__()
        w = self.where
        require(len(self.landmarks_m) >= 1 and all(len(p) == 2 for p in self.landmarks_m), w,
                "landmarks_m must be a non-empty list of [x, y]")
        require(len(self.prior_mean_m) == 2 and len(self.prior_sd_m) == 2, w,
                "prior_mean_m and prior_sd_m need two values (x, y)")
        if self.mode == "concrete":
            require(len(self.ranges_m) == len(self.landmarks_m), w,
                    f"ranges_m needs one list of ranges per landmark (landmarks_m has "
                    f"{len(self.landmarks_m)}, ranges_m {len(self.ranges_m)})")
            require(len({len(r) for r in self.ranges_m}) == 1 and len(self.ranges_m[0]) >= 1,
                    w, "ranges_m: every landmark needs the same number (>= 1) of ranges")
            require(all(r >= 0 for rs in self.ranges_m for r in rs), w,
                    "ranges_m must be >= 0 (distances)")
            pairs = len(self.ranges_m[0])
        else:
            pairs = self.n_pairs
        require(pairs * len(self.landmarks_m) >= 2, w,
                "a position (2 coordinates) needs at least 2 ranges: add landmarks or "
                + ("ranges_m" if self.mode == "concrete" else "n_pairs"))


def label(cfg: Config) -> str:
    return f"{cfg.mode}-n{cfg.n_tracks}"


def simulate_shard(cfg: Config, shard_index: int):
    track_id = shard_track_ids(cfg, shard_index)
    n = track_id.size
    landmarks = np.asarray(cfg.landmarks_m, float)
    model = {"sigma_m": cfg.sigma_m, "prior_mean_m": list(cfg.prior_mean_m),
             "prior_sd_m": list(cfg.prior_sd_m)}
    epoch = cfg.epoch_ns
    if cfg.mode == "concrete":
        ranges = np.broadcast_to(np.asarray(cfg.ranges_m, float), (n, *np.shape(cfg.ranges_m)))
        log = RangesLog(np.arange(len(cfg.ranges_m[0]), dtype=float), landmarks, track_id,
                        ranges.copy(), model, epoch)
        return log, None
    rng = shard_rng(cfg, shard_index)
    pos = np.asarray(cfg.prior_mean_m) + np.asarray(cfg.prior_sd_m) * rng.standard_normal((n, 2))
    dist = np.hypot(pos[:, None, 0] - landmarks[:, 0], pos[:, None, 1] - landmarks[:, 1])
    noise = cfg.sigma_m * rng.standard_normal((n, len(landmarks), cfg.n_pairs))
    ranges = np.abs(dist[:, :, None] + noise)  # a range is non-negative
    log = RangesLog(np.arange(cfg.n_pairs, dtype=float), landmarks, track_id, ranges, model,
                    epoch)
    truth = arrow.table({"track_id": track_id, "x_m": pos[:, 0], "y_m": pos[:, 1]})
    return log, truth


def write_log(path, log: RangesLog, metadata=None) -> int:
    return write_ranges_log(path, log, metadata)


def read_log(path) -> RangesLog:
    return read_ranges_log(path)
