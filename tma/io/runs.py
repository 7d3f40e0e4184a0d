"""The run store: where the estimate stage writes a run and how every reader (aggregate, the
commands' plans, the Python API) finds, verifies and reads it.

Layout::

    data/runs/<dataset>/<estimator>-<key10>/
        estimates/shard-00000.parquet    # the estimates: one file per dataset shard
        shards/shard-00000.parquet.done.json  # each shard's record (key, sha256, wall time)
        shards/shard-00000.<side>.parquet     # each shard's side tables, if any
        <side>.parquet                   # a side table of every shard (e.g. covariance)
        manifest.json                    # config, dataset hash, file hashes
        timing.json                      # wall time per shard (not hashed)

The run's estimates are the folder ``estimates/``, its shard files read as one Parquet
dataset in shard order (``pd.read_parquet(folder)``, ``pyarrow.dataset.dataset(folder)``,
DuckDB's ``read_parquet('folder/*.parquet')``): no concatenated copy is written.

``key`` hashes the full estimator config (every default included), the dataset's content hash
and the package version, so a run directory's content is a pure function of its inputs:
byte-identical for any engine and number of workers. A run is built in its staging
directory and swapped in when complete (``tma.io.owned``); a finished run is reused only
after its manifest and every file it lists verify, and the dataset it reads is verified on
every use.
"""

import json
from pathlib import Path

import pyarrow as pa

from tma.errors import InputError, IntegrityError
from tma.io import arrow
from tma.io.atomic import sha256_json
from tma.io.dataset import Dataset, file_record, read_sealed_manifest
from tma.version import __version__

RUN_FORMAT = "tma-run"
RUN_FORMAT_VERSION = 3  # 3: the estimates are the folder of shard files (2: one file)
MANIFEST = "manifest.json"
ESTIMATES = "estimates"  # the folder of the run's estimates, one Parquet file per shard
SHARDS = "shards"  # each shard's record and side tables
TIMING = "timing.json"


def runs_dir(data_dir) -> Path:
    return Path(data_dir) / "runs"


def run_key(dataset: Dataset, estimator_config: dict) -> str:
    return sha256_json({"estimator": estimator_config, "dataset": dataset.content_hash,
                        "version": __version__})


def run_path(data_dir, dataset: Dataset, estimator_config: dict) -> Path:
    key = run_key(dataset, estimator_config)
    return runs_dir(data_dir) / dataset.name / f"{estimator_config['name']}-{key[:10]}"


def extra_path(shard_out: Path, name: str) -> Path:
    """Where the side table ``name`` of the shard whose estimates are ``shard_out`` goes:
    in ``shards/``, so that ``estimates/`` holds the estimates alone."""
    return shard_out.parent.parent / SHARDS / f"{shard_out.stem}.{name}.parquet"


def record_path(shard_out: Path) -> Path:
    """The record (``tma.io.shards`` sidecar) of the shard whose estimates are ``shard_out``,
    in ``shards/``."""
    return shard_out.parent.parent / SHARDS / f"{shard_out.name}.done.json"


def open_run(root) -> tuple[dict, "pa.Table"]:
    """A finished run's manifest and estimates (its shard files, in shard order, as one
    table), after ``verify_run``."""
    manifest = verify_run(root)
    return manifest, read_estimates(root, manifest)


def read_estimates(root, manifest: dict) -> "pa.Table":
    """The estimates of the run at ``root``: the shard files of its ``estimates/`` folder
    that ``manifest`` lists, in shard order, as one table (what ``pd.read_parquet`` of the
    folder gives)."""
    folder = Path(root) / ESTIMATES
    tables = [arrow.read_table(folder / name) for name in sorted(manifest["shards"])]
    return pa.concat_tables(tables) if tables else pa.table({})


def verify_run(root) -> dict:
    """A finished run's manifest, after checking the manifest and every file it lists (size
    and sha256)."""
    root = Path(root)
    remedy = "re-run estimate (it recomputes a damaged run)"
    if not (root / MANIFEST).exists():
        raise InputError(f"no finished run at {root}: run `python -m pipeline.estimate` first")
    manifest = read_sealed_manifest(root / MANIFEST, "run", RUN_FORMAT, RUN_FORMAT_VERSION,
                                    remedy)
    shards, files = manifest.get("shards"), manifest.get("files")
    if not isinstance(shards, dict) or not isinstance(files, dict):
        raise IntegrityError(f"{root / MANIFEST}: damaged run manifest; {remedy}")
    listed = {**{f"{ESTIMATES}/{k}": v for k, v in shards.items()}, **files}
    # the folder is read whole (pd.read_parquet): a file it holds that is not the run's would
    # join its estimates (temporaries, hidden, are skipped by the readers)
    folder = root / ESTIMATES
    strays = sorted(p.name for p in folder.iterdir() if not p.name.startswith((".", "_"))
                    and p.name not in shards) if folder.is_dir() else []
    if strays:
        raise IntegrityError(f"{folder / strays[0]}: not one of the run's shard files, yet "
                             f"read with them as its estimates; {remedy}")
    for relpath, record in listed.items():
        path = root / relpath
        if not path.is_file() or file_record(path) | {"rows": record.get("rows")} != record:
            raise IntegrityError(f"{path}: missing or different from its run manifest; {remedy}")
    return manifest


def seconds_per_track(root) -> float:
    """Wall seconds per track of a finished run, over its shards (``timing.json``: not
    hashed, so not verified); NaN when it is absent or unreadable."""
    try:
        shards = json.loads((Path(root) / TIMING).read_text())["shards"].values()
        return sum(s["seconds"] for s in shards) / sum(s["rows"] for s in shards)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, ZeroDivisionError):
        return float("nan")
