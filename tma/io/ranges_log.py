"""Range logs: ranges from ships to point landmarks, one MCAP message per epoch and landmark.

Topic ``/ranging/ranges`` (schema ``tma.RangeBatch``). The sensor's noise and the position
prior travel with the log as the MCAP metadata record ``tma.model`` (``sigma_m``,
``prior_mean_m``, ``prior_sd_m``, JSON-encoded). In memory: ``ranges_m`` (n_tracks, L, m)
with NaN where a ship has no range at that epoch.
"""

from dataclasses import dataclass

import numpy as np

from tma.errors import InputError
from tma.io.mcap_log import (
    Channel,
    LogWriter,
    float_array,
    json_record,
    read_json_record,
    read_log,
)

RANGES_TOPIC = "/ranging/ranges"
SCHEMAS = {RANGES_TOPIC: "tma.RangeBatch"}
CHANNELS = [Channel(RANGES_TOPIC, SCHEMAS[RANGES_TOPIC],
                    {"units": "t_s: s; range_m, landmark_*_m: m",
                     "frame": "local plane, x east, y north"})]


@dataclass
class RangesLog:
    t_s: np.ndarray  # (m,)
    landmarks_m: np.ndarray  # (L, 2)
    track_id: np.ndarray  # (n,)
    ranges_m: np.ndarray  # (n, L, m)
    model: dict  # sigma_m, prior_mean_m, prior_sd_m

    @property
    def n_tracks(self) -> int:
        return self.track_id.size

    def validate(self, where: str):
        r = self.ranges_m
        if np.isnan(r).any():
            k = np.argwhere(np.isnan(r))[0]
            raise InputError(f"{where}: NaN range for track {self.track_id[k[0]]} to landmark "
                             f"{k[1]} at t = {self.t_s[k[2]]:g} s")
        if (r < 0).any():
            k = np.argwhere(r < 0)[0]
            raise InputError(f"{where}: negative range {r[tuple(k)]:g} m for track "
                             f"{self.track_id[k[0]]} to landmark {k[1]}")
        counts = np.isfinite(r).sum(axis=(1, 2))
        if (counts < 2).any():
            bad = self.track_id[counts < 2][:10]
            raise InputError(f"{where}: track(s) {', '.join(map(str, bad))} have fewer ranges "
                             f"({counts.min()}) than unknowns (2 coordinates)")
        for key in ("sigma_m", "prior_mean_m", "prior_sd_m"):
            if key not in self.model:
                raise InputError(f"{where}: metadata tma.model lacks '{key}'")
        if not float(self.model["sigma_m"]) > 0:
            raise InputError(f"{where}: sigma_m must be positive")


def write_ranges_log(path, log: RangesLog, metadata=None) -> int:
    meta = {**(metadata or {}),
            "tma.model": json_record(log.model)}
    with LogWriter(path, CHANNELS, meta) as w:
        for k, t in enumerate(log.t_s.tolist()):
            for i, (lx, ly) in enumerate(log.landmarks_m.tolist()):
                w.write(RANGES_TOPIC, t, {
                    "t_s": t, "landmark_id": i, "landmark_x_m": lx, "landmark_y_m": ly,
                    "track_id": log.track_id, "range_m": log.ranges_m[:, i, k]})
        return w.n_messages


def read_ranges_log(path) -> RangesLog:
    messages, metadata = read_log(path, SCHEMAS)
    msgs = messages[RANGES_TOPIC]
    where = str(path)
    if not msgs:
        raise InputError(f"{where}: no messages on {RANGES_TOPIC}")
    model = read_json_record(metadata, "tma.model", where)
    t = np.unique([m["t_s"] for m in msgs])
    landmarks = {m["landmark_id"]: (m["landmark_x_m"], m["landmark_y_m"]) for m in msgs}
    lm_ids = sorted(landmarks)
    track_id = np.unique(np.concatenate([np.asarray(m["track_id"], np.int64) for m in msgs]))
    ranges = np.full((track_id.size, len(lm_ids), t.size), np.nan)
    for m in msgs:
        values = float_array(m["range_m"])
        rows = np.searchsorted(track_id, np.asarray(m["track_id"], np.int64))
        ranges[rows, lm_ids.index(m["landmark_id"]), np.searchsorted(t, m["t_s"])] = values
    log = RangesLog(t, np.array([landmarks[i] for i in lm_ids], float), track_id, ranges, model)
    log.validate(where)
    return log
