"""The aggregate stage: finished runs -> per-track metrics (Parquet) -> tables and plots.

Each family's aggregate module (``tma.families.<name>.aggregate``) provides
``aggregate_runs(entries, tables_dir, table_name, progress, table_kind)`` where ``entries`` are
``RunEntry`` items (``progress``: progress bars, None: on a terminal); it writes per-track
metrics into each run directory and returns the table files it wrote. ``metrics_dataset``
reads the metrics of every run back as one Parquet dataset.
"""

import functools
import json
import operator
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pyarrow as pa
import pyarrow.parquet as pq

if TYPE_CHECKING:  # pandas (0.2 s) and pyarrow.dataset load where used, not at start-up
    import pandas as pd
    import pyarrow.dataset as pds

from tma.errors import ConfigError, InputError
from tma.families import family as family_of
from tma.io.dataset import Dataset, check_datasets, datasets_dir
from tma.io.owned import plain_name, remove_stale_temporaries
from tma.io.runs import MANIFEST, open_run, run_path, runs_dir, seconds_per_track
from tma.plan.datasets import full_config, missing_run_line
from tma.runtime.parallel import in_threads


@dataclass
class RunEntry:
    """A finished run as a report sees it: its dataset, estimator, directory, manifest and
    estimates, and its wall seconds per track (``tma.io.runs.seconds_per_track``; NaN when
    unknown), read once here."""

    dataset: Dataset
    estimator: str
    run_root: Path
    manifest: dict
    estimates: "pd.DataFrame"
    seconds_per_track: float = float("nan")


def aggregate(data_dir, tables_dir, jobs, table=None, default_suffix="custom",
              progress=None, table_kind=None) -> list[Path]:
    """Aggregate the runs of ``jobs`` (``(Dataset, estimator config)`` pairs) into one table
    per family: ``table`` (``<table>-<family>`` when several families), else
    ``<dataset>-<estimator>`` for a single run, else ``<family>-<default_suffix>``.
    ``progress``: progress bars where a report draws per-contact outputs (None: on a
    terminal only; the stage passes its ``progress`` option); ``table_kind``: the kind of
    table, one the family's aggregate module offers (``TABLE_KINDS``; None: its own)."""
    runs = check_runs(data_dir, jobs)
    opened = in_threads(open_run, [root for _, _, root in runs])  # verified and read
    by_family: dict[str, list[RunEntry]] = {}
    for (dataset, estimator, root), (manifest, estimates) in zip(runs, opened, strict=True):
        remove_stale_temporaries(root, only_dead=True)
        by_family.setdefault(dataset.family, []).append(
            RunEntry(dataset, estimator, root, manifest, estimates.to_pandas(),
                     seconds_per_track(root)))
    written = []
    for family in by_family:
        kinds = getattr(family_of(family).aggregate, "TABLE_KINDS", {})
        if table_kind is not None and table_kind not in kinds:
            raise ConfigError(f"table_kind={table_kind}: {family} has no such table; its kinds: "
                              + (", ".join(kinds) or "none but its own (table_kind=null)"))
        recorded = [e.dataset.name for e in by_family[family]
                    if e.dataset.manifest["source"] != "simulate"]
        if table_kind is not None and len(recorded) == len(by_family[family]):
            raise ConfigError(f"table_kind={table_kind}: a table of simulated runs against "
                              f"their truth; {', '.join(sorted(set(recorded)))} is a recorded "
                              "log (no truth), whose table is the per-contact report: drop "
                              "table_kind=")
    for family, entries in by_family.items():
        module = family_of(family).aggregate
        if table is not None:
            name = table if len(by_family) == 1 else f"{table}-{family}"
        elif len(entries) == 1:
            name = f"{entries[0].dataset.name}-{entries[0].estimator}"
        else:
            name = f"{family}-{default_suffix}"
        written += module.aggregate_runs(entries, Path(tables_dir), name, progress=progress,
                                         table_kind=table_kind)
    for path in written:  # what a killed aggregate left of these files, and nothing else
        remove_stale_temporaries(path.parent, only_dead=True, names=[path.name])
    return written


def check_runs(data_dir, jobs) -> list[tuple[Dataset, str, Path]]:
    """``(dataset, estimator name, run directory)`` of each of ``jobs``, each run finished (an
    InputError naming the runs made otherwise)."""
    check_datasets(ds for ds, _ in jobs)
    runs = []
    for dataset, est_cfg in jobs:
        est_cfg = full_config(dataset, est_cfg)  # no prepare: aggregate trains nothing
        runs.append((dataset, est_cfg["name"], run_path(data_dir, dataset, est_cfg)))
        if not (runs[-1][2] / MANIFEST).exists():  # none of these settings: name those made
            raise InputError(missing_run_line(data_dir, dataset, est_cfg))
    return runs


