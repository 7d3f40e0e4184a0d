"""Vessel tracks from AIS position reports: one per MMSI, cleaned, on a local plane.

A vessel's reports are sorted by time; of reports with the same time stamp the first is
kept (the others counted as *merged*: an export that writes times to the minute merges all but
one of a ship's reports in each minute), and a report farther from the point interpolated at
its time between its two neighbours than a ship could stray in that gap is dropped as a
position error (a corrupt report; a real vessel does not jump off its track and back). A ship
no faster than ``SHIP_SPEED_MAX_M_S`` lies within v tau of its earlier neighbour and v (T -
tau) of its later one (T the gap between them, tau the time since the earlier), so within
2 v tau (T - tau) / T of the interpolated point; the bound is that plus ``SPIKE_M`` (300 m,
the position's own noise): 400 m between reports 10 s apart, 6.3 km between reports 5 minutes
either side (sparse, satellite AIS: a ship turns in that time). On a log's plane (``tma.geo``:
east-north at its origin, times in seconds from its epoch) a vessel's position at any time is
interpolated linearly between its two bracketing reports; the interval between them is the
*gap* the
interpolation bridges, infinite outside the reports (no extrapolation).
"""

from dataclasses import dataclass

import numpy as np

from tma.ais.reports import Reports
from tma.maths.geo import geodetic_to_local
from tma.sources.base import NAMED, Dropped

SPIKE_M = 300.0  # a report this far (plus what the gap allows) off its neighbours' line: dropped
SHIP_SPEED_MAX_M_S = 20.0  # 39 kn: a fast ferry's; the spike bound's speed


@dataclass(frozen=True)
class VesselTrack:
    """One vessel's cleaned reports: ``t_ns`` (UTC ns), ``lat_deg``, ``lon_deg``;
    ``spike_t_ns`` the times of the reports dropped as position errors; ``merged`` the reports
    merged into another of the same time stamp."""

    mmsi: int
    t_ns: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    spike_t_ns: tuple = ()
    merged: int = 0

    @property
    def spikes(self) -> int:
        return len(self.spike_t_ns)

    def on_plane(self, origin_deg, epoch_ns: int) -> "PlaneTrack":
        """The track on the plane tangent at ``origin_deg`` (lat, lon), times in s from
        ``epoch_ns``."""
        x, y = geodetic_to_local(self.lat_deg, self.lon_deg, origin_deg)
        return PlaneTrack(self.mmsi, (self.t_ns - epoch_ns) / 1e9, x, y)


