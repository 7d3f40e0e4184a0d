"""Decoded AIS position reports as a table (CSV, gzip'd CSV, Parquet), read by the logs'
table reader (``tma.sources.csv_layout``: its layout sniffing, ``tma.utc.time_column``: its
times) with the ``truth.*`` options of its own: ``truth.columns.time|mmsi|lat|lon|sog|cog``,
``truth.time.format|zone|ambiguous``, ``truth.csv.delimiter|decimal``, ``truth.sog_units``.

Columns are found by name in any case where no option names them (the common exports'
spellings: ``TIME``, ``MMSI``, ``LAT``, ``LON``, ``SOG``, ``COG``); times as the logs' are read,
except that a time written without a zone is UTC, as AIS time is (``truth.time.zone`` says
another), and the Danish Maritime Authority's ``dd/mm/yyyy HH:MM:SS`` is told by itself.
Speed over ground is in knots (``truth.sog_units``; a column named ``*_m_s`` or ``*_km_h``
says its unit), course over ground in degrees; both optional. A row whose time, MMSI or
position is missing or unreadable is left out and counted with its line.
"""

import io
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from tma.ais.options import SOG_UNITS, TruthError, TruthOptions
from tma.errors import InputError
from tma.sources.base import Dropped, line_places
from tma.sources.csv_layout import CsvFile, Frame
from tma.utc import UNIX_FROM_S, UNIX_SCALE_NS, UTC_FROM_NS, is_pattern, time_column

SPELLINGS = {  # per role, the names the common exports give it (lower case, spaces as _)
    "time": ("timestamp_utc", "timestamp", "basedatetime", "time_utc", "datetime", "date_time",
             "time", "utc", "t", "received", "time_s", "fecha_posicion", "fecha"),
    "mmsi": ("mmsi", "userid", "user_id", "mmsi_number", "shipid"),
    "lat": ("latitude_deg", "latitude_degrees", "latitude", "lat_deg", "lat",
            "latitud_decimal", "latitud"),
    "lon": ("longitude_deg", "longitude_degrees", "longitude", "lon_deg", "lon", "long", "lng",
            "longitud_decimal", "longitud"),
    "sog": ("sog", "sog_knots", "sog_kn", "speed_over_ground", "sog_m_s", "sog_km_h", "speed"),
    "cog": ("cog", "cog_degrees", "cog_deg", "course_over_ground", "course"),
}
REQUIRED = ("time", "mmsi", "lat", "lon")
DMA_TIME = r"^\d{2}/\d{2}/\d{4} \d{2}:\d{2}:\d{2}$"  # the Danish Maritime Authority's
PARQUET_MAGIC = b"PAR1"


def normal(name) -> str:
    """A column's name as the spellings are written: lower case, spaces as _, no ``#``."""
    import re

    return re.sub(r"\s+", "_", str(name).strip().lstrip("#").strip().lower())


def _layout_options(options: TruthOptions):
    """What the logs' table classes read of their options, from the truth options."""
    return SimpleNamespace(csv=options.csv, time=options.time,
                           observation=SimpleNamespace(role="mmsi"))


class _Columns:
    """Which column holds each role of an AIS table (mixed into the logs' table classes)."""

    def ais_columns(self, truth: TruthOptions, where: str) -> dict[str, str]:
        names = {normal(c): c for c in reversed(self.header)}
        chosen, missing = {}, []
        for role, spellings in SPELLINGS.items():
            given = getattr(truth.columns, role)
            if given is not None:
                found = given if given in self.header else names.get(normal(given))
                if found is None:
                    raise TruthError(f"{where}: truth.columns.{role}={given}: no such column; "
                                     f"columns found: {_shown(self.header)}")
                chosen[role] = found
                continue
            found = next((names[n] for n in spellings if n in names), None)
            if found is not None:
                chosen[role] = found
            elif role in REQUIRED:
                missing.append(role)
        if missing:
            kind = (" (a bearing log? truth= takes the ships' AIS, input= the bearings)"
                    if any("bearing" in normal(c) for c in self.header) else "")
            raise TruthError(f"{where}: not AIS position reports: no {' or '.join(missing)} "
                             f"column among {_shown(self.header)}{kind}; name it with "
                             + " ".join(f"truth.columns.{m}=<name>" for m in missing))
        auto = [f"{role} {col}" for role, col in chosen.items()
                if getattr(truth.columns, role) is None]
        if auto:
            self.notes.append(f"{self.path.name}: AIS columns " + ", ".join(auto)
                              + " (truth.columns.*)")
        return chosen


