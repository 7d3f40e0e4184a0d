"""What every log reader returns and declares, and what a family asks of it.

A reader turns one file of one source kind (CSV, NMEA, ROS 2 MCAP, Foxglove MCAP, tma's own
MCAP) into flat arrays: own-platform fixes (``Navigation``) and/or per-contact values
(``Contacts``). Which value a contact carries is the family's to say, as an ``Observation``
(``bearings2d``: the bearing, in deg or rad, guarded against radians read as degrees);
``tma.sources.align`` then puts fixes and values on one time base and one local east-north
plane, and the family makes its logs from them. Each reader file declares its format
(``Reader``); the reading options are assembled from the declarations (``tma.sources.options``).

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

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from tma.errors import InputError, MissingFileError


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
    read, before they are aligned (None: none); ``direction``: the value is a direction
    clockwise from north (deg), which ``align`` turns from true north where it was taken onto
    its plane's north (``tma.maths.geo.north_on_plane_deg``)."""

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
    direction: bool = False

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
    zone_option: str = "time.zone"  # what sets the zone its times were written in

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
    # directions (an Observation.direction) from the north of the tangent plane at this
    # (lat, lon), as tma's own logs hold them; None: from true north where they were taken,
    # as a sensor measures them (align turns both onto its plane)
    plane_origin_deg: tuple[float, float] | None = None


@dataclass
class Recording:
    """What one file gave: own-platform fixes and/or contacts, the file's metadata records
    (MCAP; what it says of its sensor, for the family) and the rows it left out."""

    navigation: Navigation | None
    contacts: Contacts | None
    metadata: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)  # what was found automatically, for the log
    dropped: Dropped = field(default_factory=Dropped)
    platform: str | None = None  # the platform's name, where the input names one per row




class ReadLog(Protocol):
    """What a reader's ``read`` is (``Reader.read``), declared: the file at ``path`` read with
    a family's reading options (``options``, ``tma.sources.options.source_options``);
    ``navigation`` / ``contacts``: what is wanted from it; ``date_hint_ns``: UTC ns of the first
    contact value, for navigation that carries no date. Returns one ``Recording`` per own-ship
    (at least one), each with ``Navigation`` and/or ``Contacts`` as their docstrings say:
    arrays of one length each, fixes sorted by time, either local or geographic positions.
    ``read_source`` holds every reader's answer to it (``checked_recordings``), and
    ``tests/test_readers.py`` every registered reader's declaration."""

    def __call__(self, path: Path, options, *, navigation: bool, contacts: bool,
                 date_hint_ns: int | None = None) -> list[Recording]: ...


class ReaderContractError(TypeError):
    """A reader that does not do what ``Reader`` and ``ReadLog`` declare: a fault of the
    reader, not of the file it read."""


def read_signature_fault(read: Callable) -> str:
    """How ``read``'s parameters differ from ``ReadLog``'s ('' when they do not): the same
    names, in order, of the same kinds (``navigation``, ``contacts`` and ``date_hint_ns``
    keyword-only, ``date_hint_ns`` with a default)."""
    declared = list(inspect.signature(ReadLog.__call__).parameters.values())[1:]
    try:
        given = list(inspect.signature(read).parameters.values())
    except (TypeError, ValueError):
        return "read is not a function"
    shape = [(p.name, p.kind, p.default is inspect.Parameter.empty) for p in declared]
    if [(p.name, p.kind, p.default is inspect.Parameter.empty) for p in given] != shape:
        return (f"read{inspect.signature(read)} is not "
                f"read{inspect.signature(ReadLog.__call__).replace(parameters=declared)}")
    return ""


def _array_fault(what: str, arrays: dict, n: int) -> str:
    for name, a in arrays.items():
        if not isinstance(a, np.ndarray) or a.ndim < 1 or a.shape[0] != n:
            return f"{what}.{name} is not an array of {n} (one per time)"
    return ""


def _navigation_fault(nav) -> str:
    if not isinstance(nav, Navigation):
        return f"navigation is a {type(nav).__name__}, not a Navigation or None"
    if not isinstance(nav.t_s, np.ndarray) or nav.t_s.ndim != 1:
        return "navigation.t_s is not a 1-D array"
    local, geographic = nav.x_m is not None, nav.lat_deg is not None
    if local == geographic or (nav.y_m is not None) != local or (
            nav.lon_deg is not None) != geographic:
        return "navigation holds not exactly one of (x_m, y_m) and (lat_deg, lon_deg)"
    fault = _array_fault("navigation", {"x_m": nav.x_m, "y_m": nav.y_m} if local else
                         {"lat_deg": nav.lat_deg, "lon_deg": nav.lon_deg}, nav.t_s.size)
    if not fault and nav.lines is not None:
        fault = _array_fault("navigation", {"lines": nav.lines}, nav.t_s.size)
    if not fault and (np.diff(nav.t_s) < 0).any():
        fault = "navigation.t_s is not sorted by time"
    return fault


