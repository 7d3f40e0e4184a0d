"""The CSV reader: CSV / TSV tables of contacts' values and/or own-ship fixes -> ``Recording``s
(kind ``csv``: ``.csv``, ``.tsv``, ``.txt``; options ``columns.*``, ``csv.*``, ``time.format``).

One row per value (a bearing, for ``bearings2d``; or per fix in a navigation file); a header
row names the columns. What is read, and how each choice is made (every automatic choice is
noted for the log):

- columns: ``columns.<role>`` names one; otherwise our documented names (``time_s, own_x_m,
  own_y_m``, the observation's ``column`` (``bearing_deg``), ``track_id``) or a common name
  (``timestamp_utc``, ``latitude_deg``, ``lon``..., the observation's ``columns``), matched
  without regard to case;
- times (``time.format``, ``tma.utc``): relative seconds, Unix time (s, ms, us, ns; told
  apart by magnitude, or by a ``_ms``/``_us``/``_ns`` name) or ISO-8601 text with a zone;
- values in the observation's first unit (bearings: degrees clockwise from north), or
  another when ``<role>.units`` says so, the column is named ``*_<unit>`` (``bearing_rad``) or
  the units row says it;
- own-ship as ``x``/``y`` (metres east/north of any origin) or ``lat``/``lon`` (deg, WGS84);
- ``csv.delimiter`` (sniffed among ``,`` ``;`` tab), ``csv.decimal`` (``,`` found when the
  numbers are written ``12,5``); a units row under the header (``s,deg,deg`` or ``[s]``) is
  skipped; extra columns are ignored; CRLF line ends and a UTF-8 byte-order mark are fine;
- tracks: ids as written (``tma.sources.table``, which reads the rows of a file and of a
  DataFrame alike).
"""

import csv
import io
import re
import warnings
from dataclasses import dataclass, make_dataclass
from pathlib import Path

import numpy as np

from tma.config import Form, param
from tma.errors import ConfigError, InputError
from tma.sources.base import Reader, Recording, file_head
from tma.utc import AMBIGUOUS, is_pattern, pattern_problem, zone_problem

DOCUMENTED = {"time": "time_s", "x": "own_x_m", "y": "own_y_m", "track": "track_id"}
COMMON = {  # candidates per role, in order of preference (lower case)
    "time": ("time_s", "timestamp_utc", "timestamp", "time_utc", "utc", "datetime",
             "date_time", "time", "t_s", "t", "unix_time", "unix_time_s", "epoch_s",
             "time_ms", "timestamp_ms", "unix_ms", "time_us", "timestamp_us", "unix_us",
             "time_ns", "timestamp_ns", "unix_ns"),
    "x": ("own_x_m", "x_m", "own_east_m", "east_m", "easting_m", "x", "east"),
    "y": ("own_y_m", "y_m", "own_north_m", "north_m", "northing_m", "y", "north"),
    "lat": ("lat", "latitude", "latitude_deg", "lat_deg", "own_lat", "own_lat_deg",
            "own_latitude", "own_latitude_deg"),
    "lon": ("lon", "lng", "long", "longitude", "longitude_deg", "lon_deg", "own_lon",
            "own_lon_deg", "own_longitude", "own_longitude_deg"),
    "track": ("track_id", "track", "track_label", "contact_id", "contact", "target_id",
              "target", "id"),
}
SNIFFED = (",", ";", "\t")
SAMPLE_BYTES = 1 << 16
SAMPLE_LINES = 50
UNIT_WORDS = {"s", "sec", "secs", "second", "seconds", "ms", "us", "ns", "utc", "iso",
              "iso8601", "iso-8601", "deg", "degree", "degrees", "rad", "radian", "radians",
              "m", "km", "nmi", "-", "id", "1", "m/s", "kn", "knots", "unix", "text", "none"}


POSITION_ROLES = ("time", "x", "y", "lat", "lon")  # table columns besides value and track
COLUMN_DOCS = {  # what each column of a table holds (the observation's is the family's)
    "time": "the times (relative s, Unix time or ISO-8601: time.format)",
    "x": "own-ship's position east (m)", "y": "own-ship's position north (m)",
    "lat": "own-ship's latitude (deg, WGS84)", "lon": "own-ship's longitude (deg, WGS84)",
    "track": "the contact of each row (an integer id, or a label kept as written; a table "
             "without one holds one contact)"}
FOUND = "; null: tma's name or a common one, found automatically (any case)"


DELIMITER_NAMES = {"comma": ",", "semicolon": ";", "tab": "\t", "\\t": "\t", "pipe": "|",
                   "space": " "}