class AisCsv(_Columns, CsvFile):
    """An AIS CSV (its bytes, decompressed when it was gzip'd)."""

    def __init__(self, path: Path, data: bytes, truth: TruthOptions):
        self.data = data
        super().__init__(path, _layout_options(truth), head=data)

    def read(self, cols: dict[str, str]):
        import pandas as pd

        index = sorted({self.header.index(name) for name in cols.values()})
        try:
            df = pd.read_csv(io.BytesIO(self.data), sep=self.delimiter, decimal=self.decimal,
                             skiprows=[1] if self.units is not None else None, index_col=False,
                             usecols=index, skipinitialspace=True, encoding="utf-8-sig",
                             low_memory=False)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError,
                ValueError) as exc:
            raise TruthError(f"truth={self.path}: not a readable CSV "
                             f"({' '.join(str(exc).split())}); check truth.csv.delimiter"
                             ) from None
        df.columns = [self.header[i] for i in index]
        return df


class AisFrame(_Columns, Frame):
    """An AIS table read by pandas (Parquet); its lines are its rows, from 0."""

    def __init__(self, frame, path: Path, truth: TruthOptions):
        super().__init__(frame, str(path), _layout_options(truth))
        self.path = path


def _shown(header) -> str:
    return ", ".join(map(str, header[:12])) + (", ..." if len(header) > 12 else "")


def read_table(path: Path, data: bytes, truth: TruthOptions):
    """``(mmsi, t_ns, lat_deg, lon_deg, sog_m_s, cog_deg, dropped, notes)`` of an AIS table:
    CSV (``data``: its bytes) or Parquet (module docstring)."""
    import pandas as pd

    where = f"truth={path}"
    if data.startswith(PARQUET_MAGIC):
        try:
            frame = pd.read_parquet(io.BytesIO(data))
        except (OSError, ValueError) as exc:
            raise TruthError(f"{where}: not a readable Parquet file ({exc})") from None
        if frame.empty:
            raise TruthError(f"{where}: no rows")
        table = AisFrame(frame, path, truth)
    else:
        try:
            table = AisCsv(path, data, truth)
        except InputError as exc:
            raise TruthError(f"{where}: {str(exc).split(': ', 1)[-1]}") from None
    cols = table.ais_columns(truth, where)
    df = table.read(cols)
    line = table.lines(len(df))
    notes = list(table.notes)
    t_ns = _times(df[cols["time"]], cols["time"], truth, path, line, notes)
    mmsi, lat, lon = (_numbers(df[cols[r]]) for r in ("mmsi", "lat", "lon"))
    sog = _sog(df, cols, truth, path, notes)
    cog = _numbers(df[cols["cog"]]) if "cog" in cols else np.full(len(df), np.nan)
    cog = np.where((cog >= 0) & (cog < 360), cog, np.nan)  # 360: not available
    dropped, keep = Dropped("drop"), np.ones(len(df), dtype=bool)
    places = line_places(line)
    no_position = ~(np.isfinite(lat) & np.isfinite(lon))
    for bad, reason in (
            (t_ns < 0, "time missing or unreadable"),
            (~((mmsi > 0) & (mmsi < 1e9) & (mmsi == np.round(mmsi))),
             "MMSI missing or not a whole number"),
            (no_position, "position missing or not a number"
             + _decimal_commas(df[cols["lat"]], no_position)),
            (~((np.abs(lat) <= 90) & (np.abs(lon) <= 180)),
             "position not available (lat 91, lon 181) or off the globe")):
        bad &= keep
        keep &= dropped.drop(bad, reason, places, "")
    return (mmsi[keep].astype(np.int64), t_ns[keep], lat[keep], lon[keep], sog[keep],
            cog[keep], dropped, notes)


