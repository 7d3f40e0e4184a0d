"""CSV / TSV tables of contacts' values and/or own-ship fixes -> ``Recording``s.

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
- tracks: ids as written: integers (``12``) stay the ids, any other text (``T1``, ``007``,
  ``NA``) is a label, never re-read as a number. Spaces around an id are padding
  (``a, b`` tables) unless they tell ids apart: `` 7`` and ``7`` in one table are two
  contacts, as written. A DataFrame's ids are written as Python writes them (``str``): ``7``
  and ``7.0`` are two contacts. Ids alike but written differently (`` 7`` and ``7``, ``7``
  and ``7.0``, ``007`` and ``7``) are kept apart and named in a warning (``Caution``).

Everything is vectorised over the rows (pandas' C parser, numpy sorts): a million rows take
about a second. A row with a missing or unreadable time, value, track id or own-ship position
(or a time that is not absolute among absolute ones) is left out and counted with its line
(``bad_rows=drop``), or refuses the file in one line naming the column, the line and the
option (``bad_rows=fail``); a file-wide problem (a column not found, a unit, a time zone) is
always one ``InputError``.
"""

import csv
import io
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from tma.errors import InputError, MissingFileError
from tma.sources.base import Caution, Contacts, Navigation, Recording, line_places
from tma.utc import MAX_SPAN_S, UNIX_FROM_S, UNIX_MAGNITUDE, UNIX_SCALE_NS, UTC_FROM_NS, ZONED

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
MAX_TRACK_ID = 2**53  # an id written as a larger integer is kept as text
NAMED_ALIKE = 3  # groups of alike ids named in the warning
INTEGER_ID = re.compile(r"-?(?:0|[1-9][0-9]{0,15})")  # an id written as a plain integer
SAME_FIX = {"x": 1e-6, "lat": 1e-9}  # m, deg (0.1 mm): rows at one time share one own-ship
UTC_WORD = r"(?i)(?<=\d)\s*(?:UTC|GMT)$"  # a time of day ending in the word UTC: zone Z
ZONE_NAME = re.compile(r"\d\s*([A-Za-z]{2,5})")  # ... ending in a zone's name (CET, EST)
UNIT_WORDS = {"s", "sec", "secs", "second", "seconds", "ms", "us", "ns", "utc", "iso",
              "iso8601", "iso-8601", "deg", "degree", "degrees", "rad", "radian", "radians",
              "m", "km", "nmi", "-", "id", "1", "m/s", "kn", "knots", "unix", "text", "none"}


def read_csv_table(path, options, *, navigation: bool, contacts: bool) -> list[Recording]:
    """Read a CSV/TSV table with a family's reading ``options``. ``navigation``: own-ship
    positions are needed (from this file); ``contacts``: the contacts' values are needed.
    Returns one Recording per own-ship: one, unless the rows of different tracks give
    different own-ship positions at one time (then one per track, as each track had its own
    own-ship). Rows with a missing or unreadable time, value, track id or own-ship position,
    or a time not absolute among absolute ones, are left out and counted
    (``options.bad_rows``; under ``fail`` the first refuses the file)."""
    return read_table(_Table(Path(path), options), options, navigation=navigation,
                      contacts=contacts)


def read_frame(frame: pd.DataFrame, name: str, options, *, navigation: bool,
               contacts: bool) -> list[Recording]:
    """``read_csv_table`` of a pandas DataFrame (``name``: what messages call it), read as
    the same table written to a file would be: the same columns found, the same checks and
    notes; a datetime64 column is UTC times (a zone-less one is taken as UTC and noted), and
    a row's "line" is its position in the frame, from 0."""
    return read_table(_Frame(frame, name, options), options, navigation=navigation,
                      contacts=contacts)