DECIMAL_NAMES = {"dot": ".", "comma": ","}


def _delimiter_problem(value) -> str | None:
    fine = value in DELIMITER_NAMES or len(value) == 1 and value not in "\"\r\n"
    return None if fine else ""


@dataclass
class CsvFormat:
    """How a table is written (``csv.*``)."""

    delimiter: str | None = param(
        None, "the separator of a table's fields: one character or its name; null: sniffed "
        "among , ; and tab", form=Form(f"one character or one of {', '.join(DELIMITER_NAMES)}",
                                       _delimiter_problem))
    decimal: str | None = param(None, "the decimal mark: . or , (or dot, comma); null: ., or , "
                                "when the delimiter is not a comma and the numbers are written "
                                "12,5", choices=(None, ".", ",", *DECIMAL_NAMES))

    def rules(self):
        """The names of delimiters and decimal marks become the characters."""
        self.delimiter = DELIMITER_NAMES.get(self.delimiter, self.delimiter)
        self.decimal = DECIMAL_NAMES.get(self.decimal, self.decimal)
        if self.decimal is not None and self.decimal == self.delimiter:
            raise ConfigError(f"csv.decimal and csv.delimiter are both '{self.decimal}'")


TIME_FORMATS = ("auto", "s", "unix_s", "unix_ms", "unix_us", "unix_ns", "iso", "iso_utc")


def _format_problem(value) -> str | None:
    if value in TIME_FORMATS:
        return None
    return pattern_problem(value) if is_pattern(value) else ""


TIME_FORMAT = Form(f"one of {', '.join(TIME_FORMATS)} or a strptime pattern with % "
                   "('%d-%m-%y %H:%M')", _format_problem)
ZONE = Form("an IANA time zone (Europe/Madrid, UTC)", zone_problem)


@dataclass
class TimeFormat:
    """How a table's times are written (``time.format``, ``time.zone``,
    ``time.ambiguous``)."""

    format: str = param("auto", "how the times are written: auto: numbers by magnitude (Unix "
                        "s from 1e8, ms from 1e11, us from 1e14, ns from 1e17; smaller: relative "
                        "s), text as ISO-8601 with a zone; s: relative seconds; unix_s|ms|us|ns: "
                        "Unix time; iso: ISO-8601 with a zone (Z, +01:00); iso_utc: ISO-8601, a "
                        "time without zone taken as UTC; or a strptime pattern ('%d-%m-%y "
                        "%H:%M': day first, two-digit year)", form=TIME_FORMAT)
    zone: str | None = param(None, "the IANA time zone (Europe/Madrid) of times written as "
                             "text without one (local time, with its daylight saving); null: "
                             "such times are refused (iso_utc: UTC)", form=ZONE)
    ambiguous: str = param("refuse", "a local time (time.zone) that a daylight-saving change "
                           "repeats (autumn) or skips (spring): refuse the file, or read it as "
                           "the earliest or latest instant it can mean", choices=AMBIGUOUS)


def options(observation) -> dict:
    """The options only tables are read with: which column holds what (``columns.*``, the
    observation's column among them), how the file is written (``csv.*``) and its times
    (``time.format``)."""
    role, plural, units = observation.role, observation.plural, observation.units
    docs = {**COLUMN_DOCS, role: f"the {plural} ({' or '.join(u.name for u in units)}: "
                                 f"{role}.units)"}
    columns = make_dataclass("Columns", [(r, str | None, param(None, f"column of {docs[r]}"
                                                              f"{FOUND}"))
                                         for r in (*POSITION_ROLES, role, "track")])
    columns.__doc__ = ("Table column names; None = tma's name or a common one found "
                       "automatically.")
    return {"columns": columns, "csv": CsvFormat, "time": TimeFormat}


