"""Bearing logs: own-ship navigation plus bearings to contacts, one MCAP message per epoch.

A log (and a dataset shard) holds one own-ship and any number of contacts (tracks). Topics:

- ``/ownship/navigation`` (schema ``tma.OwnshipNavigation``): ``{t_s, x_m, y_m}``
- ``/sonar/bearings`` (schema ``tma.BearingBatch``): ``{t_s, track_id[], bearing_deg[]}``;
  other tools may also send one bearing per message with scalar ``track_id`` and
  ``bearing_deg``: messages with equal ``t_s`` form one epoch.

tma writes these as protobuf (the schemas' protobuf twins, lz4 chunks: a table's 36 million
bearings write and read ~10x faster than as JSON text); ``encoding="json"`` writes JSON, and
either is read.

Own-ship positions are interpolated linearly to the bearing epochs (equal epochs are exact).
In memory a log is a rectangular ``(n_tracks, n_epochs)`` array with NaN where a contact has
no bearing at an epoch.

Several platforms (ships, buoys, stations) may take a contact's bearings: such a log holds
each platform's own topics ``/platforms/<k>/navigation`` and ``/platforms/<k>/bearings`` (the
same schemas; ``/platforms/<k>/location_fix`` with an origin) and the record
``tma.platforms`` (their names, in index order) instead of the two above; a bearing is taken
from its own platform's position at the same epoch. A log of one platform is written as before.

Optional references, as metadata records: ``tma.time`` (UTC of t = 0; log times are then
absolute), ``tma.geo`` (the local plane's WGS84 origin; the log then also carries own-ship as
``foxglove.LocationFix`` on ``/ownship/location_fix`` for Foxglove's Map panel, which tma's
readers skip), ``tma.tracks`` (the contacts' text labels), ``tma.sensor`` (the nominal
bearing noise) and ``tma.target`` (how the targets move, when known: a simulation).
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from tma.errors import InputError
from tma.families.bearings2d.manoeuvre_prior import ManoeuvrePrior
from tma.io.mcap_log import (
    COMPRESSION,
    GEO,
    PLATFORMS,
    TRACKS,
    Channel,
    LogWriter,
    geo_origin,
    platform_names,
    platform_namespace,
    read_epoch,
    track_labels,
)
from tma.io.mcap_read import read_log
from tma.io.mcap_values import (
    float_array,
    int_array,
    json_record,
    number,
    read_json_record,
    schema_errors,
)
from tma.io.mcap_writer import Encoded, Ragged
from tma.io.track_epochs import epochs, scatter
from tma.maths.geo import LocationFix, check_mapped, local_to_geodetic, location_fix
from tma.utc import MAX_EPOCH_NS

OWNSHIP_TOPIC = "/ownship/navigation"
BEARINGS_TOPIC = "/sonar/bearings"
SENSOR = "tma.sensor"  # metadata record: {"sigma_deg": nominal bearing noise}, when known
TARGET = "tma.target"  # metadata record: {"accel_psd_m2_s3": the targets' motion}, when known
OWNSHIP_FIX_TOPIC = "/ownship/location_fix"  # foxglove.LocationFix, only with an origin
OWNSHIP_FRAME = "ownship"
BLOCK_BEARINGS = 1 << 16  # bearings encoded at once: bounds the memory a long log takes
SCHEMAS = {OWNSHIP_TOPIC: "tma.OwnshipNavigation", BEARINGS_TOPIC: "tma.BearingBatch"}


def platform_topics(k: int | None) -> tuple[str, str, str]:
    """The navigation, bearings and location-fix topics of platform ``k`` (None: the one
    own-ship of a log of one platform)."""
    if k is None:
        return OWNSHIP_TOPIC, BEARINGS_TOPIC, OWNSHIP_FIX_TOPIC
    space = platform_namespace(k)
    return f"{space}/navigation", f"{space}/bearings", f"{space}/location_fix"


def channels(encoding: str = "protobuf", platform: int | None = None) -> list[Channel]:
    """The own-ship and bearing channels with messages in ``encoding`` (of platform
    ``platform`` of a log of several; None: the own-ship of a log of one)."""
    nav, bearings, _ = platform_topics(platform)
    return [
        Channel(nav, SCHEMAS[OWNSHIP_TOPIC],
                {"units": "t_s: s; x_m, y_m: m", "frame": "local plane, x east, y north"},
                encoding=encoding),
        Channel(bearings, SCHEMAS[BEARINGS_TOPIC],
                {"units": "t_s: s; bearing_deg: deg",
                 "convention": "bearing clockwise from north, from own-ship at the same epoch"},
                encoding=encoding),
    ]


CHANNELS = channels()
OWNSHIP_FIX_CHANNEL = Channel.protobuf(
    OWNSHIP_FIX_TOPIC, LocationFix,
    {"source": "/ownship/navigation mapped from the local plane at the tma.geo origin",
     "altitude": "0 (sea level)"})


def fix_channel(platform: int | None) -> Channel:
    """The ``foxglove.LocationFix`` channel of a platform (None: the one own-ship)."""
    if platform is None:
        return OWNSHIP_FIX_CHANNEL
    nav, _, fix = platform_topics(platform)
    return Channel.protobuf(fix, LocationFix, {
        "source": f"{nav} mapped from the local plane at the tma.geo origin",
        "altitude": "0 (sea level)"})


@dataclass
class BearingsLog:
    """One own-ship (or several platforms) and its contacts' bearings on a common epoch grid.

    t_s: (n_epochs,) strictly increasing (with several platforms: increasing, equal times
    only for different platforms, in platform order); own_x_m, own_y_m: (n_epochs,), the
    position of the platform that took the epoch's bearings;
    track_id: (n_tracks,) int64; bearing_deg: (n_tracks, n_epochs), NaN = no bearing;
    sigma_deg: the sensor's nominal one-sigma bearing noise (deg), None when unknown (the
    estimators then estimate it from the residuals). Stored in the metadata record
    ``tma.sensor``.
    epoch_utc_ns: UTC time of ``t_s = 0`` in nanoseconds since the Unix epoch; None when the
    source gave only relative times.
    origin_deg: ``(lat, lon)`` in degrees (WGS84) of the local plane's origin (x east, y north
    are east/north metres from it); None when the source had no geographic reference.
    track_label: (n_tracks,) the source's names for the contacts (text ids such as ``T1``);
    None when the names are the integer ``track_id``s themselves.
    accel_psd_m2_s3: the targets' declared motion, the power spectral density of their
    random acceleration per axis (m^2/s^3; 0: constant velocity), as a simulation knows it;
    None when not declared (a recording: the estimators then test for manoeuvres and
    assume real-ship motion). Stored in the metadata record ``tma.target``.
    manoeuvres: the targets' declared manoeuvres (``manoeuvres.ManoeuvrePrior``), with
    ``accel_psd_m2_s3`` only; None: none (or, without ``accel_psd_m2_s3``, not declared).
    Stored in ``tma.target`` too.
    platform: (n_epochs,) int64, the index into ``platforms`` of the platform whose bearings
    each epoch holds; None (with ``platforms``) for a log of one own-ship.
    platforms: the platforms' names, ``platforms[0]`` the reference: range and bearing now
    are given from it. Stored in the metadata record ``tma.platforms``.
    """

    t_s: np.ndarray
    own_x_m: np.ndarray
    own_y_m: np.ndarray
    track_id: np.ndarray
    bearing_deg: np.ndarray
    sigma_deg: float | None = None
    epoch_utc_ns: int | None = None
    origin_deg: tuple[float, float] | None = None
    track_label: np.ndarray | None = None
    accel_psd_m2_s3: float | None = None
    manoeuvres: ManoeuvrePrior | None = None
    platform: np.ndarray | None = None
    platforms: tuple[str, ...] | None = None

    @property
    def n_tracks(self) -> int:
        return self.track_id.size

    @property
    def n_platforms(self) -> int:
        return 1 if self.platforms is None else len(self.platforms)

    def validate(self, where: str):
        """Raise InputError if times, positions or bearings are not usable."""
        if self.t_s.size == 0:
            raise InputError(f"{where}: no epochs")
        if not np.all(np.isfinite(self.t_s)):
            raise InputError(f"{where}: non-finite time stamps")
        dt = np.diff(self.t_s)
        bad = dt <= 0
        if (self.platform is None) != (self.platforms is None):
            raise InputError(f"{where}: a platform per epoch needs the platforms' names, and "
                             "the names a platform per epoch")
        if self.platform is not None:
            p = np.asarray(self.platform)
            names = self.platforms
            if p.shape != self.t_s.shape or p.dtype.kind not in "iu" or (
                    p.size and (p.min() < 0 or p.max() >= len(names))):
                raise InputError(f"{where}: the platform of each epoch must be an index into "
                                 f"the {len(names)} platforms' names")
            if len(set(names)) != len(names) or not all(isinstance(n, str) and n
                                                        for n in names):
                raise InputError(f"{where}: the platforms' names must be distinct texts")
            bad = (dt < 0) | ((dt == 0) & (np.diff(p) <= 0))  # one epoch per platform and time
        if np.any(bad):
            k = int(np.argmax(bad))
            kind = "duplicate" if dt[k] == 0 else "non-increasing"
            raise InputError(f"{where}: {kind} time stamps at t = {float(self.t_s[k + 1])!r} s")
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
        q = self.accel_psd_m2_s3
        if q is not None and not 0 <= q < 1e6:
            raise InputError(f"{where}: the targets' declared accel_psd_m2_s3 {q!r} is not in "
                             "[0, 1e6) m^2/s^3")
        m = self.manoeuvres
        if m is not None and (q is None or not (0 <= m.rate_per_h <= 1000 and m.dv_m_s >= 0
                                                and m.step_s > 0
                                                and min(m.durations_s, default=0) > 0)):
            raise InputError(f"{where}: the targets' declared manoeuvres {m!r} are not a "
                             "prior (rate in [0, 1000] per hour, sizes >= 0, durations > 0), "
                             "or are declared without accel_psd_m2_s3")
        if self.epoch_utc_ns is not None and not 0 <= self.epoch_utc_ns < MAX_EPOCH_NS:
            raise InputError(f"{where}: epoch_utc_ns {self.epoch_utc_ns!r} is not a UTC time "
                             "between 1970 and 2200 in ns")
        if self.origin_deg is not None:
            lat, lon = self.origin_deg
            if not (-90 < lat < 90 and -180 <= lon <= 180):
                raise InputError(f"{where}: origin ({lat!r}, {lon!r}) is not a latitude in "
                                 "(-90, 90) and a longitude in [-180, 180] degrees")
        if self.track_label is not None:
            labels = self.track_label
            if len(labels) != self.n_tracks or not all(isinstance(s, str) for s in labels):
                raise InputError(f"{where}: track_label must hold one text label per track")
            if len(set(labels)) != len(labels):
                raise InputError(f"{where}: two tracks share one label")


def write_bearings_log(path, log: BearingsLog, metadata=None, encoding="protobuf") -> int:
    """Write ``log`` as MCAP (atomically), messages in ``encoding`` (``"protobuf"`` or
    ``"json"``). Returns the number of messages written.

    Log times are UTC (``log.epoch_utc_ns`` + t) when the log has an epoch. With an origin
    the log also holds the record ``tma.geo`` and own-ship as ``foxglove.LocationFix``.
    Messages are encoded a block of epochs at a time (``LogWriter.columns``)."""
    metadata, chosen = dict(metadata or {}), channels(encoding)
    if log.sigma_deg is not None:
        metadata[SENSOR] = json_record({"sigma_deg": log.sigma_deg})
    if log.accel_psd_m2_s3 is not None:
        target = {"accel_psd_m2_s3": log.accel_psd_m2_s3}
        if log.manoeuvres is not None:
            target["manoeuvres"] = dataclasses.asdict(log.manoeuvres)
        metadata[TARGET] = json_record(target)
    if log.track_label is not None:
        metadata[TRACKS] = json_record({"track_id": log.track_id,
                                        "label": [str(s) for s in log.track_label]})
    several = log.platforms is not None
    platforms = range(len(log.platforms)) if several else [None]
    if several:
        metadata[PLATFORMS] = json_record({"names": list(log.platforms)})
        chosen = [ch for k in platforms for ch in channels(encoding, k)]
    if log.origin_deg is not None:
        lat0, lon0 = (float(v) for v in log.origin_deg)
        metadata[GEO] = json_record({"origin_lat_deg": lat0, "origin_lon_deg": lon0,
                                     "epoch_utc_ns": log.epoch_utc_ns})
        chosen = [*chosen, *(fix_channel(k) for k in platforms)]
        check_mapped(log.own_x_m, log.own_y_m, log.t_s)  # (no path: it may be a staging file's)
        own_lat, own_lon = local_to_geodetic(log.own_x_m, log.own_y_m, (lat0, lon0))
    with LogWriter(path, chosen, metadata, epoch_utc_ns=log.epoch_utc_ns,
                   compression=COMPRESSION[encoding]) as w:
        step = max(1, BLOCK_BEARINGS // max(1, log.n_tracks))
        for start in range(0, log.t_s.size, step):
            block = np.arange(start, min(start + step, log.t_s.size))
            for k in platforms:
                at = block if k is None else block[log.platform[block] == k]
                if at.size:
                    nav, bearings, fix = platform_topics(k)
                    messages = {nav: w.columns(nav, {  # positions as floats
                        "t_s": log.t_s[at], "x_m": np.asarray(log.own_x_m[at], float),
                        "y_m": np.asarray(log.own_y_m[at], float)})}
                    if log.origin_deg is not None:
                        messages[fix] = _ownship_fixes(w.log_times(log.t_s[at]), own_lat[at],
                                                       own_lon[at])
                    messages[bearings] = _bearing_messages(w, bearings, log, at)
                    w.write_epochs(log.t_s[at], messages)
        return w.n_messages


def _bearing_messages(w: LogWriter, topic: str, log: BearingsLog, at: np.ndarray) -> Encoded:
    """The ``tma.BearingBatch`` messages of epochs ``at``: each epoch's contacts that have a
    bearing there."""
    bearing = np.ascontiguousarray(log.bearing_deg[:, at].T)  # (epochs, tracks)
    has = np.isfinite(bearing)  # a contact missing at an epoch is left out
    if has.all():  # the common case: every contact at every epoch, nothing to pick
        counts = np.full(at.size, log.n_tracks)
        ids, values = np.tile(log.track_id, at.size), bearing.ravel()
    else:
        counts = has.sum(1)
        ids, values = np.broadcast_to(log.track_id, has.shape)[has], bearing[has]
    return w.columns(topic, {"t_s": log.t_s[at], "track_id": Ragged(ids, counts),
                             "bearing_deg": Ragged(values, counts)})


def _ownship_fixes(t_ns, lat_deg, lon_deg) -> Encoded:
    """Own-ship's ``foxglove.LocationFix`` messages at log times ``t_ns``, serialised: one
    ``location_fix`` whose changing fields are set anew for each (twice as fast as a new
    message each, the same bytes)."""
    fix, payloads = location_fix(0, OWNSHIP_FRAME, 0.0, 0.0), []
    for ns, lat, lon in zip(t_ns.tolist(), lat_deg.tolist(), lon_deg.tolist(), strict=True):
        fix.latitude, fix.longitude = lat, lon
        fix.timestamp.seconds, fix.timestamp.nanos = divmod(ns, 10**9)
        payloads.append(fix.SerializeToString(deterministic=True))
    return Encoded.of(payloads)


def nominal_sigma(metadata: dict, where: str) -> float | None:
    if SENSOR not in metadata:
        return None
    with schema_errors(where, f"the metadata record {SENSOR}"):
        sigma = read_json_record(metadata, SENSOR, where)["sigma_deg"]
        return None if sigma is None else number(sigma)


def declared_motion(metadata: dict, where: str) -> tuple[float | None, ManoeuvrePrior | None]:
    """The targets' declared wander and manoeuvres (``BearingsLog``), from ``tma.target``."""
    if TARGET not in metadata:
        return None, None
    with schema_errors(where, f"the metadata record {TARGET}"):
        record = read_json_record(metadata, TARGET, where)
        q, m = number(record["accel_psd_m2_s3"]), record.get("manoeuvres")
        if m is None:
            return q, None
        return q, ManoeuvrePrior(number(m["rate_per_h"]), number(m["dv_m_s"]),
                                 tuple(number(d) for d in m["durations_s"]),
                                 number(m["step_s"]))


