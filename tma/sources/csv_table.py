"""The CSV reader: CSV / TSV tables of contacts' values and/or own-ship fixes -> ``Recording``s
(kind ``csv``: ``.csv``, ``.tsv``, ``.txt``; options ``columns.*``, ``csv.*``, ``time.format``).

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
- tracks: ids as written (``tma.sources.table``, which reads the rows of a file and of a
  DataFrame alike).
"""

from dataclasses import dataclass, make_dataclass
from pathlib import Path

from tma.config import Form, param
from tma.errors import ConfigError
from tma.sources.base import Reader, Recording
from tma.sources.csv_layout import CsvFile, Frame
from tma.utc import AMBIGUOUS, is_pattern, pattern_problem, zone_problem

POSITION_ROLES = ("time", "x", "y", "lat", "lon")  # table columns besides value and track
COLUMN_DOCS = {  # what each column of a table holds (the observation's is the family's)
    "time": "the times (relative s, Unix time or ISO-8601: time.format)",
    "x": "own-ship's position east (m)", "y": "own-ship's position north (m)",
    "lat": "own-ship's latitude (deg, WGS84)", "lon": "own-ship's longitude (deg, WGS84)",
    "track": "the contact of each row (an integer id, or a label kept as written; a table "
             "without one holds one contact)",
    "platform": "the platform (ship, buoy, station) that took each row's value, where the "
                "row's position is (text, as written; a table without one has one own-ship)"}
FOUND = "; null: tma's name or a common one, found automatically (any case)"


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

    def rules(self):
        """The names of delimiters and decimal marks become the characters."""
        self.delimiter = DELIMITER_NAMES.get(self.delimiter, self.delimiter)
        self.decimal = DECIMAL_NAMES.get(self.decimal, self.decimal)
        if self.decimal is not None and self.decimal == self.delimiter:
            raise ConfigError(f"csv.decimal and csv.delimiter are both '{self.decimal}'")


TIME_FORMATS = ("auto", "s", "unix_s", "unix_ms", "unix_us", "unix_ns", "iso", "iso_utc")


def _format_problem(value) -> str | None:
    if value in TIME_FORMATS:
        return None
    return pattern_problem(value) if is_pattern(value) else ""


TIME_FORMAT = Form(f"one of {', '.join(TIME_FORMATS)} or a strptime pattern with % "
                   "('%d-%m-%y %H:%M')", _format_problem)
ZONE = Form("an IANA time zone (Europe/Madrid, UTC)", zone_problem)


@dataclass
class TimeFormat:
    """How a table's times are written (``time.format``, ``time.zone``,
    ``time.ambiguous``)."""

    format: str = param("auto", "how the times are written: auto: numbers by magnitude (Unix "
                        "s from 1e8, ms from 1e11, us from 1e14, ns from 1e17; smaller: relative "
                        "s), text as ISO-8601 with a zone; s: relative seconds; unix_s|ms|us|ns: "
                        "Unix time; iso: ISO-8601 with a zone (Z, +01:00); iso_utc: ISO-8601, a "
                        "time without zone taken as UTC; or a strptime pattern ('%d-%m-%y "
                        "%H:%M': day first, two-digit year)", form=TIME_FORMAT)
    zone: str | None = param(None, "the IANA time zone (Europe/Madrid) of times written as "
                             "text without one (local time, with its daylight saving); null: "
                             "such times are refused (iso_utc: UTC)", form=ZONE)
    ambiguous: str = param("refuse", "a local time (time.zone) that a daylight-saving change "
                           "repeats (autumn) or skips (spring): refuse the file, or read it as "
                           "the earliest or latest instant it can mean", choices=AMBIGUOUS)


def options(observation) -> dict:
    """The options only tables are read with: which column holds what (``columns.*``, the
    observation's column among them), how the file is written (``csv.*``) and its times
    (``time.format``)."""
    role, plural, units = observation.role, observation.plural, observation.units
    docs = {**COLUMN_DOCS, role: f"the {plural} ({' or '.join(u.name for u in units)}: "
                                 f"{role}.units)"}
    columns = make_dataclass("Columns", [(r, str | None, param(None, f"column of {docs[r]}"
                                                              f"{FOUND}"))
                                         for r in (*POSITION_ROLES, role, "track",
                                                   "platform")])
    columns.__doc__ = ("Table column names; None = tma's name or a common one found "
                       "automatically.")
    return {"columns": columns, "csv": CsvFormat, "time": TimeFormat}


def read_csv_table(path, options, *, navigation: bool, contacts: bool,
                   date_hint_ns: int | None = None) -> list[Recording]:
    """Read a CSV/TSV table with a family's reading ``options``. ``navigation``: own-ship
    positions are needed (from this file); ``contacts``: the contacts' values are needed.
    Returns one Recording per own-ship: one per platform named in a platform column
    (``columns.platform``), else one, unless the rows of different tracks give different
    own-ship positions at one time (then one per track, as each track had its own
    own-ship). Rows with a missing or unreadable time, value, track id, platform or own-ship
    position, or a time not absolute among absolute ones, are left out and counted
    (``options.bad_rows``; under ``fail`` the first refuses the file)."""
    from tma.sources.table import read_table

    return read_table(CsvFile(Path(path), options), options, navigation=navigation,
                      contacts=contacts)


def read_frame(frame, name: str, options, *, navigation: bool,
               contacts: bool) -> list[Recording]:
    """``read_csv_table`` of a pandas DataFrame (``name``: what messages
    call it), read as the same table written to a file would be: the same columns found, the
    same checks and notes; a datetime64 column is UTC times (a zone-less one is taken as UTC and
    noted), and a row's "line" is its position in the frame, from 0."""
    from tma.sources.table import read_table

    return read_table(Frame(frame, name, options), options, navigation=navigation,
                      contacts=contacts)


READER = Reader(
    kind="csv", name="a CSV table", extensions=(".csv", ".tsv", ".txt"), read=read_csv_table,
    options=options, selects_contacts="columns.{role}=<column>",
    selects_navigation="columns.lat/columns.lon or columns.x/columns.y")
