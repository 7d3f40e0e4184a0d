"""The map of a dataset without truth (an ingested log), what it draws as ``drawn_tracks``
says: ``tables/<name>.mcap`` (only with a geographic origin and UTC times), per track
``foxglove.LocationFix`` on ``/tma/estimate/<label>`` at each epoch of its estimated track (a
kept trajectory's points, else its bearing epochs; estimated position, position covariance in
ENU m^2, type KNOWN), own-ship on ``/ownship/location_fix``, the contact's ship from its AIS
on ``/tma/truth/<label>`` where the log has a truth; log times UTC, for Foxglove's Map panel.
"""

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from tma.families.bearings2d.drawn_tracks import (
    drawn_path,
    now_only,
    path_rows,
    position_covariance,
    shown_estimates,
)
from tma.families.bearings2d.log import GEO, OWNSHIP_FIX_TOPIC, OWNSHIP_FRAME
from tma.io.mcap_log import Channel, LogWriter
from tma.io.mcap_values import json_record
from tma.io.mcap_writer import Encoded
from tma.maths.geo import MAX_MAPPED_M, LocationFix, enu_covariance, local_to_geodetic, location_fix
from tma.sources.labels import shown_labels

log = logging.getLogger(__name__)

ESTIMATE_TOPIC = "/tma/estimate/{label}"
TRUTH_TOPIC = "/tma/truth/{label}"  # the contact's ship, from its AIS (ingest truth=FILE)


def write_map_mcap(path, report: pd.DataFrame, estimates: pd.DataFrame, logs, epoch_utc_ns,
                   origin_deg, run: dict, truth_track: pd.DataFrame | None = None,
                   paths: pd.DataFrame | None = None) -> Path:
    """Write the estimated tracks and own-ship as ``foxglove.LocationFix`` (see the module
    docstring), in time order; returns ``path``. Tracks whose estimate the report does not
    show (blank: ``shown_estimates``) or that lie beyond ``MAX_MAPPED_M`` of the origin are
    left out (logged). ``truth_track``: the contacts' ships from their AIS
    (``tma.ais.truth``), beside the estimates (``truth_parts``); ``paths``: the run's side
    table ``path``, if any (``path_rows``)."""
    theta, theta_cov = shown_estimates(report, estimates)
    headless = now_only(report)
    kept = path_rows(paths)
    where = {int(i): (k, row) for k, lg in enumerate(logs) for row, i in enumerate(lg.track_id)}
    own_topics = ([OWNSHIP_FIX_TOPIC] if len(logs) == 1
                  else [f"/ownship/{k}/location_fix" for k in range(len(logs))])
    channels = [Channel.protobuf(topic, LocationFix, {"frame": "own-ship, sea level"})
                for topic in own_topics]
    parts = []  # per topic: (t_s, lat, lon, covariance or None, frame_id)
    for lg in logs:
        lat, lon = local_to_geodetic(lg.own_x_m, lg.own_y_m, origin_deg)
        parts.append((lg.t_s, lat.tolist(), lon.tolist(), None, OWNSHIP_FRAME))
    skipped, used = [], set()
    shown = shown_labels(report["label"])
    for n, r in enumerate(report.itertuples(index=False)):
        k, row = where[int(r.track_id)]
        t = logs[k].t_s[np.isfinite(logs[k].bearing_deg[row])]
        held = t >= r.leg_start_s
        t = t[held] if held.any() else t  # where the solution holds (its leg)
        drawn = drawn_path(kept.get(int(r.track_id)), theta[n],
                           position_covariance(theta_cov[n:n + 1], t[-1:])[0], t[0], t[-1])
        if drawn is not None:  # the trajectory the answer rests on
            t, xy, cov = drawn
            x, y = xy.T
        else:
            t = t[-1:] if headless[n] else t  # its position now alone (now_only)
            x, y = (theta[n, :2, None] + theta[n, 2:, None] * t)
            cov = position_covariance(theta_cov[n:n + 1], t[None, :])[0]
        lat, lon = local_to_geodetic(x, y, origin_deg)
        if not np.isfinite(lat).all():  # no estimate shown, or one farther than a map
            skipped.append(shown[n])
            continue
        topic = ESTIMATE_TOPIC.format(label=shown[n])
        if topic in used:  # labels of different shards alike: the id tells them apart
            topic = f"{topic}-{r.track_id}"
        used.add(topic)
        cov = enu_covariance(cov) if np.isfinite(cov).all() else None
        if drawn is not None:
            what = ("the trajectory its answer rests on (smoothed, with its manoeuvres), from "
                    "leg_start_s to its last bearing" + (" (where it is heading now is not "
                                                         "determined)" if headless[n] else "")
                    + ", there its answer now; covariance: the trajectory's, at the last "
                    "bearing as in the report")
        elif headless[n]:
            what = ("its position at the last bearing alone (where it is heading is not "
                    "determined); covariance as in the report")
        else:
            what = ("the estimator's track over the bearings its solution rests on (from "
                    "leg_start_s); covariance as in the report")
        channels.append(Channel.protobuf(topic, LocationFix, {
            "track_id": str(r.track_id), "status": r.status, "estimate": what}))
        parts.append((t, lat.tolist(), lon.tolist(), cov, f"contact {shown[n]}"))
    if truth_track is not None:
        for channel, part in truth_parts(report, truth_track):
            channels.append(channel)
            parts.append(part)
    if skipped:
        log.warning("%s: no estimate shown (the table's note says why) or none within %g km "
                    "of the origin for %s: not in the map", path, MAX_MAPPED_M / 1e3,
                    ", ".join(skipped))
    t_all = np.concatenate([p[0] for p in parts])
    which = np.repeat(np.arange(len(parts)), [p[0].size for p in parts])
    order = np.lexsort((which, t_all))  # time order; own-ship first at equal times
    metadata = {GEO: json_record({"origin_lat_deg": origin_deg[0],
                                  "origin_lon_deg": origin_deg[1], "epoch_utc_ns": epoch_utc_ns}),
                "tma.run": json_record(run)}
    with LogWriter(path, channels, metadata, epoch_utc_ns=epoch_utc_ns) as w:
        payloads = [p for t, lat, lon, cov, frame in parts
                    for p in _fixes(w.log_times(t), frame, lat, lon, cov)]
        w.write_encoded([ch.topic for ch in channels], which[order], t_all[order],
                        Encoded.of([payloads[k] for k in order.tolist()]))
    return Path(path)


