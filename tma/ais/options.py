"""The ``truth.*`` options of ``ingest`` (a recorded log scored against the AIS of its trial)
and the errors a truth file causes.

``truth=FILE`` on the command line is ``truth.file=FILE`` (``shorthand``), so that
``truth.match={T1:235031617}`` and the other keys sit beside it in one group. In Python,
``tma.read_log(path, truth="ais.csv")`` or ``truth={"file": ..., "match": {...}}``.
"""

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from tma.config import Form, Params, param, to_plain
from tma.errors import ConfigError, InputError
from tma.sources.csv_table import TIME_FORMAT, ZONE, CsvFormat
from tma.utc import AMBIGUOUS

FIT_SIGMAS = 3.0  # a ship fits when its RMS bearing difference is within this many sigma
MIN_FIT_DEG = 0.1  # ... and never needs to fit closer than this (sigma 0, or tiny)


class TruthError(InputError, ValueError):
    """A truth file or match that cannot give the truth: one line for the user; a
    ``ValueError`` for pandas users."""


class TruthFileNotFound(InputError, FileNotFoundError):
    """``truth.file`` names no file."""


def _match_problem(value) -> str | None:
    """What is wrong with a ``truth.match`` value ('' when the form says it), or None."""
    if not isinstance(value, dict) or not value:
        return ""
    for contact, mmsi in value.items():
        text = str(mmsi).strip()
        if isinstance(mmsi, bool) or not text.isdigit() or not 10**6 <= int(text) < 10**9:
            return f"contact {contact}'s MMSI {mmsi!r} is not a whole number of 7 to 9 digits"
    return None


MATCH = Form("a map {contact: MMSI} (truth.match={T1:235031617}), MMSIs of 7 to 9 digits",
             _match_problem)


SOG_UNITS = {"kn": 1852.0 / 3600.0, "m_s": 1.0, "km_h": 1.0 / 3.6}  # to m/s


def _column(role: str, found: str):
    return param(None, f"the AIS table's column of {role}; null: found by its name ({found}), "
                 "any case")


@dataclass
class AisColumns:
    """Which column of an AIS table (CSV, Parquet) holds what (``truth.columns.*``)."""

    time: str | None = _column("the reports' times", "Timestamp, BaseDateTime, Time...")
    mmsi: str | None = _column("the MMSI", "MMSI, UserID...")
    lat: str | None = _column("the latitude (deg)", "Latitude, LAT, lat_deg...")
    lon: str | None = _column("the longitude (deg)", "Longitude, LON, lon_deg...")
    sog: str | None = _column("the speed over ground (truth.sog_units)", "SOG, SOG_knots...")
    cog: str | None = _column("the course over ground (deg)", "COG, COG_degrees...")


@dataclass
class AisTime:
    """How an AIS table's times are written (``truth.time.*``): as the logs' (``time.*``),
    but a time without a zone is UTC, as AIS time is, unless ``truth.time.zone`` says
    another."""

    format: str = param("auto", "how the times are written: auto: Unix time by magnitude, "
                        "ISO-8601 (without a zone: UTC) or dd/mm/yyyy HH:MM:SS (the Danish "
                        "Maritime Authority's); unix_s|ms|us|ns; iso; iso_utc; or a strptime "
                        "pattern ('%d-%m-%y %H:%M')", form=TIME_FORMAT)
    zone: str | None = param(None, "the IANA time zone (Europe/Madrid) of times written "
                             "without one; null: UTC (AIS time)", form=ZONE)
    ambiguous: str = param("refuse", "a local time (truth.time.zone) that a daylight-saving "
                           "change repeats or skips: refuse, or read it as the earliest or "
                           "latest instant it can mean", choices=AMBIGUOUS)


GROUPS = {"columns": AisColumns, "time": AisTime, "csv": CsvFormat}


