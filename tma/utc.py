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
(``tma.io.mcap_log``) and the recorded-log readers (``tma.sources``).
"""

import re
from datetime import UTC, datetime, timedelta

from tma.errors import ConfigError

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
