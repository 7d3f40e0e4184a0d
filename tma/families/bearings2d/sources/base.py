"""What every bearing-log reader returns, and the ingest options they read.

A reader turns one file of one source kind (CSV, NMEA, ROS 2 MCAP, Foxglove MCAP, tma's own
MCAP) into flat arrays: own-ship fixes (``Navigation``) and/or bearings (``Bearings``).
``assemble`` then puts both on one time base and one local east-north plane and makes the
``BearingsLog``s a dataset stores.

Conventions: times are float seconds since ``epoch_utc_ns`` (UTC nanoseconds since the Unix
epoch) when the source has absolute times, else seconds from an arbitrary zero with
``epoch_utc_ns = None``; bearings in degrees clockwise from north (readers convert radians
and direction vectors); positions either local (x east, y north, metres) or geographic
(latitude, longitude in degrees, WGS84).
"""

from dataclasses import dataclass, field, fields, is_dataclass

import numpy as np
from omegaconf import DictConfig, OmegaConf

from tma.config import validate
from tma.errors import ConfigError


@dataclass
class Navigation:
    """Own-ship fixes, sorted by time. Exactly one of (x_m, y_m) or (lat_deg, lon_deg) is set."""

    t_s: np.ndarray
    epoch_utc_ns: int | None
    source: str  # for messages: "file.mcap: /gps/fix (sensor_msgs/msg/NavSatFix)"
    x_m: np.ndarray | None = None
    y_m: np.ndarray | None = None
    lat_deg: np.ndarray | None = None
    lon_deg: np.ndarray | None = None

    @property
    def geographic(self) -> bool:
        return self.lat_deg is not None


@dataclass
class Bearings:
    """One row per bearing: time, contact and bearing (deg clockwise from north)."""

    t_s: np.ndarray
    epoch_utc_ns: int | None
    track: np.ndarray  # int64 ids, or str labels (object array) kept as labels in outputs
    bearing_deg: np.ndarray
    source: str
    # True when the units were stated (bearing.units, or radians by a name or units row): then
    # no guard against radians read as degrees; a name saying degrees does not count (a
    # mislabelled column of radians says the same)
    units_stated: bool = False


@dataclass
class Recording:
    """What one file gave: own-ship fixes and/or bearings, and what it says of its sensor."""

    navigation: Navigation | None
    bearings: Bearings | None
    sigma_deg: float | None = None  # the sensor's nominal noise when the file declares it
    notes: list[str] = field(default_factory=list)  # what was found automatically, for the log


@dataclass
class Columns:
    """CSV column names; None = our documented name or a common one found automatically."""

    time: str | None = None
    x: str | None = None
    y: str | None = None
    lat: str | None = None
    lon: str | None = None
    bearing: str | None = None
    track: str | None = None


@dataclass
class BearingSource:
    """Where the bearings are: an MCAP topic and a dotted field path (``data``, ``vector``,
    ``bearing_deg``), and their units (deg | rad; None = degrees unless the name says rad)."""

    topic: str | None = None
    field: str | None = None
    units: str | None = None

    def __post_init__(self):
        _one_of("bearing.units", self.units, (None, "deg", "rad"))


@dataclass
class OwnshipSource:
    topic: str | None = None  # None: found by its schema (NavSatFix, LocationFix, Odometry...)


DELIMITER_NAMES = {"comma": ",", "semicolon": ";", "tab": "\t", "\\t": "\t", "pipe": "|",
                   "space": " "}
DECIMAL_NAMES = {"dot": ".", "comma": ","}


@dataclass
class CsvFormat:
    """``delimiter``: one character or its name (comma, semicolon, tab, pipe, space); None:
    sniffed among ``,`` ``;`` tab. ``decimal``: ``.`` or ``,`` (or dot, comma); None: ``.``,
    or ``,`` when the delimiter is not a comma and the numbers are written ``12,5``."""

    delimiter: str | None = None
    decimal: str | None = None

    def __post_init__(self):
        if self.delimiter is not None:
            self.delimiter = DELIMITER_NAMES.get(self.delimiter, self.delimiter)
            if len(self.delimiter) != 1 or self.delimiter in "\"\r\n":
                raise ConfigError(f"csv.delimiter must be one character or one of "
                                  f"{', '.join(DELIMITER_NAMES)}, got '{self.delimiter}'")
        if self.decimal is not None:
            self.decimal = DECIMAL_NAMES.get(self.decimal, self.decimal)
            _one_of("csv.decimal", self.decimal, (None, ".", ",", "dot", "comma"))
            if self.decimal == self.delimiter:
                raise ConfigError(f"csv.decimal and csv.delimiter are both '{self.decimal}'")


TIME_FORMATS = ("auto", "s", "unix_s", "unix_ms", "unix_us", "unix_ns", "iso", "iso_utc")