@dataclass
class TruthOptions(Params):
    """What ``ingest`` scores a recorded log against (``truth.*``)."""

    file: str | None = param(None, "the AIS of the trial: decoded position reports (CSV with "
                             "time, MMSI, latitude, longitude) or NMEA !AIVDM/!AIVDO sentences "
                             "with time stamps; null: no truth")
    match: Any = param(None, "which ship each contact is: {contact: MMSI} (contacts left out "
                       "are matched by their bearings); null: every contact by its bearings",
                       form=MATCH)
    max_gap_s: float = param(90.0, "the truth of a contact is refused where its ship's AIS has "
                             "a gap longer than this (s) over the contact's bearings",
                             "(0, 1e6)")
    max_rms_deg: float | None = param(None, "a ship fits a contact when the RMS difference "
                                      "between the bearings it would give and the contact's is "
                                      "at most this (deg); null: 3 sigma (the log's nominal "
                                      "sigma, else estimated from the bearings' second "
                                      "differences), at least 0.1 deg", "(0, 180)")
    ambiguity_ratio: float = param(2.0, "a second ship that fits with an RMS within this factor "
                                   "of the best one's makes the match ambiguous (no truth)",
                                   "[1, 1e3)")
    max_range_km: float = param(100.0, "a ship farther than this (km) from own-ship at every "
                                "bearing of a contact is not that contact", "(0, 2000)")
    velocity_span_s: float = param(120.0, "the true course and speed at the last bearing: the "
                                   "ship's mean velocity over this span before it (s)",
                                   "(0, 3600)")
    accel_sd_m_s2: float = param(0.02, "the truth's own uncertainty where the AIS is sparse: "
                                 "a ship's one-sigma acceleration (m/s^2); a position "
                                 "interpolated tau s after a report, T - tau before the next, "
                                 "is uncertain by accel tau (T - tau) / 2 (m) per axis, and the "
                                 "z-scores and covered include it; 0: the AIS is exact",
                                 "[0, 10]")
    own_mmsi: int | None = param(None, "own-ship's MMSI: its track from the same AIS is the "
                                 "own-ship of the log (interpolated at each bearing; a log of "
                                 "time, contact and bearing needs no navigation then); null: "
                                 "own-ship from the log or navigation=", "[1000000, 999999999]")
    sog_units: str = param("kn", "units of an AIS table's speed over ground: kn (knots, as "
                           "AIS), m_s, km_h", choices=tuple(SOG_UNITS))
    columns: AisColumns = param(factory=AisColumns)
    time: AisTime = param(factory=AisTime)
    csv: CsvFormat = param(factory=CsvFormat)

    @property
    def where(self) -> str:
        return ""  # the keys say it: truth.max_gap_s

    @property
    def key_prefix(self) -> str:
        return "truth."

    def __post_init__(self):
        super().__post_init__()
        if self.file is not None and not str(self.file).strip():
            raise ConfigError("truth.file must be a file path, got ''")
        self.match = _match_map(self.match)
        if self.match and self.file is None:
            raise ConfigError("truth.match needs the AIS file: give truth=FILE")
        if self.own_mmsi is not None and self.file is None:
            raise ConfigError("truth.own_mmsi needs the AIS file: give truth=FILE")
        try:
            self.csv.rules()
        except ConfigError as exc:
            raise ConfigError(f"truth.{exc}") from None

    def table_options(self) -> dict:
        """The options of an AIS table that are set (``{"truth.columns.time": ...}``)."""
        out = {}
        for group, cls in GROUPS.items():
            value, default = getattr(self, group), cls()
            out.update({f"truth.{group}.{f.name}": getattr(value, f.name) for f in fields(cls)
                        if getattr(value, f.name) != getattr(default, f.name)})
        return out

    def record(self) -> dict:
        """The options as a manifest keeps them (the file is in its sources)."""
        return {k: v for k, v in to_plain(self).items() if k != "file"}


def _match_map(value) -> dict[str, int] | None:
    """``{contact: mmsi}`` with contacts as text and MMSIs as integers."""
    if value is None:
        return None
    problem = _match_problem(value)
    if problem:
        raise ConfigError(f"truth.match={value}: {problem}; truth.match must be {MATCH.text}")
    if problem is not None:
        raise ConfigError(f"truth.match must be {MATCH.text}, got '{value}'")
    return {str(contact): int(str(mmsi).strip()) for contact, mmsi in value.items()}


def truth_options(node) -> TruthOptions:
    """The truth options from a path (``truth=FILE``), a config node of the group, or None."""
    if isinstance(node, TruthOptions):
        return node
    if node is None:
        node = {}
    elif not isinstance(node, dict):
        from omegaconf import DictConfig, OmegaConf

        node = (OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig)
                else {"file": str(node)})
    nested: dict = {}
    for key, value in node.items():  # dotted keys ({"columns.time": ...}) as groups
        group, _, name = str(key).partition(".")
        if name:
            nested.setdefault(group, {})[name] = value
        elif isinstance(value, dict) and isinstance(nested.get(group), dict):
            nested[group] = {**value, **nested[group]}
        else:
            nested[group] = value
    node = nested
    known = TruthOptions.__dataclass_fields__
    unknown = [k for k in node if k not in known]
    if unknown:
        raise ConfigError(f"unknown option truth.{unknown[0]} (the truth options: "
                          f"{', '.join(f'truth.{k}' for k in known)})")
    node = dict(node)
    if isinstance(node.get("file"), Path):
        node["file"] = str(node["file"])
    for group, cls in GROUPS.items():
        values = node.get(group)
        if values is None or isinstance(values, cls):
            node.pop(group, None) if values is None else None
            continue
        names = [f.name for f in fields(cls)]
        if not isinstance(values, dict):
            raise ConfigError(f"truth.{group} holds options (truth.{group}.<name>=...), not a "
                              f"value: got truth.{group}='{values}'")
        wrong = [k for k in values if k not in names]
        if wrong:
            raise ConfigError(f"unknown option truth.{group}.{wrong[0]} (the truth.{group} "
                              f"options: {', '.join(f'truth.{group}.{k}' for k in names)})")
        node[group] = cls(**values)
    return TruthOptions(**node)


def shorthand(arguments: list[str]) -> list[str]:
    """The command line with ``truth=FILE`` as ``truth.file=FILE`` (the group holds
    ``truth.match`` and the bounds beside the file)."""
    return [f"truth.file={a.split('=', 1)[1]}" if a.startswith("truth=") else a
            for a in arguments]
