"""What every log reader returns, what a family asks of it, and the reading options.

A reader turns one file of one source kind (CSV, NMEA, ROS 2 MCAP, Foxglove MCAP, tma's own
MCAP) into flat arrays: own-platform fixes (``Navigation``) and/or per-contact values
(``Contacts``). Which value a contact carries is the family's to say, as an ``Observation``
(``bearings2d``: the bearing, in deg or rad, guarded against radians read as degrees);
``tma.sources.align`` then puts fixes and values on one time base and one local east-north
plane, and the family makes its logs from them.

Bad rows (``bad_rows=drop|fail``): a row whose time, value or own-ship position is missing or
unreadable, a stamp not absolute among absolute ones, a fix flagged "no fix" or far off the
rest is left out and counted per reason (``Dropped``: how many, and where the first few are:
file line numbers or message times); under ``fail`` the first such row refuses the file in one
line instead (fixes the receiver itself flags as "no fix" are left out under either policy).

Conventions: times are float seconds since ``epoch_utc_ns`` (UTC nanoseconds since the Unix
epoch) when the source has absolute times, else seconds from an arbitrary zero with
``epoch_utc_ns = None`` (``tma.utc``); values in the observation's first unit (readers
convert the others, and direction vectors when the observation takes them); positions either
local (x east, y north, metres) or geographic (latitude, longitude in degrees, WGS84).
"""

import datetime
import functools
from collections.abc import Callable
from dataclasses import MISSING as MISSING_FACTORY
from dataclasses import dataclass, field, fields, is_dataclass, make_dataclass
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

from tma.config import Form, Params, describe, param, validate
from tma.errors import ConfigError, InputError
from tma.utc import parse_utc


@dataclass(frozen=True)
class Unit:
    """A unit an observation may come in: its name (``deg``), its words (``degrees``), what
    else a units row may call it, the conversion to the observation's first unit, and the
    largest magnitude a value may have in it (with that range as text, for messages)."""

    name: str
    words: str
    aliases: tuple[str, ...]
    to_first: Callable
    limit: float
    range_text: str


@dataclass(frozen=True)
class Observation:
    """The value a family reads for each contact, as the readers need to find and check it.

    ``role``: its name in options and messages (``bearing``: ``columns.bearing``, the option
    group ``bearing.topic|field|units``); ``plural``: for messages (``bearings``);
    ``column``: tma's own column name, ``columns``: the names a table may give it and
    ``fields``: the MCAP message fields that may hold it (both in order of preference);
    ``units``: the first is the one the family computes in (a name ending in another unit's
    ``_<name>`` states that unit); ``from_vector``: the value of a direction vector (x east,
    y north), None if the observation is no direction, and ``vector_rule`` that rule as text
    (``atan2(x, y)``); ``topic`` and ``schema``: the topic
    and tma schema of the family's own logs (messages ``{t_s, track_id, <column>}``);
    ``guard(recordings, options, where)``: a check of the values of all the recordings once
    read, before they are aligned (None: none)."""

    role: str
    plural: str
    column: str
    columns: tuple[str, ...]
    fields: tuple[str, ...]
    units: tuple[Unit, ...]
    from_vector: Callable | None = None
    vector_rule: str = ""
    topic: str | None = None
    schema: str | None = None
    guard: Callable | None = None

    def unit(self, name: str) -> Unit:
        return next(u for u in self.units if u.name == name)

    def check_range(self, values, unit: Unit, where: str, place=None) -> None:
        """InputError when a value lies outside ``unit``'s range: the first such value (at
        ``where``, ``place(k)`` saying where value k is, e.g. its line) and the
        ``<role>.units`` setting that would read it, for every reader alike."""
        outside = np.abs(values) > unit.limit
        if not outside.any():
            return
        k = int(np.argmax(outside))
        if unit is self.units[0]:
            others = ", ".join(f"{self.role}.units={u.name}" for u in self.units[1:])
            why = f"{self.plural} must be in {unit.words} (or set {others})"
        else:
            why = (f"{self.plural} in {unit.words} were stated ({self.role}.units={unit.name}"
                   f" or the name), but this is no value in {unit.words}: set "
                   f"{self.role}.units={self.units[0].name} if they are in "
                   f"{self.units[0].words}")
        raise InputError(f"{where} {values[k]:g}{place(k) if place else ''} is outside "
                         f"{unit.range_text}; {why}")

    def unit_of_name(self, name: str) -> Unit | None:
        """The unit a column or field name ends in (``bearing_rad``), other than the first
        (a name saying the first unit states nothing: a mislabelled column says it too)."""
        return next((u for u in self.units[1:] if name.lower().endswith(f"_{u.name}")), None)


