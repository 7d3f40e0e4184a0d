"""The estimate stage: (dataset, estimator config) -> a run directory (its layout, key and
readers: ``tma.io.runs``).

Each shard of the dataset is a task: its log is read and verified once, every estimator of the
command on it gives its ``Estimates`` (``tma.estimator``), written as the shard's file of the
run's ``estimates/`` and its side tables; the run is finished (its side tables concatenated,
its manifest sealed) and swapped in as soon as its last shard is in.
"""

import logging
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter

import numpy as np
import pyarrow as pa

from tma.errors import TmaError
from tma.estimator import Estimates
from tma.families import build_estimator, estimator_class, scenario_module
from tma.io import arrow
from tma.io.atomic import sha256_json, write_json_atomic, write_parquet_atomic
from tma.io.dataset import Dataset, check_datasets, file_record, sealed
from tma.io.owned import building
from tma.io.runs import (
    ESTIMATES,
    MANIFEST,
    RUN_FORMAT,
    RUN_FORMAT_VERSION,
    SHARDS,
    TIMING,
    extra_path,
    record_path,
    run_key,
    run_path,
    verify_run,
)
from tma.io.shards import finished_record, mark_finished
from tma.plan.datasets import full_config
from tma.runtime.parallel import in_threads, iter_tasks
from tma.version import __version__

log = logging.getLogger(__name__)


def columns_to_table(track_id, columns: dict) -> pa.Table:
    """``Estimates.columns`` (checked: ``Estimates.check``) -> table: a row per track or, with
    per-step outputs such as filter estimates at every scan, (n_tracks, n_steps), a long table,
    one row per (track_id, step), the per-track columns repeated on each of their rows."""
    steps = {c.shape[1] for c in columns.values() if np.ndim(c) == 2}
    if not steps:
        return arrow.table({"track_id": track_id, **columns})
    n_steps = steps.pop()
    long = {"track_id": np.repeat(track_id, n_steps),
            "step": np.tile(np.arange(n_steps, dtype=np.int64), track_id.size)}
    for name, col in columns.items():
        long[name] = np.ravel(col) if np.ndim(col) == 2 else np.repeat(col, n_steps)
    return arrow.table(long)


@dataclass(frozen=True)
class ShardTask:
    dataset_root: str
    shard: str
    estimator_config: dict
    out_path: str
    key: str
    data_dir: str


def estimate_shard_group(tasks: list[ShardTask]) -> list[dict]:
    """Run several estimators over one dataset shard (worker function): the log is read and
    verified once; each estimator's output and timing are its own."""
    records = [_finished_record(t) for t in tasks]
    todo = [i for i, r in enumerate(records) if r is None]
    if todo:
        dataset = Dataset.open(tasks[todo[0]].dataset_root)
        log = scenario_module(dataset.family).read_log(
            dataset.verified_path(tasks[todo[0]].shard))
        for i in todo:
            records[i] = estimate_shard(tasks[i], log)
    return records


def _finished_record(task: ShardTask):
    """The sidecar record of a finished shard output, if it is whole (else: recompute)."""
    record = finished_record(task.out_path, task.key, record_path(Path(task.out_path)))
    whole = (record is not None and isinstance(record.get("side_tables"), list)
             and all(isinstance(record.get(k), int) for k in ("rows", "epochs"))
             and isinstance(record.get("seconds"), int | float))
    return record if whole else None


def estimate_log(estimator, log):
    """``estimator`` over one log: its output as a table (a row per track, ``track_id``
    first), its side tables (small tables it declares, e.g. sample points for plots) and the
    seconds it took. What every shard of a run, and ``tma.estimate``, computes."""
    start = perf_counter()
    out = estimator.estimate(log)
    seconds = perf_counter() - start
    if not isinstance(out, Estimates):
        raise RuntimeError(f"estimator '{estimator.name}' returned a {type(out).__name__}, "
                           "not Estimates (tma.estimator)")
    out.check(estimator, log.track_id.size)
    return columns_to_table(log.track_id, out.columns), out.side_tables, seconds


