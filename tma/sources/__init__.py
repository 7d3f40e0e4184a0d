"""Recorded logs of any platform, read behind one interface: ``read_source(path, kind, options,
...)`` returns own-platform fixes and per-contact values (``base.py``) for any family.

One reader file per format, each declaring it (``READER``, a ``base.Reader``: its kind,
extensions, sniffing rule, options and read function), listed once in ``READERS``: a new
format is one file plus one line there. Everything else is derived from the declarations: the
``format`` option's values (``KINDS``), which reader reads a file (``source_kind``: the
``format`` option, or under ``auto`` the readers' sniffing rules on the file's first bytes,
then its extension), the reading options' groups and which kinds read each
(``tma.sources.options``), and the messages naming them. The declarations are light, since
every command imports them: each reader imports its heavy libraries (pandas, the MCAP stack)
when a file of its kind is read. ``align.py`` puts what the readers return on one clock and
one plane; a family's ``ingest`` module declares its ``Observation`` and makes its logs from
the aligned arrays (``tma.stages.ingest``).
"""

import functools
import importlib
from pathlib import Path

from tma.errors import ConfigError
from tma.sources.base import SNIFF_BYTES, Reader, Recording, checked_recordings, file_head

READERS = (  # one line per format: its reader file's module
    "tma.sources.csv_table",
    "tma.sources.nmea",
    "tma.sources.mcap",
)


def readers() -> list[Reader]:
    """The registered readers (``READERS``), in order."""
    return list(_declared(READERS))


@functools.cache
def _declared(modules: tuple[str, ...]) -> tuple[Reader, ...]:
    found = tuple(importlib.import_module(m).READER for m in modules)
    kinds = [r.kind for r in found]
    if len(set(kinds)) != len(kinds):
        raise RuntimeError(f"two readers declare one kind: {kinds}")
    return found


def kinds() -> tuple[str, ...]:
    """The kinds of log tma reads (the ``format`` option's values besides ``auto``)."""
    return tuple(r.kind for r in readers())


def extensions() -> dict[str, str]:
    """``{extension: kind}`` of every reader (``.csv``: ``csv``)."""
    return {ext: r.kind for r in readers() for ext in r.extensions}


def reader(kind: str) -> Reader:
    """The reader of ``kind``."""
    return next(r for r in readers() if r.kind == kind)


def source_kind(path, fmt="auto", option: str | None = "format") -> str:
    """The kind of the file at ``path`` (``fmt``: auto or one of ``kinds()``): the first
    reader whose sniffing rule knows its first bytes, else its extension's. ``option``: the
    option that sets the kind, named in the message when it cannot be told (None: there is
    none, the file's extension must say it)."""
    path = Path(path)
    known = kinds()
    if fmt != "auto":
        if fmt not in known:
            raise ConfigError(f"{option} must be auto, {', '.join(known[:-1])} or {known[-1]}, "
                              f"got '{fmt}'")
        return fmt
    head = file_head(path, SNIFF_BYTES, "a log file")
    sniffed = next((r.kind for r in readers() if r.sniff is not None and r.sniff(head)), None)
    kind = sniffed or extensions().get(path.suffix.lower())
    if kind is None:
        fix = (f"set {', '.join(f'{option}={k}' for k in known[:-1])} or {option}={known[-1]}"
               if option else
               f"name it with the extension of its kind ({', '.join(extensions())})")
        raise ConfigError(f"cannot tell the kind of {path} from its extension or its first "
                          f"line: {fix}")
    return kind


def read_source(path, kind: str, options, *, navigation: bool, contacts: bool,
                date_hint_ns: int | None = None) -> list[Recording]:
    """Read one file of ``kind`` with the reading ``options`` of a family
    (``tma.sources.options.options_schema``); ``navigation`` / ``contacts``: what is wanted
    from it (the CSV reader then looks only for those columns); ``date_hint_ns``: UTC ns of
    the first contact value, which dates navigation that carries no date (NMEA GGA). One
    Recording per own-ship (several only when a table's tracks report different own-ship
    positions), held to the readers' contract (``tma.sources.base.ReadLog``)."""
    return checked_recordings(reader(kind).read(path, options, navigation=navigation,
                                                contacts=contacts, date_hint_ns=date_hint_ns),
                              kind)
