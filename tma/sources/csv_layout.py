"""A table's layout and columns, for the CSV reader (``tma.sources.csv_table``) and the AIS
exports (``tma.ais.table``): ``CsvFile`` tells a file's delimiter, decimal mark, header and
units row from its first lines and finds which column holds what (``columns.<role>``, tma's
names, common names, any case); ``Frame`` does the same for a pandas DataFrame. Both hand the
chosen columns to ``tma.sources.table.read_table``."""

import csv
import io
import re
import warnings
from pathlib import Path

import numpy as np

from tma.errors import InputError
from tma.sources.base import file_head

DOCUMENTED = {"time": "time_s", "x": "own_x_m", "y": "own_y_m", "track": "track_id",
              "platform": "platform"}
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
    "platform": ("platform", "platform_id", "platform_name", "observer", "sensor_platform",
                 "station"),
}
SNIFFED = (",", ";", "\t")
SAMPLE_BYTES = 1 << 16
SAMPLE_LINES = 50
UNIT_WORDS = {"s", "sec", "secs", "second", "seconds", "ms", "us", "ns", "utc", "iso",
              "iso8601", "iso-8601", "deg", "degree", "degrees", "rad", "radian", "radians",
              "m", "km", "nmi", "-", "id", "1", "m/s", "kn", "knots", "unix", "text", "none"}


class CsvFile:
    """A table's layout and columns: the file's from its first lines (delimiter, decimal
    mark, header, units row), and which column holds what (``columns``); ``read`` reads the
    chosen columns with pandas. ``tma.sources.table.Frame`` is a DataFrame's."""

    id_hint = ""  # what a refusal of duplicate times per contact adds (a frame's float ids)
    own_from_ais = True  # own-ship may come from the AIS (truth.own_mmsi): a file's, not a frame's

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
        platform = self._find("platform", required=False)
        if platform is not None:
            chosen["platform"] = platform
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
                         "give the own-ship in a separate file with navigation=FILE"
                         + (", or take it from the AIS with truth.own_mmsi=<MMSI>"
                            if self.own_from_ais else ""))

    def read(self, cols: dict[str, str]):
        """The chosen columns (by position, so odd header spellings cannot get in the way).
        Every column is parsed, so that a line with more fields than the header is refused.
        The track and platform columns are text as written (``007`` is not ``7``, ``NA`` is
        a name)."""
        import pandas as pd

        index = sorted({self.header.index(name) for name in cols.values()})
        text = {self.header.index(cols[r]): str for r in ("track", "platform") if r in cols}
        try:
            with warnings.catch_warnings():  # a row longer than the header: refused
                warnings.simplefilter("error", pd.errors.ParserWarning)
                df = pd.read_csv(self.path, sep=self.delimiter, decimal=self.decimal,
                                 skiprows=[1] if self.units is not None else None,
                                 index_col=False, skipinitialspace=True,
                                 encoding="utf-8-sig", low_memory=False,
                                 dtype=text or None)
                named = sorted(text)  # the track's and the platform's names, as written

                def as_written(columns, skip_space):  # (one read for all of them)
                    return pd.read_csv(self.path, sep=self.delimiter, usecols=columns,
                                       dtype=str, keep_default_na=False,
                                       skipinitialspace=skip_space, encoding="utf-8-sig",
                                       skiprows=[1] if self.units is not None else None)

                missing = [c for c in named if df.iloc[:, c].isna().any()]
                if missing:  # pandas read a name such as NA or null as missing
                    raw = as_written(missing, True)
                    for j, c in enumerate(missing):
                        df.iloc[:, c] = raw.iloc[:, j]
                if named and _space_after(self.path, self.delimiter):
                    # skipinitialspace took the spaces before the names: ' 7' is not '7'
                    raw = as_written(named, False)
                    for j, c in enumerate(named):
                        df.iloc[:, c] = with_leading_space(df.iloc[:, c], raw.iloc[:, j])
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

    own_from_ais = False  # a frame gives its own-ship in its columns or navigation=

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
            elif role == "platform":
                series = series.astype(str).where(series.notna(), "").astype(object)
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
