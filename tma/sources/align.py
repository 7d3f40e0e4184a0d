"""Readers' fixes and contacts -> one clock, one plane, own-ship at every value (``align``).

- One time base: every source has absolute UTC times, or every one relative times (mixing
  them is refused: nothing relates the two clocks), unless ``time.start_utc`` gives the UTC of
  the relative times' 0, which makes them absolute. The dataset starts at t = 0 at the first
  value kept; ``epoch_utc_ns`` is the UTC time of that t = 0 (None for relative times).
- One plane: latitude/longitude go to east/north metres (``tma.maths.geo.geodetic_to_local``, WGS84,
  h = 0) at the origin ``origin.lat``/``origin.lon`` or the first own-ship fix. The plane is
  tangent at the origin, and its north leans from true north away from it by the meridian
  convergence (0.0156 deg per km east-west at 60 deg latitude: 1.2 deg between shore stations
  80 km apart), so a direction taken from true north where its platform was (a bearing) is
  turned onto the plane's north there (``north_on_plane_deg``; tma's own logs, whose
  bearings are from their plane's north, from that plane's). Own-ship given in metres stays
  as it is, and so do its directions (``origin.*`` then states where its 0, 0 lies).
- Own-ship at each value: linear interpolation between fixes; a value up to
  ``nav.max_extrapolation_s`` outside the fixes' span is extrapolated from the end segment,
  one further out is dropped and counted. Gaps between fixes longer than ``nav.max_gap_s``
  are reported (values inside are interpolated across them); values inside a gap longer
  than ``nav.max_bridge_s`` (at least ``nav.max_gap_s``) are dropped and counted: own-ship's
  track across it is unknown (it may have turned), and a straight line would be made up.
- Text track labels become ids 0..n-1 in sorted label order (``Aligned.labels``, and the
  summary); a note says how each one unsafe for file names or Markdown is shown
  (``tma.sources.labels``).
- Own-ship fixes that cannot be right are outliers, left out and counted with the rows the
  readers left out (``bad_rows``; under ``fail`` the first refuses the file): a fix at exactly
  latitude 0, longitude 0 (what receivers report before their first fix), and a fix far off
  the track (``far_off``: farther from the median of the fixes around it, ``OUTLIER_NEIGHBOURS``
  on each side, than own-ship could have gone at ``nav.max_speed_m_s``, plus
  ``OUTLIER_TOLERANCE_M`` for the fixes' own noise).

What comes out is one ``Platform`` per own-ship: flat arrays, one row per value; the family
makes its logs from them (``bearings2d``: one epoch grid per own-ship, shared by its tracks;
platforms named by the input, ``Recording.platform``, share one grid, a contact's values from
all of them one track). A platform given by a single fix (a buoy, a shore station) is fixed
there: it is at that place at every value's time.
"""

from dataclasses import dataclass

import numpy as np

from tma.errors import ConfigError, InputError
from tma.maths.geo import geodetic_to_local, local_to_geodetic, north_on_plane_deg
from tma.sources.base import Dropped, Navigation, Recording
from tma.sources.labels import shown_labels
from tma.utc import format_utc, stamp_text

MAX_LISTED_GAPS = 20
OUTLIER_NEIGHBOURS = 10  # fixes on each side whose median a fix is held against
OUTLIER_TOLERANCE_M = 100.0  # the fixes' own noise (GNSS, multipath) the rule allows for
# more steps between successive fixes than this share (and at least MIXED_MIN_JUMPS) faster
# than own-ship can go: not outliers but own-ship jumping between places, as the rows of
# several platforms do (refused, ``_one_platform``)
MIXED_SHARE, MIXED_MIN_JUMPS = 0.1, 10


@dataclass
class Platform:
    """One own-ship's values on the common clock (t = 0 at the first value kept), one row
    each: time, own-ship position (local metres), contact id, value; and its recording."""

    t_s: np.ndarray
    own_x_m: np.ndarray
    own_y_m: np.ndarray
    track_id: np.ndarray  # int64
    values: np.ndarray
    recording: Recording


