"""Radar plot logs: one MCAP message per scan on ``/radar/plots`` (schema ``tma.PlotBatch``).

The metadata record ``tma.sensor`` describes the radar and its noise (JSON-encoded values):
``noise`` (``cartesian`` or ``polar``), ``sigma_m``, ``radar_x_m``, ``radar_y_m``,
``range_sd_m``, ``bearing_sd_deg``. In memory: ``plots_m`` (n_tracks, n_scans, 2), NaN where
a scan has no plot (estimators skip it).
"""

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
from tma.io.track_epochs import scatter

PLOTS_TOPIC = "/radar/plots"
SCHEMAS = {PLOTS_TOPIC: "tma.PlotBatch"}


def channels(encoding: str = "protobuf") -> list[Channel]:
    """The plots channel, messages in ``encoding`` (``"protobuf"`` or ``"json"``)."""
    return [Channel(PLOTS_TOPIC, SCHEMAS[PLOTS_TOPIC],
                    {"units": "t_s: s; x_m, y_m: m", "frame": "local plane, x east, y north"},
                    encoding=encoding)]


@dataclass
class RadarLog:
    t_s: np.ndarray  # (n_scans,)
    track_id: np.ndarray  # (n,)
    plots_m: np.ndarray  # (n, n_scans, 2)
    sensor: dict
    epoch_utc_ns: int | None = None  # UTC of t = 0 (ns since 1970); None: relative times

    @property
    def n_tracks(self) -> int:
        return self.track_id.size

    def validate(self, where: str):
        dt = np.diff(self.t_s)
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            raise InputError(f"{where}: scan times are not increasing at t = {self.t_s[k + 1]:g} s")
        if self.t_s.size < 3:
            raise InputError(f"{where}: {self.t_s.size} scans; tracking needs at least 3")
        noise = self.sensor.get("noise")
        if noise not in ("cartesian", "polar"):
            raise InputError(f"{where}: metadata tma.sensor: noise must be 'cartesian' or "
                             f"'polar', got {noise!r}")
        need = (("sigma_m",) if noise == "cartesian"
                else ("radar_x_m", "radar_y_m", "range_sd_m", "bearing_sd_deg"))
        bad = [k for k in need if not is_number(self.sensor.get(k))]
        if bad:
            raise InputError(f"{where}: metadata tma.sensor: {', '.join(bad)} must be numbers "
                             f"for {noise} noise")


def write_radar_log(path, log: RadarLog, metadata=None, encoding="protobuf") -> int:
    """Write ``log`` as MCAP (atomically), messages in ``encoding``; returns their number."""
    meta = {**(metadata or {}), "tma.sensor": json_record(log.sensor)}
    with LogWriter(path, channels(encoding), meta, epoch_utc_ns=log.epoch_utc_ns,
                   compression=COMPRESSION[encoding]) as w:
        for k, t in enumerate(log.t_s.tolist()):
            w.write(PLOTS_TOPIC, t, {"t_s": t, "track_id": log.track_id,
                                     "x_m": log.plots_m[:, k, 0], "y_m": log.plots_m[:, k, 1]})
        return w.n_messages


def read_radar_log(path) -> RadarLog:
    messages, metadata = read_log(path, SCHEMAS, nonempty=True)
    msgs = messages[PLOTS_TOPIC]
    where = str(path)
    sensor = read_json_record(metadata, "tma.sensor", where)
    with schema_errors(where, f"a message on {PLOTS_TOPIC}"):
        t = np.array([number(m["t_s"]) for m in msgs])
        ids = [int_array(m["track_id"]) for m in msgs]
        xs = [float_array(m["x_m"]) for m in msgs]
        ys = [float_array(m["y_m"]) for m in msgs]
    for i, x, y in zip(ids, xs, ys, strict=True):
        if not i.size == x.size == y.size:
            raise InputError(f"{where}: track_id, x_m and y_m differ in length in a message")
    scan = np.repeat(np.arange(t.size), [i.size for i in ids])  # a message is a scan
    track_id, plots = scatter(np.concatenate(ids), scan,
                              np.c_[np.concatenate(xs), np.concatenate(ys)], t.size, where,
                              "plots", t.__getitem__)
    log = RadarLog(t, track_id, plots, sensor, read_epoch(metadata, where))
    log.validate(where)
    return log