def _import_aggregate(name: str):
    try:
        family_of(name).aggregate  # noqa: B018 (imported for its side effect: the module loaded)
    except Exception:  # left for the aggregate stage, which imports it again and says why
        pass


def prefetch_aggregate(name: str) -> threading.Thread | None:
    """Import family ``name``'s aggregate module (matplotlib, about 0.5 s) in a thread, e.g.
    while the workers estimate and the caller mostly waits for them, so that aggregate
    starts with it loaded; join the thread before aggregating. None when ``name`` is no
    family (the stages say what is wrong)."""
    from tma.families import NAMES

    if name not in NAMES:
        return None
    thread = threading.Thread(target=_import_aggregate, args=(name,), daemon=True)
    thread.start()
    return thread


# -- every run's metrics as one dataset -------------------------------------------------------

KEY_COLUMNS = ("family", "dataset", "estimator", "run")


def sweep_record(sweep: str | None, job: int, data_dir, tables_dir, jobs,
                 table_kind=None) -> dict:
    """What one aggregate job of a sweep read (its runs, the kind of table), for
    ``aggregate_sweep``."""
    return {"sweep": sweep, "job": job, "data_dir": str(Path(data_dir).resolve()),
            "table_kind": table_kind,
            "tables_dir": str(Path(tables_dir).resolve()),
            "runs": [{"dataset": str(Path(ds.root).resolve()), "estimator": est}
                     for ds, est in jobs]}


def sweep_table(sweep_dir, sweep: str, record_name: str, table: str | None = None
                ) -> list[Path]:
    """``aggregate_sweep`` of the records (files ``record_name`` under ``sweep_dir``, written
    by the aggregate jobs of a sweep) tagged ``sweep``."""
    records = [record for path in Path(sweep_dir).rglob(record_name)
               if (record := json.loads(path.read_text())).get("sweep") == sweep]
    return aggregate_sweep(records, table)


def aggregate_sweep(records: list[dict], table: str | None = None) -> list[Path]:
    """One table of every run the aggregate jobs of a sweep read (their ``sweep_record``s):
    ``table``, default ``<family>-sweep``; each run once, in job order."""
    if table is not None:
        plain_name(table, "table")
    groups: dict[tuple, dict] = {}
    for record in sorted(records, key=lambda r: r["job"]):
        runs = groups.setdefault((record["data_dir"], record["tables_dir"]), {})
        for run in record["runs"]:
            runs.setdefault((run["dataset"], json.dumps(run["estimator"], sort_keys=True)), run)
    written = []
    for (data_dir, tables_dir), runs in groups.items():
        jobs = [(Dataset.open(r["dataset"]), r["estimator"]) for r in runs.values()]
        kind = next((r.get("table_kind") for r in records), None)
        written += aggregate(data_dir, tables_dir, jobs, table=table, default_suffix="sweep",
                             table_kind=kind)
    return written


def _flat(node, prefix: str) -> dict:
    """Scalar leaves of a nested config as ``{prefix.dotted.key: value}`` (lists left out)."""
    out = {}
    for key, value in node.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}.{key}"))
        elif value is None or isinstance(value, bool | int | float | str):
            out[f"{prefix}.{key}"] = value
    return out


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _constant_type(values: list) -> pa.DataType:
    present = [v for v in values if v is not None]
    try:
        return pa.array(present).type
    except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed types: compare as text
        return pa.string()


def runs_without_metrics(data_dir="data", family=None, name="metrics") -> list[str]:
    """Runs (``<dataset>/<run>``) under ``<data_dir>/runs/`` that are finished (a manifest)
    but hold no ``<name>.parquet``: never aggregated, or computed again since
    (``estimate force=true`` removes it); ``metrics_dataset`` cannot include them. Runs of
    recorded logs are not among them: with no truth they never have metrics
    (``recorded_runs``)."""
    return [run for run, recorded, has in _finished_runs(data_dir, family, name)
            if not has and not recorded]


def recorded_runs(data_dir="data", family=None) -> list[str]:
    """The finished runs under ``<data_dir>/runs/`` of recorded logs (ingested datasets):
    no truth, so no per-track metrics; their results are the per-contact tables aggregate
    writes."""
    return [run for run, recorded, _ in _finished_runs(data_dir, family) if recorded]


def _finished_runs(data_dir, family, name="metrics") -> list[tuple[str, bool, bool]]:
    """``(<dataset>/<run>, of a recorded log?, holds <name>.parquet?)`` of every finished run
    (of ``family``, a known family, when given)."""
    if family is not None:
        family_of(family)  # a ConfigError naming the families for another name
    out = []
    for manifest_path in sorted(runs_dir(data_dir).glob(f"*/*/{MANIFEST}")):
        run_root = manifest_path.parent
        if run_root.name.startswith(".") or run_root.parent.name.startswith("."):
            continue  # staging directories
        if family is not None and (_read_json(manifest_path).get("dataset") or {}).get(
                "family") != family:
            continue
        source = _read_json(datasets_dir(data_dir) / run_root.parent.name / MANIFEST).get(
            "source")
        out.append((f"{run_root.parent.name}/{run_root.name}",
                    source not in (None, "simulate"), (run_root / f"{name}.parquet").exists()))
    return out