@dataclass
class TimeFormat:
    """``auto``: numbers by magnitude (Unix seconds from 1e8, ms from 1e11, us from 1e14, ns
    from 1e17; smaller: relative seconds), text as ISO-8601 with a zone; ``s``: relative
    seconds; ``unix_s|ms|us|ns``: Unix time; ``iso``: ISO-8601 with a zone (``Z``,
    ``+01:00``); ``iso_utc``: ISO-8601, a time without zone taken as UTC."""

    format: str = "auto"

    def __post_init__(self):
        _one_of("time.format", self.format, TIME_FORMATS)


@dataclass
class NavLimits:
    max_extrapolation_s: float = 1.0  # a bearing further outside the nav span is dropped
    max_gap_s: float = 10.0  # a longer gap between fixes is reported

    def __post_init__(self):
        if not 0 <= self.max_extrapolation_s < 1e9:
            raise ConfigError(f"nav.max_extrapolation_s must be a number of seconds in "
                              f"[0, 1e9), got {self.max_extrapolation_s}")
        if not 0 < self.max_gap_s < 1e9:
            raise ConfigError(f"nav.max_gap_s must be a number of seconds in (0, 1e9), "
                              f"got {self.max_gap_s}")


@dataclass
class Origin:
    lat: float | None = None  # deg; None: the first own-ship fix
    lon: float | None = None

    def __post_init__(self):
        if (self.lat is None) != (self.lon is None):
            raise ConfigError("origin.lat and origin.lon go together: give both or neither")
        if self.lat is not None and not (-90 < self.lat < 90 and -180 <= self.lon <= 360):
            raise ConfigError(f"origin.lat must lie in (-90, 90) and origin.lon in [-180, 360] "
                              f"degrees, got {self.lat}, {self.lon}")


@dataclass
class SourceOptions:
    """The reading part of the ``ingest`` config (conf key in brackets)."""

    columns: Columns = field(default_factory=Columns)  # [columns.*]
    bearing: BearingSource = field(default_factory=BearingSource)  # [bearing.*]
    ownship: OwnshipSource = field(default_factory=OwnshipSource)  # [ownship.topic]
    csv: CsvFormat = field(default_factory=CsvFormat)  # [csv.*]
    time: TimeFormat = field(default_factory=TimeFormat)  # [time.format]
    nav: NavLimits = field(default_factory=NavLimits)  # [nav.*]
    origin: Origin = field(default_factory=Origin)  # [origin.*]


def _one_of(key: str, value, allowed):
    if value not in allowed:
        shown = ", ".join("null" if a is None else str(a) for a in allowed)
        raise ConfigError(f"{key} must be one of {shown}, got '{value}'")


GROUPS = tuple(f.name for f in fields(SourceOptions))  # the ingest config's reading groups


def option_keys(schema=SourceOptions, prefix="") -> list[str]:
    """Every dotted option key of ``schema`` (``columns.time``, ``nav.max_gap_s``, ...)."""
    keys = []
    for f in fields(schema):
        default = f.default_factory() if callable(f.default_factory) else f.default
        if is_dataclass(default):
            keys += option_keys(type(default), f"{prefix}{f.name}.")
        else:
            keys.append(f"{prefix}{f.name}")
    return keys


def unknown_option(key: str) -> str | None:
    """A one-line complaint if the dotted ``key`` (``columns.foo``) is under one of the
    reading groups but is not an option; None if it is one (or not under a group)."""
    if key.split(".")[0] not in GROUPS or key in option_keys() or key in GROUPS:
        return None
    group = key.split(".")[0]
    known = [k for k in option_keys() if k.startswith(group + ".")]
    return f"unknown option {key} (the {group} options: {', '.join(known)})"


def source_options(node) -> SourceOptions:
    """``SourceOptions`` from a config node (DictConfig, dict or None) holding some of the
    groups ``columns``, ``bearing``, ``ownship``, ``csv``, ``time``, ``nav``, ``origin``;
    an unknown key or a bad value is a ConfigError naming the key."""
    if isinstance(node, SourceOptions):
        return node
    if isinstance(node, DictConfig):
        node = OmegaConf.to_container(node, resolve=True)
    node = {group: OmegaConf.to_container(values, resolve=True)
            if isinstance(values, DictConfig) else values for group, values in (node or {}).items()}
    for group, values in node.items():
        if group not in GROUPS:
            raise ConfigError(f"unknown option {group} (known: {', '.join(GROUPS)})")
        if not isinstance(values, dict):
            raise ConfigError(f"{group} holds options ({group}.<name>=...), not a value: "
                              f"got {group}='{values}'")
        for key in values:
            complaint = unknown_option(f"{group}.{key}")
            if complaint:
                raise ConfigError(complaint)
    return validate(SourceOptions, node, "ingest")  # types, finiteness, then the ranges