class Caution(str):
    """A note that may be a mistake in the log (ids alike but written differently): the log
    shows it as a warning; the manifest keeps it with the other notes."""


BAD_ROWS = ("drop", "fail")
NAMED = 5  # places named per reason: the first few


@dataclass
class Dropped:
    """Rows left out, per reason: ``{reason: {"count": n, "first": [place, ...]}}``, the
    places (``line 12``, or a message's time) of the first ``NAMED``. ``policy``: what
    ``drop`` does with a bad row: leave it out (``drop``) or refuse the file (``fail``)."""

    policy: str = "drop"
    reasons: dict = field(default_factory=dict)

    def drop(self, bad, reason: str, places: Callable, refusal: str) -> np.ndarray:
        """The rows to keep, ``~bad``; the bad ones counted under ``reason``. ``places``:
        row indices -> their places (texts); ``refusal``: the one line under
        ``bad_rows=fail`` (the places and the option are appended)."""
        bad = np.asarray(bad, dtype=bool)
        if not bad.any():
            return ~bad
        rows = np.flatnonzero(bad)
        named = [str(p) for p in places(rows[:NAMED])]
        if self.policy == "fail":
            raise InputError(f"{refusal} ({', '.join(named)}); bad_rows=drop leaves such rows "
                             "out")
        self.add(reason, rows.size, named)
        return ~bad

    def add(self, reason: str, count: int, named: list[str]):
        """Count ``count`` rows left out under ``reason`` whatever the policy."""
        entry = self.reasons.setdefault(reason, {"count": 0, "first": []})
        entry["count"] += int(count)
        entry["first"] = (entry["first"] + list(named))[:NAMED]

    def merge(self, other: "Dropped"):
        for reason, entry in other.reasons.items():
            self.add(reason, entry["count"], entry["first"])

    @property
    def count(self) -> int:
        return sum(e["count"] for e in self.reasons.values())

    def record(self) -> dict:
        """For the manifest: the policy, the total and each reason's count and places."""
        return {"policy": self.policy, "count": self.count, "reasons": self.reasons}

    def text(self) -> str:
        """``3 with bearing missing or not a number (line 12, line 40, ...); 1 with ...``."""
        return "; ".join(f"{e['count']} with {reason} ({', '.join(e['first'])}"
                         f"{', ...' if e['count'] > len(e['first']) else ''})"
                         for reason, e in self.reasons.items())


def line_places(lines: np.ndarray) -> Callable:
    """Row indices -> ``line N`` (file line numbers of the rows)."""
    return lambda rows: [f"line {n}" for n in lines[rows]]


@dataclass
class Navigation:
    """Own-platform fixes, sorted by time. Exactly one of (x_m, y_m) or (lat_deg, lon_deg) is
    set. ``lines``: each fix's line in its file, when it has lines (a table, NMEA), else
    ``topic`` (MCAP), to name a fix in messages."""

    t_s: np.ndarray
    epoch_utc_ns: int | None
    source: str  # for messages: "file.mcap: /gps/fix (sensor_msgs/msg/NavSatFix)"
    x_m: np.ndarray | None = None
    y_m: np.ndarray | None = None
    lat_deg: np.ndarray | None = None
    lon_deg: np.ndarray | None = None
    lines: np.ndarray | None = None
    topic: str | None = None  # the MCAP topic, for messages

    @property
    def geographic(self) -> bool:
        return self.lat_deg is not None


@dataclass
class Contacts:
    """One row per observation: time, contact and value (in the observation's first unit)."""

    t_s: np.ndarray
    epoch_utc_ns: int | None
    track: np.ndarray  # int64 ids, or str labels (object array) kept as labels in outputs
    values: np.ndarray
    source: str
    # True when the units were stated (an option, or a name or units row naming a unit other
    # than the first): a family's guard then trusts them
    units_stated: bool = False


@dataclass
class Recording:
    """What one file gave: own-platform fixes and/or contacts, the file's metadata records
    (MCAP; what it says of its sensor, for the family) and the rows it left out."""

    navigation: Navigation | None
    contacts: Contacts | None
    metadata: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)  # what was found automatically, for the log
    dropped: Dropped = field(default_factory=Dropped)


