"""The estimate stage: (dataset, estimator config) -> a run directory.

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
import logging
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter

import numpy as np
import pyarrow as pa

from tma.config import to_plain
from tma.errors import ConfigError, InputError, IntegrityError, TmaError
from tma.families import build_estimator, estimator_class, scenario_module
from tma.io import arrow
from tma.io.atomic import sha256_json, write_json_atomic, write_parquet_atomic
from tma.io.dataset import Dataset, file_record, read_sealed_manifest, sealed
from tma.io.owned import building
from tma.io.shards import finished_record, mark_finished
from tma.runtime.parallel import in_threads, iter_tasks
from tma.version import __version__

log = logging.getLogger(__name__)
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


def check_compatible(dataset: Dataset, estimator_config: dict):
    cls = estimator_class(estimator_config["name"])
    if cls.family != dataset.family:
        raise ConfigError(
            f"estimator '{cls.name}' reads '{cls.family}' datasets, but {dataset.name} is a "
            f"'{dataset.family}' dataset"
        )


def columns_to_table(track_id, columns: dict) -> pa.Table:
    """Estimator output -> table. Columns are (n_tracks,) or, for per-step outputs such as
    filter estimates at every scan, (n_tracks, n_steps): then the table is long, one row per
    (track_id, step), and per-track columns repeat on each of their rows."""
    steps = {c.shape[1] for c in columns.values() if np.ndim(c) == 2}
    if not steps:
        return arrow.table({"track_id": track_id, **columns})
    if len(steps) > 1:
        raise ValueError(f"per-step columns disagree on the number of steps: {steps}")
    n_steps = steps.pop()
    long = {"track_id": np.repeat(track_id, n_steps),
            "step": np.tile(np.arange(n_steps, dtype=np.int64), track_id.size)}
    for name, col in columns.items():
        long[name] = np.ravel(col) if np.ndim(col) == 2 else np.repeat(col, n_steps)
    return arrow.table(long)


def extra_path(shard_out: Path, name: str) -> Path:
    """Where the side table ``name`` of the shard whose estimates are ``shard_out`` goes:
    in ``shards/``, so that ``estimates/`` holds the estimates alone."""
    return shard_out.parent.parent / SHARDS / f"{shard_out.stem}.{name}.parquet"


def record_path(shard_out: Path) -> Path:
    """The record (``tma.io.shards`` sidecar) of the shard whose estimates are ``shard_out``,
    in ``shards/``."""
    return shard_out.parent.parent / SHARDS / f"{shard_out.name}.done.json"


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
    whole = (record is not None and isinstance(record.get("extras"), list)
             and all(isinstance(record.get(k), int) for k in ("rows", "epochs"))
             and isinstance(record.get("seconds"), int | float))
    return record if whole else None


def estimate_log(estimator, log):
    """``estimator`` over one log: its output as a table (a row per track, ``track_id``
    first), its side tables (small tables it declares, e.g. sample points for plots) and the
    seconds it took. What every shard of a run, and ``tma.estimate``, computes."""
    start = perf_counter()
    columns = estimator.estimate(log)
    seconds = perf_counter() - start
    extras = columns.pop("extras", {})
    if not set(extras) <= set(estimator.side_tables):  # a shard may hold none of them
        raise RuntimeError(f"estimator '{estimator.name}' returned side tables "
                           f"{sorted(extras)}, declared {sorted(estimator.side_tables)}")
    return columns_to_table(log.track_id, columns), extras, seconds


AHEAD_TRACKS = 2  # tracks of the small log each estimator of a command runs on ahead
_AHEAD: set = set()  # the estimators compile_ahead started in this process


def compile_ahead(scenarios: list[dict], estimators: list[dict]):
    """Start compiling the kernels a command will run, in processes of their own forked from
    the command's worker server (``tma.runtime.forkserver``), while the command goes on
    (composing, simulating): on a machine whose numba cache is empty, the estimate stage's
    workers then find the kernels compiled, or wait for the compilation under way
    (``tma.runtime.jit.compiling``) instead of each compiling them. Each estimator config
    of ``estimators`` runs in a process of its own (their kernels compile side by side) on a
    log of ``AHEAD_TRACKS`` tracks of each scenario point of ``scenarios`` of its family (the
    same code paths, so the same kernels and argument types), unless numba's cache holds
    kernels of their families already (``compiled_before``: then nothing runs, and a kernel
    still missing is compiled by the first worker that needs it, once). Nothing is printed
    and failures are ignored: the stages run as they would without it. Started from a
    thread, so that the command does not wait for the server to be ready; None (nothing
    started) without a worker server (a Python session), without scenarios or when this
    process started it for these estimators before, else that thread."""
    from tma.runtime.forkserver import server_started

    names = {node.get("name") for node in estimators}
    if not server_started() or not scenarios or names <= _AHEAD:
        return None  # e.g. the next job of a multirun in this process: done by the first
    _AHEAD.update(names)
    import multiprocessing
    import threading

    process = multiprocessing.get_context("forkserver").Process(
        target=_compile_ahead, args=(scenarios, estimators), daemon=True,
        name="tma-compile-ahead")
    thread = threading.Thread(target=process.start, daemon=True)
    thread.start()
    return thread


def _compile_ahead(scenarios: list[dict], estimators: list[dict]) -> None:
    import os

    from tma.families import load_scenario
    from tma.runtime import jit

    built = []
    for node in estimators:
        try:
            built.append(build_estimator(node))  # imports its modules, and so their kernels
        except Exception:  # the command itself says what is wrong with it
            continue
    if all(jit.compiled_before(f"tma.families.{f}") for f in {e.family for e in built}):
        return  # this machine compiled them before: nothing to do ahead
    logs = []
    for node in scenarios:
        try:
            module, cfg = load_scenario({**node, "n_tracks": AHEAD_TRACKS,
                                         "shard_size": AHEAD_TRACKS})
            logs.append((cfg.own_family(), module.simulate_shard(cfg, 0)[0]))
        except Exception:
            continue
    children = []
    for i, estimator in enumerate(built):
        child = os.fork() if i < len(built) - 1 else 0  # the last runs in this process
        if child:
            children.append(child)
            continue
        try:
            for family, log in logs:
                if family == estimator.family:
                    estimate_log(estimator, log)
        except Exception:  # e.g. an estimator that needs its prepare (training)
            pass
        finally:
            if i < len(built) - 1:  # a forked process: ends here, whatever happened
                os._exit(0)
    for child in children:
        os.waitpid(child, 0)


def estimate_shard(task: ShardTask, log) -> dict:
    """Run one estimator over one dataset shard's log and write its output."""
    out = Path(task.out_path)
    estimator = build_estimator(task.estimator_config)
    estimator.data_dir = Path(task.data_dir)
    table, extras, seconds = estimate_log(estimator, log)
    for name, side in extras.items():  # written beside the shard
        write_parquet_atomic(extra_path(out, name), arrow.table(side))
    write_parquet_atomic(out, table)
    epochs = int(log.t_s.size)
    return mark_finished(out, task.key, record_path(out), rows=int(log.n_tracks),
                         epochs=epochs, seconds=seconds, extras=sorted(extras))


