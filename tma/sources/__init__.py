"""Recorded logs of any platform, read behind one interface: ``read_source(path, kind, options,
...)`` returns own-platform fixes and per-contact values (``base.py``) for any family.

Source kinds, one reader file each: ``csv`` (CSV/TSV tables, ``csv_table.py``), ``nmea`` (NMEA
0183 own-ship navigation, ``nmea.py``), ``mcap`` (``mcap.py``: ROS 2 messages ``ros2.py``,
Foxglove's ``foxglove.py``, tma's own schemas ``tma_log.py``). The kind is the ``format``
option or, under ``auto``, told from the file: the MCAP magic bytes or a first line starting
with ``$`` (NMEA), else the extension (.csv/.tsv/.txt: CSV; .nmea/.nmea0183/.log: NMEA; .mcap:
MCAP). Each reader is imported when a file of its kind is read (pandas for CSV, the MCAP
stack), not by every command that imports the reading options of ``base.py``. ``align.py``
puts what the readers return on one clock and one plane; a family's ``ingest`` module
declares its ``Observation`` and makes its logs from the aligned arrays (``tma.ingest``).
"""

from pathlib import Path

from tma.errors import ConfigError, InputError, MissingFileError
from tma.sources.base import Recording

KINDS = ("csv", "nmea", "mcap")
EXTENSIONS = {".csv": "csv", ".tsv": "csv", ".txt": "csv", ".nmea": "nmea", ".nmea0183": "nmea",
              ".log": "nmea", ".mcap": "mcap"}
MCAP_MAGIC = b"\x89MCAP"


def source_kind(path, fmt="auto", option: str | None = "format") -> str:
    """``csv``, ``nmea`` or ``mcap`` for the file at ``path`` (``fmt``: auto or one of them).
    ``option``: the option that sets the kind, named in the message when it cannot be told
    (None: there is none, the file's extension must say it)."""
    path = Path(path)
    if fmt != "auto":
        if fmt not in KINDS:
            raise ConfigError(f"{option} must be auto, csv, nmea or mcap, got '{fmt}'")
        return fmt
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except FileNotFoundError:
        raise MissingFileError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: a directory, not a log file") from None
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    from tma.sources.nmea import is_nmea

    if is_nmea(head):
        return "nmea"
    kind = EXTENSIONS.get(path.suffix.lower())
    if kind is None:
        fix = (f"set {option}=csv, {option}=nmea or {option}=mcap" if option else
               f"name it with the extension of its kind ({', '.join(EXTENSIONS)})")
        raise ConfigError(f"cannot tell the kind of {path} from its extension or its first "
                          f"line: {fix}")
    return kind


def read_source(path, kind: str, options, *, navigation: bool, contacts: bool,
                date_hint_ns: int | None = None) -> list[Recording]:
    """Read one file of ``kind`` with the reading ``options`` of a family (``base.
    options_schema``); ``navigation`` / ``contacts``: what is wanted from it (the CSV reader
    then looks only for those columns); ``date_hint_ns``: UTC ns of the first contact value,
    which dates navigation that carries no date (NMEA GGA). One Recording per own-ship
    (several only when a table's tracks report different own-ship positions)."""
    if kind == "csv":
        from tma.sources.csv_table import read_csv_table

        return read_csv_table(path, options, navigation=navigation, contacts=contacts)
    if kind == "nmea":
        if contacts:
            raise InputError(f"{path}: NMEA holds own-ship navigation only: give it as "
                             f"navigation=FILE and the {options.observation.plural} as input=")
        from tma.sources.nmea import read_nmea

        return [read_nmea(path, options, date_hint_ns)]
    from tma.sources.mcap import read_mcap

    need = (("navigation",) if navigation else ()) + (("contacts",) if contacts else ())
    return [read_mcap(path, options, need=need, navigation=navigation)]