def read_table(table, options, *, navigation: bool, contacts: bool) -> list[Recording]:
    """The Recordings of a ``_Table`` (a file's layout) or ``_Frame``."""
    path = table.path
    role = options.observation.role
    cols = table.columns(navigation=navigation, contacts=contacts)
    df = table.read(cols)
    line = table.lines(len(df))
    notes = list(table.notes)
    rows, keep = options.dropped(), np.ones(len(df), dtype=bool)

    def drop(bad, reason, refusal):
        keep[:] &= rows.drop(bad & keep, reason, line_places(line), f"{path}: {refusal}")

    tcol = cols["time"]
    t_raw, fmt, t_ok, not_absolute = _time_column(df, tcol, options.time.format, path, line,
                                                  notes)
    drop(~t_ok, "time missing or unreadable",
         f"column {tcol} has missing times or values that are not "
         + ("ISO-8601 times such as 2024-05-01T10:00:00Z; set columns.time or time.format"
            if fmt in ("iso", "iso_utc") else "numbers"))
    unit = fmt.replace("unix_", "")
    drop(not_absolute, "time not absolute among absolute times",
         f"column {tcol} has times that are not Unix times ({unit}) like the others: times "
         "must be all Unix or all relative (time.format=s, unix_s, unix_ms, unix_us, unix_ns)"
         if fmt.startswith("unix") else
         f"column {tcol} has times before 2000 among UTC times")
    if role in cols:
        b_raw = _number_column(df, cols[role], path)
        drop(~np.isfinite(b_raw), f"{role} missing or not a number",
             f"column {cols[role]} has missing, NaN or non-numeric values")
        track_raw = _track_text(df, cols.get("track"))
        if track_raw is not None:
            drop((track_raw == "").to_numpy(), "track id missing",
                 f"column {cols['track']} has missing track ids")
    geo = "lat" in cols
    if navigation:
        p0, p1 = (_number_column(df, cols[k], path) for k in (("lat", "lon") if geo else "xy"))
        drop(~(np.isfinite(p0) & np.isfinite(p1)), "own-ship position missing or not a number",
             f"columns {', '.join(cols[k] for k in (('lat', 'lon') if geo else 'xy'))} have "
             "missing, NaN or non-numeric values")
    if not keep.any():
        raise InputError(f"{path}: no usable row: {rows.text()}")
    if not keep.all():
        line, t_raw = line[keep], t_raw[keep]
    t, epoch = _seconds(t_raw, fmt, tcol, path, line)
    track = None
    if role in cols:
        b, stated = _values(b_raw[keep], cols[role], options, table, path, line, notes)
        track = _tracks(None if track_raw is None else track_raw[keep], len(t), notes,
                        f"{path}: {cols.get('track')}")
        _check_increasing(t, track, tcol, path, line)
    if not navigation:
        return [Recording(None, Contacts(t, epoch, track, b, str(path), stated), notes=notes,
                          dropped=rows)]
    pos = (p0[keep], p1[keep])
    if geo:
        _check_lat_lon(*pos, cols, path, line)
    nav_rows, consistent = _one_fix_per_time(t, pos, SAME_FIX["lat" if geo else "x"])
    if not consistent.all() and not contacts:
        row = nav_rows[int(np.flatnonzero(~consistent)[0])]
        raise InputError(f"{path}: two different own-ship positions at the time of line "
                         f"{line[row]} ({tcol}): one fix per time")
    if not contacts:
        return [Recording(_navigation(t, epoch, pos, nav_rows, geo, path, line), None,
                          notes=notes, dropped=rows)]
    if consistent.all():
        return [Recording(_navigation(t, epoch, pos, nav_rows, geo, path, line),
                          Contacts(t, epoch, track, b, str(path), stated), notes=notes,
                          dropped=rows)]
    notes.append("tracks report different own-ship positions at one time: each track gets "
                 "its own own-ship (and dataset shard)")
    recordings = []
    code = _codes(track)
    order = np.argsort(code, kind="stable")
    starts = np.flatnonzero(np.r_[True, code[order][1:] != code[order][:-1]])
    for k, group in enumerate(np.split(order, starts[1:])):  # times increase (checked)
        nav = _navigation(t, epoch, pos, group, geo, path, line)
        recordings.append(Recording(nav, Contacts(t[group], epoch, track[group], b[group],
                                                  str(path), stated), notes=notes,
                                    dropped=rows if k == 0 else options.dropped()))
    return recordings


