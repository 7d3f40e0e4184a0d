"""The truth of a recorded bearing log from the AIS of its trial (``ingest truth=FILE``).

The log must be dated (UTC) and geographic (own-ship latitude/longitude: its plane has an
origin). The AIS file is read (``reports``), its ships' tracks put on the log's plane and
clock (``tracks``), each contact matched to its ship (``match``: one line per contact), and
for each matched contact the truth is taken from its ship's track:

- at each bearing time, its position (linear between reports; ``truth_track.parquet``:
  ``track_id``, ``t_s``, ``x_m``, ``y_m``, ``lat_deg``, ``lon_deg``);
- at the last bearing ("now"), its position and its velocity as the mean over the
  ``truth.velocity_span_s`` (120 s) before it, with their own uncertainty where the AIS is
  sparse (``PlaneTrack.interpolation_sd``: a ship of one-sigma acceleration
  ``truth.accel_sd_m_s2`` strays from the chord between two reports T s apart by up to
  a tau (T - tau) / 2; ``truth_pos_sd_m``, ``truth_vel_sd_m_s`` per axis, and the
  variances of (x0, vx): ``truth_var_x0_m2``, ``truth_cov_x0_v_m2_s``,
  ``truth_var_v_m2_s2``), as ``truth.parquet`` holds a simulated
  target's: ``x0_m``, ``y0_m``, ``vx_m_s``, ``vy_m_s`` the straight line through that state
  (so the kinematics now are the truth), ``course_deg``, ``speed_m_s``; besides them
  ``label``, ``mmsi``, ``match`` (``given`` or ``bearings``), ``rms_deg`` (the fit),
  ``t_now_s``, ``x_now_m``, ``y_now_m``, ``lat_now_deg``, ``lon_now_deg``,
  ``range_now_m`` and ``bearing_now_deg`` from own-ship then.

A contact whose ship's AIS has a gap longer than ``truth.max_gap_s`` over its bearings or its
velocity span gets no truth, and says why. The whole file is refused (``TruthError``, one
line) when it cannot be this log's AIS: a log without UTC or latitude/longitude, AIS of other
times (no overlap) or of another place (no ship within ``truth.max_range_km`` of own-ship),
a given match that cannot hold, or no contact left with a truth.
"""

import logging
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tma.ais.match import Contact, Match, bearings_from, gap_bound, match_contacts
from tma.ais.options import TruthError, TruthOptions
from tma.ais.reports import cached_reports
from tma.ais.tracks import cleaning, vessel_tracks
from tma.io.atomic import sha256_file
from tma.maths.angles import course_from_velocity
from tma.maths.geo import local_to_geodetic
from tma.sources.base import Dropped
from tma.utc import format_utc

log = logging.getLogger(__name__)
TRUTH, TRUTH_TRACK = "truth.parquet", "truth_track.parquet"
BRACKET_S = 6 * 3600.0  # a ship's reports this far around the log bracket it (sparse AIS)


@dataclass
class LogTruth:
    """``truth``: one row per contact with a truth; ``track``: its position at each bearing;
    ``matches``: what matching said of every contact; ``record``: the manifest's entry."""

    truth: pd.DataFrame
    track: pd.DataFrame
    matches: list[Match]
    record: dict


