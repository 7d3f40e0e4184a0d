"""What a time is, in one place: UTC instants, their text, and the clocks logs keep.

tma counts absolute time as UTC nanoseconds since the Unix epoch (``int``; int64 arrays), so
that MCAP log times (uint64 ns) hold it exactly. The rules every reader and config follows:

- text is a UTC instant only with a zone (``Z``, ``+02:00``, ``-0500``: ``ZONE``); a time
  without one is refused unless the user says it is UTC (``time.format=iso_utc``);
- a number of seconds is Unix time from ``UNIX_FROM_S`` (1973) on, a relative time below it
  (CSV tables, told apart by magnitude); a log stamp in ns is UTC from ``UTC_FROM_NS`` (2000)
  on, a relative clock (simulation time, older logs) below it (MCAP);
- an instant lies between 1970 and 2200 (``MAX_EPOCH_NS``), and a log spans at most
  ``MAX_SPAN_S`` (int64 nanoseconds: about 292 years).

Used by the scenario configs (``epoch_utc``), the log writers and readers
(``tma.io.mcap_log``) and the recorded-log readers (``tma.sources``), whose tables' time
columns are read here too (``time_column``, ``table_seconds``: ``time.format``; pandas is
imported when a table is read).
"""

import re
from datetime import UTC, datetime, timedelta

import numpy as np

from tma.errors import ConfigError, InputError

ZONE = r"(?:[Zz]|[+-]\d\d(?::?\d\d)?)"  # what makes a time of day an instant
ZONED = rf"\d\d:\d\d(?::\d\d(?:[.,]\d+)?)?\s*{ZONE}\s*$"  # a text ending in a zoned time
_ISO_UTC = re.compile(r"(\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(?::\d{2})?)(?:[.,](\d{1,9}))?"
                      rf"({ZONE})", re.IGNORECASE)
_UNIX_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
MAX_EPOCH_NS = 7_258_118_400 * 10**9  # 2200-01-01: leaves log_time (uint64 ns) 350 years
MAX_SPAN_S = 9.2e9  # a log's span: nanoseconds in 64 bits hold about 292 years
MAX_NS = 9.2e18  # int64 nanoseconds: +-292 years around 1970
UNIX_FROM_S = 1e8  # seconds: 1973; smaller numbers of seconds are relative times
UTC_FROM_NS = 946_684_800 * 10**9  # 2000-01-01T00:00:00Z: earlier stamps are a relative clock
UNIX_SCALE_NS = {"unix_s": 10**9, "unix_ms": 10**6, "unix_us": 10**3, "unix_ns": 1}
# Unix time told from a plain number by its magnitude: ns from 1e17, us from 1e14, ...
UNIX_MAGNITUDE = ((1e17, "unix_ns"), (1e14, "unix_us"), (1e11, "unix_ms"),
                  (UNIX_FROM_S, "unix_s"))
UTC_WORD = r"(?i)(?<=\d)\s*(?:UTC|GMT)$"  # a time of day ending in the word UTC: zone Z
ZONE_NAME = re.compile(r"\d\s*([A-Za-z]{2,5})")  # ... ending in a zone's name (CET, EST)


def parse_utc(text) -> int:
    """An ISO-8601 time with a zone (``2026-01-01T00:00:00Z``, ``...T02:00:00.25+02:00``) as
    UTC nanoseconds since the Unix epoch, exact to the nanosecond; between 1970 and 2200.
    Raises ValueError saying what is wrong."""
    match = _ISO_UTC.fullmatch(text.strip()) if isinstance(text, str) else None
    if match is None:
        raise ValueError(f"'{text}' is not an ISO-8601 time with a zone "
                         "(e.g. 2026-01-01T00:00:00Z or 2026-01-01T01:00:00+01:00)")
    base, fraction, zone = match.groups()
    try:
        when = datetime.fromisoformat(base.replace(" ", "T")
                                      + ("+00:00" if zone.upper() == "Z" else zone))
    except ValueError as exc:
        raise ValueError(f"'{text}' is not a valid time ({exc})") from None
    ns = (when - _UNIX_EPOCH) // timedelta(seconds=1) * 10**9 + int((fraction or "").ljust(9, "0"))
    if not 0 <= ns < MAX_EPOCH_NS:
        raise ValueError(f"'{text}' is not between 1970 and 2200")
    return ns


def format_utc(ns: int) -> str:
    """UTC nanoseconds since the Unix epoch as ISO-8601 (``2026-01-01T00:20:00.5Z``)."""
    seconds, nanos = divmod(int(ns), 10**9)
    text = (_UNIX_EPOCH + timedelta(seconds=seconds)).strftime("%Y-%m-%dT%H:%M:%S")
    return text + (f".{nanos:09d}".rstrip("0") if nanos else "") + "Z"


def config_epoch_ns(value, where: str, key: str = "epoch_utc") -> int:
    """A config's ``epoch_utc`` (UTC of t = 0) in ns; ConfigError naming the key otherwise."""
    try:
        return parse_utc(value)
    except ValueError as exc:
        raise ConfigError(f"{where}: {key}: {exc}") from None


def stamp_text(t_ns: int) -> str:
    """A log stamp for messages: ISO-8601 on the UTC clock, ``t = ... s`` on a relative one."""
    return format_utc(t_ns) if t_ns >= UTC_FROM_NS else f"t = {t_ns / 1e9!r} s"


# -- a table's column of times (CSV, DataFrames: tma.sources.table) ---------------------------

def time_column(series, col, fmt, path, line, notes, numbers):
    """A table's column ``col`` of times (``series``, pandas), written as ``fmt``
    (``time.format``): ``(values, format, ok, not_absolute)``, the times as read (ns since 1970
    for ISO text, else the numbers), their format (``iso``/``iso_utc``, ``s``, ``rel_ms``...,
    ``unix_*``), which rows hold a readable time, and which hold a time that is not absolute
    where the others are (a 0 among Unix times, a 1970 stamp among UTC ones: a clock that was
    not set, never a relative clock). ``numbers()``: the column as float64, NaN where a cell is
    no number; ``line``: each row's line, ``path``: the table, for messages; what was found
    automatically goes into ``notes``."""
    import pandas as pd

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
        ok = series.notna().to_numpy()  # a DataFrame's UTC times, exact to the ns
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
        values = numbers()
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


def table_seconds(values, fmt, col, path, line) -> tuple[np.ndarray, int | None]:
    """Seconds (float64) since ``epoch_utc_ns`` (absolute times) or relative (epoch None), of
    times as ``time_column`` read them (every one usable)."""
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
    import pandas as pd

    sample = series.dropna().astype(str).head(1000)
    numeric = pd.to_numeric(sample, errors="coerce").notna().mean() if len(sample) else 0
    return numeric < 0.5


def _iso_times(series, col, fmt, path, line, notes) -> tuple[np.ndarray, np.ndarray]:
    """ISO-8601 texts as UTC ns (int64) and which rows hold one. A column whose times mostly
    have no zone is refused (unless ``iso_utc``): the times would be guessed; a few rows
    without one among zoned times are rows without a readable time."""
    import pandas as pd

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
