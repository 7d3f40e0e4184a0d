"""AIS position reports from a file, as one table: MMSI, UTC time, latitude, longitude.

Two kinds of file, told apart by their content:

- **decoded reports**: a table (CSV, gzip'd CSV or Parquet) as the common exports write
  them, read by the logs' table reader with the ``truth.*`` table options
  (``tma.ais.table``): a time, an MMSI, a latitude and a longitude column, found by name in
  any case (Danish Maritime Authority ``# Timestamp`` (dd/mm/yyyy), MarineCadastre
  ``BaseDateTime``, Stone Soup's Solent file ``Time``/``Latitude_degrees``...) or named by
  ``truth.columns.*``, speed and course over ground when there; other columns ignored. Times
  as the logs' (``truth.time.*``), a time without a zone UTC, as AIS time is;
- **raw NMEA** ``!AIVDM``/``!AIVDO`` sentences (any talker), each with a time stamp: a tag
  block's ``c:`` (Unix time), an ISO-8601 or Unix time before the sentence, or a Unix time
  after its checksum. Decoded by pyais; multi-part messages are assembled (their time is
  that of their last part). Position reports are types 1, 2, 3 (class A), 18, 19 (class B)
  and 27 (long range); other types (static data, base stations...) are counted and not used.

Left out and counted per reason, with their line numbers (``tma.sources.base.Dropped``): a
bad checksum, a sentence pyais cannot read or decode, a multi-part message missing a part, a
sentence without a time stamp, a missing or unreadable time, MMSI or position, a position
"not available" (latitude 91, longitude 181) or off the globe. A file of another kind (an
MCAP log, own-ship NMEA, a bearing log) or with no usable report left is refused in one line.
Times are the receiver's stamps (the reports' own UTC second is not used).
"""

import copy
import functools
import gzip
import json
import re
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from tma.ais.options import TruthError, TruthFileNotFound, TruthOptions, truth_options
from tma.sources.base import Dropped
from tma.utc import UNIX_MAGNITUDE, UNIX_SCALE_NS, UTC_FROM_NS

POSITION_TYPES = (1, 2, 3, 18, 19, 27)
SENTENCE = re.compile(rb"(?:\\[^\\]*\\)?![A-Z]{2}VD[MO],[^*\s]*\*[0-9A-Fa-f]{2}")
AIS_IN = re.compile(rb"![A-Z]{2}VD[MO],")
OTHER_NMEA = re.compile(rb"[$!]([A-Z][A-Z0-9]{1,5}),")  # a receiver's $PGHP, own-ship's $GPRMC
TAG_TIME = re.compile(rb"^\\[^\\]*\bc:(\d+(?:\.\d+)?)")
MCAP_MAGIC = b"\x89MCAP"
GZIP_MAGIC = b"\x1f\x8b"
TYPE_NAMES = {4: "base station", 5: "static and voyage data", 8: "binary broadcast",
              21: "aid to navigation", 24: "class B static data"}


@dataclass
class Reports:
    """Position reports, sorted by MMSI then time: ``mmsi`` (int64), ``t_ns`` (UTC ns since
    1970, int64), ``lat_deg``, ``lon_deg`` (WGS84); ``kind`` ``csv`` or ``nmea``; ``dropped``
    what was left out and why; ``notes`` what was found by itself."""

    source: str
    kind: str
    mmsi: np.ndarray
    t_ns: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    dropped: Dropped = field(default_factory=Dropped)
    notes: list[str] = field(default_factory=list)
    sog_m_s: np.ndarray | None = None  # speed over ground (m/s), NaN where not known
    cog_deg: np.ndarray | None = None  # course over ground (deg), NaN where not known

    def __len__(self) -> int:
        return self.mmsi.size

    def span_text(self) -> str:
        """``2016-01-12T13:02:11Z to 14:26:41Z`` (whole seconds)."""
        a, b = (datetime.fromtimestamp(v // 10**9, UTC) for v in (self.t_ns.min(),
                                                                   self.t_ns.max()))
        end = b.strftime("%H:%M:%SZ" if a.date() == b.date() else "%Y-%m-%dT%H:%M:%SZ")
        return f"{a.strftime('%Y-%m-%dT%H:%M:%SZ')} to {end}"

    def record(self) -> dict:
        """What a dataset's manifest keeps of the file read."""
        return {"kind": self.kind, "reports": len(self), "ships": int(np.unique(self.mmsi).size),
                "dropped": self.dropped.record(), "notes": list(self.notes)}


