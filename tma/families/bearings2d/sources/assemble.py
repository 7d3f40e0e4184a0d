"""Readers' fixes and bearings -> the ``BearingsLog``s of a dataset (one per own-ship).

- One time base: every source has absolute UTC times, or every one relative times (mixing
  them is refused: nothing relates the two clocks). The dataset starts at t = 0 at the first
  bearing kept; ``epoch_utc_ns`` is the UTC time of that t = 0 (None for relative times).
- One plane: latitude/longitude go to east/north metres (pymap3d ``geodetic2enu``, WGS84,
  h = 0) at the origin ``origin.lat``/``origin.lon`` or the first own-ship fix. The plane is
  tangent at the origin, so bearings (clockwise from its north) stay true to within the
  meridian convergence, about 0.015 deg per km east-west at 60 deg latitude. Own-ship given
  in metres stays as it is (``origin.*`` then states where its 0, 0 lies).
- Own-ship at each bearing: linear interpolation between fixes; a bearing up to
  ``nav.max_extrapolation_s`` outside the fixes' span is extrapolated from the end segment,
  one further out is dropped and counted. Gaps between fixes longer than ``nav.max_gap_s``
  are reported (bearings inside are interpolated across them).
- One epoch grid per own-ship, shared by its tracks (NaN where a track has no bearing).
  Text track labels become ids 0..n-1 in sorted label order (labels kept in
  ``BearingsLog.track_label`` and the summary).
"""

import numpy as np

from tma.errors import InputError
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.sources.base import Navigation, Recording, SourceOptions
from tma.io.mcap_log import format_utc

MAX_CELLS = 1 << 26  # bearings grid cells (tracks x epochs) per log: 512 MiB of float64
MAX_LISTED_GAPS = 20
RADIANS_MIN_COUNT = 10


def assemble(recordings: list[Recording], options: SourceOptions,
             where: str) -> tuple[list[BearingsLog], dict]:
    """``BearingsLog``s (times from 0, own-ship in local metres) and a summary for the
    manifest (``epoch_utc_ns``, ``start_utc``, ``origin_deg``, ``track_labels``,
    ``dropped_bearings``, ``nav_gaps``, ``notes``, ``time_origin_s``). Every recording must
    hold own-ship fixes and bearings. ``where``: the input, for messages."""
    ref = _time_reference(recordings, options)
    navs = [_shifted(r.navigation.t_s, r.navigation.epoch_utc_ns, ref) for r in recordings]
    obs = [_shifted(r.bearings.t_s, r.bearings.epoch_utc_ns, ref) for r in recordings]
    origin, positions, notes = _local_plane(recordings, navs, options)
    ids, labels = _track_ids([r.bearings.track for r in recordings])
    _check_radians(recordings, options, where)

    per_nav, dropped, gaps = [], {"before_navigation": 0, "after_navigation": 0}, []
    for rec, t_nav, (x_nav, y_nav), t_obs, track in zip(recordings, navs, positions, obs, ids,
                                                        strict=True):
        t_nav, x_nav, y_nav = _distinct_fixes(t_nav, x_nav, y_nav, rec.navigation)
        x, y, before, after = _ownship_at(t_obs, t_nav, x_nav, y_nav,
                                          options.nav.max_extrapolation_s)
        dropped["before_navigation"] += int(before.sum())
        dropped["after_navigation"] += int(after.sum())
        keep = ~(before | after)
        gaps += _gaps(t_nav, t_obs[keep], options.nav.max_gap_s, rec.navigation.source)
        per_nav.append((t_obs[keep], x[keep], y[keep], track[keep],
                        rec.bearings.bearing_deg[keep], rec))
    if not any(p[0].size for p in per_nav):
        r = recordings[0]
        raise InputError(
            f"{where}: no bearing lies within the own-ship fixes' time span (fixes "
            f"{_span(navs[0])}, bearings {_span(obs[0])} s on the common clock; see "
            f"{r.navigation.source}): do both sources use the same clock (time.format)? "
            "Or raise nav.max_extrapolation_s")

    t0 = min(float(p[0].min()) for p in per_nav if p[0].size)
    epoch = None if ref is None else ref + int(round(t0 * 1e9))
    logs = []
    for t, x, y, track, bearing, rec in per_nav:
        if t.size:
            logs += _logs(t - t0, x, y, track, bearing, rec, where)
    for lg in logs:
        lg.epoch_utc_ns = epoch
        lg.origin_deg = origin
        if labels is not None:
            lg.track_label = labels[lg.track_id]

    n_dropped = dropped["before_navigation"] + dropped["after_navigation"]
    for gap in gaps:
        gap["from_s"], gap["to_s"] = gap["from_s"] - t0, gap["to_s"] - t0
    summary = {
        "epoch_utc_ns": epoch,
        "start_utc": None if epoch is None else format_utc(epoch),
        "time_origin_s": t0 if ref is None else epoch / 1e9,
        "origin_deg": None if origin is None else [origin[0], origin[1]],
        "track_labels": None if labels is None else {str(i): str(s)
                                                     for i, s in enumerate(labels)},
        "dropped_bearings": {
            "count": n_dropped, **dropped,
            "why": (f"more than nav.max_extrapolation_s = {options.nav.max_extrapolation_s:g} s "
                    "outside the own-ship fixes' time span")},
        "nav_gaps": {"max_gap_s": options.nav.max_gap_s, "count": len(gaps),
                     "longest_s": max((g["length_s"] for g in gaps), default=None),
                     "gaps": gaps[:MAX_LISTED_GAPS]},
        "notes": [*dict.fromkeys(n for r in recordings for n in r.notes), *notes],
    }
    return logs, summary


