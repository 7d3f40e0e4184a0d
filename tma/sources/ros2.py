"""ROS 2 messages (CDR, decoded by mcap-ros2-support) in a recorded log: own-ship and stamps.

Own-ship readers, by schema name (``ownship.topic`` or found by schema, ``mcap.py``),
each ``reader(msgs, file) -> (t_ns, columns, no_fix)`` (``no_fix``: the fixes the receiver
flags as invalid, or None):

- ``sensor_msgs/msg/NavSatFix``: latitude, longitude (deg, WGS84); a fix with status
  ``STATUS_NO_FIX`` (-1) is flagged, left out and counted by the caller (``STATUS_UNKNOWN``,
  -2, the default of drivers that do not set it, is kept);
- ``nav_msgs/msg/Odometry`` (``pose.pose.position``) and ``geometry_msgs/msg/PoseStamped``
  (``pose.position``): x east, y north in metres of a local frame (REP 103's ENU, as a
  ``map`` or ``odom`` frame is).

Times are ``file.message_times``: ``header.stamp`` (``header_stamps_ns``), or ``log_time``
when unset. The caller drops NaN fixes (counted). Contacts' values on ROS 2 topics
(``std_msgs/msg/Float64`` ``data``, ``geometry_msgs/msg/Vector3Stamped`` ``vector``...) are
read by field path in ``mcap.py``.
"""

import numpy as np

from tma.io.mcap_values import float_array, schema_errors

NAVSATFIX = "sensor_msgs/msg/NavSatFix"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
STATUS_NO_FIX = -1  # sensor_msgs/msg/NavSatStatus


def header_stamps_ns(decoded: list) -> np.ndarray | None:
    """``header.stamp`` of each message as int64 ns (sec, nanosec); None when the messages
    have no ROS header."""
    header = getattr(decoded[0], "header", None)
    if header is None or not hasattr(getattr(header, "stamp", None), "nanosec"):
        return None
    n = len(decoded)
    sec = np.fromiter((m.header.stamp.sec for m in decoded), np.int64, n)
    nanosec = np.fromiter((m.header.stamp.nanosec for m in decoded), np.int64, n)
    return sec * 10**9 + nanosec


def navsatfix(msgs, file):
    """Own-ship latitude/longitude (deg) from NavSatFix, and which fixes have status NO_FIX
    (the caller leaves them out, and the NaN ones, as for every reader)."""
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        status = np.fromiter((m.status.status for m in msgs.decoded), np.int64,
                             len(msgs.decoded))
        lat = float_array([m.latitude for m in msgs.decoded])
        lon = float_array([m.longitude for m in msgs.decoded])
    no_fix = status == STATUS_NO_FIX  # counted where they are dropped
    return file.message_times(msgs), {"lat_deg": lat, "lon_deg": lon}, no_fix


def _local(msgs, file, position):
    frames = sorted({m.header.frame_id for m in msgs.decoded})
    file.notes.append(f"{msgs.topic}: positions in frame {', '.join(map(repr, frames))} taken "
                      "as x east, y north (m)")
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        points = [position(m) for m in msgs.decoded]
        x = float_array([p.x for p in points])
        y = float_array([p.y for p in points])
    return file.message_times(msgs), {"x_m": x, "y_m": y}, None


def odometry(msgs, file):
    """Own-ship x east, y north (m) from ``pose.pose.position`` of Odometry."""
    return _local(msgs, file, lambda m: m.pose.pose.position)


def pose_stamped(msgs, file):
    """Own-ship x east, y north (m) from ``pose.position`` of PoseStamped."""
    return _local(msgs, file, lambda m: m.pose.position)
