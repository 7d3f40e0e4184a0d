"""Contact labels made safe to show: in tables (Markdown), file names and map topics.

A recorder may name a contact anything: a 300-character id, text with ``|`` or a newline, a
topic name (``/sonar/contact/a``). The dataset keeps each id as written (the manifest's
``track_labels``, the log's ``tma.tracks``, the report's CSV); every other output names the
contact by its shown label (``shown_labels``): the id with leading and trailing path
separators and spaces stripped, ``|``, path separators and control characters (newline, tab)
replaced by ``_``, and shortened to ``MAX_SHOWN`` characters ending in ``~`` and the first 8
hex digits of the id's sha256 when longer; ids alike once made safe are told apart by that
hash too. ``file_part`` makes a shown label part of a file name, ``fit_file_name`` shortens
one that would not fit the file system. Ingest computes the shown labels (and notes each one
that differs from its id), so no output can fail on a name later.
"""

import hashlib
import re
from collections import Counter

from tma.errors import ConfigError

MAX_SHOWN = 64  # bytes (UTF-8) of a shown label
UNSAFE = re.compile(r"[|/\\\x00-\x1f\x7f]")
NAME_MAX = 255  # bytes of a file name (Linux, macOS, Windows)
TEMPORARY = 24  # bytes atomic writes add to a name (".<name>.tmp-<pid>")


def _hash(label: str) -> str:
    return hashlib.sha256(label.encode()).hexdigest()[:8]


def _cut(text: str, limit: int) -> str:
    """``text`` cut to at most ``limit`` UTF-8 bytes, on a character boundary."""
    return text.encode()[:limit].decode(errors="ignore")


def _with_hash(text: str, label: str) -> str:
    return _cut(text, MAX_SHOWN - 9) + "~" + _hash(label)


def shown_label(label: str) -> str:
    """One id made safe (``shown_labels`` also tells apart ids alike once safe)."""
    text = UNSAFE.sub("_", str(label).strip().strip("/\\").strip()) or "_"
    if len(text.encode()) > MAX_SHOWN or text == "_" != label:
        return _with_hash(text, label)
    return text


def shown_labels(labels) -> list[str]:
    """The shown label of each id of ``labels`` (text), all different: see the module."""
    labels = [str(s) for s in labels]
    shown = [shown_label(s) for s in labels]
    taken = Counter(shown)
    return [s if taken[s] == 1 or s == label or s.endswith("~" + _hash(label))
            else _with_hash(s, label) for s, label in zip(shown, labels, strict=True)]


def file_part(shown: str) -> str:
    """A shown label as part of a file name: characters other than letters, digits, ``._-``
    become ``_`` (no leading ``.``)."""
    return re.sub(r"[^A-Za-z0-9._-]", "_", shown).lstrip(".") or "_"


def fit_file_name(stem: str, part: str, suffix: str) -> str:
    """``<stem>-<part><suffix>``, with ``part`` cut and ended by its hash when the name would
    not fit ``NAME_MAX`` bytes (with room for an atomic write's temporary name); ConfigError
    when ``stem`` leaves no room for ``part``."""
    name = f"{stem}-{part}{suffix}"
    room = NAME_MAX - TEMPORARY - len(f"{stem}-{suffix}".encode())
    if len(name.encode()) <= NAME_MAX - TEMPORARY:
        return name
    if room < 10:
        raise ConfigError(f"the table name {stem[:40]}... ({len(stem.encode())} bytes) leaves no "
                          f"room for its contacts' file names ({stem[:20]}...-<contact>{suffix}: "
                          f"{NAME_MAX - TEMPORARY} bytes at most); choose a shorter table=")
    return f"{stem}-{_cut(part, room - 9)}~{_hash(part)}{suffix}"


def name_room(family_estimators, suffix: str = ".png") -> int:
    """The longest dataset name whose tables' per-contact files
    (``<dataset>-<estimator>-<shown label><suffix>``) fit a file name."""
    longest = max((len(e) for e in family_estimators), default=0)
    return NAME_MAX - TEMPORARY - (1 + longest + 1 + MAX_SHOWN + len(suffix))
