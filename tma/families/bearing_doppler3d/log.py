"""Hydrophone logs: one MCAP channel per sensor (``/hydrophones/<i>``, schema
``tma.HydrophoneBatch``), one message per sensor and epoch carrying every track.

The metadata record ``tma.model`` holds the JSON-encoded model the filters assume: sensor
positions, noise standard deviations, tone frequency, sound speed, dynamics parameters, the
initial distribution and time steps. In memory: ``obs`` (n_tracks, n_epochs, n_obs) in the
model's order (xi, eta[, omega] per sensor), NaN where a reading is missing.
"""

import json
from dataclasses import dataclass

import numpy as np

from tma.errors import InputError
from tma.io.mcap_log import COMPRESSION, Channel, LogWriter, read_epoch
from tma.io.mcap_read import read_log
from tma.io.mcap_values import (
    float_array,
    int_array,
    is_number,
    json_record,
    number,
    read_json_record,
    schema_errors,
)

SCHEMA = "tma.HydrophoneBatch"
FIELDS = ("elevation_sin", "bearing_cos", "doppler_hz")


def topic(sensor: int) -> str:
    return f"/hydrophones/{sensor}"


@dataclass
class HydrophoneLog:
    t_s: np.ndarray  # (n_epochs,)
    track_id: np.ndarray  # (n,)
    obs: np.ndarray  # (n, n_epochs, n_obs)
    model: dict  # the model record (``model.model_record``; ``AuvModel.from_record`` reads it)
    epoch_utc_ns: int | None = None  # UTC of t = 0 (ns since 1970); None: relative times

    @property
    def n_tracks(self) -> int:
        return self.track_id.size

    @property
    def per_sensor(self) -> int:
        return 2 if self.model["no_doppler"] else 3


def write_hydrophone_log(path, log: HydrophoneLog, metadata=None, encoding="protobuf") -> int:
    """Write ``log`` as MCAP (atomically), messages in ``encoding`` (``"protobuf"`` or
    ``"json"``); returns their number. A missing reading is NaN (JSON: null)."""
    sensors = log.model["sensors_m"]
    per = log.per_sensor
    channels = [Channel(topic(i), SCHEMA, {"sensor_xyz_m": json.dumps(s),
                                           "units": "t_s: s; doppler_hz: Hz"},
                        encoding=encoding)
                for i, s in enumerate(sensors)]
    meta = {**(metadata or {}), "tma.model": json_record(log.model)}
    obs = np.where(np.isfinite(log.obs), log.obs, np.nan)  # any non-finite reading: missing
    with LogWriter(path, channels, meta, epoch_utc_ns=log.epoch_utc_ns,
                   compression=COMPRESSION[encoding]) as w:
        for k, t in enumerate(log.t_s.tolist()):
            for i in range(len(sensors)):
                msg = {"t_s": t, "sensor_id": i, "track_id": log.track_id}
                for f, name in enumerate(FIELDS[:per]):
                    msg[name] = obs[:, k, per * i + f]
                w.write(topic(i), t, msg)
        return w.n_messages


def read_hydrophone_log(path) -> HydrophoneLog:
    where = str(path)
    _, metadata = read_log(path, {})
    model = read_json_record(metadata, "tma.model", where)
    sensors, no_doppler = model.get("sensors_m"), model.get("no_doppler")
    if not (isinstance(sensors, list) and sensors and all(
            isinstance(s, list) and len(s) == 3 and all(map(is_number, s)) for s in sensors)):
        raise InputError(f"{where}: metadata tma.model: sensors_m must be a list of "
                         "[x, y, z] positions")
    if not isinstance(no_doppler, bool):
        raise InputError(f"{where}: metadata tma.model: no_doppler must be true or false")
    n_sensors, per = len(sensors), 2 if no_doppler else 3
    messages, _ = read_log(path, {topic(i): SCHEMA for i in range(n_sensors)})
    first = messages[topic(0)]
    with schema_errors(where, f"a message on {topic(0)}"):
        t = np.array([number(m["t_s"]) for m in first])
        track_id = int_array(first[0]["track_id"]) if first else np.zeros(0, np.int64)
    if np.unique(track_id).size != track_id.size:
        raise InputError(f"{where}: a track_id appears twice in a message on {topic(0)}")
    obs = np.full((track_id.size, t.size, n_sensors * per), np.nan)
    for i in range(n_sensors):
        msgs = messages[topic(i)]
        if len(msgs) != t.size:
            raise InputError(f"{where}: {topic(i)} has {len(msgs)} epochs, {topic(0)} {t.size}")
        with schema_errors(where, f"a message on {topic(i)}"):
            for k, m in enumerate(msgs):
                if number(m["t_s"]) != t[k] or not np.array_equal(int_array(m["track_id"]),
                                                                  track_id):
                    raise InputError(f"{where}: {topic(i)} is not aligned with {topic(0)} at "
                                     f"t = {t[k]!r} s (time or track ids differ)")
                for f, name in enumerate(FIELDS[:per]):
                    if name not in m:
                        raise InputError(f"{where}: {topic(i)} lacks {name}")
                    values = float_array(m[name])
                    if values.size != track_id.size:
                        raise InputError(f"{where}: {name} and track_id differ in length in a "
                                         f"message on {topic(i)}")
                    obs[:, k, per * i + f] = values
    if t.size and np.any(np.diff(t) <= 0):
        raise InputError(f"{where}: epochs are not increasing")
    return HydrophoneLog(t, track_id, obs, model, read_epoch(metadata, where))
