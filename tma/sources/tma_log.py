"""tma's own schemas in a recorded log (JSON or protobuf, ``tma/io/schemas``).

- own-ship ``tma.OwnshipNavigation``: ``{t_s, x_m, y_m}`` (s; x east, y north in m);
- contacts: the family's schema (``Observation.schema``, e.g. ``tma.BearingBatch``)
  ``{t_s, track_id, <column>}``, arrays (one message per epoch) or scalars (one value per
  message).

Times come from ``t_s``, never from log times: seconds after the log's epoch (metadata record
``tma.time``) when it has one, else on the log's own clock. With a geographic origin (record
``tma.geo``) own-ship is returned as latitude/longitude (``tma.maths.geo.local_to_geodetic``, the
inverse of the local plane tma writes), so the origin reaches every output. The readers return
raw fixes and values: navigation may start after the first value or end before the last
(``align`` decides what to keep).
"""

import numpy as np

from tma.errors import InputError
from tma.io.mcap_log import GEO, geo_origin, read_epoch, track_labels
from tma.io.mcap_values import float_array, int_array, number, schema_errors
from tma.maths.geo import local_to_geodetic
from tma.utc import MAX_NS

OWNSHIP = "tma.OwnshipNavigation"


def _times_ns(t_s: np.ndarray, file, topic: str) -> np.ndarray:
    """``t_s`` (s after the epoch, or on the log's clock) as int64 ns on the UTC or log clock."""
    epoch = read_epoch(file.metadata, file.where) or 0
    far = ~(np.abs(t_s * 1e9 + epoch) < MAX_NS)  # NaN too
    if far.any():
        raise InputError(f"{file.where}: t_s {float(t_s[far][0])!r} on {topic} is not a time in "
                         "seconds within +-292 years of 1970")
    return np.round(t_s * 1e9).astype(np.int64) + epoch


def navigation(msgs, file):
    """Own-ship from ``tma.OwnshipNavigation``: ``(t_ns, columns, None)``, x/y (m), or lat/lon
    (deg) with ``tma.geo``; the time is ``t_s``, not the log time."""
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        t_s = np.array([number(m["t_s"]) for m in msgs.decoded])
        x = float_array([m["x_m"] for m in msgs.decoded])
        y = float_array([m["y_m"] for m in msgs.decoded])
    t_ns = _times_ns(t_s, file, msgs.topic)
    origin = geo_origin(file.metadata, file.where)
    if origin is None:
        return t_ns, {"x_m": x, "y_m": y}, None
    file.notes.append(f"{msgs.topic}: x/y mapped to latitude/longitude at the log's origin "
                      f"{origin[0]:.9g}, {origin[1]:.9g} deg ({GEO}; origin.lat/origin.lon "
                      "keep its plane)")
    lat, lon = local_to_geodetic(x, y, origin)
    return t_ns, {"lat_deg": lat, "lon_deg": lon}, None


def contacts(msgs, file, column: str):
    """The values ``column`` (``bearing_deg``) of a family's schema: ``(t_ns, track, values,
    message)`` one row per value (``message``: the index of its message); tracks are the
    int64 ids, or their text labels from the record ``tma.tracks``."""
    obs = msgs.decoded
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        t_msg = np.array([number(m["t_s"]) for m in obs])
        message = np.arange(t_msg.size)
        ids = [m["track_id"] for m in obs]
        values = [m[column] for m in obs]
        arrays = (list, np.ndarray)  # JSON arrays; protobuf messages' numpy arrays
        if any(type(v) in arrays for v in ids) or any(type(v) in arrays for v in values):
            ids = [int_array(v) for v in ids]  # arrays: one message per epoch
            values = [float_array(v) for v in values]
            sizes = np.array([v.size for v in ids])
            if np.any(sizes != [v.size for v in values]):
                raise InputError(f"{file.where}: track_id and {column} differ in length in "
                                 f"a message on {msgs.topic}")
            t_msg, message = np.repeat(t_msg, sizes), np.repeat(message, sizes)
            ids, values = np.concatenate(ids), np.concatenate(values)
        else:  # scalars, one value per message: converted at once
            ids, values = int_array(ids), float_array(values)
    known, index = np.unique(ids, return_inverse=True)
    labels = track_labels(file.metadata, known, file.where)
    if labels is not None:
        ids = labels[index]
    return _times_ns(t_msg, file, msgs.topic), ids, values, message