def log_truth(contacts: list[Contact], origin_deg, epoch_ns, options: TruthOptions,
              where: str) -> LogTruth:
    """The truth of ``contacts`` (a log's, on the plane at ``origin_deg``, times from
    ``epoch_ns``) from the AIS file ``options.file`` (module docstring)."""
    path = options.file
    if epoch_ns is None or origin_deg is None:
        missing = " and ".join(filter(None, [
            "UTC times (give time.start_utc= for a log of relative times)" if epoch_ns is None
            else "", "own-ship latitude/longitude (a plane with a geographic origin: give "
                     "origin.lat/origin.lon for x/y navigation)" if origin_deg is None else ""]))
        raise TruthError(f"truth={path}: scoring {where} against AIS needs {missing}")
    reports = cached_reports(options)
    t0 = min(float(c.t_s[0]) for c in contacts)
    t1 = max(float(c.t_s[-1]) for c in contacts)
    log_span = f"{format_utc(epoch_ns + int(t0 * 1e9))} to {format_utc(epoch_ns + int(t1 * 1e9))}"
    margin = options.max_gap_s + options.velocity_span_s
    lo, hi = epoch_ns + int((t0 - margin) * 1e9), epoch_ns + int((t1 + margin) * 1e9)
    near = (reports.t_ns >= lo) & (reports.t_ns <= hi)
    if not near.any():
        from tma.sources.align import hours_apart

        hours = hours_apart(np.array([t0, t1]) + epoch_ns / 1e9, reports.t_ns / 1e9)
        if hours:
            raise TruthError(
                f"truth={path}: its AIS covers {reports.span_text()} and {where} {log_span}, "
                f"{hours:+d} h apart: one of them is local time read as UTC; give its zone "
                "(truth.time.zone= for the AIS's, time.zone= for the log's, e.g. "
                "Europe/Madrid)")
        raise TruthError(f"truth={path}: its AIS covers {reports.span_text()} and {where} "
                         f"{log_span}: AIS of another time, not this log's trial")
    kept = _subset(reports, near | _bracketing(reports, lo, hi))
    tracks = vessel_tracks(kept)
    cleaned, cleaned_text = cleaning(tracks, kept.t_ns)
    ships = {m: t.on_plane(origin_deg, epoch_ns) for m, t in tracks.items()}
    ships = {m: s for m, s in ships.items() if s.t_s.size >= 2 and m != options.own_mmsi}
    _check_place(ships, contacts, options, path, where)
    matches = match_contacts(contacts, ships, options, epoch_ns, where)
    rows, track = [], []
    for contact, m in zip(contacts, matches, strict=True):
        if m.has_truth:
            row = _truth_row(contact, ships[m.mmsi], m, options, epoch_ns)
            if row is not None:
                rows.append(row)
                x, y = ships[m.mmsi].at(contact.t_s)
                track.append(pd.DataFrame({"track_id": contact.track_id, "t_s": contact.t_s,
                                           "x_m": x, "y_m": y}))
        (log.info if m.has_truth else log.warning)("%s contact %s: %s", where, m.label, m.note)
    if not rows:
        gaps = [m.max_gap_s for m in matches if m.verdict == "gap"]
        if gaps:  # the one way out, first: the contacts were matched, their AIS is sparse
            raise TruthError(
                f"truth={path}: no contact of {where} has a truth: {len(gaps)} of "
                f"{len(matches)} matched to their ship, whose AIS has gaps up to "
                f"{max(gaps):.0f} s, longer than truth.max_gap_s = {options.max_gap_s:g} s; "
                f"set truth.max_gap_s={gap_bound(max(gaps))} to take the truth across them")
        shown = "; ".join(f"{m.label}: {m.note}" for m in matches[:3])
        raise TruthError(f"truth={path}: no contact of {where} has a truth ({shown}"
                         f"{'; ...' if len(matches) > 3 else ''})")
    truth = pd.DataFrame(rows)
    truth["lat_now_deg"], truth["lon_now_deg"] = local_to_geodetic(
        truth["x_now_m"].to_numpy(), truth["y_now_m"].to_numpy(), origin_deg)
    track = pd.concat(track, ignore_index=True)
    track["lat_deg"], track["lon_deg"] = local_to_geodetic(
        track["x_m"].to_numpy(), track["y_m"].to_numpy(), origin_deg)
    dropped = Dropped()
    dropped.merge(reports.dropped)
    dropped.merge(cleaned)
    record = {"path": str(path), "sha256": sha256_file(path), **reports.record(),
              "dropped": dropped.record(),
              "ships_in_log_times": len(ships),
              "options": options.record(),
              "contacts": [m.record() for m in matches],
              "with_truth": int(len(truth))}
    log.info("%s: truth for %d of %d contact(s) from %s (%d reports of %d ships in the log's "
             "times)", where, len(truth), len(matches), path, int(near.sum()), len(ships))
    if reports.dropped.count:
        log.warning("truth=%s: left out %d report(s): %s", path, reports.dropped.count,
                    reports.dropped.text())
    if cleaned.count:
        log.warning("truth=%s: of the reports in the log's times, left out %d: %s", path,
                    cleaned.count, cleaned_text)
    return LogTruth(truth, track, matches, record)


def _bracketing(reports, lo: int, hi: int) -> np.ndarray:
    """Per ship its last report before ``lo`` and its first after ``hi`` (UTC ns), within
    ``BRACKET_S``: sparse AIS (a satellite's, every few minutes) still covers the log, and the
    gap it bridges is said (``truth.max_gap_s``) rather than the ship lost."""
    t, same = reports.t_ns, reports.mmsi[1:] == reports.mmsi[:-1]  # sorted by MMSI, time
    before = (t < lo) & (t >= lo - BRACKET_S * 10**9)
    after = (t > hi) & (t <= hi + BRACKET_S * 10**9)
    last_before = before & ~np.r_[same & before[1:], False]
    first_after = after & ~np.r_[False, same & after[:-1]]
    return last_before | first_after