def estimate_shard(task: ShardTask, log) -> dict:
    """Run one estimator over one dataset shard's log and write its output."""
    out = Path(task.out_path)
    estimator = build_estimator(task.estimator_config, task.data_dir)
    table, side_tables, seconds = estimate_log(estimator, log)
    for name, side in side_tables.items():  # written beside the shard
        write_parquet_atomic(extra_path(out, name), arrow.table(side))
    write_parquet_atomic(out, table)
    epochs = int(log.t_s.size)
    return mark_finished(out, task.key, record_path(out), rows=int(log.n_tracks),
                         epochs=epochs, seconds=seconds, side_tables=sorted(side_tables))


def plan_run(data_dir, dataset: Dataset, estimator_config: dict, key: str, stage: Path):
    """Shard tasks of one run of key ``key`` (``estimator_config`` after ``prepare``),
    writing into ``stage``."""
    tasks = []
    for shard in dataset.shard_paths:
        out = stage / ESTIMATES / (Path(shard).stem + ".parquet")
        shard_key = sha256_json({"run": key, "shard": shard,
                                 "sha256": dataset.manifest["shards"][shard]["sha256"]})
        tasks.append(ShardTask(str(dataset.root), shard, estimator_config, str(out), shard_key,
                               str(data_dir)))
    return tasks


def _summary(paths) -> tuple[int, list[str], "pa.Table"]:
    """Rows, column names and the ``converged``/``status``/``step`` columns of the shard
    files ``paths`` read as one dataset; a ValueError when their schemas differ (the folder
    would not read as one table)."""
    import pyarrow.parquet as pq

    files = [pq.ParquetFile(p) for p in paths]
    schema = files[0].schema_arrow if files else pa.schema([])
    for path, f in zip(paths, files, strict=True):
        if not f.schema_arrow.equals(schema):
            raise ValueError(f"{path}: its columns differ from the first shard's "
                             f"({f.schema_arrow} against {schema}): the shards of a run must "
                             "have one schema")
    wanted = [c for c in ("converged", "status", "step") if c in schema.names]
    table = pa.concat_tables([f.read(columns=wanted) for f in files]) if files else pa.table({})
    return sum(f.metadata.num_rows for f in files), schema.names, table


def finish_run(stage: Path, dataset: Dataset, estimator_config: dict, tasks, records) -> None:
    """Write the run manifest (the shard files of ``estimates/`` checked to read as one
    table) and its side tables, each concatenated over the shards."""
    import pyarrow.compute as pc  # here: a re-run whose runs are all done needs none of it

    folder = stage / ESTIMATES
    folder.mkdir(exist_ok=True)  # a dataset without shards: an empty folder
    ours = {Path(t.out_path).name for t in tasks}
    for path in folder.iterdir():  # a damaged run's stray file: it would join the estimates
        if path.name not in ours and not path.name.startswith((".", "_")):
            shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
    # what a run of format 2 adopted here left: its concatenated copy and its shard outputs
    (stage / "estimates.parquet").unlink(missing_ok=True)
    for path in (stage / SHARDS).glob("shard-*.parquet"):
        if re.fullmatch(r"shard-\d+\.parquet", path.name):
            path.unlink()
    n_rows, columns, table = _summary([t.out_path for t in tasks])
    shards = {Path(t.out_path).name: file_record(t.out_path, rows=r["rows"])
              for t, r in zip(tasks, records, strict=True)}
    files = {}
    for name in sorted({n for r in records for n in r.get("side_tables", [])}):
        parts = [extra_path(Path(t.out_path), name) for t in tasks]
        extra = pa.concat_tables(arrow.read_table(p) for p in parts if p.exists())
        write_parquet_atomic(stage / f"{name}.parquet", extra)
        files[f"{name}.parquet"] = file_record(stage / f"{name}.parquet", rows=extra.num_rows)
    manifest = sealed({
        "format": RUN_FORMAT,
        "format_version": RUN_FORMAT_VERSION,
        "estimator": estimator_config["name"],
        "config": estimator_config,
        "dataset": {"name": dataset.name, "family": dataset.family,
                    "content_hash": dataset.content_hash},
        "package": {"name": "tma", "version": __version__},
        "shards": shards,
        "files": files,
        "n_tracks": n_rows,
        **({"n_converged": int(pc.sum(table["converged"]).as_py() or 0)}
           if "converged" in columns else {}),
        **({"status_counts": dict(sorted(
            (str(v["values"]), int(v["counts"]))
            for v in pc.value_counts(table["status"]).to_pylist()))}
           if "status" in columns and "step" not in columns else {}),
    })
    write_json_atomic(stage / MANIFEST, manifest)
    timing = {"shards": {Path(t.out_path).name: {"seconds": r["seconds"], "rows": r["rows"],
                                                 "epochs": r["epochs"]}
                         for t, r in zip(tasks, records, strict=True)}}
    write_json_atomic(stage / TIMING, timing)