def _run_files(run_root: Path, name: str) -> list[Path]:
    """A run's ``<name>.parquet``, or the shard files of its folder ``<name>/`` (a run's
    ``estimates``), in shard order; none when it has neither."""
    if (run_root / f"{name}.parquet").is_file():
        return [run_root / f"{name}.parquet"]
    return sorted(p for p in (run_root / name).glob("*.parquet") if not p.name.startswith("."))


def metrics_dataset(data_dir="data", name="metrics", family=None) -> "pds.Dataset":
    """Every run's ``<name>.parquet`` (``metrics``, written by aggregate), or the files of its
    folder ``<name>`` (``estimates``: a file per shard), under ``<data_dir>/runs/`` as one
    ``pyarrow.dataset``, nothing loaded yet (runs in name order, each run's files in shard
    order). Besides the file's
    own columns each row carries its run's ``family``, ``dataset``, ``estimator`` and ``run``
    (directory name) and its config values ``scenario.<key>`` (from the dataset manifest)
    and ``estimator.<key>`` (from the run manifest; nested keys dotted, lists left out),
    constant per file, so filters on them skip whole files::

        ds = metrics_dataset("data", family="bearings2d")
        ds.to_table(filter=pc.field("scenario.sigma_deg") == 0.5).to_pandas()

    Runs of several families share one schema (their columns' union, null where absent);
    a column whose types disagree between files fails: give ``family``.
    """
    import pyarrow.compute as pc
    import pyarrow.dataset as pds
    import pyarrow.fs as pafs

    if family is not None:
        family_of(family)  # a ConfigError naming the families for another name
    constants, paths = [], []
    root = runs_dir(data_dir)
    for run_root in sorted(path.parent for path in root.glob(f"*/*/{MANIFEST}")):
        files = _run_files(run_root, name)
        if not files or run_root.name.startswith(".") or run_root.parent.name.startswith("."):
            continue  # none of these files, or a staging directory
        manifest = _read_json(run_root / MANIFEST)
        dataset = manifest.get("dataset", {})
        if family is not None and dataset.get("family") != family:
            continue
        scenario = _read_json(datasets_dir(data_dir) / run_root.parent.name / MANIFEST)
        constants.append({"family": dataset.get("family"), "dataset": run_root.parent.name,
                          "estimator": manifest.get("estimator"), "run": run_root.name,
                          **_flat(scenario.get("config") or {}, "scenario"),
                          **_flat(manifest.get("config") or {}, "estimator")})
        constants[-1].pop("scenario.family", None)  # the same as family
        constants[-1].pop("estimator.name", None)  # the same as estimator
        constants += [constants[-1]] * (len(files) - 1)  # the same run's for each file
        paths += files
    if not paths:
        recorded = recorded_runs(data_dir, family)
        raise InputError(f"no {name}.parquet in any run under {root}"
                         + (f" of family '{family}'" if family else "")
                         + (f": the {len(recorded)} run(s) there are of recorded logs, which "
                            "have no truth to measure against (their per-contact results are "
                            "the tables aggregate writes, tables/<dataset>-<estimator>.csv)"
                            if recorded and not runs_without_metrics(data_dir, family, name)
                            else ": run `python -m pipeline.aggregate` first"))
    try:
        schema = pa.unify_schemas([pq.read_schema(p).remove_metadata() for p in paths],
                                  promote_options="permissive")
    except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
        raise InputError(f"the {name}.parquet files of several families disagree ({exc}); "
                         "give family=") from None
    keys = list(dict.fromkeys(k for c in constants for k in c))
    types = {k: _constant_type([c.get(k) for c in constants]) for k in keys}
    keys = [k for k in keys if types[k] != pa.null() and k not in schema.names]
    for k in keys:
        schema = schema.append(pa.field(k, types[k]))
    fmt, local = pds.ParquetFileFormat(), pafs.LocalFileSystem()
    fragments = []
    for path, const in zip(paths, constants, strict=True):
        terms = []
        for k in keys:
            value = const.get(k)
            if value is None:
                terms.append(pc.field(k).is_null())
            else:
                value = str(value) if types[k] == pa.string() else value
                terms.append(pc.field(k) == pa.scalar(value, types[k]))
        fragments.append(fmt.make_fragment(str(path), filesystem=local,
                                           partition_expression=functools.reduce(
                                               operator.and_, terms)))
    return pds.FileSystemDataset(fragments, schema, fmt, local)