def dataset_config(dataset: Dataset, estimator_config: dict, keep=()) -> dict:
    """``estimator_config`` as it runs on ``dataset``: on a recorded log (a dataset that was
    not simulated) the estimator's ``recorded_defaults`` replace its values, except for the
    keys in ``keep`` (those the command line sets)."""
    if dataset.manifest["source"] == "simulate":
        return estimator_config
    recorded = estimator_class(estimator_config["name"]).recorded_defaults
    return {**estimator_config, **{k: v for k, v in recorded.items() if k not in keep}}


def full_config(dataset: Dataset, estimator_config: dict) -> dict:
    """The estimator config with every default filled in (the run key hashes it, so it
    changes with them), checked against the dataset's family."""
    check_compatible(dataset, estimator_config)
    return to_plain(build_estimator(estimator_config).config)


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
    for name in sorted({n for r in records for n in r.get("extras", [])}):
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


def seconds_per_track(root) -> float:
    """Wall seconds per track of a finished run, over its shards (``timing.json``: not
    hashed, so not verified); NaN when it is absent or unreadable."""
    try:
        shards = json.loads((Path(root) / TIMING).read_text())["shards"].values()
        return sum(s["seconds"] for s in shards) / sum(s["rows"] for s in shards)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, ZeroDivisionError):
        return float("nan")


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


def check_datasets(datasets) -> None:
    """``Dataset.check_files`` of each dataset once, however many jobs read it: a missing or
    truncated file stops the stage before it starts. Each file's sha256 is checked where its
    bytes are read (an estimate worker its shard, a report the truth), so no stage reads a
    dataset twice and every byte read is verified."""
    for dataset in {id(ds): ds for ds in datasets}.values():
        dataset.check_files()


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


def missing_run_line(data_dir, dataset: Dataset, config: dict) -> str:
    """One line for a run of ``config`` (full, as ``run_path`` hashes it) on ``dataset`` that
    does not exist: the finished runs of ``dataset`` that do, each with the overrides that
    select it (``estimator=NAME`` and the values that differ from NAME's on this dataset)."""
    from tma.plan.points import override_text

    found, stale = [], 0
    for path in sorted((runs_dir(data_dir) / dataset.name).glob(f"*/{MANIFEST}")):
        try:
            manifest = read_sealed_manifest(path, "run", RUN_FORMAT, RUN_FORMAT_VERSION, "")
            name = manifest["config"]["name"]
            base = full_config(dataset, dataset_config(dataset, {"name": name}))
        except (TmaError, OSError, KeyError, TypeError):
            continue  # not a run this tma can read: not one to offer
        if (manifest.get("dataset", {}).get("content_hash") != dataset.content_hash
                or manifest.get("package", {}).get("version") != __version__):
            stale += 1  # of another content of the dataset, or another tma: not selectable
            continue
        selected = [f"estimator={name}"] + [
            override_text(f"estimator.{key}", value) for key, value in
            _differing(manifest["config"], base)]
        found.append(f"{path.parent.name} ({' '.join(selected)})")
    line = (f"no finished run of {config['name']} on dataset {dataset.name} with these "
            f"settings ({run_path(data_dir, dataset, config).name}): make it with "
            "`python -m pipeline.estimate` and the same overrides")
    if found:
        line += f", or aggregate a run that exists: {'; '.join(found)}"
    if stale:
        line += (f" ({stale} other run(s) of {dataset.name} were made from another content "
                 "of the dataset or by another tma version)")
    return line


def _differing(config: dict, base: dict, prefix: str = ""):
    """``(dotted key, value)`` of ``config`` that differ from ``base``, for keys ``base`` has
    (a prepared config's records, e.g. an artefact's hash, are no option)."""
    for key, value in config.items():
        if key not in base:
            continue
        if isinstance(value, dict) and isinstance(base[key], dict):
            yield from _differing(value, base[key], f"{prefix}{key}.")
        elif value != base[key]:
            yield f"{prefix}{key}", value


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