@dataclass
class Aligned:
    """What ``align`` gives: the platforms, the UTC of t = 0 (None: relative times), the
    plane's origin (None: local metres without one), the contacts' text labels indexed by id
    (None: numbered contacts) and a summary for the manifest."""

    platforms: list[Platform]
    epoch_utc_ns: int | None
    origin_deg: tuple[float, float] | None
    labels: np.ndarray | None
    summary: dict
    dropped: Dropped  # every row left out so far (readers and outliers), under the policy


def align(recordings: list[Recording], options, where: str) -> Aligned:
    """The recordings (each with own-ship fixes and contacts) on one clock and one plane, with
    own-ship at every value, read with a family's ``options`` (whose observation's ``guard``
    runs here, once the values of all the recordings are known). The summary holds
    ``epoch_utc_ns``, ``start_utc``, ``origin_deg``, ``track_labels``,
    ``dropped_<plural>``, ``nav_gaps``, ``notes``, ``time_origin_s``. ``where``: the input,
    for messages."""
    observation = options.observation
    plural = observation.plural
    bad = options.dropped()
    for r in recordings:
        bad.merge(r.dropped)
    ref, start, notes_time = _time_reference(recordings, options)
    navs = [_shifted(r.navigation.t_s, r.navigation.epoch_utc_ns, ref, start)
            for r in recordings]
    obs = [_shifted(r.contacts.t_s, r.contacts.epoch_utc_ns, ref, start) for r in recordings]
    origin, positions, navs, notes = _local_plane(recordings, navs, options, bad)
    ids, labels = _track_ids([r.contacts.track for r in recordings])
    if labels is not None:
        notes += [f"contact {label[:40]!r}{'...' if len(label) > 40 else ''} is shown as "
                  f"{s!r} in tables, file names and map topics (the CSV and the manifest keep "
                  "it as written)"
                  for label, s in zip(labels, shown_labels(labels), strict=True) if s != label]
    if observation.guard is not None:
        observation.guard(recordings, options, where)

    per_nav, gaps = [], []
    dropped = {"before_navigation": 0, "after_navigation": 0, "in_navigation_gaps": 0}
    bridge_s = max(options.nav.max_bridge_s, options.nav.max_gap_s)
    for rec, t_nav, (x_nav, y_nav), t_obs, track in zip(recordings, navs, positions, obs, ids,
                                                        strict=True):
        t_nav, x_nav, y_nav = _distinct_fixes(t_nav, x_nav, y_nav, rec.navigation,
                                              observation.role, fixed=rec.platform is not None)
        if t_nav.size == 1:  # a fixed platform (rec.platform named: a buoy, a station)
            x, y = np.full(t_obs.size, x_nav[0]), np.full(t_obs.size, y_nav[0])
            before = after = np.zeros(t_obs.size, dtype=bool)
            notes.append(f"platform {rec.platform!r} has one fix: taken as fixed there (a "
                         "buoy, a station)")
        else:
            x, y, before, after = _ownship_at(t_obs, t_nav, x_nav, y_nav,
                                              options.nav.max_extrapolation_s)
        dropped["before_navigation"] += int(before.sum())
        dropped["after_navigation"] += int(after.sum())
        keep = ~(before | after)
        unknown = _in_long_gaps(t_obs, t_nav, bridge_s) & keep  # own-ship's track unknown
        dropped["in_navigation_gaps"] += int(unknown.sum())
        keep &= ~unknown
        gaps += _gaps(t_nav, t_obs[keep], options.nav.max_gap_s, rec.navigation.source, plural)
        values = rec.contacts.values[keep]
        if observation.direction and origin is not None and rec.navigation.geographic:
            values = values + _onto_plane(x[keep], y[keep], origin,
                                          rec.contacts.plane_origin_deg)
            values = np.where(np.abs(values) >= 360.0, np.fmod(values, 360.0), values)
        per_nav.append((t_obs[keep], x[keep], y[keep], track[keep], values, rec))
    if not any(p[0].size for p in per_nav):
        r = recordings[0]
        hours = hours_apart(obs[0], navs[0])
        if hours:
            nav_zone = r.navigation.zone_option  # (the AIS's own, for own-ship from it)
            zone = "" if nav_zone == "time.zone" else f"{nav_zone}=<Area/City> for the AIS's, "
            raise InputError(
                f"{where}: no {observation.role} lies within the own-ship fixes' time span, "
                f"but they would if the {plural} were {hours:+d} h later (fixes {_span(navs[0])}, "
                f"{plural} {_span(obs[0])} s on the common clock; see "
                f"{r.navigation.source}): one of them is local time read as UTC, or the two "
                f"are in different zones; give each the IANA zone it was written in ({zone}"
                "time.zone=<Area/City> for the log's, e.g. Europe/Helsinki)")
        raise InputError(
            f"{where}: no {observation.role} lies within the own-ship fixes' time span (fixes "
            f"{_span(navs[0])}, {plural} {_span(obs[0])} s on the common clock; see "
            f"{r.navigation.source}): do both sources use the same clock (time.format)? "
            "Or raise nav.max_extrapolation_s")

    t0 = min(float(p[0].min()) for p in per_nav if p[0].size)
    epoch = None if ref is None else ref + int(round(t0 * 1e9))
    platforms = [Platform(t - t0, x, y, track, values, rec)
                 for t, x, y, track, values, rec in per_nav if t.size]
    n_dropped = sum(dropped.values())
    if len(platforms) > 1 and all(p.recording.platform for p in platforms):
        notes.append("several platforms: " + ", ".join(
            f"{p.recording.platform!r} ({p.t_s.size} {plural})" for p in platforms)
            + "; range and bearing now are given from the first unless the estimator's "
            "reference_platform names another")
    for gap in gaps:
        gap["from_s"], gap["to_s"] = gap["from_s"] - t0, gap["to_s"] - t0
    summary = {
        "epoch_utc_ns": epoch,
        "start_utc": None if epoch is None else format_utc(epoch),
        "time_origin_s": t0 if ref is None else epoch / 1e9,
        "origin_deg": None if origin is None else [origin[0], origin[1]],
        "track_labels": None if labels is None else {str(i): str(s)
                                                     for i, s in enumerate(labels)},
        f"dropped_{plural}": {
            "count": n_dropped, **dropped,
            "why": _why_dropped(dropped, options.nav.max_extrapolation_s, bridge_s)},
        "nav_gaps": {"max_gap_s": options.nav.max_gap_s, "count": len(gaps),
                     "longest_s": max((g["length_s"] for g in gaps), default=None),
                     "gaps": gaps[:MAX_LISTED_GAPS]},
        "notes": [*dict.fromkeys(n for r in recordings for n in r.notes), *notes_time, *notes],
    }
    return Aligned(platforms, epoch, origin, labels, summary, bad)


