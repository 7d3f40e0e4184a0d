"""Atomic file writes: write to a temporary sibling, then rename over the target.

A killed process leaves at worst a ``.tmp-*`` file behind, never a truncated file under
the final name, so a file that exists under its final name is complete.
"""

import contextlib
import hashlib
import json
import os
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; rename it to ``path`` if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_json_atomic(path, obj):
    """Write ``obj`` as stable, indented JSON (sorted keys) atomically."""
    text = json.dumps(obj, indent=2, sort_keys=True, allow_nan=False) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_parquet_atomic(path, table):
    """Write a pyarrow table to Parquet atomically (zstd, no pandas metadata)."""
    with atomic_path(path) as tmp:
        import pyarrow.parquet as pq  # here: most commands never write Parquet

        pq.write_table(table, tmp, compression="zstd")


def write_text_atomic(path, text: str):
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def sha256_file(path, chunk_bytes=1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()


def sha256_json(obj) -> str:
    """Hex sha256 of the canonical JSON form of ``obj`` (sorted keys, no spaces)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()