def _is_good(root: Path) -> bool:
    """True if the run at ``root`` exists and verifies; a damaged one is logged."""
    if not root.exists():
        return False
    try:
        verify_run(root)  # its estimates are not read: a finished run is only reused
        return True
    except TmaError as exc:
        log.warning("%s; computing the run again", exc)
        return False


def estimate_runs(data_dir, jobs, *, engine=2, progress=True, force=False
                  ) -> list[tuple[Path, bool]]:
    """Run every (dataset, estimator config) job, all shards in one worker pool; returns each
    job's run directory and whether it was reused (finished before and verified)."""
    check_datasets(ds for ds, _ in jobs)
    planned = []
    for dataset, est_cfg in jobs:
        est_cfg = full_config(dataset, est_cfg)
        planned.append((run_path(data_dir, dataset, est_cfg), dataset, est_cfg))
    with building([p[0] for p in planned]) as outputs:  # one process per run; others wait
        return _estimate_locked(outputs, data_dir, planned, engine=engine, progress=progress,
                                force=force)


def _estimate_locked(outputs, data_dir, planned, *, engine, progress, force):
    # finished runs are reused once their files verify, checked several at a time
    reuse = [False] * len(planned) if force else in_threads(_is_good, [p[0] for p in planned])
    todo, tasks = [], []
    for (root, dataset, est_cfg), good in zip(planned, reuse, strict=True):
        if good or any(p[0] == root for p in todo):
            continue
        # a broken run is adopted: its verified shards are reused, the rest recomputed
        stage = outputs.stage(root, fresh=force, adopt=True)
        # the key hashes the config before prepare, so training (an artefact the prepared
        # config records by content hash) happens only when the run must be computed
        key = run_key(dataset, est_cfg)
        est_cfg = estimator_class(est_cfg["name"]).prepare(est_cfg, dataset, data_dir, engine,
                                                           progress)
        run_tasks_ = plan_run(data_dir, dataset, est_cfg, key, stage)
        todo.append((root, stage, dataset, est_cfg, run_tasks_))
        tasks += run_tasks_
    groups = {}  # every estimator on the same dataset shard shares one read of the log
    for t in tasks:
        groups.setdefault((t.dataset_root, t.shard), []).append(t)
    done, waiting = {}, {id(run): len(run[4]) for run in todo}  # shards still to come
    run_of = {t.out_path: run for run in todo for t in run[4]}
    for root, stage, dataset, est_cfg, ts in todo:
        if not ts:  # a dataset without shards: nothing to wait for
            finish_run(stage, dataset, est_cfg, ts, [])
            outputs.swap(root)
    # each run is finished (concatenated, sealed, swapped in) as soon as its last shard is
    # in, while the workers go on with the next runs' shards
    for group, records in zip(groups.values(), iter_tasks(
            estimate_shard_group, list(groups.values()), engine=engine, desc="estimate",
            progress=progress), strict=True):
        for t, record in zip(group, records, strict=True):
            done[t.out_path] = record
            root, stage, dataset, est_cfg, ts = run = run_of[t.out_path]
            waiting[id(run)] -= 1
            if not waiting[id(run)]:
                finish_run(stage, dataset, est_cfg, ts, [done[u.out_path] for u in ts])
                outputs.swap(root)
    return [(p[0], good) for p, good in zip(planned, reuse, strict=True)]