def _onto_plane(x, y, origin, plane_origin=None) -> np.ndarray:
    """What turns directions taken at (``x``, ``y``) on the plane at ``origin`` onto its
    north (deg): from true north there (a sensor's bearing) the meridian convergence, from
    another plane's north (tma's own log at ``plane_origin``) the difference of the two."""
    lat, lon = local_to_geodetic(x, y, origin)
    turn = north_on_plane_deg(lat, lon, origin)
    if plane_origin is not None:
        turn -= north_on_plane_deg(lat, lon, plane_origin)
    return turn


def _time_reference(recordings, options):
    """``(reference, start, notes)``: the earliest epoch (UTC ns) when every source is
    absolute, or made so by ``time.start_utc`` (``start``: the UTC of the relative sources'
    time 0, else None); None when every source is relative and no start is given. A mixture
    without a start, or a start for a log without relative times, raises."""
    sources = [(s.epoch_utc_ns, s.source) for r in recordings
               for s in (r.navigation, r.contacts)]
    start = options.time.start_ns
    relative = [where for e, where in sources if e is None]
    if start is not None:
        if not relative:
            raise ConfigError(f"time.start_utc={options.time.start_utc} applies to logs of "
                              f"relative times: {sources[0][1]} has UTC times; leave "
                              "time.start_utc unset")
        note = (f"relative times of {', '.join(dict.fromkeys(relative))} made absolute: time 0 "
                f"is {format_utc(start)} (time.start_utc)")
        return min([start, *(e for e, _ in sources if e is not None)]), start, [note]
    if not relative:
        return min(e for e, _ in sources), None, []
    if len(relative) == len(sources):
        return None, None, []
    rel = relative[0]
    abs_ = next(s for e, s in sources if e is not None)
    raise InputError(f"{rel} has relative times (seconds from an arbitrary zero) but {abs_} "
                     f"has absolute UTC times (time.format={options.time.format}): nothing "
                     "relates the two clocks; give both as absolute times (Unix or ISO-8601 "
                     "with a zone: time.format=unix_s|unix_ms|unix_ns|iso) or both relative, or "
                     "give the UTC of the relative times' 0 with time.start_utc=")