def _expected_topics(metadata: dict, where: str) -> dict:
    names = platform_names(metadata, where)
    if names is None:
        return SCHEMAS
    return {topic: SCHEMAS[base] for k in range(len(names))
            for topic, base in zip(platform_topics(k)[:2], SCHEMAS, strict=True)}


def read_bearings_log(path) -> BearingsLog:
    """Read a bearing log written by ``write_bearings_log`` or any tool using the schemas.

    ``track_id`` and ``bearing_deg`` may be arrays or scalars (one bearing per message);
    messages with equal ``t_s`` are one epoch, and a contact may appear once per epoch.
    A message that does not follow its schema raises InputError naming the file. Times come
    from ``t_s``, never from log times; the epoch, origin and labels from the metadata
    records; other channels (``/ownship/location_fix``) are not read. A log of several
    platforms (``tma.platforms``) has each platform's topics, read alike and put on one grid
    of (time, platform) epochs.
    """
    messages, metadata = read_log(path, _expected_topics, nonempty=True)
    where = str(path)
    names = platform_names(metadata, where)
    if names is None:
        t, own_x, own_y, track_id, bearing = _platform_part(messages, None, where)
        platform = None
    else:
        parts = [_platform_part(messages, k, where) for k in range(len(names))]
        t, own_x, own_y, track_id, bearing, platform = _on_one_grid(parts)
    log = BearingsLog(
        t_s=t, own_x_m=own_x, own_y_m=own_y, track_id=track_id, bearing_deg=bearing,
        sigma_deg=nominal_sigma(metadata, where), epoch_utc_ns=read_epoch(metadata, where),
        origin_deg=geo_origin(metadata, where),
        track_label=track_labels(metadata, track_id, where), platform=platform,
        platforms=names)
    log.accel_psd_m2_s3, log.manoeuvres = declared_motion(metadata, where)
    log.validate(where)
    return log