def _subset(reports, mask):
    from dataclasses import replace

    return replace(reports, mmsi=reports.mmsi[mask], t_ns=reports.t_ns[mask],
                   lat_deg=reports.lat_deg[mask], lon_deg=reports.lon_deg[mask],
                   sog_m_s=None if reports.sog_m_s is None else reports.sog_m_s[mask],
                   cog_deg=None if reports.cog_deg is None else reports.cog_deg[mask])


def _check_place(ships, contacts, options, path, where):
    """``TruthError`` when no ship comes within reach of own-ship during the log."""
    own = np.concatenate([np.column_stack([c.own_x_m, c.own_y_m]) for c in contacts])
    own = own[:: max(1, own.shape[0] // 200)]  # how near, within kilometres: a sample
    nearest, who = np.inf, None
    for mmsi, ship in ships.items():
        pts = np.column_stack([ship.x_m, ship.y_m])[:: max(1, ship.t_s.size // 100)]
        d = np.sqrt(((pts[:, None, :] - own[None, :, :]) ** 2).sum(-1)).min()
        if d < nearest:
            nearest, who = d, mmsi
    if nearest > options.max_range_km * 1e3:
        shown = (f"; the nearest, MMSI {who}, stays {nearest / 1e3:,.0f} km away" if who
                 else "")
        raise TruthError(f"truth={path}: no ship comes within {options.max_range_km:g} km of "
                         f"own-ship during {where}{shown}: AIS of another place, not this "
                         "log's trial (truth.max_range_km sets the reach)")


def _truth_row(contact: Contact, ship, m: Match, options: TruthOptions, epoch_ns) -> dict | None:
    """The truth at the contact's last bearing; None (and ``m`` refused) when the velocity
    span before it is not covered."""
    t = float(contact.t_s[-1])
    ta = t - options.velocity_span_s
    gap = ship.max_gap(ta, t)
    if gap > options.max_gap_s:
        m.verdict, m.max_gap_s = "gap", gap
        m.note += (f"; but its AIS does not cover the {options.velocity_span_s:g} s before the "
                   f"last bearing ({format_utc(epoch_ns + int(round(t * 1e9)))}) without a gap "
                   f"over truth.max_gap_s = {options.max_gap_s:g} s"
                   + (f" (truth.max_gap_s={gap_bound(gap)} accepts it)" if np.isfinite(gap)
                      else "") + ": no truth")
        return None
    x, y = ship.at(t)
    vx, vy = ship.mean_velocity(ta, t)
    x, y, vx, vy = float(x), float(y), float(vx), float(vy)
    sd_now, sd_before = (float(v) for v in ship.interpolation_sd([t, ta],
                                                                 options.accel_sd_m_s2))
    span = options.velocity_span_s
    var_p, var_v = sd_now ** 2, (sd_now ** 2 + sd_before ** 2) / span ** 2  # v = dp / span
    cov_pv = var_p / span
    return {
        # the truth's own uncertainty (per axis, x and y alike and independent): position now,
        # velocity, and (x0, vx) of the straight line, x0 = x - vx t
        "truth_pos_sd_m": float(f"{sd_now:.12g}"),  # 264.48, not 264.47999999999996
        "truth_vel_sd_m_s": float(f"{np.sqrt(var_v):.12g}"),
        "truth_gap_s": float(ship.gap([t])[0]),
        "truth_var_x0_m2": var_p - 2 * t * cov_pv + t * t * var_v,
        "truth_cov_x0_v_m2_s": cov_pv - t * var_v, "truth_var_v_m2_s2": var_v,
        "track_id": contact.track_id, "label": contact.label, "mmsi": m.mmsi, "match": m.how,
        "rms_deg": m.rms_deg, "x0_m": x - vx * t, "y0_m": y - vy * t, "vx_m_s": vx,
        "vy_m_s": vy, "course_deg": float(np.rad2deg(course_from_velocity(vx, vy))),
        "speed_m_s": float(np.hypot(vx, vy)), "t_now_s": t, "x_now_m": x, "y_now_m": y,
        "range_now_m": float(np.hypot(x - contact.own_x_m[-1], y - contact.own_y_m[-1])),
        "bearing_now_deg": float(bearings_from(contact, np.array([x]), np.array([y]))[-1]),
    }