def _shifted(t_s, epoch, ref, start=None) -> np.ndarray:
    """Times on the common clock (``start``: the epoch of a source of relative times)."""
    t = np.asarray(t_s, dtype=float)
    epoch = start if epoch is None else epoch
    return t if ref is None else t + (epoch - ref) / 1e9


def _local_plane(recordings, navs, options, dropped: Dropped):
    """``(origin (lat, lon) or None, [(x, y) per recording], [times per recording], notes)``,
    the outlier fixes left out (``dropped``)."""
    geographic = [r.navigation.geographic for r in recordings]
    given = options.origin.lat is not None
    notes = []
    if not any(geographic):
        if given:
            notes.append(f"own-ship x/y taken as metres east/north of origin.lat/lon = "
                         f"{options.origin.lat:g}, {options.origin.lon:g}")
        origin = (options.origin.lat, options.origin.lon) if given else None
        positions, times = [], []
        for r, t in zip(recordings, navs, strict=True):
            nav = r.navigation
            keep = _on_track(t, nav.x_m, nav.y_m, nav, np.arange(t.size), options, dropped)
            positions.append((nav.x_m[keep], nav.y_m[keep]))
            times.append(t[keep])
        if given:
            _near_the_fixes(positions, options)
        return origin, positions, times, notes
    if not all(geographic):
        raise InputError("own-ship positions come both as latitude/longitude and as local x/y "
                         "metres: give one kind")
    kept = []  # per recording: the rows kept
    for r in recordings:
        nav = r.navigation
        zero = (nav.lat_deg == 0) & (nav.lon_deg == 0)
        keep = dropped.drop(zero, "own-ship fix at 0, 0", fix_places(nav, np.arange(zero.size)),
                            f"{nav.source}: an own-ship fix at 0, 0 (a receiver without a fix)")
        kept.append(np.flatnonzero(keep))
    fixes = np.concatenate([np.c_[r.navigation.lat_deg[rows], r.navigation.lon_deg[rows]]
                            for r, rows in zip(recordings, kept, strict=True)])
    if not fixes.size:
        raise InputError(f"{recordings[0].navigation.source}: no own-ship fix left: "
                         f"{dropped.text()}")
    middle = tuple(np.median(fixes, axis=0))  # a plane no outlier can move far
    for k, (r, t, rows) in enumerate(zip(recordings, navs, kept, strict=True)):
        x, y = geodetic_to_local(r.navigation.lat_deg[rows], r.navigation.lon_deg[rows], middle)
        kept[k] = rows[_on_track(t[rows], x, y, r.navigation, rows, options, dropped)]
    if given:
        lat0, lon0 = options.origin.lat, options.origin.lon
    else:
        first = int(np.argmin([t[rows[0]] if rows.size else np.inf
                               for t, rows in zip(navs, kept, strict=True)]))
        nav, row = recordings[first].navigation, kept[first][0]
        lat0, lon0 = float(nav.lat_deg[row]), float(nav.lon_deg[row])
        notes.append(f"local plane origin at the first own-ship fix {lat0:.7f}, {lon0:.7f} "
                     "(origin.lat/origin.lon)")
    positions = [geodetic_to_local(r.navigation.lat_deg[rows], r.navigation.lon_deg[rows],
                                   (lat0, lon0)) for r, rows in zip(recordings, kept, strict=True)]
    if given:
        _near_the_fixes(positions, options)
    return (lat0, lon0), positions, [t[rows] for t, rows in zip(navs, kept, strict=True)], notes


