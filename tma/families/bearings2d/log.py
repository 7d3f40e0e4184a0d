"""Bearing logs: own-ship navigation plus bearings to contacts, one MCAP message per epoch.

A log (and a dataset shard) holds one own-ship and any number of contacts (tracks). Topics:

- ``/ownship/navigation`` (schema ``tma.OwnshipNavigation``): ``{t_s, x_m, y_m}``
- ``/sonar/bearings`` (schema ``tma.BearingBatch``): ``{t_s, track_id[], bearing_deg[]}``;
  other tools may also send one bearing per message with scalar ``track_id`` and
  ``bearing_deg``: messages with equal ``t_s`` form one epoch.

Own-ship positions are interpolated linearly to the bearing epochs (equal epochs are exact).
In memory a log is a rectangular ``(n_tracks, n_epochs)`` array with NaN where a contact has
no bearing at an epoch.
"""

from dataclasses import dataclass

import numpy as np

from tma.errors import InputError
from tma.io.mcap_log import (
    Channel,
    LogWriter,
    float_array,
    int_array,
    json_record,
    number,
    read_json_record,
    read_log,
    schema_errors,
)

OWNSHIP_TOPIC = "/ownship/navigation"
BEARINGS_TOPIC = "/sonar/bearings"
SENSOR = "tma.sensor"  # metadata record: {"sigma_deg": nominal bearing noise}, when known
SCHEMAS = {OWNSHIP_TOPIC: "tma.OwnshipNavigation", BEARINGS_TOPIC: "tma.BearingBatch"}
CHANNELS = [
    Channel(OWNSHIP_TOPIC, SCHEMAS[OWNSHIP_TOPIC],
            {"units": "t_s: s; x_m, y_m: m", "frame": "local plane, x east, y north"}),
    Channel(BEARINGS_TOPIC, SCHEMAS[BEARINGS_TOPIC],
            {"units": "t_s: s; bearing_deg: deg",
             "convention": "bearing clockwise from north, from own-ship at the same epoch"}),
]


@dataclass
class BearingsLog:
    """One own-ship and its contacts' bearings on a common epoch grid.

    t_s: (n_epochs,) strictly increasing; own_x_m, own_y_m: (n_epochs,);
    track_id: (n_tracks,) int64; bearing_deg: (n_tracks, n_epochs), NaN = no bearing;
    sigma_deg: the sensor's nominal one-sigma bearing noise (deg), None when unknown (the
    estimators then estimate it from the residuals). Stored in the metadata record
    ``tma.sensor``.
    """

    t_s: np.ndarray
    own_x_m: np.ndarray
    own_y_m: np.ndarray
    track_id: np.ndarray
    bearing_deg: np.ndarray
    sigma_deg: float | None = None

    @property
    def n_tracks(self) -> int:
        return self.track_id.size

    def validate(self, where: str):
        """Raise InputError if times, positions or bearings are not usable."""
        if self.t_s.size == 0:
            raise InputError(f"{where}: no epochs")
        if not np.all(np.isfinite(self.t_s)):
            raise InputError(f"{where}: non-finite time stamps")
        dt = np.diff(self.t_s)
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            kind = "duplicate" if dt[k] == 0 else "non-increasing"
            raise InputError(f"{where}: {kind} time stamps at t = {self.t_s[k + 1]!r} s")
        if not (np.all(np.isfinite(self.own_x_m)) and np.all(np.isfinite(self.own_y_m))):
            raise InputError(f"{where}: non-finite own-ship position")
        b = self.bearing_deg[np.isfinite(self.bearing_deg)]
        if b.size and (b.min() < -360 or b.max() > 360):
            raise InputError(
                f"{where}: bearings outside [-360, 360] deg (min {b.min():g}, max {b.max():g}); "
                "bearings must be in degrees"
            )
        if np.unique(self.track_id).size != self.track_id.size:
            raise InputError(f"{where}: duplicate track ids")
        if self.sigma_deg is not None and not 0 <= self.sigma_deg < 90:
            raise InputError(f"{where}: nominal bearing noise sigma_deg {self.sigma_deg!r} is "
                             "not in [0, 90) degrees")


