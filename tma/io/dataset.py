"""Datasets: a directory with ``manifest.json``, MCAP log shards and (if simulated) truth.

Layout::

    data/datasets/<name>/
        manifest.json        # written last: a directory without it is incomplete
        truth.parquet        # one row per track (simulated datasets only)
        log/shard-00000.mcap # one own-ship + its contacts per shard

The manifest records the resolved config, seed, package version, and for every file its
sha256 and row or message count; ``content_hash`` is a hash over those file hashes and
identifies the dataset's bytes.
"""

import json
from dataclasses import dataclass
from pathlib import Path

import pyarrow.parquet as pq

from tma import __version__
from tma.errors import InputError, IntegrityError
from tma.io.atomic import sha256_file, sha256_json, write_json_atomic

FORMAT = "tma-dataset"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"


def datasets_dir(data_dir) -> Path:
    return Path(data_dir) / "datasets"


def shard_relpath(index: int) -> str:
    return f"log/shard-{index:05d}.mcap"


def file_record(path, **counts) -> dict:
    return {"sha256": sha256_file(path), **counts}


def write_manifest(root, *, family, source, config, shards, files, extra=None) -> dict:
    """Write ``manifest.json`` atomically; ``shards`` and ``files`` map relpath -> record."""
    manifest = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "family": family,
        "name": Path(root).name,
        "source": source,
        "package": {"name": "tma", "version": __version__},
        "config": config,
        "shards": shards,
        "files": files,
        "content_hash": sha256_json({"shards": shards, "files": files}),
        **(extra or {}),
    }
    write_json_atomic(Path(root) / MANIFEST, manifest)
    return manifest


@dataclass
class Dataset:
    root: Path
    manifest: dict

    @classmethod
    def open(cls, root) -> "Dataset":
        root = Path(root)
        path = root / MANIFEST
        if not path.exists():
            hint = " (incomplete: re-run the stage that writes it)" if root.exists() else ""
            raise InputError(f"no dataset at {root}{hint}")
        try:
            manifest = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise InputError(f"{path}: not valid JSON ({exc})") from None
        if manifest.get("format") != FORMAT:
            raise InputError(f"{path}: not a tma dataset manifest")
        if manifest.get("format_version") != FORMAT_VERSION:
            raise InputError(f"{path}: dataset format version {manifest.get('format_version')} "
                             f"is not supported (expected {FORMAT_VERSION})")
        return cls(root, manifest)

    @property
    def name(self) -> str:
        return self.root.name

    @property
    def family(self) -> str:
        return self.manifest["family"]

    @property
    def content_hash(self) -> str:
        return self.manifest["content_hash"]

    @property
    def shard_paths(self) -> list[str]:
        return sorted(self.manifest["shards"])

    @property
    def has_truth(self) -> bool:
        return "truth.parquet" in self.manifest["files"]

    def verified_path(self, relpath: str) -> Path:
        """Path of a dataset file after checking its sha256 against the manifest."""
        record = self.manifest["shards"].get(relpath) or self.manifest["files"].get(relpath)
        if record is None:
            raise InputError(f"{self.root}: '{relpath}' is not listed in the manifest")
        path = self.root / relpath
        if not path.exists():
            raise IntegrityError(f"{path}: listed in the manifest but missing")
        actual = sha256_file(path)
        if actual != record["sha256"]:
            raise IntegrityError(
                f"{path}: sha256 {actual[:12]}... does not match the manifest "
                f"({record['sha256'][:12]}...); the dataset was modified or damaged: "
                "re-create it (simulate/ingest with force=true)"
            )
        return path

    def read_truth(self):
        """Truth table as pandas (verified), or None for a dataset without truth."""
        if not self.has_truth:
            return None
        return pq.read_table(self.verified_path("truth.parquet")).to_pandas()