@dataclass(frozen=True)
class PlaneTrack:
    """A vessel's reports on a local plane: ``t_s`` (s, increasing), ``x_m`` east, ``y_m``
    north."""

    mmsi: int
    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray

    def at(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) at times ``t`` (s), linear between reports (NaN outside them)."""
        t = np.asarray(t, float)
        inside = (t >= self.t_s[0]) & (t <= self.t_s[-1])
        x = np.where(inside, np.interp(t, self.t_s, self.x_m), np.nan)
        y = np.where(inside, np.interp(t, self.t_s, self.y_m), np.nan)
        return x, y

    def gap(self, t) -> np.ndarray:
        """Per time in ``t`` the interval (s) between the reports that bracket it (0 at a
        report's own time); inf outside the reports."""
        t = np.asarray(t, float)
        i = np.searchsorted(self.t_s, t, side="right")
        inside = (t >= self.t_s[0]) & (t <= self.t_s[-1])
        hi = self.t_s[np.clip(i, 0, self.t_s.size - 1)]
        lo = self.t_s[np.clip(i - 1, 0, self.t_s.size - 1)]
        at_report = np.isin(t, self.t_s)
        return np.where(inside, np.where(at_report, 0.0, hi - lo), np.inf)

    def interpolation_sd(self, t, accel_sd_m_s2: float) -> np.ndarray:
        """Per time in ``t`` the one-sigma error (m, per axis) of the position interpolated
        there: a ship whose acceleration is at most ``accel_sd_m_s2`` strays from the chord
        between its two bracketing reports by at most a tau (T - tau) / 2 (T the gap, tau
        the time since its first report), taken as one sigma; 0 at a report, inf outside."""
        t = np.asarray(t, float)
        i = np.clip(np.searchsorted(self.t_s, t, side="right"), 1, self.t_s.size - 1)
        inside = (t >= self.t_s[0]) & (t <= self.t_s[-1])
        tau = np.clip(t - self.t_s[i - 1], 0.0, None)
        rest = np.clip(self.t_s[i] - t, 0.0, None)
        return np.where(inside, accel_sd_m_s2 * tau * rest / 2.0, np.inf)

    def max_gap(self, t0: float, t1: float) -> float:
        """The longest interval (s) without a report over [t0, t1], counting the reports that
        bracket it; inf when the reports do not cover [t0, t1]."""
        if t0 < self.t_s[0] or t1 > self.t_s[-1]:
            return float("inf")
        i0 = np.searchsorted(self.t_s, t0, side="right") - 1
        i1 = np.searchsorted(self.t_s, t1, side="left")
        return float(np.max(np.diff(self.t_s[i0:i1 + 1]))) if i1 > i0 else 0.0

    def mean_velocity(self, ta, tb) -> tuple[np.ndarray, np.ndarray]:
        """Mean velocity (m/s east, north) from ``ta`` to ``tb`` (s): displacement / time."""
        ta, tb = np.asarray(ta, float), np.asarray(tb, float)
        xa, ya = self.at(ta)
        xb, yb = self.at(tb)
        return (xb - xa) / (tb - ta), (yb - ya) / (tb - ta)


def _off_track(t, lat, lon) -> np.ndarray:
    """Per interior report (times ``t`` in s, increasing) its distance from the point
    interpolated between its neighbours over the bound there (> 1: off track)."""
    import pymap3d

    gap, tau = t[2:] - t[:-2], t[1:-1] - t[:-2]
    w = tau / gap
    lat_i = lat[:-2] + w * (lat[2:] - lat[:-2])
    lon_i = lon[:-2] + w * (lon[2:] - lon[:-2])
    e, n, _ = pymap3d.geodetic2enu(lat[1:-1], lon[1:-1], 0.0, lat_i, lon_i, 0.0)
    return np.hypot(e, n) / (SPIKE_M + 2 * SHIP_SPEED_MAX_M_S * tau * (gap - tau) / gap)


def drop_spikes(t_ns: np.ndarray, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Mask of the reports to keep (times increasing): drops a report farther from the point
    interpolated at its time between its two neighbours than ``SPIKE_M`` + 2 v tau (T - tau)
    / T, v = ``SHIP_SPEED_MAX_M_S`` (module docstring). The worst first, then again without
    it: a position error throws its neighbours' interpolated points off too."""
    keep = np.ones(t_ns.size, dtype=bool)
    t = (t_ns - t_ns[0]) / 1e9
    while keep.sum() >= 3:
        left = np.flatnonzero(keep)
        ratio = _off_track(t[left], lat[left], lon[left])
        worst = int(np.argmax(ratio))
        if ratio[worst] <= 1.0:
            break
        keep[left[worst + 1]] = False
    return keep


def vessel_tracks(reports: Reports, mmsis=None) -> dict[int, VesselTrack]:
    """One cleaned ``VesselTrack`` per MMSI of ``reports`` (of ``mmsis`` only, if given)."""
    starts = np.flatnonzero(np.r_[True, reports.mmsi[1:] != reports.mmsi[:-1]])
    ends = np.r_[starts[1:], reports.mmsi.size]
    wanted = None if mmsis is None else {int(m) for m in mmsis}
    tracks = {}
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        mmsi = int(reports.mmsi[a])
        if wanted is not None and mmsi not in wanted:
            continue
        t, lat, lon = reports.t_ns[a:b], reports.lat_deg[a:b], reports.lon_deg[a:b]
        first = np.r_[True, t[1:] != t[:-1]]  # sorted by time: one report per time stamp
        t, lat, lon = t[first], lat[first], lon[first]
        keep = drop_spikes(t, lat, lon)
        tracks[mmsi] = VesselTrack(mmsi, t[keep], lat[keep], lon[keep],
                                   tuple(int(v) for v in t[~keep]), int((~first).sum()))
    return tracks


SPIKE_REASON = ("position off its ship's track by more than the ship can move between its "
                "neighbours (a position error)")
MERGED_REASON = "the same time stamp as an earlier report of its ship (merged into it)"


def cleaning(tracks: dict[int, VesselTrack], t_ns: np.ndarray) -> tuple[Dropped, str]:
    """What cleaning ``tracks`` left out, as a ``Dropped`` (``SPIKE_REASON``: each named by
    its MMSI and time; ``MERGED_REASON``), and a sentence for the log ("" when nothing):
    with merged reports, whether the times ``t_ns`` (the reports read) are whole minutes."""
    from tma.utc import format_utc

    dropped = Dropped()
    spikes = [(m, v) for m, track in sorted(tracks.items()) for v in track.spike_t_ns]
    if spikes:
        dropped.add(SPIKE_REASON, len(spikes),
                    [f"MMSI {m} at {format_utc(v)}" for m, v in spikes[:NAMED]])
    merged = {m: track.merged for m, track in tracks.items() if track.merged}
    if merged:
        dropped.add(MERGED_REASON, sum(merged.values()),
                    [f"MMSI {m}: {n}" for m, n in sorted(merged.items())[:NAMED]])
    if not dropped.count:
        return dropped, ""
    minutes = t_ns.size and bool(np.all(np.asarray(t_ns) % (60 * 10**9) == 0))
    text = dropped.text() + (
        "; its times are whole minutes, so its tracks are good to the minute only"
        if merged and minutes else "")
    return dropped, text