# -- the reading options (conf/ingest.yaml) ----------------------------------------------------
# Each option is a ``param``: its default, its doc (with units) and what it allows, in one
# place; ``check_params`` checks them all (one line naming the key, the value and what is
# allowed) and ``python -m tma.options ingest`` lists them. The rules between options stay as
# code (``ReadingOptions.__post_init__``).

POSITION_ROLES = ("time", "x", "y", "lat", "lon")  # table columns besides value and track
COLUMN_DOCS = {  # what each column of a table holds (the observation's is the family's)
    "time": "the times (relative s, Unix time or ISO-8601: time.format)",
    "x": "own-ship's position east (m)", "y": "own-ship's position north (m)",
    "lat": "own-ship's latitude (deg, WGS84)", "lon": "own-ship's longitude (deg, WGS84)",
    "track": "the contact of each row (an integer id, or a label kept as written; a table "
             "without one holds one contact)"}
FOUND = "; null: tma's name or a common one, found automatically (any case)"


def _topics_problem(value) -> str | None:
    entries = list(value) if isinstance(value, list | tuple) else [value]
    fine = entries and all(isinstance(e, str | int | float) and not isinstance(e, bool)
                           and str(e).strip() for e in entries)
    return None if fine else ""


TOPICS = Form("a topic, a pattern or a list of them", _topics_problem)


class ContactSource:
    """Where the values are in an MCAP log: ``topic`` (a topic, a pattern or a list of them),
    ``field`` and ``units``; a family's options declare them in its observation's words
    (``options_schema``)."""

    topic: Any
    field: str | None
    units: str | None

    @property
    def topics(self) -> list[str] | None:
        """The topics or patterns given, as a list; None when none is."""
        return None if self.topic is None else (
            list(self.topic) if isinstance(self.topic, list) else [self.topic])


@dataclass
class OwnshipSource:
    """Where the own-ship's fixes are in an MCAP log (``ownship.*``)."""

    topic: str | None = param(None, "MCAP topic of the own-ship's fixes; null: found by its "
                              "schema (NavSatFix, LocationFix, Odometry, PoseStamped...)")


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


TIME_FORMATS = ("auto", "s", "unix_s", "unix_ms", "unix_us", "unix_ns", "iso", "iso_utc")


def _utc_problem(value) -> str | None:
    try:
        parse_utc(str(value))
    except ValueError as exc:  # "'...' is not a valid time (...)": what is wrong, if more
        return "" if "ISO-8601" in str(exc) else str(exc).rpartition("' is ")[2]
    return None


def _date_problem(value) -> str | None:
    try:
        datetime.date.fromisoformat(str(value))
    except ValueError:
        return ""
    return None if len(str(value)) == 10 else ""


@dataclass
class TimeFormat:
    """How a table's times are written, and when a relative log starts (``time.*``)."""

    format: str = param("auto", "how the times are written: auto: numbers by magnitude (Unix "
                        "s from 1e8, ms from 1e11, us from 1e14, ns from 1e17; smaller: relative "
                        "s), text as ISO-8601 with a zone; s: relative seconds; unix_s|ms|us|ns: "
                        "Unix time; iso: ISO-8601 with a zone (Z, +01:00); iso_utc: ISO-8601, a "
                        "time without zone taken as UTC", choices=TIME_FORMATS)
    start_utc: str | None = param(
        None, "the UTC of time 0 of a log of relative times, which makes it absolute; null: "
        "such a log stays undated",
        form=Form("an ISO-8601 time with a zone (e.g. 2026-01-01T08:00:00Z or "
                  "2026-01-01T09:00:00+01:00)", _utc_problem))

    @property
    def start_ns(self) -> int | None:
        return None if self.start_utc is None else parse_utc(str(self.start_utc))


@dataclass
class NmeaOptions:
    """What NMEA navigation does not say (``nmea.*``)."""

    date: str | None = param(None, "the UTC date of NMEA GGA fixes that no RMC sentence dates; "
                             "null: from RMC, else from the values' absolute times",
                             form=Form("a date YYYY-MM-DD", _date_problem))


@dataclass
class NavLimits:
    """What own-ship's navigation may do (``nav.*``)."""

    max_extrapolation_s: float = param(1.0, "a value further than this (s) outside the "
                                       "own-ship's fixes is dropped", "[0, 1e9)")
    max_gap_s: float = param(10.0, "a gap between own-ship's fixes longer than this (s) is "
                             "reported", "(0, 1e9)")
    max_speed_m_s: float = param(50.0, "own-ship never moves faster (m/s): a fix farther off "
                                 "its neighbours is an outlier", "(0, 1e5)")