class CsvFile:
    """A table's layout and columns: the file's from its first lines (delimiter, decimal
    mark, header, units row), and which column holds what (``columns``); ``read`` reads the
    chosen columns with pandas. ``tma.sources.table.Frame`` is a DataFrame's."""

    id_hint = ""  # what a refusal of duplicate times per contact adds (a frame's float ids)

    def __init__(self, path: Path, options, head: bytes | None = None):
        self.path, self.options, self.notes = path, options, []
        raw = file_head(path, SAMPLE_BYTES, "a CSV file") if head is None else \
            head[:SAMPLE_BYTES]  # a file read already (decompressed: an AIS export)
        try:
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            if exc.start < len(raw) - 4:  # not merely a character cut by the sample's end
                raise InputError(f"{path}: not UTF-8 text (byte {exc.start}); save the table "
                                 "as UTF-8 CSV") from None
            text = raw[:exc.start].decode("utf-8-sig")
        lines = text.splitlines()[:SAMPLE_LINES]
        if len(raw) == SAMPLE_BYTES and len(lines) > 1:
            lines = lines[:-1]  # the last line of the sample may be cut
        lines = [ln for ln in lines if ln.strip()]
        if not lines:
            raise InputError(f"{path}: empty file (a CSV needs a header row and data rows)")
        self.delimiter = options.csv.delimiter or self._sniff(lines)
        rows = list(csv.reader(io.StringIO("\n".join(lines[:3])), delimiter=self.delimiter,
                               skipinitialspace=True))
        self.header = [c.strip() for c in rows[0]]
        self.decimal = options.csv.decimal or self._decimal(lines[1:])
        if all(is_number(c, self.decimal) for c in self.header if c):
            raise InputError(f"{path}: the first line holds numbers, not column names: the "
                             f"table needs a header row (time, {options.observation.role}, "
                             "own-ship columns)")
        self.units = rows[1] if len(rows) > 2 and self._units_row(rows[1], rows[2]) else None
        if self.units is not None:
            self.units = [u.strip() for u in self.units]
            self.notes.append(f"{path.name}: line 2 ({', '.join(self.units)}) read as a units "
                              "row and skipped")

    def _sniff(self, lines) -> str:
        """The candidate found in the header and equally often in every sampled line."""
        counts = {d: [ln.count(d) for ln in lines] for d in SNIFFED}
        steady = [d for d in SNIFFED if counts[d][0] > 0 and len(set(counts[d])) == 1]
        pool = steady or [d for d in SNIFFED if counts[d][0] > 0] or [","]
        delimiter = max(pool, key=lambda d: counts[d][0] if d in counts else 0)
        if delimiter != ",":
            self.notes.append(f"{self.path.name}: columns separated by "
                              f"{'tab' if delimiter == chr(9) else repr(delimiter)}")
        return delimiter

    def _decimal(self, lines) -> str:
        if self.delimiter == ",":
            return "."
        fields = [f.strip() for ln in lines for f in ln.split(self.delimiter)]
        comma = sum(bool(re.fullmatch(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?", f)) for f in fields)
        dot = sum(bool(re.fullmatch(r"[+-]?\d*\.\d+(?:[eE][+-]?\d+)?", f)) for f in fields)
        if comma and not dot:
            self.notes.append(f"{self.path.name}: decimal comma (12,5) found")
            return ","
        return "."

    def _units_row(self, second, third) -> bool:
        """Line 2 is a units row if it holds no number while line 3 has a number in a column
        where line 2 has text, and its texts look like units (``deg``, ``[s]``, ``(m)``)."""
        second = [c.strip() for c in second]
        if any(is_number(c, self.decimal) for c in second if c):
            return False
        text_over_number = any(c and is_number(d.strip(), self.decimal)
                               for c, d in zip(second, third, strict=False))
        unit_like = all(not c or c.lower() in UNIT_WORDS or re.fullmatch(r"[\[(].*[\])]", c)
                        for c in second)
        return text_over_number and unit_like

    def unit_of(self, column: str) -> str | None:
        if self.units is None:
            return None
        i = self.header.index(column)
        return self.units[i].strip("[]() ").lower() if i < len(self.units) else None

    def columns(self, *, navigation: bool, contacts: bool) -> dict[str, str]:
        """Role -> header name of the columns to read (``time``, the observation's role,
        ``track``, ``x``/``y`` or ``lat``/``lon``); InputError naming the option when one is
        missing."""
        chosen = {}
        roles = ["time"] + ([self.options.observation.role, "track"] if contacts else [])
        for role in roles:
            name = self._find(role, required=role != "track")
            if name is not None:
                chosen[role] = name
        if navigation:
            chosen.update(self._position())
        return chosen

    def _given(self, role):
        return self.options.column(role)

    def _find(self, role, required=True, note=True) -> str | None:
        given = self._given(role)
        lower = {c.lower(): c for c in reversed(self.header)}
        if given is not None:
            if given in self.header:
                return given
            if given.lower() in lower:
                return lower[given.lower()]
            raise InputError(f"{self.path}: columns.{role}={given}: no such column; columns "
                             f"found: {', '.join(self.header)}")
        observation = self.options.observation
        own = observation.column if role == observation.role else DOCUMENTED.get(role)
        for candidate in observation.columns if role == observation.role else COMMON[role]:
            if candidate in lower:
                name = lower[candidate]
                if note and name != own:
                    self.notes.append(f"{self.path.name}: {role} from column '{name}' "
                                      f"(columns.{role}={name})")
                return name
        if required:
            raise InputError(f"{self.path}: no {role} column: columns found: "
                             f"{', '.join(self.header)}; set columns.{role}=<name>")
        return None

    def _position(self) -> dict[str, str]:
        c = self.options.columns
        local_given, geo_given = c.x is not None or c.y is not None, c.lat is not None or \
            c.lon is not None
        if local_given and geo_given:
            raise InputError(f"{self.path}: give own-ship as columns.x/columns.y or as "
                             "columns.lat/columns.lon, not both")
        if not local_given:
            lat, lon = self._find("lat", False, False), self._find("lon", False, False)
            if lat and lon:
                for role, name in (("lat", lat), ("lon", lon)):
                    if self._given(role) is None and name != role:
                        self.notes.append(f"{self.path.name}: {role} from column '{name}'")
                return {"lat": lat, "lon": lon}
            if geo_given or (lat or lon):
                missing = "lon" if lat else "lat"
                raise InputError(f"{self.path}: own-ship {'latitude' if lat else 'longitude'} "
                                 f"in column '{lat or lon}' but no {missing} column: columns "
                                 f"found: {', '.join(self.header)}; set columns.{missing}=<name>")
        x, y = self._find("x", False), self._find("y", False)
        if x and y:
            return {"x": x, "y": y}
        if local_given or x or y:
            missing = "y" if x else "x"
            raise InputError(f"{self.path}: own-ship {'x' if x else 'y'} in column '{x or y}' "
                             f"but no {missing} column: columns found: "
                             f"{', '.join(self.header)}; set columns.{missing}=<name>")
        raise InputError(f"{self.path}: no own-ship position: columns found: "
                         f"{', '.join(self.header)}; set columns.lat=<name> columns.lon=<name> "
                         "(degrees) or columns.x=<name> columns.y=<name> (metres east, north), "
                         "give the own-ship in a separate file with navigation=FILE, or take it "
                         "from the AIS with truth.own_mmsi=<MMSI>")

    def read(self, cols: dict[str, str]):
        """The chosen columns (by position, so odd header spellings cannot get in the way).
        Every column is parsed, so that a line with more fields than the header is refused.
        The track column is text as written (``007`` is not ``7``, ``NA`` is a name)."""
        import pandas as pd

        index = sorted({self.header.index(name) for name in cols.values()})
        track = self.header.index(cols["track"]) if "track" in cols else None
        try:
            with warnings.catch_warnings():  # a row longer than the header: refused
                warnings.simplefilter("error", pd.errors.ParserWarning)
                df = pd.read_csv(self.path, sep=self.delimiter, decimal=self.decimal,
                                 skiprows=[1] if self.units is not None else None,
                                 index_col=False, skipinitialspace=True,
                                 encoding="utf-8-sig", low_memory=False,
                                 dtype=None if track is None else {track: str})
                if track is not None and df.iloc[:, track].isna().any():
                    # pandas read a name such as NA or null as missing: the ids as written
                    df.iloc[:, track] = pd.read_csv(
                        self.path, sep=self.delimiter, usecols=[track], dtype=str,
                        keep_default_na=False, skipinitialspace=True, encoding="utf-8-sig",
                        skiprows=[1] if self.units is not None else None).iloc[:, 0]
                if track is not None and _space_after(self.path, self.delimiter):
                    # skipinitialspace took the spaces before the ids: ' 7' is not '7'
                    df.iloc[:, track] = with_leading_space(df.iloc[:, track], pd.read_csv(
                        self.path, sep=self.delimiter, usecols=[track], dtype=str,
                        keep_default_na=False, encoding="utf-8-sig",
                        skiprows=[1] if self.units is not None else None).iloc[:, 0])
        except (pd.errors.ParserError, pd.errors.ParserWarning, pd.errors.EmptyDataError,
                UnicodeDecodeError, ValueError) as exc:
            raise InputError(f"{self.path}: not a readable CSV "
                             f"({' '.join(str(exc).split())}); check csv.delimiter") from None
        if df.empty:
            raise InputError(f"{self.path}: no rows")
        df = df.iloc[:, index]
        df.columns = [self.header[i] for i in index]
        return df

    def lines(self, n: int) -> np.ndarray:
        """File line number of each data row (1 = the header)."""
        return np.arange(n) + (3 if self.units is not None else 2)


def _space_after(path: Path, delimiter: str) -> bool:
    """Whether the file holds a space or tab right after a delimiter anywhere (a field that
    pandas' ``skipinitialspace`` shortens); a file without spaces is told at memchr speed."""
    import mmap

    with open(path, "rb") as f:
        if f.seek(0, 2) == 0:
            return False
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            if data.find(b" ") < 0 and data.find(b"\t") < 0:
                return False
            sep = re.escape(delimiter.encode())
            return re.search(sep + rb"[ \t]", data) is not None


def with_leading_space(kept, raw):
    """The ids as written: ``raw`` (read without ``skipinitialspace``) where it is ``kept``
    with spaces before it; ``kept`` elsewhere (a quoted id after a space, which only
    ``skipinitialspace`` reads as its text)."""
    kept = kept.astype(object)
    return raw.where(raw.str.lstrip(" \t") == kept.fillna(""), kept)


class Frame(CsvFile):
    """A pandas DataFrame as a table: its columns are the header, its rows the lines."""

    def __init__(self, frame, name: str, options):
        import pandas as pd

        if not isinstance(frame, pd.DataFrame):
            raise InputError(f"{name}: a pandas DataFrame is needed, got {type(frame).__name__}")
        if frame.empty:
            raise InputError(f"{name}: no rows")
        self.path, self.options, self.notes = Path(name), options, []
        self.frame = frame.reset_index(drop=True)
        self.header = [str(c) for c in frame.columns]
        if len(set(self.header)) != len(self.header):
            raise InputError(f"{name}: two columns share a name: {', '.join(self.header)}")
        self.units, self.delimiter, self.decimal = None, ",", "."
        self.zone = options.time.zone

    def read(self, cols: dict[str, str]):
        """The chosen columns; datetime64 ones in UTC (``tma.utc.time_column`` takes their
        nanoseconds as they are), the track column as text as written (numbers as Python
        prints them: ``7``, ``7.5``)."""
        import pandas as pd

        out = {}
        for role, name in cols.items():
            series = self.frame.iloc[:, self.header.index(name)]
            if pd.api.types.is_datetime64_any_dtype(series):
                if getattr(series.dt, "tz", None) is None and self.zone is not None:
                    pass  # local times of time.zone, left naive: tma.utc.time_column
                    # localizes them (time.ambiguous) and says which instants
                elif getattr(series.dt, "tz", None) is None:
                    self.notes.append(f"{self.path}: {name} without time zone read as UTC")
                    series = series.dt.tz_localize("UTC")
                else:
                    series = series.dt.tz_convert("UTC")
            elif role == "track":
                if pd.api.types.is_float_dtype(series):  # 7 and 7.0 are one float there
                    self.id_hint = (f"; the frame's column {name} holds floats ({series.dtype}), "
                                    "in which ids such as 7 and 7.0 are one number: two "
                                    "contacts may have been read as one; give the ids as text "
                                    f"(frame[{name!r}].astype(str) before they are mixed) to "
                                    "keep them apart")
                series = series.astype(str).where(series.notna(), "").astype(object)
            out[name] = series
        return pd.DataFrame(out)

    def lines(self, n: int) -> np.ndarray:
        return np.arange(n)


def is_number(text: str, decimal: str = ".") -> bool:
    try:
        float(text.replace(decimal, ".") if decimal != "." else text)
    except ValueError:
        return False
    return True


def read_csv_table(path, options, *, navigation: bool, contacts: bool,
                   date_hint_ns: int | None = None) -> list[Recording]:
    """Read a CSV/TSV table with a family's reading ``options``. ``navigation``: own-ship
    positions are needed (from this file); ``contacts``: the contacts' values are needed.
    Returns one Recording per own-ship: one, unless the rows of different tracks give
    different own-ship positions at one time (then one per track, as each track had its own
    own-ship). Rows with a missing or unreadable time, value, track id or own-ship position,
    or a time not absolute among absolute ones, are left out and counted
    (``options.bad_rows``; under ``fail`` the first refuses the file)."""
    from tma.sources.table import read_table

    return read_table(CsvFile(Path(path), options), options, navigation=navigation,
                      contacts=contacts)


def read_frame(frame, name: str, options, *, navigation: bool,
               contacts: bool) -> list[Recording]:
    """``read_csv_table`` of a pandas DataFrame (``name``: what messages
    call it), read as the same table written to a file would be: the same columns found, the
    same checks and notes; a datetime64 column is UTC times (a zone-less one is taken as UTC and
    noted), and a row's "line" is its position in the frame, from 0."""
    from tma.sources.table import read_table

    return read_table(Frame(frame, name, options), options, navigation=navigation,
                      contacts=contacts)


READER = Reader(
    kind="csv", name="a CSV table", extensions=(".csv", ".tsv", ".txt"), read=read_csv_table,
    options=options, selects_contacts="columns.{role}=<column>",
    selects_navigation="columns.lat/columns.lon or columns.x/columns.y")