def write_bearings_log(path, log: BearingsLog, metadata=None) -> int:
    """Write ``log`` as MCAP (atomically). Returns the number of messages written."""
    if log.sigma_deg is not None:
        metadata = {**(metadata or {}), SENSOR: json_record({"sigma_deg": log.sigma_deg})}
    with LogWriter(path, CHANNELS, metadata) as w:
        for k, t in enumerate(log.t_s.tolist()):
            w.write(OWNSHIP_TOPIC, t, {"t_s": t, "x_m": float(log.own_x_m[k]),
                                       "y_m": float(log.own_y_m[k])})
            has = np.isfinite(log.bearing_deg[:, k])
            ids = log.track_id if has.all() else log.track_id[has]
            w.write(BEARINGS_TOPIC, t, {"t_s": t, "track_id": ids,
                                        "bearing_deg": log.bearing_deg[has, k]})
        return w.n_messages


def _nominal_sigma(metadata: dict, where: str) -> float | None:
    if SENSOR not in metadata:
        return None
    with schema_errors(where, f"the metadata record {SENSOR}"):
        sigma = read_json_record(metadata, SENSOR, where)["sigma_deg"]
        return None if sigma is None else number(sigma)


def read_bearings_log(path) -> BearingsLog:
    """Read a bearing log written by ``write_bearings_log`` or any tool using the schemas.

    ``track_id`` and ``bearing_deg`` may be arrays or scalars (one bearing per message);
    messages with equal ``t_s`` are one epoch, and a contact may appear once per epoch.
    A message that does not follow its schema raises InputError naming the file.
    """
    messages, metadata = read_log(path, SCHEMAS, nonempty=True)
    nav, obs = messages[OWNSHIP_TOPIC], messages[BEARINGS_TOPIC]
    where = str(path)
    with schema_errors(where, f"a message on {OWNSHIP_TOPIC}"):
        nav_t = np.array([number(m["t_s"]) for m in nav])
        nav_x = np.array([number(m["x_m"]) for m in nav])
        nav_y = np.array([number(m["y_m"]) for m in nav])
    with schema_errors(where, f"a message on {BEARINGS_TOPIC}"):
        t_msg = np.array([number(m["t_s"]) for m in obs])
        ids_per_msg = [int_array(m["track_id"]) for m in obs]
        vals_per_msg = [float_array(m["bearing_deg"]) for m in obs]
    if any(i.size != v.size for i, v in zip(ids_per_msg, vals_per_msg, strict=True)):
        raise InputError(f"{where}: track_id and bearing_deg differ in length in a message")
    if np.any(np.diff(nav_t) <= 0):
        raise InputError(f"{where}: {OWNSHIP_TOPIC} time stamps are not strictly increasing")
    back = np.diff(t_msg) < 0
    if back.any():
        k = int(np.argmax(back)) + 1
        raise InputError(f"{where}: {BEARINGS_TOPIC} time stamps are not increasing "
                         f"at t = {t_msg[k]!r} s")
    if t_msg[0] < nav_t[0] or t_msg[-1] > nav_t[-1]:
        raise InputError(f"{where}: bearings outside the own-ship navigation time span")

    t = np.unique(t_msg)  # equal t_s: one epoch sent as several messages
    all_ids = np.concatenate(ids_per_msg)
    track_id = np.unique(all_ids)
    bearing = np.full((track_id.size, t.size), np.nan)
    if t.size == len(obs) and all(np.array_equal(i, track_id) for i in ids_per_msg):
        bearing[:] = np.stack(vals_per_msg, axis=1)  # the common case: every contact, every epoch
    else:
        rows = np.searchsorted(track_id, all_ids)
        cols = np.repeat(np.searchsorted(t, t_msg), [i.size for i in ids_per_msg])
        cell = rows * t.size + cols
        unique, first = np.unique(cell, return_index=True)
        if unique.size != cell.size:
            dup = np.setdiff1d(np.arange(cell.size), first)[0]
            raise InputError(f"{where}: track_id {all_ids[dup]} twice at the epoch "
                             f"t = {t[cols[dup]]!r} s")
        bearing[rows, cols] = np.concatenate(vals_per_msg)
    log = BearingsLog(
        t_s=t, own_x_m=np.interp(t, nav_t, nav_x), own_y_m=np.interp(t, nav_t, nav_y),
        track_id=track_id, bearing_deg=bearing, sigma_deg=_nominal_sigma(metadata, where),
    )
    log.validate(where)
    return log