def _contacts_fault(c) -> str:
    if not isinstance(c, Contacts):
        return f"contacts is a {type(c).__name__}, not a Contacts or None"
    if not isinstance(c.t_s, np.ndarray) or c.t_s.ndim != 1:
        return "contacts.t_s is not a 1-D array"
    return _array_fault("contacts", {"track": c.track, "values": c.values}, c.t_s.size)


def checked_recordings(recordings, kind: str) -> list:
    """``recordings`` as reader ``kind`` returned them, if they are what ``ReadLog`` declares;
    else a ReaderContractError naming the reader and the first fault."""
    fault = ""
    if not isinstance(recordings, list) or not recordings:
        what = "an empty list" if isinstance(recordings, list) else type(recordings).__name__
        fault = f"read returned {what}, not a list of at least one Recording"
    for k, rec in enumerate(recordings if not fault else []):
        if not isinstance(rec, Recording):
            fault = f"recording {k} is a {type(rec).__name__}, not a Recording"
        elif rec.navigation is not None and (f := _navigation_fault(rec.navigation)):
            fault = f"recording {k}: {f}"
        elif rec.contacts is not None and (f := _contacts_fault(rec.contacts)):
            fault = f"recording {k}: {f}"
        elif not isinstance(rec.metadata, dict) or not isinstance(rec.notes, list) or \
                not isinstance(rec.dropped, Dropped):
            fault = f"recording {k}: metadata, notes or dropped of another type"
        if fault:
            break
    if fault:
        raise ReaderContractError(f"the {kind} reader does not keep its contract "
                                  f"(tma.sources.base.ReadLog): {fault}")
    return recordings


def _no_options(observation: Observation) -> dict:
    return {}


@dataclass(frozen=True)
class Reader:
    """A log format, as its reader file declares it (``READER`` in
    ``tma/sources/<file>.py``, the file listed once in ``tma.sources.READERS``). Everything
    else about formats is derived from these declarations: the ``format`` option's values,
    which reader reads a file, the reading options' groups, which options a kind of input
    reads, and the messages that name them.

    - ``kind``: the format's name (``format=<kind>``; the manifest's ``kind``);
    - ``name``: a file of it as messages call it (``a CSV table``);
    - ``extensions``: the endings of a file name that say the kind (``.csv``), lower case;
    - ``sniff(head)``: True when a file's first ``SNIFF_BYTES`` bytes are of this kind
      whatever its name (the MCAP magic, an NMEA sentence); None: the extension says it;
    - ``options(observation)``: the options only this kind reads, ``{group: dataclass}`` of
      ``tma.config.param`` fields (``csv``: ``{"csv": CsvFormat, ...}``); fields of one group
      declared by several readers are one group (``bearing.topic`` by MCAP,
      ``bearing.units`` by every kind, ``tma.sources.options``); a group's
      ``rules(self)``, if it has one, checks what relates its options;
    - ``read``: a ``ReadLog``, ``read(path, options, *, navigation, contacts, date_hint_ns)
      -> list[Recording]``; heavy libraries imported inside it, since every command imports
      the declarations (``tests/test_startup.py``);
    - ``selects_contacts`` / ``selects_navigation``: the options that name where the values
      and the own-ship are, for the message when none is found (``{role}``: the
      observation's role); None: a file of this kind holds none that tma reads (NMEA: no
      contacts)."""

    kind: str
    name: str
    extensions: tuple[str, ...]
    read: ReadLog
    sniff: Callable[[bytes], bool] | None = None
    options: Callable[[Observation], dict] = _no_options
    selects_contacts: str | None = None
    selects_navigation: str | None = None


SNIFF_BYTES = 4096  # the head of a file a reader's sniff sees


def file_head(path: Path, size: int, what: str) -> bytes:
    """The first ``size`` bytes of the file at ``path``; MissingFileError when there is none,
    InputError for a directory (``what``: what it should have been, ``a log file``)."""
    try:
        with open(path, "rb") as f:
            return f.read(size)
    except FileNotFoundError:
        raise MissingFileError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: a directory, not {what}") from None
