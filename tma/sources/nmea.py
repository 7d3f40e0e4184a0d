"""NMEA 0183 own-ship navigation (``$--GGA``, ``$--RMC``, any talker) -> ``Recording``.

Navigation only: use the file as ``navigation=FILE`` while ``input=`` holds the contacts.
RMC carries date, time and position; GGA carries time and position, its date comes from the
RMC before it (or, for GGA sentences ahead of the first RMC, from that first RMC), with the
day advanced when the time of day wraps past midnight. A GGA with fix quality 0 and an RMC
with status V (no valid fix) are dropped; a GGA and an RMC of the same fix (one time) are
merged (the first one in the file is kept). Lines that are not NMEA, have a bad or missing
checksum or cannot be parsed are counted and reported, and are fatal only when no fix is left.
Times are UTC.
"""

import datetime as dt
from pathlib import Path

import numpy as np
import pynmea2

from tma.errors import InputError
from tma.sources.base import Navigation, Recording

DAY_NS = 86_400 * 10**9
HALF_DAY_NS = DAY_NS // 2


def is_nmea(head: bytes) -> bool:
    """True if the first non-empty line of ``head`` looks like an NMEA sentence."""
    for line in head.splitlines():
        if line.strip():
            return line.lstrip(b"\xef\xbb\xbf").lstrip()[:1] in (b"$", b"!")
    return False


def read_nmea(path) -> Recording:
    """Own-ship fixes (lat/lon, deg WGS84; seconds since the first fix's UTC) from GGA/RMC."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("ascii", errors="replace")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    fixes = []  # (kind, line, time of day ns, date or None, lat, lon)
    skipped = {"not NMEA": 0, "bad or missing checksum": 0, "unparsable": 0,
               "no valid fix": 0}
    other = 0
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        if line[0] not in "$!":
            skipped["not NMEA"] += 1
            continue
        try:
            msg = pynmea2.parse(line, check=True)
        except pynmea2.ChecksumError:
            skipped["bad or missing checksum"] += 1
            continue
        except (pynmea2.ParseError, ValueError, TypeError, AttributeError):
            skipped["unparsable"] += 1
            continue
        kind = getattr(msg, "sentence_type", None)
        if kind not in ("GGA", "RMC"):
            other += 1
            continue
        fix = _fix(msg, kind, number)
        if fix is None:
            skipped["no valid fix"] += 1
        elif fix is False:
            skipped["unparsable"] += 1
        else:
            fixes.append(fix)
    counts = ", ".join(f"{n} {why}" for why, n in skipped.items() if n)
    if not fixes:
        raise InputError(f"{path}: no own-ship fix in the NMEA file (GGA or RMC sentences with "
                         f"a valid fix and checksum){': ' + counts if counts else ''}")
    t_ns = _utc_ns(fixes, path)
    lat = np.array([f[4] for f in fixes])
    lon = np.array([f[5] for f in fixes])
    order = np.argsort(t_ns, kind="stable")
    t_ns, lat, lon = t_ns[order], lat[order], lon[order]
    first = np.r_[True, t_ns[1:] != t_ns[:-1]]  # GGA + RMC of one fix: keep the first
    merged = int((~first).sum())
    t_ns, lat, lon = t_ns[first], lat[first], lon[first]
    epoch = int(t_ns[0])
    n_gga = sum(f[0] == "GGA" for f in fixes)
    notes = [f"{path.name}: NMEA {n_gga} GGA and {len(fixes) - n_gga} RMC fixes, {t_ns.size} "
             f"distinct times ({merged} merged)"
             + (f"; skipped {counts}" if counts else "")
             + (f"; {other} other sentences ignored" if other else "")]
    nav = Navigation((t_ns - epoch) / 1e9, epoch, f"{path} (NMEA GGA/RMC)", lat_deg=lat,
                     lon_deg=lon)
    return Recording(nav, None, notes=notes)


def _fix(msg, kind, number):
    """(kind, line, time of day ns, date, lat, lon); None without a valid fix; False when the
    fields are malformed."""
    if (kind == "GGA" and str(msg.gps_qual or "0").strip() in ("", "0")) or (
            kind == "RMC" and msg.status != "A"):
        return None
    if not (msg.lat and msg.lon and msg.timestamp):
        return None
    try:
        lat, lon = float(msg.latitude), float(msg.longitude)
        stamp = msg.timestamp
        day_ns = ((stamp.hour * 60 + stamp.minute) * 60 + stamp.second) * 10**9 + \
            stamp.microsecond * 1000
        date = msg.datestamp if kind == "RMC" else None
    except (ValueError, TypeError, AttributeError):
        return False
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        return False
    return kind, number, day_ns, date, lat, lon


def _utc_ns(fixes, path) -> np.ndarray:
    """UTC ns of every fix: RMC from its own date; GGA from the date of the nearest RMC before
    it (or the first RMC), the day moved by one where the time of day wrapped past midnight."""
    dated = [i for i, f in enumerate(fixes) if f[3] is not None]
    if not dated:
        raise InputError(f"{path}: the NMEA file has GGA fixes but no RMC sentence with a valid "
                         "fix: GGA carries no date, so the fixes cannot be placed in time; log "
                         "RMC sentences too (they carry the date)")
    out = np.empty(len(fixes), dtype=np.int64)
    ref = dated[0]  # the RMC giving the date
    for i, (_, _, day_ns, date, _, _) in enumerate(fixes):
        if date is not None:
            ref = i
            out[i] = _day_start_ns(date) + day_ns
            continue
        base = _day_start_ns(fixes[ref][3])
        ref_ns = base + fixes[ref][2]
        value = base + day_ns
        if value < ref_ns - HALF_DAY_NS:  # after midnight, past the RMC's day
            value += DAY_NS
        elif value > ref_ns + HALF_DAY_NS:  # before midnight (a GGA ahead of the first RMC)
            value -= DAY_NS
        out[i] = value
    return out


def _day_start_ns(date: dt.date) -> int:
    return (date - dt.date(1970, 1, 1)).days * DAY_NS
