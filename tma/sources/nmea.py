"""The NMEA reader: NMEA 0183 own-ship navigation (``$--GGA``, ``$--RMC``, any talker) ->
``Recording`` (kind ``nmea``: a first line starting with ``$`` or ``!``, or ``.nmea``,
``.nmea0183``, ``.log``; option ``nmea.date``).

Navigation only: use the file as ``navigation=FILE`` while ``input=`` holds the contacts.
RMC carries date, time and position; GGA carries time and position, its date comes from the
RMC before it (or, for GGA sentences ahead of the first RMC, from that first RMC), with the
day advanced when the time of day wraps past midnight. A file of GGA sentences only is dated
by ``nmea.date=YYYY-MM-DD``, else by the bearings' absolute times (the day that puts its first
fix nearest the first bearing), else refused naming the option. A GGA with fix quality 0 and an RMC
with status V (no valid fix) are left out and counted; a GGA and an RMC of the same fix (one
time) are merged (the first one in the file is kept). Lines that are not NMEA, have a bad or
missing checksum or cannot be parsed are left out and counted with their line numbers
(``bad_rows=drop``; under ``fail`` the first refuses the file), and are fatal only when no fix
is left. Times are UTC.
"""

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tma.config import Form, param
from tma.errors import InputError, MissingFileError
from tma.sources.base import NAMED, Navigation, Reader, Recording, line_places

DAY_NS = 86_400 * 10**9
HALF_DAY_NS = DAY_NS // 2


def is_nmea(head: bytes) -> bool:
    """True if the first non-empty line of ``head`` looks like an NMEA sentence."""
    for line in head.splitlines():
        if line.strip():
            return line.lstrip(b"\xef\xbb\xbf").lstrip()[:1] in (b"$", b"!")
    return False


def _date_problem(value) -> str | None:
    try:
        dt.date.fromisoformat(str(value))
    except ValueError:
        return ""
    return None if len(str(value)) == 10 else ""


@dataclass
class NmeaOptions:
    """What NMEA navigation does not say (``nmea.*``)."""

    date: str | None = param(None, "the UTC date of NMEA GGA fixes that no RMC sentence dates; "
                             "null: from RMC, else from the values' absolute times",
                             form=Form("a date YYYY-MM-DD", _date_problem))


BAD_LINES = {  # kind of line left out: (reason in the manifest, refusal under bad_rows=fail)
    "not NMEA": ("NMEA line not NMEA", "a line that is not NMEA"),
    "bad or missing checksum": ("NMEA line with a bad or missing checksum",
                                "an NMEA sentence with a bad or missing checksum"),
    "unparsable": ("NMEA sentence unparsable", "a GGA or RMC sentence that cannot be read"),
}


def read_nmea(path, options, date_hint_ns: int | None = None) -> Recording:
    """Own-ship fixes (lat/lon, deg WGS84; seconds since the first fix's UTC) from GGA/RMC.
    Damaged lines are left out and counted (``options.bad_rows``; under ``fail`` the first
    refuses the file); fixes the receiver flags as invalid are left out and counted under
    either policy. Without RMC sentences, GGA fixes are dated by ``nmea.date``, else by
    ``date_hint_ns`` (UTC ns of the first bearing: the GGA day nearest it)."""
    import pynmea2

    path = Path(path)
    try:
        text = path.read_bytes().decode("ascii", errors="replace")
    except FileNotFoundError:
        raise MissingFileError(f"{path}: no such file") from None
    fixes = []  # (kind, line, time of day ns, date or None, lat, lon)
    skipped = {"not NMEA": [], "bad or missing checksum": [], "unparsable": [],
               "no valid fix": []}  # line numbers
    other = 0
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        if line[0] not in "$!":
            skipped["not NMEA"].append(number)
            continue
        try:
            msg = pynmea2.parse(line, check=True)
        except pynmea2.ChecksumError:
            skipped["bad or missing checksum"].append(number)
            continue
        except (pynmea2.ParseError, ValueError, TypeError, AttributeError):
            skipped["unparsable"].append(number)
            continue
        kind = getattr(msg, "sentence_type", None)
        if kind not in ("GGA", "RMC"):
            other += 1
            continue
        fix = _fix(msg, kind, number)
        if fix is None:
            skipped["no valid fix"].append(number)
        elif fix is False:
            skipped["unparsable"].append(number)
        else:
            fixes.append(fix)
    dropped = options.dropped()
    for why, (reason, refusal) in BAD_LINES.items():
        lines = np.array(skipped[why], dtype=np.int64)
        dropped.drop(np.ones(lines.size, dtype=bool), reason, line_places(lines),
                     f"{path}: {refusal}")
    if skipped["no valid fix"]:  # the receiver's own verdict: left out under either policy
        dropped.add("own-ship fix flagged no fix", len(skipped["no valid fix"]),
                    [f"line {n}" for n in skipped["no valid fix"][:NAMED]])
    counts = ", ".join(f"{len(n)} {why}" for why, n in skipped.items() if n)
    if not fixes:
        raise InputError(f"{path}: no own-ship fix in the NMEA file (GGA or RMC sentences with "
                         f"a valid fix and checksum){': ' + counts if counts else ''}")
    t_ns, dated_by = _utc_ns(fixes, path, options.nmea.date, date_hint_ns)
    lat = np.array([f[4] for f in fixes])
    lon = np.array([f[5] for f in fixes])
    line = np.array([f[1] for f in fixes], dtype=np.int64)
    order = np.argsort(t_ns, kind="stable")
    t_ns, lat, lon, line = t_ns[order], lat[order], lon[order], line[order]
    first = np.r_[True, t_ns[1:] != t_ns[:-1]]  # GGA + RMC of one fix: keep the first
    merged = int((~first).sum())
    t_ns, lat, lon, line = t_ns[first], lat[first], lon[first], line[first]
    epoch = int(t_ns[0])
    n_gga = sum(f[0] == "GGA" for f in fixes)
    notes = [f"{path.name}: NMEA {n_gga} GGA and {len(fixes) - n_gga} RMC fixes, {t_ns.size} "
             f"distinct times ({merged} merged)"
             + (f"; skipped {counts}" if counts else "")
             + (f"; {other} other sentences ignored" if other else "")]
    if dated_by:
        notes.append(f"{path.name}: {dated_by}")
    nav = Navigation((t_ns - epoch) / 1e9, epoch, f"{path} (NMEA GGA/RMC)", lat_deg=lat,
                     lon_deg=lon, lines=line)
    return Recording(nav, None, notes=notes, dropped=dropped)


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