class _Table:
    """The file's layout from its first lines: delimiter, decimal mark, header, units row."""

    def __init__(self, path: Path, options):
        self.path, self.options, self.notes = path, options, []
        try:
            with open(path, "rb") as f:
                raw = f.read(SAMPLE_BYTES)
        except FileNotFoundError:
            raise MissingFileError(f"{path}: no such file") from None
        except IsADirectoryError:
            raise InputError(f"{path}: a directory, not a CSV file") from None
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
        if all(_is_number(c, self.decimal) for c in self.header if c):
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
        if any(_is_number(c, self.decimal) for c in second if c):
            return False
        text_over_number = any(c and _is_number(d.strip(), self.decimal)
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
                         "or give the own-ship in a separate file with navigation=FILE")

    def read(self, cols: dict[str, str]) -> pd.DataFrame:
        """The chosen columns (by position, so odd header spellings cannot get in the way).
        Every column is parsed, so that a line with more fields than the header is refused.
        The track column is text as written (``007`` is not ``7``, ``NA`` is a name)."""
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
                    df.iloc[:, track] = _with_leading_space(df.iloc[:, track], pd.read_csv(
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


def _with_leading_space(kept: pd.Series, raw: pd.Series) -> pd.Series:
    """The ids as written: ``raw`` (read without ``skipinitialspace``) where it is ``kept``
    with spaces before it; ``kept`` elsewhere (a quoted id after a space, which only
    ``skipinitialspace`` reads as its text)."""
    kept = kept.astype(object)
    return raw.where(raw.str.lstrip(" \t") == kept.fillna(""), kept)


class _Frame(_Table):
    """A pandas DataFrame as a table: its columns are the header, its rows the lines."""

    def __init__(self, frame: pd.DataFrame, name: str, options):
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

    def read(self, cols: dict[str, str]) -> pd.DataFrame:
        """The chosen columns; datetime64 ones in UTC (``_time_column`` takes their
        nanoseconds as they are), the track column as text as written (numbers as Python
        prints them: ``7``, ``7.5``)."""
        out = {}
        for role, name in cols.items():
            series = self.frame.iloc[:, self.header.index(name)]
            if pd.api.types.is_datetime64_any_dtype(series):
                if getattr(series.dt, "tz", None) is None:
                    self.notes.append(f"{self.path}: {name} without time zone read as UTC")
                    series = series.dt.tz_localize("UTC")
                series = series.dt.tz_convert("UTC")
            elif role == "track":
                series = series.astype(str).where(series.notna(), "").astype(object)
            out[name] = series
        return pd.DataFrame(out)

    def lines(self, n: int) -> np.ndarray:
        return np.arange(n)


def _is_number(text: str, decimal: str = ".") -> bool:
    try:
        float(text.replace(decimal, ".") if decimal != "." else text)
    except ValueError:
        return False
    return True


def _number_column(df, col, path) -> np.ndarray:
    """A column as float64, NaN where a cell is missing or not a number (true/false columns
    are refused: no number is meant)."""
    series = df[col]
    if pd.api.types.is_bool_dtype(series):
        raise InputError(f"{path}: column {col} holds true/false, not numbers")
    if pd.api.types.is_numeric_dtype(series):
        return series.to_numpy(dtype=float)
    try:
        return pd.to_numeric(series, errors="coerce").to_numpy(dtype=float)
    except (OverflowError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: column {col} has values that are not numbers of a "
                         f"usable size ({exc})") from None


def _time_column(df, col, fmt, path, line, notes):
    """``(values, format, ok, not_absolute)``: the times as read (ns since 1970 for ISO text,
    else the numbers), their format (``iso``/``iso_utc``, ``s``, ``rel_ms``..., ``unix_*``),
    which rows hold a readable time, and which hold a time that is not absolute where the
    others are (a 0 among Unix times, a 1970 stamp among UTC ones: a clock that was not set,
    never a relative clock)."""
    series = df[col]
    numeric = pd.api.types.is_numeric_dtype(series)  # true/false too: refused as numbers
    ns = None
    if pd.api.types.is_timedelta64_dtype(series):  # a DataFrame's durations: relative times
        if fmt not in ("auto", "s"):
            raise InputError(f"{path}: {col} holds durations (timedelta64: times relative to "
                             f"a start), not time.format={fmt} times; leave time.format=auto "
                             "(time.start_utc=... dates them)")
        ok = series.notna().to_numpy()
        notes.append(f"{path.name}: {col} read as relative times (durations)")
        return (np.where(ok, series.dt.as_unit("ns").array.asi8, 0), "rel_ns", ok,
                np.zeros_like(ok))
    if pd.api.types.is_datetime64_any_dtype(series) and fmt in ("auto", "iso", "iso_utc"):
        ok = series.notna().to_numpy()  # a DataFrame's UTC times (``_Frame``), exact to the ns
        ns = np.where(ok, series.dt.as_unit("ns").array.asi8, 0)
    elif fmt in ("iso", "iso_utc") or (fmt == "auto" and not numeric and _mostly_text(series)):
        ns, ok = _iso_times(series, col, fmt, path, line, notes)
    if ns is not None:
        early = ok & (ns < UTC_FROM_NS)
        absolute = ok.any() and np.median(ns[ok]) >= UTC_FROM_NS
        return ns, "iso" if fmt == "auto" else fmt, ok, early if absolute else np.zeros_like(ok)
    if pd.api.types.is_integer_dtype(series):
        values = series.to_numpy(dtype=np.int64)
        ok = np.ones(values.size, dtype=bool)
    else:
        values = _number_column(df, col, path)
        ok = np.isfinite(values)
    if not ok.any():
        return values, "s", ok, np.zeros_like(ok)
    median = abs(float(np.median(values[ok])))
    scaled_name = re.search(r"_(ms|us|ns)$", col.lower())
    if fmt == "auto":
        if scaled_name:  # the name says the unit; the magnitude says Unix or relative
            unit = scaled_name.group(1)
            per_s = UNIX_SCALE_NS["unix_s"] / UNIX_SCALE_NS["unix_" + unit]
            fmt = ("unix_" if median / per_s >= UNIX_FROM_S else "rel_") + unit
        else:
            fmt = next((f for bound, f in UNIX_MAGNITUDE if median >= bound), "s")
        if fmt != "s":
            notes.append(f"{path.name}: {col} read as "
                         f"{fmt.replace('unix_', 'Unix time in ').replace('rel_', 'relative ')}"
                         f" (time.format={fmt if fmt.startswith('unix') else 's'})")
    not_absolute = np.zeros_like(ok)
    if fmt.startswith("unix"):
        bound = UNIX_FROM_S * (1e9 / UNIX_SCALE_NS[fmt])
        if median >= bound:  # Unix times: all must be (a 0 is a clock not set)
            not_absolute = ok & (values < bound)
    return values, fmt, ok, not_absolute


def _seconds(values, fmt, col, path, line) -> tuple[np.ndarray, int | None]:
    """Seconds (float64) since ``epoch_utc_ns`` (absolute times) or relative (epoch None), of
    times as ``_time_column`` read them (every one usable)."""
    if fmt in ("iso", "iso_utc"):
        first = int(values.min())
        return _checked_span((values - first) / 1e9, values, col, path, line), first
    if fmt in ("s", "rel_ms", "rel_us", "rel_ns"):
        seconds = values.astype(float) / {"s": 1, "rel_ms": 1e3, "rel_us": 1e6,
                                           "rel_ns": 1e9}[fmt]
        span = seconds.max() - seconds.min()
        if span > MAX_SPAN_S:
            far = int(np.argmax(np.abs(seconds - np.median(seconds))))
            raise InputError(f"{path}: {col} {values[far]:g} on line {line[far]} makes the log "
                             f"span {span:.3g} s (at most {MAX_SPAN_S:.3g} s): {col} must be "
                             "seconds (or set time.format)")
        return seconds, None
    scale = UNIX_SCALE_NS[fmt]
    if values.dtype.kind == "i":
        first = int(values.min())
        seconds = (values - first).astype(float) * (scale / 1e9)
        return _checked_span(seconds, values, col, path, line), first * scale
    if np.abs(values).max() * scale >= 2**63:
        k = int(np.argmax(np.abs(values)))
        raise InputError(f"{path}: {col} {values[k]:g} on line {line[k]} is beyond the year "
                         f"2262 as Unix time ({fmt}); check time.format")
    first = float(values.min())
    seconds = (values - first) * (scale / 1e9)
    return _checked_span(seconds, values, col, path, line), int(round(first * scale))


def _checked_span(seconds, values, col, path, line):
    if seconds.max() > MAX_SPAN_S:
        k = int(np.argmax(seconds))
        raise InputError(f"{path}: {col} {values[k]:g} on line {line[k]} makes the log span "
                         f"{seconds.max():.3g} s (at most {MAX_SPAN_S:.3g} s)")
    return seconds


def _mostly_text(series) -> bool:
    """A text column of times, not numbers with a few bad cells (those are reported as such)."""
    sample = series.dropna().astype(str).head(1000)
    numeric = pd.to_numeric(sample, errors="coerce").notna().mean() if len(sample) else 0
    return numeric < 0.5


def _iso_times(series, col, fmt, path, line, notes) -> tuple[np.ndarray, np.ndarray]:
    """ISO-8601 texts as UTC ns (int64) and which rows hold one. A column whose times mostly
    have no zone is refused (unless ``iso_utc``): the times would be guessed; a few rows
    without one among zoned times are rows without a readable time."""
    text = series.astype("str").str.strip()
    missing = series.isna().to_numpy() | (text == "").to_numpy()
    utc_word = text.str.contains(UTC_WORD, regex=True)
    if utc_word.any():  # "... 08:00:00 UTC": the zone Z, as loggers often write it
        text = text.str.replace(UTC_WORD, "Z", regex=True)
        notes.append(f"{path.name}: {col}: ' UTC' read as the zone Z")
    zoned = text.str.contains(ZONED, regex=True).to_numpy(dtype=bool)
    unzoned = ~zoned & ~missing
    if fmt != "iso_utc" and unzoned.sum() * 2 >= (~missing).sum() and unzoned.any():
        k = int(np.argmax(unzoned))
        named = re.search(rf"{ZONE_NAME.pattern}$", text.iloc[k])
        if named:  # "CET", "EST": no offset (summer time?): the offset is the user's to say
            raise InputError(f"{path}: {col} '{text.iloc[k]}' on line {line[k]} names its zone "
                             f"({named.group(1)}), which is no offset: write it as one "
                             f"({text.iloc[k][:named.start(1)].rstrip()}+01:00, say) or Z for "
                             "UTC")
        raise InputError(f"{path}: {col} '{text.iloc[k]}' on line {line[k]} has no time zone: "
                         f"write times with one ({text.iloc[k]}Z for UTC) or set "
                         "time.format=iso_utc to read zone-less times as UTC")
    if fmt == "iso_utc" and unzoned.any():
        notes.append(f"{path.name}: {col} without time zone read as UTC (time.format=iso_utc)")
    try:
        parsed = pd.to_datetime(text.where(~missing & (zoned | (fmt == "iso_utc"))),
                                format="ISO8601", utc=True, errors="coerce")
    except (ValueError, OverflowError) as exc:
        raise InputError(f"{path}: column {col}: not ISO-8601 times ({exc})") from None
    ok = parsed.notna().to_numpy()
    if fmt == "auto" and ok.any():
        notes.append(f"{path.name}: {col} read as ISO-8601 times (time.format=iso)")
    return np.where(ok, parsed.dt.as_unit("ns").array.asi8, 0), ok


def _values(values, col, options, table, path, line, notes):
    """The observation's ``values`` (of column ``col``) in its first unit, and whether a unit
    was stated: by ``<role>.units``, or another unit than the first by the units row or the
    column's name. A name or units row saying the first unit is what a column in another unit
    mislabelled would say too, so the family's guard still checks it."""
    observation = options.observation
    plural = observation.plural
    units, stated = options.contact.units, options.contact.units is not None
    if units is None:
        in_row = table.unit_of(col)
        by_row = next((u for u in observation.units[1:] if in_row in u.aliases), None)
        by_name = observation.unit_of_name(col)
        if by_row is not None:
            units, stated = by_row.name, True
            notes.append(f"{path.name}: {plural} in {by_row.words} (units row)")
        elif by_name is not None:
            units, stated = by_name.name, True
            notes.append(f"{path.name}: {plural} in {by_name.words} (column name {col})")
    unit = observation.unit(units or observation.units[0].name)
    observation.check_range(values, unit, f"{path}: {col}", lambda k: f" on line {line[k]}")
    return unit.to_first(values), stated


def _track_text(df, col):
    """The track ids as written (text, spaces included; empty where missing), or None
    without a track column. An id of spaces only is missing."""
    if col is None:
        return None
    text = df[col].fillna("").astype(str)
    return text.where(text.str.strip() != "", "")


def _tracks(text, n: int, notes: list, where: str) -> np.ndarray:
    """Track ids as written: int64 when every id is written as a plain integer (``12``,
    ``-3``: the ids themselves), else the texts (object array), kept as labels: ``007`` and
    ``7``, ``1e3`` and ``1000`` are different contacts, ``NA`` is a name. Spaces around the
    ids are dropped unless they tell ids apart (`` 7`` and ``7``: two contacts, kept as
    written); ids alike but written differently are noted (``_alike_ids``). No track column:
    one contact, 0."""
    if text is None:
        return np.zeros(n, dtype=np.int64)
    text = _unpadded(text)
    _alike_ids(text, notes, where)
    if text.str.fullmatch(INTEGER_ID.pattern).all():
        ids = text.astype(np.int64).to_numpy()
        if np.all(np.abs(ids) <= MAX_TRACK_ID):
            return ids
    return text.to_numpy(dtype=object)


def _unpadded(text: pd.Series) -> pd.Series:
    """The ids without the spaces around them, except the ids that only those spaces tell
    apart (`` 7`` beside ``7``), kept as written."""
    stripped = text.str.strip()
    if (stripped == text).all():
        return text
    codes, written = pd.factorize(text)
    padded_alike = pd.Series(written).str.strip().duplicated(keep=False).to_numpy()
    return stripped.where(~padded_alike[codes], text)


def _alike(text: str):
    """What two ids written differently may both mean: the number they write, else the text
    without its spaces."""
    stripped = text.strip()
    try:
        return float(stripped)
    except ValueError:
        return stripped


def _alike_ids(text: pd.Series, notes: list, where: str) -> None:
    """Note (as a warning) the ids alike but written differently (`` 7`` and ``7``, ``7``
    and ``7.0``, ``007`` and ``7``): they are kept apart, as written."""
    written = pd.unique(text)
    if len(written) < 2 or len(written) > 100_000:  # ids by the row: nothing to tell apart
        return
    groups: dict = {}
    for w in written:
        groups.setdefault(_alike(w), []).append(w)
    alike = [sorted(g) for g in groups.values() if len(g) > 1]
    if alike:
        shown = "; ".join(" and ".join(repr(w) for w in g) for g in alike[:NAMED_ALIKE])
        notes.append(Caution(
            f"{where}: {len(alike)} group(s) of contact ids alike but written differently "
            f"({shown}{' ...' if len(alike) > NAMED_ALIKE else ''}) are kept as different "
            "contacts (ids are kept as written): write each contact's id alike if they are "
            "one"))


def _codes(track: np.ndarray) -> np.ndarray:
    """Integer codes of the tracks (labels factorised: sorting numbers is faster)."""
    return pd.factorize(track)[0] if track.dtype == object else track


def _check_increasing(t, track, col, path, line):
    """Times must increase strictly within each track, in file order."""
    code = _codes(track)
    order = np.argsort(code, kind="stable")
    ts, tr = t[order], code[order]
    bad = (tr[1:] == tr[:-1]) & (np.diff(ts) <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        kind = "duplicate" if ts[k + 1] == ts[k] else "non-increasing"
        raise InputError(f"{path}: {kind} {col} for track {track[order[k + 1]]} on line "
                         f"{line[order[k + 1]]} ({col} must increase within a track)")


def _check_lat_lon(lat, lon, cols, path, line):
    for values, name, limit in ((lat, cols["lat"], 90), (lon, cols["lon"], 360)):
        outside = (values < -limit) | (values > limit) if limit == 90 else \
            (values < -180) | (values > 360)
        if outside.any():
            k = int(np.argmax(outside))
            raise InputError(f"{path}: {name} {values[k]:g} on line {line[k]} is not a "
                             f"{'latitude' if limit == 90 else 'longitude'} in degrees; are "
                             "columns.lat and columns.lon right?")


def _one_fix_per_time(t, pos, tolerance):
    """Rows of the first occurrence of each distinct time (sorted by time), and per distinct
    time whether every row there gives the same own-ship position (within ``tolerance``)."""
    order = np.argsort(t, kind="stable")
    ts = t[order]
    starts = np.flatnonzero(np.r_[True, ts[1:] != ts[:-1]])
    same = np.ones(starts.size, dtype=bool)
    for values in pos:
        v = values[order]
        same &= np.maximum.reduceat(v, starts) - np.minimum.reduceat(v, starts) <= tolerance
    return order[starts], same


def _navigation(t, epoch, pos, rows, geo, path, line) -> Navigation:
    """Own-ship fixes of ``rows`` (their times distinct), sorted by time."""
    rows = rows[np.argsort(t[rows], kind="stable")]
    a, b = pos[0][rows], pos[1][rows]
    if geo:
        return Navigation(t[rows], epoch, str(path), lat_deg=a, lon_deg=b, lines=line[rows])
    return Navigation(t[rows], epoch, str(path), x_m=a, y_m=b, lines=line[rows])