def _time_reference(recordings, options) -> int | None:
    """The earliest epoch (UTC ns) when every source is absolute; None when every source is
    relative; InputError when they are mixed."""
    sources = [(s.epoch_utc_ns, s.source) for r in recordings
               for s in (r.navigation, r.bearings)]
    absolute = [e is not None for e, _ in sources]
    if all(absolute):
        return min(e for e, _ in sources)
    if not any(absolute):
        return None
    rel = next(s for e, s in sources if e is None)
    abs_ = next(s for e, s in sources if e is not None)
    raise InputError(f"{rel} has relative times (seconds from an arbitrary zero) but {abs_} "
                     f"has absolute UTC times (time.format={options.time.format}): nothing "
                     "relates the two clocks; give both as absolute times (Unix or ISO-8601 "
                     "with a zone: time.format=unix_s|unix_ms|unix_ns|iso) or both relative")


def _shifted(t_s, epoch, ref) -> np.ndarray:
    t = np.asarray(t_s, dtype=float)
    return t if ref is None else t + (epoch - ref) / 1e9


def _local_plane(recordings, navs, options):
    """(origin (lat, lon) or None, [(x, y) per recording], notes)."""
    geographic = [r.navigation.geographic for r in recordings]
    given = options.origin.lat is not None
    notes = []
    if not any(geographic):
        if given:
            notes.append(f"own-ship x/y taken as metres east/north of origin.lat/lon = "
                         f"{options.origin.lat:g}, {options.origin.lon:g}")
        origin = (options.origin.lat, options.origin.lon) if given else None
        return origin, [(r.navigation.x_m, r.navigation.y_m) for r in recordings], notes
    if not all(geographic):
        raise InputError("own-ship positions come both as latitude/longitude and as local x/y "
                         "metres: give one kind")
    if given:
        lat0, lon0 = options.origin.lat, options.origin.lon
    else:
        first = int(np.argmin([t[0] for t in navs]))
        lat0 = float(recordings[first].navigation.lat_deg[0])
        lon0 = float(recordings[first].navigation.lon_deg[0])
        notes.append(f"local plane origin at the first own-ship fix {lat0:.7f}, {lon0:.7f} "
                     "(origin.lat/origin.lon)")
    import pymap3d  # latitude/longitude navigation only

    positions = []
    for r in recordings:
        east, north, _ = pymap3d.geodetic2enu(r.navigation.lat_deg, r.navigation.lon_deg, 0.0,
                                              lat0, lon0, 0.0, deg=True)
        positions.append((np.asarray(east, dtype=float), np.asarray(north, dtype=float)))
    return (lat0, lon0), positions, notes


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