def read_reports(path, options: TruthOptions | None = None) -> Reports:
    """The position reports of an AIS file (module docstring) read with the ``truth.*``
    ``options`` (a table's columns, times, layout: ``tma.ais.table``); ``TruthError`` for a
    file of another kind or without a usable report, ``TruthFileNotFound`` for no file."""
    path = Path(path)
    options = TruthOptions() if options is None else options
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise TruthFileNotFound(f"truth={path}: no such file") from None
    except IsADirectoryError:
        raise TruthError(f"truth={path}: a directory, not an AIS file") from None
    if data.startswith(GZIP_MAGIC):
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError) as exc:
            raise TruthError(f"truth={path}: a damaged gzip file ({exc})") from None
    if data.startswith(MCAP_MAGIC):
        raise TruthError(f"truth={path}: an MCAP log, not AIS: truth= takes decoded AIS "
                         "position reports (CSV: time, MMSI, latitude, longitude) or NMEA "
                         "!AIVDM/!AIVDO sentences; give the log as input=")
    if b"\x00" in data[:4096] and not data.startswith(b"PAR1"):  # Parquet: a table
        raise TruthError(f"truth={path}: a binary file, not AIS position reports (CSV) or "
                         "NMEA !AIVDM/!AIVDO sentences")
    if AIS_IN.search(data[:65536]):
        table = options.table_options()
        if table:
            key, value = next(iter(table.items()))
            raise TruthError(f"{key}={value} does not apply to truth={path} (NMEA !AIVDM "
                             "sentences, not a table): leave it unset")
        reports = _read_nmea(path, data)
    else:
        reports = _read_table(path, data, options)
    if not len(reports):
        why = reports.dropped.text() or "the file holds none"
        raise TruthError(f"truth={path}: no AIS position report could be read ({why})")
    order = np.lexsort((reports.t_ns, reports.mmsi))
    for name in ("mmsi", "t_ns", "lat_deg", "lon_deg", "sog_m_s", "cog_deg"):
        if getattr(reports, name) is not None:
            setattr(reports, name, getattr(reports, name)[order])
    return reports


@functools.lru_cache(maxsize=2)
def _cached(path: str, stamp: tuple, options_json: str) -> Reports:
    return read_reports(path, truth_options(json.loads(options_json)))


def cached_reports(options: TruthOptions) -> Reports:
    """``read_reports`` of ``options.file``, read once while the file and the table options
    stay the same (own-ship and the truth read the same AIS)."""
    path = Path(options.file)
    try:
        stat = path.stat()
    except FileNotFoundError:
        raise TruthFileNotFound(f"truth={path}: no such file") from None
    table = {"file": str(path), "sog_units": options.sog_units,
             **{k.removeprefix("truth."): v for k, v in options.table_options().items()}}
    reports = _cached(str(path), (stat.st_mtime_ns, stat.st_size),
                      json.dumps(table, sort_keys=True))
    # (copies: a caller that counts more in them must not change the cached reports)
    return replace(reports, dropped=copy.deepcopy(reports.dropped), notes=list(reports.notes))


# -- raw NMEA ----------------------------------------------------------------------------------

