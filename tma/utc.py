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
from pathlib import Path

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

def time_column(series, col, fmt, path, line, notes, numbers, zone=None, ambiguous="refuse",
                prefix="", utc_default=False):
    """A table's column ``col`` of times (``series``, pandas), written as ``fmt``
    (``time.format``): ``(values, format, ok, not_absolute)``, the times as read (ns since 1970
    for ISO text, else the numbers), their format (``iso``/``iso_utc``, ``s``, ``rel_ms``...,
    ``unix_*``), which rows hold a readable time, and which hold a time that is not absolute
    where the others are (a 0 among Unix times, a 1970 stamp among UTC ones: a clock that was
    not set, never a relative clock). ``numbers()``: the column as float64, NaN where a cell is
    no number; ``line``: each row's line, ``path``: the table, for messages; what was found
    automatically goes into ``notes``. ``fmt`` may be a strptime pattern
    (``%d-%m-%y %H:%M``); ``zone`` (an IANA name, ``time.zone``) is the zone of times written
    without one, its daylight-saving changes resolved as ``ambiguous`` says (``local_ns``);
    ``prefix`` starts the options' names in messages (``truth.`` for the AIS);
    ``utc_default``: a pattern's times without a zone are UTC (AIS time), else refused
    without ``time.zone``."""
    import pandas as pd

    numeric = pd.api.types.is_numeric_dtype(series)  # true/false too: refused as numbers
    ns = None
    local = TimeZone(zone, ambiguous, col, path, line, notes, prefix, utc_default)
    if is_pattern(fmt):
        ns, ok = _pattern_times(series, fmt, local)
        early = ok & (ns < UTC_FROM_NS)
        return ns, fmt, ok, early if np.median(ns[ok]) >= UTC_FROM_NS else np.zeros_like(ok)
    if zone is not None and (numeric or pd.api.types.is_timedelta64_dtype(series)):
        raise InputError(f"{path}: {prefix}time.zone={zone} is the zone of times written as a "
                         f"date and time of day without one; column {col} holds numbers "
                         f"({series.dtype}): leave {prefix}time.zone unset")
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
        if getattr(series.dt, "tz", None) is None:  # local times (time.zone): to UTC
            ns = local.utc_ns(series.dt.as_unit("ns").array.asi8, ok,
                              series.astype(str).to_numpy())
        else:
            local.refuse_zoned(series.astype(str).to_numpy(), ok)
            ns = np.where(ok, series.dt.as_unit("ns").array.asi8, 0)
    elif fmt in ("iso", "iso_utc") or (fmt == "auto" and not numeric and _mostly_text(series)):
        ns, ok = _iso_times(series, col, fmt, path, line, notes, local)
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
    if fmt in ("iso", "iso_utc") or is_pattern(fmt):
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


def _no_pattern(text, line, col, path, prefix) -> InputError:
    """The refusal of a column of times none of which tma reads by itself."""
    return InputError(f"{path}: {col} '{text}' on line {line} is not a time tma reads by "
                      "itself (ISO-8601, Unix time): give the pattern it is written in, "
                      f"{prefix}time.format='%d-%m-%y %H:%M' say (strptime), and "
                      f"{prefix}time.zone=<IANA zone> for local times")


