"""Reuse of finished shard outputs across re-runs.

A shard output ``X`` is finished when its sidecar ``X.done.json`` exists, records the same
task key (a hash of everything the output depends on) and the output's sha256 matches. The
sidecar is written after the output, both atomically, so a killed run leaves either a complete
pair or something that is recomputed; a damaged sidecar also just means "recompute".
"""

import json
from pathlib import Path

from tma.io.atomic import sha256_file, write_json_atomic


def sidecar(path) -> Path:
    path = Path(path)
    return path.with_name(path.name + ".done.json")


def finished_record(path, key: str, record_path=None) -> dict | None:
    """The sidecar record of ``path`` (at ``record_path``, by default ``sidecar(path)``) if
    the output is finished for ``key``, else None."""
    path = Path(path)
    try:
        record = json.loads(Path(record_path or sidecar(path)).read_text())
        if (isinstance(record, dict) and record.get("key") == key
                and record.get("sha256") == sha256_file(path)):
            return record
    except (OSError, ValueError):  # absent, unreadable or not JSON: not finished
        pass
    return None


def mark_finished(path, key: str, record_path=None, **info) -> dict:
    """Write the sidecar record of the finished output ``path`` (at ``record_path``, by
    default ``sidecar(path)``): ``key``, its sha256 and ``info``."""
    path = Path(path)
    record = {"key": key, "sha256": sha256_file(path), **info}
    write_json_atomic(Path(record_path or sidecar(path)), record)
    return record