def _near_the_fixes(positions, options):
    """A given origin lies within ``origin.max_distance_km`` of an own-ship fix (an origin far
    from them all is a mistake: another place, swapped or mistyped coordinates)."""
    nearest = min(float(np.hypot(x, y).min()) for x, y in positions if x.size)
    limit = options.origin.max_distance_km
    if nearest > limit * 1e3:
        o = options.origin
        raise InputError(f"origin.lat/origin.lon = {o.lat:g}, {o.lon:g} lies "
                         f"{nearest / 1e3:.0f} km from the nearest own-ship fix (at most "
                         f"origin.max_distance_km = {limit:g}): is it the log's place?")


def fix_places(nav: Navigation, index: np.ndarray):
    """Row indices into ``nav``'s rows ``index`` -> their places: file lines, else the topic
    and time."""
    def places(rows):
        rows = index[rows]
        if nav.lines is not None:
            return [f"line {n}" for n in nav.lines[rows]]
        epoch = nav.epoch_utc_ns or 0
        return [f"{nav.topic or nav.source} at "
                f"{stamp_text(epoch + int(round(nav.t_s[i] * 1e9)))}" for i in rows]
    return places


def far_off(t, x, y, max_speed_m_s: float) -> np.ndarray:
    """Fixes (sorted by time ``t``, positions ``x``, ``y`` in m) farther from the
    component-wise median of the ``2 OUTLIER_NEIGHBOURS + 1`` fixes around them (itself
    included; at the ends, the first or last so many) than sqrt(2) * ``max_speed_m_s`` * (the
    longest time to one of them) + ``OUTLIER_TOLERANCE_M``. A track that never moves faster
    than ``max_speed_m_s`` always passes: every fix of the window lies within speed x time of
    the fix, so each coordinate of their median does too, and the median within sqrt(2) times
    that. A fix off the track is caught as long as fewer than half of the window is off too
    (up to ``OUTLIER_NEIGHBOURS`` bad fixes in a row). Running medians (scipy.ndimage): a
    million fixes take about 0.1 s."""
    from scipy.ndimage import maximum_filter1d, median_filter, minimum_filter1d

    n = t.size
    if n < 3:
        return np.zeros(n, dtype=bool)
    k = min(OUTLIER_NEIGHBOURS, (n - 1) // 2)
    size = 2 * k + 1
    mx, my = (median_filter(v, size=size, mode="nearest") for v in (x, y))
    reach = np.maximum(maximum_filter1d(t, size, mode="nearest") - t,
                       t - minimum_filter1d(t, size, mode="nearest"))
    if k:  # the first and last k fixes: the window of the first (last) size fixes
        for end, window in ((slice(None, k), slice(None, size)),
                            (slice(n - k, None), slice(n - size, None))):
            mx[end], my[end] = np.median(x[window]), np.median(y[window])
            reach[end] = np.maximum(t[window][-1] - t[end], t[end] - t[window][0])
    return np.hypot(x - mx, y - my) > np.sqrt(2) * max_speed_m_s * reach + OUTLIER_TOLERANCE_M


def _one_platform(t, x, y, nav: Navigation, max_speed_m_s: float):
    """Refuses fixes (sorted by time) that jump between places: more than ``MIXED_SHARE`` of
    the steps between successive fixes (and ``MIXED_MIN_JUMPS`` or more) longer than
    ``max_speed_m_s`` allows plus ``OUTLIER_TOLERANCE_M``. An outlier makes two such steps;
    the rows of two platforms taken in turn make nearly every step one."""
    step = np.hypot(np.diff(x), np.diff(y))
    jumps = step > max_speed_m_s * np.diff(t) + OUTLIER_TOLERANCE_M
    if jumps.sum() >= MIXED_MIN_JUMPS and jumps.mean() > MIXED_SHARE:
        raise InputError(
            f"{nav.source}: {jumps.sum()} of {jumps.size} steps between successive own-ship "
            f"fixes ({jumps.mean():.0%}) are faster than nav.max_speed_m_s = "
            f"{max_speed_m_s:g} m/s allows, up to {step[jumps].max() / 1000:.1f} km: own-ship "
            "jumps between places, as when the rows are values taken by several platforms "
            "(ships, buoys, stations): name each row's platform in a column (platform, or "
            "columns.platform=<column>), and each platform's positions are its own")


def _on_track(t, x, y, nav: Navigation, index, options, dropped: Dropped) -> np.ndarray:
    """The fixes to keep: those ``far_off`` finds off the track are left out (``index``: the
    rows of ``nav`` they are)."""
    order = np.argsort(t, kind="stable")
    _one_platform(t[order], x[order], y[order], nav, options.nav.max_speed_m_s)
    off = np.zeros(t.size, dtype=bool)
    off[order] = far_off(t[order], x[order], y[order], options.nav.max_speed_m_s)
    return dropped.drop(off, "own-ship fix far off the track", fix_places(nav, index),
                        f"{nav.source}: an own-ship fix far off the track (farther from its "
                        f"neighbours than nav.max_speed_m_s = {options.nav.max_speed_m_s:g} m/s "
                        "allows)")


def _track_ids(tracks: list[np.ndarray]):
    """int64 ids per recording, and the labels (object array indexed by id) when the tracks
    are named by text: ids are then 0..n-1 in sorted label order."""
    if not any(t.dtype == object for t in tracks):
        return [np.asarray(t, dtype=np.int64) for t in tracks], None
    import pandas as pd  # text labels only: a log of numbered tracks is read without pandas

    codes, names = [], []
    for t in tracks:
        code, uniques = pd.factorize(np.asarray(t).astype(str).astype(object))
        codes.append(code)
        names.append(np.asarray(uniques, dtype=object))
    labels = np.unique(np.concatenate(names)).astype(object)
    return [np.searchsorted(labels, n)[c].astype(np.int64)
            for c, n in zip(codes, names, strict=True)], labels


def _distinct_fixes(t, x, y, nav: Navigation, role: str, fixed: bool = False):
    """Fixes sorted by time; repeated times must repeat the position (then kept once).
    ``fixed``: one fix is enough (a named platform that does not move)."""
    order = np.argsort(t, kind="stable")
    t, x, y = t[order], x[order], y[order]
    same = t[1:] == t[:-1]
    if same.any():
        moved = same & ((x[1:] != x[:-1]) | (y[1:] != y[:-1]))
        if moved.any():
            k = int(np.argmax(moved))
            raise InputError(f"{nav.source}: two different own-ship positions at one time "
                             f"({t[k]:.9g} s on the common clock)")
        keep = np.r_[True, ~same]
        t, x, y = t[keep], x[keep], y[keep]
    if t.size < 2 - fixed:
        raise InputError(f"{nav.source}: {t.size} own-ship fix(es): at least two are needed "
                         f"to place the own-ship at the {role} times")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(t))):
        raise InputError(f"{nav.source}: non-finite own-ship fixes")
    return t, x, y