def _iso_times(series, col, fmt, path, line, notes, local) -> tuple[np.ndarray, np.ndarray]:
    """ISO-8601 texts as UTC ns (int64) and which rows hold one. A column whose times mostly
    have no zone is refused (unless ``iso_utc``, or ``time.zone`` names theirs): the times
    would be guessed; a few rows without one among zoned times are rows without a readable
    time."""
    import pandas as pd

    text = series.astype("str").str.strip()
    missing = series.isna().to_numpy() | (text == "").to_numpy()
    utc_word = text.str.contains(UTC_WORD, regex=True)
    if utc_word.any():  # "... 08:00:00 UTC": the zone Z, as loggers often write it
        text = text.str.replace(UTC_WORD, "Z", regex=True)
        notes.append(f"{path.name}: {col}: ' UTC' read as the zone Z")
    zoned = text.str.contains(ZONED, regex=True).to_numpy(dtype=bool)
    unzoned = ~zoned & ~missing
    if local.zone is not None:  # local times without a zone: the zone is time.zone's
        if fmt == "iso_utc":
            raise InputError(f"{path}: {local.prefix}time.format=iso_utc reads times without "
                             f"a zone as UTC and {local.prefix}time.zone={local.zone} as "
                             f"{local.zone}: give one of them")
        local.refuse_zoned(text.to_numpy(), zoned & ~missing)
        ns, ok = _parsed_iso(text, ~missing, missing, False, local)
        return local.utc_ns(ns, ok, text.to_numpy()), ok
    if fmt != "iso_utc" and unzoned.sum() * 2 >= (~missing).sum() and unzoned.any():
        k = int(np.argmax(unzoned))
        named = re.search(rf"{ZONE_NAME.pattern}$", text.iloc[k])
        if named:  # "CET", "EST": no offset (summer time?): the offset is the user's to say
            raise InputError(f"{path}: {col} '{text.iloc[k]}' on line {line[k]} names its zone "
                             f"({named.group(1)}), which is no offset: write it as one "
                             f"({text.iloc[k][:named.start(1)].rstrip()}+01:00, say) or Z for "
                             "UTC")
        if pd.to_datetime(text.where(~missing), format="ISO8601", utc=True,
                          errors="coerce").isna().all():  # no ISO-8601 at all: a pattern
            raise _no_pattern(text.iloc[k], line[k], col, path, local.prefix)
        raise InputError(f"{path}: {col} '{text.iloc[k]}' on line {line[k]} has no time zone: "
                         f"write times with one ({text.iloc[k]}Z for UTC), set "
                         f"{local.prefix}time.zone=<IANA zone> (Europe/Madrid) for local "
                         f"times, or set {local.prefix}time.format=iso_utc to read zone-less "
                         "times as UTC")
    if fmt == "iso_utc" and unzoned.any():
        notes.append(f"{path.name}: {col} without time zone read as UTC (time.format=iso_utc)")
    ns, ok = _parsed_iso(text, ~missing & (zoned | (fmt == "iso_utc")), missing, True, local)
    if fmt == "auto" and ok.any():
        notes.append(f"{path.name}: {col} read as ISO-8601 times (time.format=iso)")
    return np.where(ok, ns, 0), ok


def _parsed_iso(text, rows, missing, utc: bool, local) -> tuple[np.ndarray, np.ndarray]:
    """ISO-8601 ``text`` of ``rows`` as ns (UTC, or wall-clock times when not ``utc``) and
    which rows hold one; one line with an example when no row does."""
    import pandas as pd

    try:
        parsed = pd.to_datetime(text.where(rows), format="ISO8601", utc=utc, errors="coerce")
    except (ValueError, OverflowError) as exc:
        raise InputError(f"{local.path}: column {local.col}: not ISO-8601 times ({exc})"
                         ) from None
    ok = parsed.notna().to_numpy()
    if not ok.any() and (~missing).any():
        k = int(np.argmax(~missing))
        raise _no_pattern(text.iloc[k], local.line[k], local.col, local.path, local.prefix)
    return parsed.dt.as_unit("ns").array.asi8, ok


# -- times as people write them: a strptime pattern, a local zone --------------------------

AMBIGUOUS = ("refuse", "earliest", "latest")


def is_pattern(fmt) -> bool:
    """``time.format`` is a strptime pattern (``%d-%m-%y %H:%M``), not one of the names."""
    return isinstance(fmt, str) and "%" in fmt


def zone_problem(value) -> str | None:
    """What is wrong with ``time.zone`` (an IANA zone name), or None."""
    from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

    try:
        ZoneInfo(str(value))
    except (ZoneInfoNotFoundError, ValueError):
        return "no such IANA time zone"
    return None


YEAR_DIRECTIVES = ("%Y", "%y", "%G", "%c", "%x")  # strptime's directives that give a year


def pattern_problem(value) -> str | None:
    """What is wrong with a ``time.format`` pattern: one that formats a date back as itself
    (no % directive), that strftime cannot write, or that gives no year (the time of day
    alone)."""
    try:
        datetime(2001, 2, 3, 4, 5, 6).strftime(str(value))
    except ValueError as exc:
        return f"not a strptime pattern ({exc})"
    if not any(d in str(value) for d in YEAR_DIRECTIVES):
        return ("no year in it: strptime reads such times as on 1900-01-01, and a clock of "
                "the time of day wraps at midnight; write each time with its date and give "
                "the pattern of both ('%Y-%m-%d %H:%M:%S')")
    return None


