"""Range logs: ranges from ships to point landmarks, one MCAP message per epoch and landmark.

Topic ``/ranging/ranges`` (schema ``tma.RangeBatch``). The sensor's noise and the position
prior travel with the log as the MCAP metadata record ``tma.model`` (``sigma_m``,
``prior_mean_m``, ``prior_sd_m``, JSON-encoded). In memory: ``ranges_m`` (n_tracks, L, m)
with NaN where a ship has no range at that epoch.
"""

from dataclasses import dataclass

import numpy as np

from tma.errors import InputError
from tma.io.mcap_log import COMPRESSION, Channel, LogWriter, read_epoch
from tma.io.mcap_read import read_log
from tma.io.mcap_values import (
    float_array,
    int_array,
    integer,
    is_number,
    json_record,
    number,
    read_json_record,
    schema_errors,
)
from tma.io.track_epochs import scatter

RANGES_TOPIC = "/ranging/ranges"
SCHEMAS = {RANGES_TOPIC: "tma.RangeBatch"}


def channels(encoding: str = "protobuf") -> list[Channel]:
    """The ranges channel, messages in ``encoding`` (``"protobuf"`` or ``"json"``)."""
    return [Channel(RANGES_TOPIC, SCHEMAS[RANGES_TOPIC],
                    {"units": "t_s: s; range_m, landmark_*_m: m",
                     "frame": "local plane, x east, y north"}, encoding=encoding)]


@dataclass
class RangesLog:
    t_s: np.ndarray  # (m,)
    landmarks_m: np.ndarray  # (L, 2)
    track_id: np.ndarray  # (n,)
    ranges_m: np.ndarray  # (n, L, m)
    model: dict  # sigma_m, prior_mean_m, prior_sd_m
    epoch_utc_ns: int | None = None  # UTC of t = 0 (ns since 1970); None: relative times

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
        sigma, mean, sd = (self.model[k] for k in ("sigma_m", "prior_mean_m", "prior_sd_m"))
        if not (is_number(sigma) and sigma > 0):
            raise InputError(f"{where}: sigma_m must be a positive number")
        if not (_pair(mean) and _pair(sd) and min(sd) > 0):
            raise InputError(f"{where}: metadata tma.model: prior_mean_m and prior_sd_m must "
                             "be two numbers (x, y), prior_sd_m positive")


def _pair(value) -> bool:
    return isinstance(value, list | tuple | np.ndarray) and len(value) == 2 and all(
        is_number(v) for v in value)


def write_ranges_log(path, log: RangesLog, metadata=None, encoding="protobuf") -> int:
    """Write ``log`` as MCAP (atomically), messages in ``encoding``; returns their number."""
    meta = {**(metadata or {}),
            "tma.model": json_record(log.model)}
    with LogWriter(path, channels(encoding), meta, epoch_utc_ns=log.epoch_utc_ns,
                   compression=COMPRESSION[encoding]) as w:
        for k, t in enumerate(log.t_s.tolist()):
            for i, (lx, ly) in enumerate(log.landmarks_m.tolist()):
                w.write(RANGES_TOPIC, t, {
                    "t_s": t, "landmark_id": i, "landmark_x_m": lx, "landmark_y_m": ly,
                    "track_id": log.track_id, "range_m": log.ranges_m[:, i, k]})
        return w.n_messages


def read_ranges_log(path) -> RangesLog:
    messages, metadata = read_log(path, SCHEMAS, nonempty=True)
    msgs = messages[RANGES_TOPIC]
    where = str(path)
    model = read_json_record(metadata, "tma.model", where)
    with schema_errors(where, f"a message on {RANGES_TOPIC}"):
        t_msg = np.array([number(m["t_s"]) for m in msgs])
        lm_msg = [integer(m["landmark_id"]) for m in msgs]
        positions = [(number(m["landmark_x_m"]), number(m["landmark_y_m"])) for m in msgs]
        ids = [int_array(m["track_id"]) for m in msgs]
        values = [float_array(m["range_m"]) for m in msgs]
    landmarks = {}
    for lm, pos in zip(lm_msg, positions, strict=True):
        if landmarks.setdefault(lm, pos) != pos:
            raise InputError(f"{where}: landmark {lm} at two positions, {landmarks[lm]} and {pos}")
    t, lm_ids = np.unique(t_msg), sorted(landmarks)
    cols, lm_rows = np.searchsorted(t, t_msg), [lm_ids.index(lm) for lm in lm_msg]
    if len(set(zip(lm_rows, cols.tolist(), strict=True))) != len(msgs):
        raise InputError(f"{where}: two messages for the same landmark and epoch")
    for i, v in zip(ids, values, strict=True):
        if i.size != v.size:
            raise InputError(f"{where}: track_id and range_m differ in length in a message")
    cell = np.repeat(np.array(lm_rows) * t.size + cols, [i.size for i in ids])  # (landmark, epoch)
    track_id, ranges = scatter(np.concatenate(ids), cell, np.concatenate(values),
                               len(lm_ids) * t.size, where, "ranges of one landmark",
                               lambda k: t[k % t.size])
    ranges = ranges.reshape(track_id.size, len(lm_ids), t.size)
    log = RangesLog(t, np.array([landmarks[i] for i in lm_ids], float), track_id, ranges, model,
                    read_epoch(metadata, where))
    log.validate(where)
    return log