@dataclass
class Origin:
    """The local east-north plane's origin (``origin.*``)."""

    lat: float | None = param(None, "latitude (deg, WGS84) of the local east-north plane's "
                              "origin; null: the first own-ship fix", "(-90, 90)")
    lon: float | None = param(None, "longitude (deg, WGS84) of the origin (with lat)",
                              "[-180, 360]")
    max_distance_km: float = param(100.0, "a given origin lies at most this far (km) from an "
                                   "own-ship fix", "(0, 20000)")


class ReadingOptions(Params):
    """Base of a family's ``SourceOptions`` (``options_schema``): the groups ``columns``,
    ``<role>`` (the observation's ``ContactSource``), ``ownship``, ``csv``, ``time``, ``nmea``,
    ``nav``, ``origin`` and the option ``bad_rows``. ``observation`` is the family's;
    ``contact`` its group. Every option's declared type and values are checked first
    (``Params``, keys as the command line writes them), then the rules between options; the
    names of delimiters and decimal marks become the characters, a topic's number its text."""

    observation: Observation

    @property
    def where(self) -> str:
        return ""  # the keys say it: csv.delimiter, nav.max_gap_s

    @property
    def contact(self) -> ContactSource:
        return getattr(self, self.observation.role)

    def column(self, role: str) -> str | None:
        return getattr(self.columns, role)

    def __post_init__(self):
        super().__post_init__()
        topic = self.contact.topic
        if topic is not None:
            self.contact.topic = ([str(e) for e in topic] if isinstance(topic, list | tuple)
                                  else str(topic))
        csv = self.csv
        csv.delimiter = DELIMITER_NAMES.get(csv.delimiter, csv.delimiter)
        csv.decimal = DECIMAL_NAMES.get(csv.decimal, csv.decimal)
        if csv.decimal is not None and csv.decimal == csv.delimiter:
            raise ConfigError(f"csv.decimal and csv.delimiter are both '{csv.decimal}'")
        if (self.origin.lat is None) != (self.origin.lon is None):
            raise ConfigError("origin.lat and origin.lon go together: give both or neither")

    def dropped(self) -> Dropped:
        """A new count of the rows left out, under this policy."""
        return Dropped(self.bad_rows)


@functools.cache
def options_schema(observation: Observation) -> type:
    """The reading options (a dataclass) of a family reading ``observation``: its column
    under ``columns`` and its group named by its role (``bearing.topic|field|units``), their
    docs in its words."""
    role, plural, units = observation.role, observation.plural, observation.units
    docs = {**COLUMN_DOCS, role: f"the {plural} ({' or '.join(u.name for u in units)}: "
                                 f"{role}.units)"}
    columns = make_dataclass("Columns", [(r, str | None, param(None, f"column of {docs[r]}"
                                                              f"{FOUND}"))
                                         for r in (*POSITION_ROLES, role, "track")])
    columns.__doc__ = ("Table column names; None = tma's name or a common one found "
                       "automatically.")
    source = make_dataclass(f"{role.title()}Source", [
        ("topic", Any, param(None, f"MCAP topic(s) of the {plural}: a topic, a pattern "
                                   "(fnmatch: /sonar/contact/*) or a list of them; each topic "
                                   "is a contact (named by its topic) unless its messages "
                                   f"name contacts (track_id); null: {observation.topic} or "
                                   "the family's schema", form=TOPICS)),
        ("field", str | None, param(None, f"dotted field path of the {role} in its messages; "
                                          f"null: the first of {', '.join(observation.fields)} "
                                          "found")),
        ("units", str | None, param(None, f"units of the {plural}: "
                                          f"{', '.join(f'{u.name} ({u.words})' for u in units)};"
                                          f" null: {units[0].name} unless a column's or field's "
                                          "name or a units row says another",
                                    choices=(None, *(u.name for u in units))))],
        bases=(ContactSource,))
    groups = [("columns", columns, field(default_factory=columns)),
              (role, source, field(default_factory=source)),
              ("ownship", OwnshipSource, field(default_factory=OwnshipSource)),
              ("csv", CsvFormat, field(default_factory=CsvFormat)),
              ("time", TimeFormat, field(default_factory=TimeFormat)),
              ("nmea", NmeaOptions, field(default_factory=NmeaOptions)),
              ("nav", NavLimits, field(default_factory=NavLimits)),
              ("origin", Origin, field(default_factory=Origin)),
              ("bad_rows", str, param("drop", "drop: a row with a missing or unreadable value, "
                                      "time or fix, or a fix off the track, is left out and "
                                      "counted (log line, manifest); fail: the first such row "
                                      "refuses the file", choices=BAD_ROWS))]  # a value
    return make_dataclass("SourceOptions", groups, bases=(ReadingOptions,),
                          namespace={"observation": observation})