def _utc_ns(fixes, path, date: str | None, hint_ns: int | None):
    """UTC ns of every fix, and how GGA-only fixes were dated (None when RMC dated them):
    RMC from its own date; GGA from the date of the nearest RMC before it (or the first RMC),
    the day moved by one where the time of day wrapped past midnight. Without any RMC the
    first GGA is dated by ``date`` (``nmea.date``), else by the day that puts it nearest
    ``hint_ns``."""
    dated = [i for i, f in enumerate(fixes) if f[3] is not None]
    note = None
    if dated:
        ref_date, ref_day_ns = fixes[dated[0]][3], fixes[dated[0]][2]
        if date is not None:
            note = "nmea.date not used: the RMC sentences carry the date"
    elif date is not None:
        ref_date, ref_day_ns = dt.date.fromisoformat(str(date)), fixes[0][2]
        note = f"GGA dated {ref_date} by nmea.date"
    elif hint_ns is not None:
        day = dt.date(1970, 1, 1) + dt.timedelta(days=int(hint_ns // DAY_NS))
        ref_day_ns = fixes[0][2]
        ref_date = min((day + dt.timedelta(days=d) for d in (-1, 0, 1)),
                       key=lambda d: abs(_day_start_ns(d) + ref_day_ns - hint_ns))
        note = (f"GGA dated {ref_date} from the bearings' times (nmea.date=YYYY-MM-DD sets "
                "it)")
    else:
        raise InputError(f"{path}: the NMEA file has GGA fixes but no RMC sentence with a valid "
                         "fix: GGA sentences carry no date and nothing else dates them: set "
                         "nmea.date=YYYY-MM-DD (or log RMC sentences, which carry the date)")
    out = np.empty(len(fixes), dtype=np.int64)
    ref_ns = _day_start_ns(ref_date) + ref_day_ns
    for i, (_, _, day_ns, fix_date, _, _) in enumerate(fixes):
        if fix_date is not None:
            out[i] = ref_ns = _day_start_ns(fix_date) + day_ns
            continue
        value = ref_ns - ref_ns % DAY_NS + day_ns
        if value < ref_ns - HALF_DAY_NS:  # after midnight, past the reference's day
            value += DAY_NS
        elif value > ref_ns + HALF_DAY_NS:  # before midnight (ahead of the first RMC)
            value -= DAY_NS
        out[i] = value
        if not dated:  # GGA only: each fix dates the next, across midnight
            ref_ns = value
    return out, note


def _day_start_ns(date: dt.date) -> int:
    return (date - dt.date(1970, 1, 1)).days * DAY_NS


def read(path, options, *, navigation: bool, contacts: bool,
         date_hint_ns: int | None = None) -> list[Recording]:
    """``read_nmea`` as a reader (``Reader.read``): navigation only."""
    if contacts:
        raise InputError(f"{path}: NMEA holds own-ship navigation only: give it as "
                         f"navigation=FILE and the {options.observation.plural} as input=")
    return [read_nmea(path, options, date_hint_ns)]


READER = Reader(kind="nmea", name="an NMEA file", extensions=(".nmea", ".nmea0183", ".log"),
                read=read, sniff=is_nmea, options=lambda observation: {"nmea": NmeaOptions})