def _decimal_commas(series, bad) -> str:
    """What to say when most of the unreadable positions ``bad`` are numbers written with a
    decimal comma (``50,79``): the option that reads them; else ""."""
    if not bad.any() or pd_numeric(series):
        return ""
    text = series[bad].astype(str).str.strip()
    comma = text.str.fullmatch(r"[-+]?\d+,\d+")
    if comma.mean() < 0.5:
        return ""
    return (f": numbers with a decimal comma ({text[comma].iloc[0]}); set truth.csv.decimal=, "
            "to read them")


def pd_numeric(series) -> bool:
    import pandas as pd

    return pd.api.types.is_numeric_dtype(series)


def _numbers(series) -> np.ndarray:
    import pandas as pd

    if pd.api.types.is_numeric_dtype(series) and not pd.api.types.is_bool_dtype(series):
        return series.to_numpy(dtype=float)
    return pd.to_numeric(series.astype(str).str.strip(), errors="coerce").to_numpy(float)


def _sog(df, cols, truth: TruthOptions, path: Path, notes: list) -> np.ndarray:
    """Speed over ground (m/s), NaN where unknown (AIS 102.3 kn: not available)."""
    if "sog" not in cols:
        return np.full(len(df), np.nan)
    name, units = normal(cols["sog"]), truth.sog_units
    by_name = next((u for u in ("m_s", "km_h") if name.endswith(u)), None)
    if by_name is not None and units == "kn":
        units = by_name
        notes.append(f"{path.name}: speed over ground in {units} (column name {cols['sog']})")
    sog = _numbers(df[cols["sog"]])
    sog = np.where((sog >= 0) & (sog < 102.2 if units == "kn" else sog >= 0), sog, np.nan)
    return sog * SOG_UNITS[units]


def _times(series, col: str, truth: TruthOptions, path: Path, line, notes) -> np.ndarray:
    """The reports' times as UTC ns (int64), -1 where missing or unreadable: the logs' rules
    (``tma.utc.time_column``), but a time without a zone is UTC (AIS time) unless
    ``truth.time.zone`` says another, and DMA's dd/mm/yyyy is found by itself."""
    import pandas as pd

    fmt, zone = truth.time.format, truth.time.zone
    text_column = not pd.api.types.is_numeric_dtype(series) and not \
        pd.api.types.is_datetime64_any_dtype(series)
    if fmt == "auto" and text_column:
        text = series.dropna().astype(str).str.strip().head(1000)
        numeric = pd.to_numeric(text, errors="coerce").notna().mean() > 0.5
        if not numeric and text.str.match(DMA_TIME).mean() > 0.5:
            fmt = "%d/%m/%Y %H:%M:%S"
            notes.append(f"{path.name}: {col} read as dd/mm/yyyy HH:MM:SS (truth.time.format)")
        elif not numeric and zone is None and not text.str.contains(
                r"(?:[Zz]|[+-]\d\d:?\d\d|UTC|GMT)$", regex=True).mean() > 0.5:
            fmt = "iso_utc"
            notes.append(f"{path.name}: {col} has no time zone: taken as UTC (AIS time is UTC; "
                         "truth.time.zone says another)")

    def numbers():
        return _numbers(series)

    values, fmt, ok, not_absolute = time_column(series, col, fmt, path, line, notes, numbers,
                                                zone, truth.time.ambiguous, prefix="truth.",
                                                utc_default=True)
    ok = ok & ~not_absolute
    if fmt in ("iso", "iso_utc") or is_pattern(fmt):
        ns = np.asarray(values, dtype=np.int64)
    elif fmt.startswith("unix_"):
        ns = np.where(ok, np.round(np.nan_to_num(np.asarray(values, float))
                                   * UNIX_SCALE_NS[fmt]), -1).astype(np.int64)
    else:
        median = float(np.median(np.asarray(values, float)[ok])) if ok.any() else float("nan")
        raise TruthError(f"truth={path}: {col} holds relative times (median {median:g}); AIS "
                         f"reports need UTC times (ISO-8601, a date and time of day, or Unix "
                         f"time from {UNIX_FROM_S:g} s; truth.time.format says how they are "
                         "written)")
    return np.where(ok & (ns >= UTC_FROM_NS), ns, -1)
