"""Trained or precomputed artefacts (e.g. CMNF gains, a simulated training bundle).

``data/artefacts/<kind>-<key12>/`` holds ``arrays.npz`` and ``manifest.json`` (kind, the full
spec it was built from, package version, the npz's sha256). The key hashes the spec and the
package version, so a later run with the same spec reuses the artefact (after checking its
hash) and a different spec builds its own. An artefact is referenced by the record
``{"kind", "key", "sha256"}`` (``key`` the directory name): no path, so a run that uses it
does not depend on how ``paths.data_dir`` is spelled.
"""

import json
import logging
from pathlib import Path
from time import perf_counter

import numpy as np

from tma.errors import IntegrityError
from tma.io.atomic import atomic_path, sha256_file, sha256_json, write_json_atomic
from tma.io.owned import locked, remove_stale_temporaries
from tma.version import __version__

ARRAYS = "arrays.npz"
log = logging.getLogger(__name__)


def artefact_dir(data_dir, kind: str, spec: dict) -> Path:
    key = sha256_json({"kind": kind, "spec": spec, "version": __version__})
    return Path(data_dir) / "artefacts" / f"{kind}-{key[:12]}"


def load_or_build(data_dir, kind: str, spec: dict, build) -> dict:
    """The record ``{"kind", "key", "sha256"}`` of the artefact for ``spec``; ``build()`` ->
    dict of arrays when it is absent or damaged."""
    root = artefact_dir(data_dir, kind, spec)
    with locked([root]):  # a second process building the same artefact waits, then reuses it
        remove_stale_temporaries(root.parent, only_dead=True)
        path, sha = _load_or_build(root, kind, spec, build)
    return {"kind": kind, "key": path.parent.name, "sha256": sha}


def _load_or_build(root: Path, kind: str, spec: dict, build) -> tuple[Path, str]:
    manifest = root / "manifest.json"
    try:
        record = json.loads(manifest.read_text())
        if sha256_file(root / ARRAYS) == record["sha256"]:
            return root / ARRAYS, record["sha256"]
    except (OSError, ValueError, KeyError, TypeError):  # absent or damaged: build it again
        pass
    start = perf_counter()
    arrays = build()
    # what a run spends before its shards (e.g. simulating a training bundle, training)
    log.info("artefact %s built in %.2f s", kind, perf_counter() - start)
    with atomic_path(root / ARRAYS) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)
    sha = sha256_file(root / ARRAYS)
    write_json_atomic(manifest, {"kind": kind, "spec": spec, "sha256": sha,
                                 "package": {"name": "tma", "version": __version__},
                                 "arrays": {k: list(np.shape(v)) for k, v in arrays.items()}})
    return root / ARRAYS, sha


def is_record(record) -> bool:
    """True for what ``load_or_build`` returns: ``{"kind", "key", "sha256"}``."""
    return isinstance(record, dict) and {"kind", "key", "sha256"} <= set(record)


def load_arrays(record: dict, data_dir) -> dict:
    """Arrays of the artefact ``record`` under ``data_dir`` (hash-checked)."""
    path = Path(data_dir) / "artefacts" / record["key"] / ARRAYS
    if sha256_file(path) != record["sha256"]:
        raise IntegrityError(f"{path}: artefact does not match its recorded sha256")
    with np.load(path) as data:
        return {k: data[k] for k in data.files}