def _read_nmea(path: Path, data: bytes) -> Reports:
    from pyais.exceptions import AISBaseException
    from pyais.messages import AISSentence, NMEASentenceFactory

    dropped, rows, others, pending, not_ais = Dropped("drop"), [], {}, {}, {}
    bad = {"bad checksum": [], "not a readable AIS sentence": [], "no time stamp": [],
           "undecodable AIS message": [], "position not available (lat 91, lon 181)": [],
           "multi-part message missing a part": []}
    zoneless = False
    for number, line in enumerate(data.splitlines(), start=1):
        found = SENTENCE.search(line)
        if found is None:
            other = None if AIS_IN.search(line) else OTHER_NMEA.search(line)
            if other is not None:  # NMEA of another kind (a receiver's $PGHP, own GPS)
                name = other.group(0)[:1].decode() + other.group(1).decode()
                not_ais[name] = not_ais.get(name, 0) + 1
            elif line.strip():
                bad["not a readable AIS sentence"].append(number)
            continue
        raw = found.group(0)
        try:
            sentence = NMEASentenceFactory.produce(raw)
        except (AISBaseException, ValueError):
            bad["not a readable AIS sentence"].append(number)
            continue
        if not sentence.is_valid:
            bad["bad checksum"].append(number)
            continue
        t_ns, naive = _line_time(raw, line[:found.start()], line[found.end():])
        zoneless |= naive
        if t_ns is None:
            bad["no time stamp"].append(number)
            continue
        if sentence.frag_cnt > 1:  # a part of a multi-part message: wait for the others
            key = (sentence.talker_id, sentence.channel, sentence.seq_id)
            parts = pending.get(key)
            if sentence.frag_num == 1 or parts is None:
                if parts:
                    bad["multi-part message missing a part"].append(parts[0][1])
                parts = pending[key] = []
            parts.append((sentence, number))
            if len(parts) < sentence.frag_cnt:
                continue
            del pending[key]
            if [p.frag_num for p, _ in parts] != list(range(1, sentence.frag_cnt + 1)):
                bad["multi-part message missing a part"].append(parts[0][1])
                continue
            sentence = AISSentence.assemble_from_iterable([p for p, _ in parts])
        try:
            message = sentence.decode()
            kind = int(message.msg_type)
            if kind in POSITION_TYPES:
                lat, lon, mmsi = float(message.lat), float(message.lon), int(message.mmsi)
        except (AISBaseException, ValueError, TypeError, AttributeError, KeyError):
            bad["undecodable AIS message"].append(number)
            continue
        if kind not in POSITION_TYPES:
            others[kind] = others.get(kind, 0) + 1
        elif not (abs(lat) <= 90 and abs(lon) <= 180):
            bad["position not available (lat 91, lon 181)"].append(number)
        else:
            rows.append((mmsi, t_ns, lat, lon))
    for parts in pending.values():
        bad["multi-part message missing a part"].append(parts[0][1])
    for reason, lines in bad.items():
        if lines:
            dropped.add(reason, len(lines), [f"line {n}" for n in lines[:5]])
    notes = []
    if others:
        notes.append(f"{path.name}: {sum(others.values())} AIS message(s) that are not position "
                     "reports, not used (" + ", ".join(
                         f"{n} of type {k}" + (f" {TYPE_NAMES[k]}" if k in TYPE_NAMES else "")
                         for k, n in sorted(others.items())) + ")")
    if not_ais:
        notes.append(f"{path.name}: {sum(not_ais.values())} NMEA sentence(s) that are not AIS, "
                     "not used (" + ", ".join(f"{n} {name}" for name, n in sorted(
                         not_ais.items(), key=lambda item: -item[1])) + ")")
    if zoneless:
        notes.append(f"{path.name}: time stamps without a zone taken as UTC (AIS time is UTC)")
    table = np.array(rows, dtype=float).reshape(-1, 4)
    return Reports(str(path), "nmea", table[:, 0].astype(np.int64),
                   np.array([r[1] for r in rows], dtype=np.int64), table[:, 2], table[:, 3],
                   dropped, notes)


def _line_time(sentence: bytes, before: bytes, after: bytes) -> tuple[int | None, bool]:
    """UTC ns of a sentence's line: its tag block's ``c:``, else a time before it, else a
    Unix time after its checksum; and whether the text had no zone (taken as UTC)."""
    tag = TAG_TIME.match(sentence)
    if tag:
        return _unix_ns(float(tag.group(1))), False
    text = before.decode("ascii", "replace").strip().strip(",;")
    if text:
        return _text_ns(text)
    text = after.decode("ascii", "replace").strip().strip(",;").split(",")[0].strip()
    if text:
        return _text_ns(text)
    return None, False


def _unix_ns(value: float) -> int | None:
    """Unix time in s, ms, us or ns (by magnitude) as UTC ns; None below 1973."""
    unit = next((u for bound, u in UNIX_MAGNITUDE if value >= bound), None)
    return None if unit is None else int(round(value * UNIX_SCALE_NS[unit]))


def _text_ns(text: str) -> tuple[int | None, bool]:
    try:
        return _unix_ns(float(text)), False
    except ValueError:
        pass
    try:
        when = datetime.fromisoformat(text.replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError:
        return None, False
    naive = when.tzinfo is None
    when = when.replace(tzinfo=UTC) if naive else when
    ns = int(round(when.timestamp() * 1e6)) * 1000
    return (ns if ns >= UTC_FROM_NS else None), naive


# -- decoded reports (CSV, Parquet) ----------------------------------------------------------

def _read_table(path: Path, data: bytes, options: TruthOptions) -> Reports:
    from tma.ais.table import read_table

    first = next((line for line in data[:4096].splitlines() if line.strip()), b"")
    if first.lstrip().startswith(b"$"):
        raise TruthError(f"truth={path}: NMEA without AIS sentences (own-ship navigation: "
                         "GGA/RMC?); truth= takes the ships' AIS: NMEA !AIVDM/!AIVDO sentences "
                         "or decoded position reports (CSV: time, MMSI, latitude, longitude)")
    mmsi, t_ns, lat, lon, sog, cog, dropped, notes = read_table(path, data, options)
    return Reports(str(path), "parquet" if data.startswith(b"PAR1") else "csv", mmsi, t_ns,
                   lat, lon, dropped, notes, sog, cog)
