"""Own-ship from the AIS of the trial (``truth.own_mmsi=MMSI``): its track in the same AIS as
every other ship becomes the log's own-ship, so that a log of time, contact and bearing needs
no navigation of its own.

Own-ship's reports (cleaned as every ship's: ``tma.ais.tracks``) are its fixes, read as a
navigation file's are (``tma.sources.align``: interpolated at each bearing, outliers left
out). AIS reports come every 2 s to 3 min, so the interpolation can bridge long gaps: a
bearing inside a gap of own-ship's AIS longer than ``nav.max_gap_s`` is left out and
counted (its origin would be guessed), and a log left without a bearing is refused in one
line naming a ``nav.max_gap_s`` that would keep them. The bearings must have UTC times
(AIS time). What the dataset, its table and its map say of own-ship's source is
``source_text``.
"""

import dataclasses
import logging

import numpy as np

from tma.ais.match import gap_bound
from tma.ais.options import TruthError, TruthOptions
from tma.errors import InputError
from tma.sources.base import Navigation, Recording
from tma.utc import format_utc

log = logging.getLogger(__name__)
GAP_REASON = "bearing in a gap of own-ship's AIS longer than nav.max_gap_s"


def source_text(options: TruthOptions) -> str:
    """How own-ship's source is named in messages, manifests, tables and maps."""
    return f"{options.file} (AIS of own-ship MMSI {options.own_mmsi}: truth.own_mmsi)"


def ownship_recording(options: TruthOptions, reading, contacts: list[Recording],
                      where: str) -> Recording:
    """A Recording of own-ship's fixes (MMSI ``options.own_mmsi`` in ``options.file``) for
    the ``contacts`` read from the log ``where``; bearings in its AIS gaps over
    ``reading.nav.max_gap_s`` are left out of the contacts and counted there."""
    from tma.ais.reports import cached_reports
    from tma.ais.tracks import vessel_tracks

    own = options.own_mmsi
    named = [f"columns.{r}={reading.column(r)}" for r in ("lat", "lon", "x", "y")
             if _named(reading, r)]
    if named:  # two own-ships asked for: which one is meant is the user's to say
        raise TruthError(f"{where}: own-ship from its AIS (truth.own_mmsi={own}) or from the "
                         f"log's {' and '.join(named)}, not both: drop truth.own_mmsi to use "
                         f"the log's own-ship, or {', '.join(n.split('=')[0] for n in named)} "
                         "to use the AIS's")
    if len(contacts) != 1 or contacts[0].contacts is None:
        raise InputError(f"{where}: no {reading.observation.plural} found in the input")
    values = contacts[0].contacts
    if values.epoch_utc_ns is None:
        raise TruthError(f"{where}: truth.own_mmsi={own} takes own-ship from its AIS, which "
                         f"needs the {reading.observation.plural}' UTC times: give absolute "
                         "times (time.format, time.zone) or time.start_utc=")
    reports = cached_reports(options)
    track = vessel_tracks(reports, [own]).get(own)
    if track is None or track.t_ns.size < 2:
        ships = np.unique(reports.mmsi)
        raise TruthError(f"truth.own_mmsi={own}: {'no' if track is None else 'one'} position "
                         f"report of MMSI {own} in truth={options.file} ({ships.size} ships: "
                         f"{', '.join(map(str, ships[:8]))}{', ...' if ships.size > 8 else ''})"
                         "; check the MMSI")
    merged = ""
    if track.merged or track.spikes:
        from tma.ais.tracks import cleaning

        _, merged = cleaning({own: track}, reports.t_ns[reports.mmsi == own])
        log.warning("truth.own_mmsi=%d: of own-ship's AIS reports in %s, left out %d: %s", own,
                    options.file, track.merged + track.spikes, merged)
        merged = f"; {merged}"
    epoch = int(track.t_ns[0])
    t_own = (track.t_ns - epoch) / 1e9
    t_obs = (values.epoch_utc_ns - epoch) / 1e9 + values.t_s
    i = np.clip(np.searchsorted(t_own, t_obs, side="right"), 1, t_own.size - 1)
    inside = (t_obs >= t_own[0]) & (t_obs <= t_own[-1])
    gap = np.where(inside, t_own[i] - t_own[i - 1], 0.0)  # outside: align drops them
    in_gap = gap > reading.nav.max_gap_s
    if in_gap.all() and in_gap.any():
        raise TruthError(
            f"{where}: every {reading.observation.role} lies in a gap of own-ship's AIS (MMSI "
            f"{own}) longer than nav.max_gap_s = {reading.nav.max_gap_s:g} s (own-ship reports "
            f"every {np.median(np.diff(t_own)):.0f} s, gaps up to {gap.max():.0f} s); set "
            f"nav.max_gap_s={gap_bound(gap.max())} to interpolate own-ship across them")
    rec = contacts[0]
    if in_gap.any():
        log.warning(
            "%s: %d of %d %s (%.0f %%) lie in gaps of own-ship's AIS (MMSI %d) longer than "
            "nav.max_gap_s = %g s and are left out (own-ship is not interpolated across "
            "them); own-ship reports every %.0f s (median), gaps up to %.0f s: "
            "nav.max_gap_s=%d keeps them all", where, int(in_gap.sum()), in_gap.size,
            reading.observation.plural, 100 * in_gap.mean(), own, reading.nav.max_gap_s,
            np.median(np.diff(t_own)), gap.max(), gap_bound(gap.max()))
        lines = [f"{format_utc(values.epoch_utc_ns + int(round(t * 1e9)))}"
                 for t in values.t_s[in_gap][:5]]
        rec.dropped.add(GAP_REASON, int(in_gap.sum()), lines)
        keep = ~in_gap
        rec.contacts = dataclasses.replace(values, t_s=values.t_s[keep],
                                           track=values.track[keep],
                                           values=values.values[keep])
    nav = Navigation(t_own, epoch, source_text(options), zone_option="truth.time.zone",
                     lat_deg=track.lat_deg,
                     lon_deg=track.lon_deg)
    note = (f"own-ship from the AIS of MMSI {own} in {options.file} (truth.own_mmsi): "
            f"{t_own.size} reports, every {np.median(np.diff(t_own)):.1f} s (median)"
            + merged
            + (f"; {int(in_gap.sum())} {reading.observation.plural} in its gaps over "
               f"nav.max_gap_s = {reading.nav.max_gap_s:g} s left out" if in_gap.any() else ""))
    return Recording(nav, None, notes=[note])


def _named(reading, role: str) -> bool:
    """Whether the user named the log's own-ship column ``role`` (lat, lon, x, y)."""
    try:
        return reading.column(role) is not None
    except AttributeError:  # a reader without that column
        return False


def ownship_of(manifest: dict) -> dict:
    """What a dataset's table and map say of its own-ship's source: ``{"ownship": text}``
    when it is not the log itself (its AIS, a navigation file or one per platform), else
    ``{}``."""
    nav = manifest.get("navigation") or {}
    if isinstance(nav, list):  # one file per platform
        return {"ownship": ", ".join(n["path"] for n in nav)}
    if nav.get("kind") == "ais":
        return {"ownship": f"AIS of MMSI {nav.get('mmsi')} in {nav.get('path')}"}
    return {"ownship": f"{nav['path']}"} if nav.get("path") else {}