def _ownship_at(t, t_nav, x_nav, y_nav, max_extrapolation_s):
    """Own-ship x, y at times ``t`` (linear between fixes, the end segments extended), and the
    masks of times too far before / after the fixes."""
    x, y = np.interp(t, t_nav, x_nav), np.interp(t, t_nav, y_nav)
    for end, (a, b) in ((t < t_nav[0], (0, 1)), (t > t_nav[-1], (-2, -1))):
        if end.any():
            dt = t[end] - t_nav[a if a == 0 else b]
            span = t_nav[b] - t_nav[a]
            x[end] += dt * (x_nav[b] - x_nav[a]) / span
            y[end] += dt * (y_nav[b] - y_nav[a]) / span
    before = t < t_nav[0] - max_extrapolation_s
    after = t > t_nav[-1] + max_extrapolation_s
    return x, y, before, after


def _why_dropped(dropped: dict, max_extrapolation_s: float, bridge_s: float) -> str:
    """Why values were dropped, the causes of ``dropped`` (counts) that occurred (the
    extrapolation limit alone where none did)."""
    outside = (f"more than nav.max_extrapolation_s = {max_extrapolation_s:g} s outside the "
               "own-ship fixes' time span")
    in_gaps = (f"inside a gap between the own-ship fixes longer than nav.max_bridge_s = "
               f"{bridge_s:g} s (own-ship's track there is unknown; a larger nav.max_bridge_s "
               "interpolates across it)")
    if not dropped["in_navigation_gaps"]:
        return outside
    if dropped["before_navigation"] + dropped["after_navigation"]:
        return f"{outside}; {in_gaps}"
    return in_gaps


