"""Reuse of finished shard outputs across re-runs.

A shard output ``X`` is finished when its sidecar ``X.done.json`` exists, records the same
task key (a hash of everything the output depends on) and the output's sha256 matches. The
sidecar is written after the output, both atomically, so a killed run leaves either a complete
pair or something that is recomputed.
"""

import json
from pathlib import Path

from tma.io.atomic import sha256_file, write_json_atomic


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".done.json")


def is_finished(path, key: str) -> bool:
    path = Path(path)
    side = _sidecar(path)
    if not (path.exists() and side.exists()):
        return False
    try:
        record = json.loads(side.read_text())
    except json.JSONDecodeError:
        return False
    return record.get("key") == key and record.get("sha256") == sha256_file(path)


def mark_finished(path, key: str, **info) -> dict:
    path = Path(path)
    record = {"key": key, "sha256": sha256_file(path), **info}
    write_json_atomic(_sidecar(path), record)
    return record


def finished_record(path) -> dict:
    return json.loads(_sidecar(Path(path)).read_text())
