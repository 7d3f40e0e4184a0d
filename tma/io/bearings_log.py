"""Bearing logs: own-ship navigation plus bearings to contacts, one MCAP message per epoch.

A log (and a dataset shard) holds one own-ship and any number of contacts (tracks). Topics:

- ``/ownship/navigation`` (schema ``tma.OwnshipNavigation``): ``{t_s, x_m, y_m}``
- ``/sonar/bearings`` (schema ``tma.BearingBatch``): ``{t_s, track_id[], bearing_deg[]}``

Own-ship positions are interpolated linearly to the bearing epochs (equal epochs are exact).
In memory a log is a rectangular ``(n_tracks, n_epochs)`` array with NaN where a contact has
no bearing at an epoch.
"""

from dataclasses import dataclass

import numpy as np

from tma.errors import InputError
from tma.io.mcap_log import Channel, LogWriter, read_log

OWNSHIP_TOPIC = "/ownship/navigation"
BEARINGS_TOPIC = "/sonar/bearings"
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
    track_id: (n_tracks,) int64; bearing_deg: (n_tracks, n_epochs), NaN = no bearing.
    """

    t_s: np.ndarray
    own_x_m: np.ndarray
    own_y_m: np.ndarray
    track_id: np.ndarray
    bearing_deg: np.ndarray

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


def write_bearings_log(path, log: BearingsLog, metadata=None) -> int:
    """Write ``log`` as MCAP (atomically). Returns the number of messages written."""
    with LogWriter(path, CHANNELS, metadata) as w:
        for k, t in enumerate(log.t_s.tolist()):
            w.write(OWNSHIP_TOPIC, t, {"t_s": t, "x_m": float(log.own_x_m[k]),
                                       "y_m": float(log.own_y_m[k])})
            has = np.isfinite(log.bearing_deg[:, k])
            ids = log.track_id if has.all() else log.track_id[has]
            w.write(BEARINGS_TOPIC, t, {"t_s": t, "track_id": ids,
                                        "bearing_deg": log.bearing_deg[has, k]})
        return w.n_messages


def read_bearings_log(path) -> BearingsLog:
    """Read a bearing log written by ``write_bearings_log`` or any tool using the schemas."""
    messages, _ = read_log(path, SCHEMAS)
    nav, obs = messages[OWNSHIP_TOPIC], messages[BEARINGS_TOPIC]
    where = str(path)
    if not nav:
        raise InputError(f"{where}: no messages on {OWNSHIP_TOPIC}")
    if not obs:
        raise InputError(f"{where}: no messages on {BEARINGS_TOPIC}")
    try:
        nav_t = np.array([m["t_s"] for m in nav], dtype=float)
        nav_x = np.array([m["x_m"] for m in nav], dtype=float)
        nav_y = np.array([m["y_m"] for m in nav], dtype=float)
        t = np.array([m["t_s"] for m in obs], dtype=float)
        ids_per_epoch = [np.asarray(m["track_id"], dtype=np.int64) for m in obs]
        vals_per_epoch = [np.asarray(m["bearing_deg"], dtype=float) for m in obs]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{where}: message does not follow its schema ({exc})") from None
    if any(i.shape != v.shape for i, v in zip(ids_per_epoch, vals_per_epoch, strict=True)):
        raise InputError(f"{where}: track_id and bearing_deg differ in length in a message")
    if np.any(np.diff(nav_t) <= 0):
        raise InputError(f"{where}: {OWNSHIP_TOPIC} time stamps are not strictly increasing")
    if t.size and (t[0] < nav_t[0] or t[-1] > nav_t[-1]):
        raise InputError(f"{where}: bearings outside the own-ship navigation time span")

    track_id = np.unique(np.concatenate(ids_per_epoch))
    bearing = np.full((track_id.size, t.size), np.nan)
    same = all(i.size == track_id.size for i in ids_per_epoch) and all(
        np.array_equal(i, track_id) for i in ids_per_epoch
    )
    if same:
        bearing[:] = np.stack(vals_per_epoch, axis=1)
    else:
        for k, (ids, vals) in enumerate(zip(ids_per_epoch, vals_per_epoch, strict=True)):
            if np.unique(ids).size != ids.size:
                raise InputError(f"{where}: duplicate track_id within the epoch t = {t[k]} s")
            bearing[np.searchsorted(track_id, ids), k] = vals
    log = BearingsLog(
        t_s=t, own_x_m=np.interp(t, nav_t, nav_x), own_y_m=np.interp(t, nav_t, nav_y),
        track_id=track_id, bearing_deg=bearing,
    )
    log.validate(where)
    return log