def _in_long_gaps(t, t_nav, max_gap_s) -> np.ndarray:
    """Which times ``t`` lie strictly inside a gap between consecutive fixes ``t_nav``
    (sorted, common clock seconds) longer than ``max_gap_s``."""
    if t_nav.size < 2:  # (a fixed platform: one fix, no gap)
        return np.zeros(t.size, dtype=bool)
    k = np.clip(np.searchsorted(t_nav, t, side="right"), 1, t_nav.size - 1)
    return (t > t_nav[k - 1]) & (t < t_nav[k]) & (t_nav[k] - t_nav[k - 1] > max_gap_s)


def _gaps(t_nav, t_obs, max_gap_s, source, plural) -> list[dict]:
    """Gaps between consecutive fixes longer than ``max_gap_s`` (common clock seconds) with a
    value inside: own-ship is interpolated across those; a gap without one is interpolated
    for none (own-ship from its AIS leaves the values in its gaps out beforehand,
    ``tma.ais.ownship``)."""
    dt = np.diff(t_nav)
    where = np.flatnonzero(dt > max_gap_s)
    t_sorted = np.sort(t_obs)
    inside = (np.searchsorted(t_sorted, t_nav[where + 1], side="left")
              - np.searchsorted(t_sorted, t_nav[where], side="right"))
    return [{"from_s": float(t_nav[k]), "to_s": float(t_nav[k + 1]), "length_s": float(dt[k]),
             f"{plural}_inside": int(n), "source": source}
            for k, n in zip(where, inside, strict=True) if n > 0]


def hours_apart(t_a, t_b, max_hours: int = 14) -> int:
    """The whole number of hours k (1 <= |k| <= ``max_hours``, the smallest) by which times
    ``t_a`` (s) shifted lie nearly all (90 %) within the span of ``t_b``, when unshifted
    none does: two clocks a zone apart (local time read as UTC). 0 when there is none."""
    t_a, t_b = np.asarray(t_a, float), np.asarray(t_b, float)
    if not t_a.size or not t_b.size:
        return 0
    lo, hi = t_b.min(), t_b.max()
    if ((t_a >= lo) & (t_a <= hi)).any():
        return 0
    for k in sorted(range(-max_hours, max_hours + 1), key=lambda k: (abs(k), k)):
        shifted = t_a + 3600.0 * k
        if k and ((shifted >= lo) & (shifted <= hi)).mean() >= 0.9:
            return k
    return 0


def _span(t) -> str:
    return f"{t.min():.6g} to {t.max():.6g}" if t.size else "none"