def _on_one_grid(parts):
    """The platforms' parts (``_platform_part``: each its epochs and its contacts) on one
    grid of epochs ordered by time, then platform; the tracks the union of theirs."""
    track_id = np.unique(np.concatenate([p[3] for p in parts]))
    platform = np.concatenate([np.full(p[0].size, k, np.int64) for k, p in enumerate(parts)])
    t, col, first = epochs(np.concatenate([p[0] for p in parts]), platform)
    grid = np.full((track_id.size, t.size), np.nan)
    start = 0
    for p in parts:  # (a platform's epochs are distinct: one column each)
        grid[np.searchsorted(track_id, p[3])[:, None], col[start:start + p[0].size]] = p[4]
        start += p[0].size
    own_x = np.concatenate([p[1] for p in parts])[first]
    own_y = np.concatenate([p[2] for p in parts])[first]
    return t, own_x, own_y, track_id, grid, platform[first]


def _platform_part(messages: dict, k: int | None, where: str):
    """``(t, own_x, own_y, track_id, bearing)`` of one platform's topics (``k``; None: the
    one own-ship of a log of one platform): its epochs, its position at them, its contacts
    and their (tracks x epochs) bearings."""
    nav_topic, bearings_topic, _ = platform_topics(k)
    nav, obs = messages[nav_topic], messages[bearings_topic]
    with schema_errors(where, f"a message on {nav_topic}"):
        nav_t = np.array([number(m["t_s"]) for m in nav])
        nav_x = np.array([number(m["x_m"]) for m in nav])
        nav_y = np.array([number(m["y_m"]) for m in nav])
    with schema_errors(where, f"a message on {bearings_topic}"):
        t_msg = np.array([number(m["t_s"]) for m in obs])
        ids_per_msg = [int_array(m["track_id"]) for m in obs]
        vals_per_msg = [float_array(m["bearing_deg"]) for m in obs]
    if any(i.size != v.size for i, v in zip(ids_per_msg, vals_per_msg, strict=True)):
        raise InputError(f"{where}: track_id and bearing_deg differ in length in a message")
    if np.any(np.diff(nav_t) <= 0):
        raise InputError(f"{where}: {nav_topic} time stamps are not strictly increasing")
    back = np.diff(t_msg) < 0
    if back.any():
        k = int(np.argmax(back)) + 1
        raise InputError(f"{where}: {bearings_topic} time stamps are not increasing "
                         f"at t = {t_msg[k]!r} s")
    if t_msg[0] < nav_t[0] or t_msg[-1] > nav_t[-1]:
        raise InputError(f"{where}: bearings outside the own-ship navigation time span")

    first = ids_per_msg[0]
    if (np.all(np.diff(t_msg) > 0) and np.all(np.diff(first) > 0)
            and all(np.array_equal(i, first) for i in ids_per_msg)):
        # the common case: every contact at every epoch, one message each
        t, track_id = t_msg, first.copy()
        bearing = np.stack(vals_per_msg, axis=1)
    else:  # equal t_s: one epoch sent as several messages (an epoch may hold no bearing)
        t, msg_col, _ = epochs(t_msg)
        cols = np.repeat(msg_col, [i.size for i in ids_per_msg])
        track_id, bearing = scatter(np.concatenate(ids_per_msg), cols,
                                    np.concatenate(vals_per_msg), t.size, where, "bearings",
                                    t.__getitem__)
    return t, np.interp(t, nav_t, nav_x), np.interp(t, nav_t, nav_y), track_id, bearing