def _fixes(t_ns, frame: str, lat, lon, cov) -> list[bytes]:
    """``location_fix`` messages, serialised: one message whose changing fields are set anew
    for each (3x faster than a new message each, the same bytes)."""
    fix, out = location_fix(0, frame, 0.0, 0.0, None if cov is None else cov[0]), []
    for k, (ns, a, b) in enumerate(zip(t_ns.tolist(), lat, lon, strict=True)):
        fix.latitude, fix.longitude = a, b
        fix.timestamp.seconds, fix.timestamp.nanos = divmod(ns, 10**9)
        if cov is not None:
            fix.position_covariance[:] = cov[k]
        out.append(fix.SerializeToString(deterministic=True))
    return out


def truth_parts(report: pd.DataFrame, truth_track: pd.DataFrame) -> list:
    """``(channel, part)`` per contact with an AIS truth: its ship's position at each of its
    bearing times on ``/tma/truth/<label>`` (``foxglove.LocationFix``, no covariance), as
    ``write_map_mcap`` writes the estimates beside it."""
    shown = dict(zip(report["track_id"].tolist(), shown_labels(report["label"]), strict=True))
    mmsi = (dict(zip(report["track_id"].tolist(), report["truth_mmsi"].tolist(), strict=True))
            if "truth_mmsi" in report else {})
    out = []
    for track_id, rows in truth_track.groupby("track_id", sort=True):
        if track_id not in shown:
            continue
        label = shown[track_id]
        channel = Channel.protobuf(TRUTH_TOPIC.format(label=label), LocationFix, {
            "track_id": str(track_id), "mmsi": str(mmsi.get(track_id, "")),
            "truth": "the contact's ship from its AIS, interpolated at its bearing times"})
        out.append((channel, (rows["t_s"].to_numpy(float), rows["lat_deg"].tolist(),
                              rows["lon_deg"].tolist(), None, f"AIS {mmsi.get(track_id, '')}"
                              f" (contact {label})")))
    return out
