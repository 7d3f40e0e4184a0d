"""The map of a dataset without truth (an ingested log), what it draws as ``drawn_tracks``
says: ``tables/<name>.mcap`` (only with a geographic origin and UTC times), per track
``foxglove.LocationFix`` on ``/tma/estimate/<label>`` at each epoch of its estimated track (a
kept trajectory's points, else its bearing epochs; estimated position, position covariance in
ENU m^2, type KNOWN), own-ship on ``/ownship/location_fix``, the contact's ship from its AIS
on ``/tma/truth/<label>`` where the log has a truth; log times UTC, for Foxglove's Map panel.

A log of several platforms (ships, buoys, shore stations) has each platform's track instead
of own-ship's, on ``/platforms/<k>/location_fix`` at its own epochs, and per contact its lines
of sight as ``foxglove.GeoJSON`` on ``/tma/lines_of_sight/<label>``: at each drawn bearing
(every k-th of each platform's, ``drawn_tracks.drawn_bearings``) each platform's latest line
of sight so far, from where it was, so that at any time of the playback the map shows the
lines whose crossing fixes the contact.
"""

import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd
from foxglove_schemas_protobuf.GeoJSON_pb2 import GeoJSON

from tma.families.bearings2d.drawn_tracks import (
    drawn_bearings,
    drawn_path,
    now_only,
    path_rows,
    platform_colour,
    platform_epochs,
    position_covariance,
    shown_estimates,
    sight_ends,
    sight_reach,
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
SIGHTS_TOPIC = "/tma/lines_of_sight/{label}"  # a log of several platforms: foxglove.GeoJSON


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
    # per topic: (t_s, lat, lon, covariance or None, frame_id) of location fixes, or
    # (t_s, payloads) of messages encoded already (lines of sight)
    channels, parts = [], []
    for s, lg in enumerate(logs):
        for channel, part in _platform_parts(lg, s, len(logs), origin_deg):
            channels.append(channel)
            parts.append(part)
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
        if logs[k].platform is not None:  # each platform's lines of sight to it
            sights = SIGHTS_TOPIC.format(label=topic.removeprefix(ESTIMATE_TOPIC.format(
                label="")))
            channels.append(Channel.protobuf(sights, GeoJSON, {
                "track_id": str(r.track_id), "lines_of_sight": SIGHTS_TEXT}))
            parts.append(_sight_part(logs[k], row, np.column_stack([x, y]), origin_deg))
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
    order = np.lexsort((which, t_all))  # time order; platforms first at equal times
    metadata = {GEO: json_record({"origin_lat_deg": origin_deg[0],
                                  "origin_lon_deg": origin_deg[1], "epoch_utc_ns": epoch_utc_ns}),
                "tma.run": json_record(run)}
    with LogWriter(path, channels, metadata, epoch_utc_ns=epoch_utc_ns) as w:
        payloads = [p for part in parts  # lines of sight come encoded
                    for p in (part[1] if len(part) == 2 else
                              _fixes(w.log_times(part[0]), part[4], *part[1:4]))]
        w.write_encoded([ch.topic for ch in channels], which[order], t_all[order],
                        Encoded.of([payloads[k] for k in order.tolist()]))
    return Path(path)


SIGHTS_TEXT = ("at each drawn bearing (every k-th of each platform's), each platform's latest "
               "line of sight so far, from where it was, as far as the estimated track")


def _platform_parts(lg, s: int, n_logs: int, origin_deg) -> list:
    """``(channel, part)`` of the platforms of log ``s`` of ``n_logs``: own-ship on
    ``/ownship/location_fix`` (``/ownship/<s>/location_fix`` of several logs); a log of
    several platforms each platform's own epochs on ``/platforms/<k>/location_fix``
    (``/ownship/<s>/platforms/<k>/location_fix``), its name the ``frame_id``."""
    lat, lon = local_to_geodetic(lg.own_x_m, lg.own_y_m, origin_deg)
    if lg.platform is None:
        topic = OWNSHIP_FIX_TOPIC if n_logs == 1 else f"/ownship/{s}/location_fix"
        return [(Channel.protobuf(topic, LocationFix, {"frame": "own-ship, sea level"}),
                 (lg.t_s, lat.tolist(), lon.tolist(), None, OWNSHIP_FRAME))]
    out = []
    for k, epochs in enumerate(platform_epochs(lg)):
        topic = f"/platforms/{k}/location_fix" if n_logs == 1 else (
            f"/ownship/{s}/platforms/{k}/location_fix")
        out.append((Channel.protobuf(topic, LocationFix, {
            "frame": "the platform, sea level", "platform": lg.platforms[k],
            "colour": platform_colour(k)}),
                    (lg.t_s[epochs], lat[epochs].tolist(), lon[epochs].tolist(), None,
                     lg.platforms[k])))
    return out


def _sight_part(lg, row: int, track, origin_deg) -> tuple:
    """``(t_s, payloads)`` of a contact's lines of sight (``SIGHTS_TOPIC``) in a log of
    several platforms: at each drawn bearing a ``foxglove.GeoJSON`` FeatureCollection of each
    platform's latest drawn line of sight so far (a LineString from the platform's position
    then, lon/lat in degrees as GeoJSON orders them, as far as ``track`` (m, 2) is from
    them), its properties ``name`` (platform and bearing), ``platform``, ``t_s``,
    ``bearing_deg`` and a leaflet ``style`` in the platform's colour. A line whose end lies
    beyond the map (``MAX_MAPPED_M``) is left out."""
    valid = np.flatnonzero(np.isfinite(lg.bearing_deg[row]))
    drawn = drawn_bearings(lg, valid)
    at = np.sort(np.concatenate([epochs for _, epochs, _ in drawn]))
    start, end = sight_ends(lg, row, at, sight_reach(
        np.column_stack([lg.own_x_m[at], lg.own_y_m[at]]), track))
    lat0, lon0 = local_to_geodetic(start[:, 0], start[:, 1], origin_deg)
    lat1, lon1 = local_to_geodetic(end[:, 0], end[:, 1], origin_deg)
    latest, payloads = {}, []
    for j, e in enumerate(at.tolist()):
        k = int(lg.platform[e])
        name, b = lg.platforms[k], float(lg.bearing_deg[row, e])
        if np.isfinite([lat0[j], lon0[j], lat1[j], lon1[j]]).all():
            latest[k] = {"type": "Feature", "geometry": {
                "type": "LineString", "coordinates": [[float(lon0[j]), float(lat0[j])],
                                                      [float(lon1[j]), float(lat1[j])]]},
                "properties": {"name": f"{name} {b:.1f} deg", "platform": name,
                               "t_s": float(lg.t_s[e]), "bearing_deg": b,
                               "style": {"color": platform_colour(k), "weight": 1}}}
        else:
            latest.pop(k, None)  # its line now would leave the map: none is drawn
        text = json.dumps({"type": "FeatureCollection",
                           "features": [latest[i] for i in sorted(latest)]})
        payloads.append(GeoJSON(geojson=text).SerializeToString(deterministic=True))
    return lg.t_s[at], payloads


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
