"""Foxglove messages in a recorded log (protobuf via mcap-protobuf-support, or JSON).

Own-ship: ``foxglove.LocationFix`` (latitude, longitude in deg, WGS84), found by its schema
whatever its topic (``mcap.py``, which also drops NaN fixes). Times are
``file.message_times``: the Foxglove ``timestamp`` field (``timestamps_ns``: protobuf
``seconds``/``nanos`` or JSON ``sec``/``nsec``), or ``log_time`` when unset. Contacts' values
on Foxglove channels (e.g. a JSON-schema channel ``{"track_id": 1, "bearing_deg": ...}``) are
read by field path in ``mcap.py``.
"""

import numpy as np
from google.protobuf.message import Message

from tma.io.mcap_values import float_array, int_array, schema_errors

LOCATION_FIX = "foxglove.LocationFix"
_PROTOBUF_TIMESTAMP = "google.protobuf.Timestamp"


def timestamps_ns(decoded: list) -> np.ndarray | None:
    """The ``timestamp`` field of each message as int64 ns; None when the messages have no
    Foxglove timestamp (a ``google.protobuf.Timestamp``, or a JSON ``{sec, nsec}``)."""
    sample = decoded[0]
    if isinstance(sample, dict):
        stamp = sample.get("timestamp")
        if not (isinstance(stamp, dict) and "sec" in stamp and "nsec" in stamp):
            return None
        sec = int_array([m["timestamp"]["sec"] for m in decoded])
        nsec = int_array([m["timestamp"]["nsec"] for m in decoded])
    elif isinstance(sample, Message):
        field = sample.DESCRIPTOR.fields_by_name.get("timestamp")
        if field is None or field.message_type is None or (
                field.message_type.full_name != _PROTOBUF_TIMESTAMP):
            return None
        n = len(decoded)
        sec = np.fromiter((m.timestamp.seconds for m in decoded), np.int64, n)
        nsec = np.fromiter((m.timestamp.nanos for m in decoded), np.int64, n)
    else:
        return None
    return sec * 10**9 + nsec


def location_fix(msgs, file):
    """Own-ship latitude/longitude (deg) from LocationFix (JSON or protobuf)."""
    json = isinstance(msgs.decoded[0], dict)
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        lat = float_array([m["latitude"] if json else m.latitude for m in msgs.decoded])
        lon = float_array([m["longitude"] if json else m.longitude for m in msgs.decoded])
    return file.message_times(msgs), {"lat_deg": lat, "lon_deg": lon}, None
