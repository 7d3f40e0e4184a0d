"""The bearing-log readers behind one interface: ``read_source(path, kind, options, ...)``.

Source kinds: ``csv`` (CSV/TSV tables, ``csv_table.py``), ``nmea`` (NMEA 0183 own-ship
navigation, ``nmea.py``), ``mcap`` (ROS 2, Foxglove or tma's own schema, ``mcap.py``). The kind
is the ``format`` option or, under ``auto``, told from the file: the MCAP magic bytes or a
first line starting with ``$`` (NMEA), else the extension (.csv/.tsv/.txt: CSV; .nmea/.nmea0183
/.log: NMEA; .mcap: MCAP). Each reader is imported when a file of its kind is read (pandas for
CSV, the MCAP stack), not by every command that imports the reading options of ``base.py``.
"""

from pathlib import Path

from tma.errors import ConfigError, InputError
from tma.families.bearings2d.sources.base import Recording, SourceOptions

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
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: a directory, not a log file") from None
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    from tma.families.bearings2d.sources.nmea import is_nmea

    if is_nmea(head):
        return "nmea"
    kind = EXTENSIONS.get(path.suffix.lower())
    if kind is None:
        fix = (f"set {option}=csv, {option}=nmea or {option}=mcap" if option else
               f"name it with the extension of its kind ({', '.join(EXTENSIONS)})")
        raise ConfigError(f"cannot tell the kind of {path} from its extension or its first "
                          f"line: {fix}")
    return kind


def read_source(path, kind: str, options: SourceOptions, *, navigation: bool,
                bearings: bool) -> list[Recording]:
    """Read one file of ``kind``; ``navigation`` / ``bearings``: what is wanted from it (the
    CSV reader then looks only for those columns). One Recording per own-ship (several only
    when a table's tracks report different own-ship positions)."""
    if kind == "csv":
        from tma.families.bearings2d.sources.csv_table import read_csv_table

        return read_csv_table(path, options, navigation=navigation, bearings=bearings)
    if kind == "nmea":
        if bearings:
            raise InputError(f"{path}: NMEA holds own-ship navigation only: give it as "
                             "navigation=FILE and the bearings as input=")
        from tma.families.bearings2d.sources.nmea import read_nmea

        return [read_nmea(path)]
    from tma.families.bearings2d.sources.mcap import read_mcap

    need = (("navigation",) if navigation else ()) + (("bearings",) if bearings else ())
    return [read_mcap(path, options, need=need)]