KIND_NAMES = {"csv": "a CSV table", "nmea": "an NMEA file", "mcap": "an MCAP log"}
KIND_OPTIONS = {  # options (or groups) that only some kinds of input read
    "columns": ("csv",), "csv": ("csv",), "time.format": ("csv",), "ownship.topic": ("mcap",),
    "nmea": ("nmea",)}


def inapplicable(options, kinds: dict[str, str]) -> str | None:
    """A one-line complaint if an option is set that no file of ``kinds`` (``{path: kind}``)
    reads (``bearing.topic`` on a CSV table, ``nmea.date`` without NMEA); None otherwise."""
    role = options.observation.role
    only = {**KIND_OPTIONS, f"{role}.topic": ("mcap",), f"{role}.field": ("mcap",)}
    given = _set_options(options)
    for key, value in given.items():
        scope = only.get(key) or only.get(key.split(".")[0])
        if scope is None or any(kind in scope for kind in kinds.values()):
            continue
        path, kind = next(iter(kinds.items()))
        shown = ", ".join(map(str, value)) if isinstance(value, list) else value
        readers = " or ".join(k.upper() for k in scope)
        return (f"{key}={shown} does not apply to {path} ({KIND_NAMES[kind]}): it is an "
                f"option of {readers} input; leave it unset")
    return None


def _set_options(options) -> dict:
    """The dotted options whose value is not the default."""
    out = {}
    for f in fields(options):
        value = getattr(options, f.name)
        if not is_dataclass(value):
            continue
        default = type(value)()
        for g in fields(value):
            if getattr(value, g.name) != getattr(default, g.name):
                out[f"{f.name}.{g.name}"] = getattr(value, g.name)
    return out


def groups(observation: Observation) -> tuple[str, ...]:
    """The reading options' top-level keys of the ingest config: the groups (``columns``,
    ``bearing``, ``ownship``...) and the options of their own (``bad_rows``)."""
    return tuple(f.name for f in fields(options_schema(observation)))


def _scalar(observation: Observation, key: str) -> bool:
    """True for a top-level option that is a value, not a group (``bad_rows``)."""
    f = next(f for f in fields(options_schema(observation)) if f.name == key)
    return f.default_factory is MISSING_FACTORY


def unknown_option(key: str, observation: Observation) -> str | None:
    """A one-line complaint if the dotted ``key`` (``columns.foo``) is under one of the
    reading groups but is not an option; None if it is one (or not under a group)."""
    keys = [row[0] for row in describe(options_schema(observation))]  # dotted keys
    group = key.split(".")[0]
    if group not in groups(observation) or key in keys or key == group:
        return None
    if _scalar(observation, group):
        return f"unknown option {key}: {group} is one value ({group}=...)"
    known = [k for k in keys if k.startswith(group + ".")]
    return f"unknown option {key} (the {group} options: {', '.join(known)})"


def source_options(node, observation: Observation):
    """The reading options from a config node (DictConfig, dict or None) holding some of the
    groups; an unknown key or a bad value is a ConfigError naming the key."""
    schema = options_schema(observation)
    if isinstance(node, schema):
        return node
    if isinstance(node, DictConfig):
        node = OmegaConf.to_container(node, resolve=True)
    node = {group: OmegaConf.to_container(values, resolve=True)
            if isinstance(values, DictConfig) else values for group, values in (node or {}).items()}
    known = groups(observation)
    for group, values in node.items():
        if group not in known:
            raise ConfigError(f"unknown option {group} (known: {', '.join(known)})")
        if _scalar(observation, group):
            continue
        if not isinstance(values, dict):
            raise ConfigError(f"{group} holds options ({group}.<name>=...), not a value: "
                              f"got {group}='{values}'")
        for key in values:
            complaint = unknown_option(f"{group}.{key}", observation)
            if complaint:
                raise ConfigError(complaint)
    return validate(schema, node, "")  # types, finiteness, the declared values, the rules