def _check_radians(recordings, options, where):
    """Refuse bearings of unstated units that all lie within +-2 pi: radians read as degrees
    fit a far, slow target with a tiny residual, and no statistic can tell it afterwards."""
    if options.bearing.units is not None or any(r.bearings.units_stated for r in recordings):
        return
    b = np.concatenate([r.bearings.bearing_deg for r in recordings])
    if b.size >= RADIANS_MIN_COUNT and np.all(np.abs(b) <= 2 * np.pi):
        raise InputError(f"{where}: every bearing lies within +-2 pi ({b.min():.3g} to "
                         f"{b.max():.3g}): they look like radians. Set bearing.units=rad to "
                         "convert them, or bearing.units=deg if they really are degrees")


def _distinct_fixes(t, x, y, nav: Navigation):
    """Fixes sorted by time; repeated times must repeat the position (then kept once)."""
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
    if t.size < 2:
        raise InputError(f"{nav.source}: {t.size} own-ship fix(es): at least two are needed "
                         "to place the own-ship at the bearing times")
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


def _gaps(t_nav, t_obs, max_gap_s, source) -> list[dict]:
    """Gaps between consecutive fixes longer than ``max_gap_s`` (common clock seconds)."""
    dt = np.diff(t_nav)
    where = np.flatnonzero(dt > max_gap_s)
    t_sorted = np.sort(t_obs)
    inside = (np.searchsorted(t_sorted, t_nav[where + 1], side="left")
              - np.searchsorted(t_sorted, t_nav[where], side="right"))
    return [{"from_s": float(t_nav[k]), "to_s": float(t_nav[k + 1]), "length_s": float(dt[k]),
             "bearings_inside": int(n), "source": source}
            for k, n in zip(where, inside, strict=True)]


def _logs(t, x, y, track, bearing, rec, where) -> list[BearingsLog]:
    """One own-ship's bearings on its epoch grid; tracks split into several logs only when
    the grid (tracks x epochs) would exceed MAX_CELLS."""
    ids, counts = np.unique(track, return_counts=True)
    n_epochs = np.count_nonzero(np.diff(np.sort(t))) + 1
    if ids.size * n_epochs <= MAX_CELLS:
        groups = [ids]
    else:  # bound each group's grid by (tracks in it) x (its bearings)
        groups, start, total = [], 0, 0
        for k, c in enumerate(counts):
            if k > start and (k - start + 1) * (total + c) > MAX_CELLS:
                groups.append(ids[start:k])
                start, total = k, 0
            total += c
        groups.append(ids[start:])
    logs = []
    for group in groups:
        rows = np.isin(track, group) if len(groups) > 1 else slice(None)
        logs.append(_grid(t[rows], x[rows], y[rows], track[rows], bearing[rows], group, rec,
                          where))
    return logs


def _grid(t, x, y, track, bearing, ids, rec, where) -> BearingsLog:
    """The (tracks x epochs) bearing array; own-ship at each epoch (equal at equal times)."""
    order = np.argsort(t, kind="stable")
    new_epoch = np.r_[True, t[order][1:] != t[order][:-1]]
    col = np.empty(t.size, dtype=np.int64)
    col[order] = np.cumsum(new_epoch) - 1
    first = order[new_epoch]
    n_epochs = first.size
    row = np.searchsorted(ids, track)
    cell = np.sort(row * n_epochs + col)
    twice = cell[1:] == cell[:-1]
    if twice.any():
        k = int(cell[int(np.argmax(twice))])
        raise InputError(f"{where}: track {ids[k // n_epochs]} has two bearings at one time "
                         f"({t[first[k % n_epochs]]:.9g} s after the log's start)")
    grid = np.full((ids.size, n_epochs), np.nan)
    grid[row, col] = bearing
    return BearingsLog(t_s=t[first], own_x_m=x[first], own_y_m=y[first], track_id=ids,
                       bearing_deg=grid, sigma_deg=rec.sigma_deg)


def _span(t) -> str:
    return f"{t.min():.6g} to {t.max():.6g}" if t.size else "none"
