"""Datasets: a directory with ``manifest.json``, MCAP log shards and (if simulated) truth.

Layout::

    data/datasets/<name>/
        manifest.json        # written last: a directory without it is incomplete
        truth.parquet        # one row per track (simulated datasets only)
        log/shard-00000.mcap # one own-ship + its contacts per shard

The manifest records the resolved config, seed, package version, and for every file its
size, sha256 and row or message count; ``content_hash`` is a hash over those file records and
identifies the dataset's bytes; ``manifest_sha256`` hashes the rest of the manifest, so an
edited value (a relabelled sigma, a forged content hash) is refused rather than trusted.
Every stage that uses a dataset verifies it first (``Dataset.verify``).
"""

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from tma.errors import InputError, IntegrityError, MissingFileError
from tma.io import arrow
from tma.io.atomic import VerifiedPath, sha256_file, sha256_json, write_json_atomic
from tma.version import __version__

FORMAT = "tma-dataset"
FORMAT_VERSION = 2
MANIFEST = "manifest.json"
_REQUIRED = ("family", "name", "source", "config", "shards", "files", "content_hash")
_RECREATE = "re-create the dataset (simulate creates it again; ingest with force=true)"


def datasets_dir(data_dir) -> Path:
    return Path(data_dir) / "datasets"


def shard_relpath(index: int) -> str:
    return f"log/shard-{index:05d}.mcap"


def file_record(path, **counts) -> dict:
    return {"sha256": sha256_file(path), "bytes": Path(path).stat().st_size, **counts}


def sealed(manifest: dict) -> dict:
    """``manifest`` with ``manifest_sha256``: the hash of everything else in it."""
    body = {k: v for k, v in manifest.items() if k != "manifest_sha256"}
    return {**body, "manifest_sha256": sha256_json(body)}


def read_sealed_manifest(path, kind: str, fmt: str, version: int, remedy: str) -> dict:
    """Parse a manifest of format ``fmt``/``version`` written through ``sealed``; a clear
    InputError (not a tma manifest) or IntegrityError (old, damaged or edited) otherwise."""
    try:
        manifest = json.loads(Path(path).read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise IntegrityError(f"{path}: damaged {kind} manifest, not valid JSON ({exc}); "
                             f"{remedy}") from None
    if not isinstance(manifest, dict) or manifest.get("format") != fmt:
        raise InputError(f"{path}: not a tma {kind} manifest")
    if manifest.get("format_version") != version:
        raise IntegrityError(f"{path}: {kind} format version {manifest.get('format_version')} "
                             f"is not supported by tma {__version__} (expected {version}); "
                             f"{remedy}")
    if sealed(manifest)["manifest_sha256"] != manifest.get("manifest_sha256"):
        raise IntegrityError(f"{path}: the {kind} manifest was edited or damaged (its "
                             f"manifest_sha256 does not match its content); {remedy}")
    return manifest


def write_manifest(root, *, family, source, config, shards, files, extra=None,
                   name=None) -> dict:
    """Write ``manifest.json`` atomically; ``shards`` and ``files`` map relpath -> record.
    ``name``: the dataset's name when ``root`` is its staging directory."""
    manifest = sealed({
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "family": family,
        "name": name or Path(root).name,
        "source": source,
        "package": {"name": "tma", "version": __version__},
        "config": config,
        "shards": shards,
        "files": files,
        "content_hash": sha256_json({"shards": shards, "files": files}),
        **(extra or {}),
    })
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
            raise MissingFileError(f"no dataset at {root}{hint}")
        manifest = read_sealed_manifest(path, "dataset", FORMAT, FORMAT_VERSION, _RECREATE)
        missing = [k for k in _REQUIRED if k not in manifest]
        if missing:
            raise IntegrityError(f"{path}: damaged manifest, missing {', '.join(missing)}; "
                                 f"{_RECREATE}")
        if sha256_json({"shards": manifest["shards"], "files": manifest["files"]}) != (
                manifest["content_hash"]):
            raise IntegrityError(f"{path}: content_hash does not match the file records; "
                                 f"{_RECREATE}")
        if manifest["name"] != root.name:  # a dataset copied or moved under another name
            raise IntegrityError(f"{path}: this is dataset '{manifest['name']}', not "
                                 f"'{root.name}'; {_RECREATE}")
        return cls(root, manifest)

    def check_simulated_from(self, config: dict) -> "Dataset":
        """IntegrityError unless this dataset was simulated from scenario ``config``."""
        if self.manifest["source"] != "simulate" or self.manifest["config"] != config:
            raise IntegrityError(f"{self.root}: not the dataset simulated from this scenario "
                                 f"config (source '{self.manifest['source']}'); {_RECREATE}")
        return self

    def verify(self) -> "Dataset":
        """Check every listed file: present, of its recorded size and sha256."""
        for relpath in self.listed_paths:
            self._verify_file(relpath)
        return self

    def check_files(self) -> "Dataset":
        """Check every listed file is present with its recorded size, reading none of them:
        what a stage does before it starts. The sha256 of a file is checked by whoever reads
        its bytes (``verified_path``: each estimate worker its shard, reports the truth)."""
        for relpath in self.listed_paths:
            self._checked_size(relpath)
        return self

    @property
    def listed_paths(self) -> list[str]:
        return [*self.shard_paths, *sorted(self.manifest["files"])]

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

    def _checked_size(self, relpath: str) -> tuple[Path, dict]:
        record = self.manifest["shards"].get(relpath) or self.manifest["files"].get(relpath)
        if record is None:
            raise InputError(f"{self.root}: '{relpath}' is not listed in the manifest")
        path = self.root / relpath
        if not path.is_file():
            raise IntegrityError(f"{path}: listed in the manifest but missing; {_RECREATE}")
        size = path.stat().st_size
        if size != record["bytes"]:
            raise IntegrityError(f"{path}: {size} bytes, the manifest records {record['bytes']} "
                                 f"(truncated or replaced); {_RECREATE}")
        return path, record

    def verified_path(self, relpath: str) -> VerifiedPath:
        """Path of a dataset file after checking its size and sha256 against the manifest,
        with the bytes checked (``VerifiedPath``: a reader parses those, not a second read)."""
        path, record = self._checked_size(relpath)
        data = path.read_bytes()
        self._check_sha256(path, record, hashlib.sha256(data).hexdigest())
        return VerifiedPath.of(path, data)

    def _verify_file(self, relpath: str) -> None:
        path, record = self._checked_size(relpath)
        self._check_sha256(path, record, sha256_file(path))  # streamed: nothing kept

    @staticmethod
    def _check_sha256(path: Path, record: dict, actual: str) -> None:
        if actual != record["sha256"]:
            raise IntegrityError(
                f"{path}: sha256 {actual[:12]}... does not match the manifest "
                f"({record['sha256'][:12]}...); the dataset was modified or damaged: "
                f"{_RECREATE}"
            )

    def read_truth(self):
        """Truth table as pandas (verified), or None for a dataset without truth."""
        if not self.has_truth:
            return None
        return arrow.read_table(self.verified_path("truth.parquet")).to_pandas()


def check_datasets(datasets) -> None:
    """``Dataset.check_files`` of each dataset once, however many jobs read it: a missing or
    truncated file stops the stage before it starts. Each file's sha256 is checked where its
    bytes are read (an estimate worker its shard, a report the truth), so no stage reads a
    dataset twice and every byte read is verified."""
    for dataset in {id(ds): ds for ds in datasets}.values():
        dataset.check_files()