class TimeZone:
    """The zone of a column's times written without one (``time.zone``: an IANA name, None:
    none given) and what a daylight-saving change makes of them (``time.ambiguous``):
    ``refuse`` a time of day the change repeats (autumn) or skips (spring), or read it as
    the ``earliest`` or ``latest`` of the instants it can mean (a skipped time: with the
    offset after the change, or before it). ``col``, ``path``, ``line``: for messages."""

    def __init__(self, zone, ambiguous, col, path, line, notes, prefix="", utc_default=False):
        self.zone, self.ambiguous, self.prefix = zone, ambiguous, prefix
        self.utc_default = utc_default
        self.col, self.path, self.line, self.notes = col, path, line, notes

    def refuse_zoned(self, text, zoned):
        """InputError for times that carry their own zone where ``time.zone`` is given."""
        if self.zone is not None and zoned.any():
            k = int(np.argmax(zoned))
            raise InputError(f"{self.path}: {self.prefix}time.zone={self.zone} is the zone of "
                             f"times written without one; {self.col} '{text[k]}' on line "
                             f"{self.line[k]} has one: leave {self.prefix}time.zone unset")

    def utc_ns(self, wall_ns, ok, text) -> np.ndarray:
        """UTC ns of wall-clock times (``wall_ns``: their ns as if UTC; rows ``ok`` hold
        one) in ``zone``; without a zone they must be UTC (InputError naming the option)."""
        import pandas as pd

        wall_ns = np.where(ok, wall_ns, 0)
        if self.zone is None:
            if ok.any() and not self.utc_default:
                k = int(np.argmax(ok))
                raise InputError(f"{self.path}: {self.col} '{text[k]}' on line {self.line[k]} "
                                 "has no time zone: set "
                                 f"{self.prefix}time.zone=<IANA zone> (Europe/Madrid; UTC) to "
                                 "say which")
            if ok.any():
                self.notes.append(f"{Path(str(self.path)).name}: {self.col} without time zone "
                                  "read as UTC")
            return wall_ns
        local = pd.Series(pd.to_datetime(wall_ns)).dt.tz_localize(
            self.zone, ambiguous="NaT", nonexistent="NaT")
        ns = local.dt.as_unit("ns").array.asi8.copy()
        changed = ok & local.isna().to_numpy()
        for k in np.flatnonzero(changed):
            ns[k] = self._changed(int(wall_ns[k]), text[k], self.line[k])
        self.notes.append(f"{Path(str(self.path)).name}: {self.col} read as local time in "
                          f"{self.zone} ({self.prefix}time.zone)"
                          + (f"; {int(changed.sum())} time(s) repeated or skipped by a "
                             f"daylight-saving change read as the {self.ambiguous} "
                             f"({self.prefix}time.ambiguous)" if changed.any() else ""))
        return np.where(ok, ns, 0)

    def _changed(self, wall_ns: int, text, line) -> int:
        """UTC ns of a wall time a daylight-saving change repeats or skips, by
        ``ambiguous``."""
        from zoneinfo import ZoneInfo

        zone = ZoneInfo(self.zone)
        wall = _UNIX_EPOCH.replace(tzinfo=None) + timedelta(microseconds=wall_ns // 1000)
        offsets = [wall.replace(tzinfo=zone, fold=f).utcoffset() for f in (0, 1)]
        instants = sorted(wall_ns - off // timedelta(microseconds=1) * 1000 for off in offsets)
        utc = datetime.fromtimestamp(instants[0] / 1e9, UTC)
        back = utc.astimezone(zone).replace(tzinfo=None)
        repeated = abs((back - wall) / timedelta(seconds=1)) < 1e-3
        if self.ambiguous == "refuse":
            what = ("repeated when the clocks went back (two instants)" if repeated else
                    "skipped when the clocks went forward (no such local time)")
            raise InputError(f"{self.path}: {self.col} '{text}' on line {line} is a time of "
                             f"day in {self.zone} {what}: set {self.prefix}time.ambiguous="
                             "earliest or latest to read it as the earlier or later instant")
        return instants[0] if self.ambiguous == "earliest" else instants[-1]


def _pattern_times(series, fmt, local: "TimeZone") -> tuple[np.ndarray, np.ndarray]:
    """Texts written as the strptime pattern ``fmt`` as UTC ns and which rows hold one; the
    zone from the pattern (``%z``) or ``local``; InputError with an example row when the
    pattern matches no row."""
    import pandas as pd

    text = series.astype("str").str.strip()
    missing = series.isna().to_numpy() | (text == "").to_numpy()
    zoned = "%z" in fmt or "%Z" in fmt
    try:
        parsed = pd.to_datetime(text.where(~missing), format=fmt, errors="coerce",
                                utc=zoned)
    except (ValueError, OverflowError) as exc:
        raise InputError(f"{local.path}: {local.prefix}time.format='{fmt}': not a pattern "
                         f"of column {local.col}'s times ({exc})") from None
    ok = parsed.notna().to_numpy()
    if not ok.any():
        k = int(np.argmin(missing)) if not missing.all() else 0
        raise InputError(f"{local.path}: {local.prefix}time.format='{fmt}' matches no time of "
                         f"column {local.col} (line {local.line[k]}: '{text.iloc[k]}'); write "
                         "the pattern as strptime does (%d-%m-%y %H:%M, %Y/%m/%d %H:%M:%S)")
    wall = parsed.dt.as_unit("ns").array.asi8
    if zoned:
        local.refuse_zoned(text.to_numpy(), ok)
        return np.where(ok, wall, 0), ok
    return local.utc_ns(wall, ok, text.to_numpy()), ok
