"""The simulate stage: scenario configs -> datasets (MCAP shards, truth, manifest).

Every shard of every requested dataset is one task, so all shards share one worker pool.
Each dataset is built in its staging directory and swapped in when complete (``tma.io.owned``);
a shard whose MCAP and truth part are finished there (sidecar with matching key and hash) is
reused, so a killed run resumes. A dataset that exists and verifies is kept unless ``force``;
one that fails verification (damaged, edited, of an older format) is simulated again.
"""

import logging
import shutil
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from tma.config import to_plain
from tma.errors import ConfigError, TmaError
from tma.families import dataset_name, load_scenario
from tma.io import arrow
from tma.io.atomic import sha256_json, write_parquet_atomic
from tma.io.dataset import Dataset, datasets_dir, file_record, shard_relpath, write_manifest
from tma.io.owned import building
from tma.io.shards import finished_record, mark_finished, sidecar
from tma.runtime.parallel import in_threads, run_tasks
from tma.runtime.sharding import n_shards
from tma.version import __version__

log = logging.getLogger(__name__)
PARTS = "parts"
MAX_SHARDS = 100_000  # each shard is a task and a file; beyond this, shards are too small


@dataclass(frozen=True)
class ShardTask:
    root: str
    config: dict
    index: int

    @property
    def log_path(self) -> Path:
        return Path(self.root) / shard_relpath(self.index)

    @property
    def truth_path(self) -> Path:
        return Path(self.root) / PARTS / f"truth-{self.index:05d}.parquet"

    @property
    def key(self) -> str:
        return sha256_json({"config": self.config, "shard": self.index, "version": __version__})


def _finished(task: ShardTask):
    record = finished_record(task.log_path, task.key)
    if record and (not record.get("truth_rows") or finished_record(task.truth_path, task.key)):
        return record
    return None


def simulate_group(tasks: list[ShardTask]) -> list[dict]:
    """Simulate and write shards that share their random draws (worker function): the raw
    simulation runs once, each dataset's shard is derived from it."""
    records = [_finished(t) for t in tasks]
    todo = [i for i, r in enumerate(records) if r is None]
    if todo:
        module, cfg = load_scenario(tasks[todo[0]].config)
        raw = module.simulate_raw(cfg, tasks[todo[0]].index) if len(todo) > 1 else None
        for i in todo:
            records[i] = _write_shard(tasks[i], raw)
    return records


def _write_shard(task: ShardTask, raw=None) -> dict:
    module, cfg = load_scenario(task.config)
    if raw is None:
        log, truth = module.simulate_shard(cfg, task.index)
    else:
        log, truth = module.from_raw(cfg, task.index, raw)
    metadata = {"tma.dataset": {"family": module.FAMILY, "shard": task.index,
                                "config_sha256": sha256_json(task.config),
                                "package_version": __version__}}
    n_messages = module.write_log(task.log_path, log, metadata)
    if truth is not None:  # some scenarios (a recorded case replayed) have no truth
        write_parquet_atomic(task.truth_path, truth)
        mark_finished(task.truth_path, task.key, rows=truth.num_rows)
    return mark_finished(task.log_path, task.key, messages=n_messages, tracks=int(log.n_tracks),
                         truth_rows=0 if truth is None else truth.num_rows)


def _is_good(root: Path, config: dict) -> bool:
    """True if the dataset at ``root`` exists, verifies and was simulated from ``config``;
    a damaged or foreign one is logged."""
    if not root.exists():
        return False
    try:
        Dataset.open(root).verify().check_simulated_from(config)
        return True
    except TmaError as exc:
        log.warning("%s; simulating it again", exc)
        return False


def simulate_datasets(scenario_nodes, data_dir, *, engine=2, force=False, progress=True):
    """Create the dataset of each scenario config node; returns the dataset directories.
    ``engine``: where shards run (``tma.runtime.parallel.Engine``, or a number of local workers)."""
    configs = [load_scenario(node) for node in scenario_nodes]
    roots = [datasets_dir(data_dir) / dataset_name(module, cfg) for module, cfg in configs]
    with building(roots) as outputs:  # a second simulate of a dataset waits, finds it done
        return _simulate_locked(outputs, configs, roots, engine=engine, force=force,
                                progress=progress)


def _simulate_locked(outputs, configs, roots, *, engine, force, progress):
    plains = [to_plain(cfg) for _, cfg in configs]
    # a dataset that exists and verifies is kept; they are checked several at a time
    kept = [False] * len(roots) if force else in_threads(
        lambda item: _is_good(*item), list(zip(roots, plains, strict=True)))
    plans, tasks = [], []
    for (module, cfg), root, plain, good in zip(configs, roots, plains, kept, strict=True):
        if good or any(p[0] == root for p in plans):
            plans.append((root, None, module, plain, None))
            continue
        if n_shards(cfg) > MAX_SHARDS:
            raise ConfigError(f"scenario '{module.FAMILY}': n_tracks / shard_size gives "
                              f"{n_shards(cfg)} shards (at most {MAX_SHARDS}): raise shard_size")
        stage = outputs.stage(root, fresh=force)
        shard_tasks = [ShardTask(str(stage), plain, i) for i in range(n_shards(cfg))]
        plans.append((root, stage, module, plain, shard_tasks))
        tasks += shard_tasks
    groups = {}  # shards of different datasets that share their random draws run together
    for t in tasks:
        module, cfg = load_scenario(t.config)
        key = (sha256_json(module.simulation_key(cfg, t.index))
               if hasattr(module, "simulation_key") else (t.root, t.index))
        groups.setdefault(key, []).append(t)
    done = {}
    for group, records in zip(groups.values(), run_tasks(
            simulate_group, list(groups.values()), engine=engine, desc="simulate",
            progress=progress), strict=True):
        done.update({(t.root, t.index): r for t, r in zip(group, records, strict=True)})
    for root, stage, module, plain, shard_tasks in plans:
        if shard_tasks is None:
            continue
        records = [done[(t.root, t.index)] for t in shard_tasks]
        shards = {
            shard_relpath(t.index): {"sha256": r["sha256"], "bytes": t.log_path.stat().st_size,
                                     "messages": r["messages"], "tracks": r["tracks"]}
            for t, r in zip(shard_tasks, records, strict=True)
        }
        files = {}
        if any(r["truth_rows"] for r in records):
            truth = pa.concat_tables(arrow.read_table(t.truth_path) for t in shard_tasks)
            write_parquet_atomic(stage / "truth.parquet", truth)
            files["truth.parquet"] = file_record(stage / "truth.parquet", rows=truth.num_rows)
        write_manifest(stage, family=module.FAMILY, source="simulate", config=plain,
                       shards=shards, files=files, name=root.name,
                       extra={"seed": plain.get("seed"), "time_origin_s": 0.0})
        shutil.rmtree(stage / PARTS, ignore_errors=True)  # inside our own staging directory
        for t in shard_tasks:  # resume bookkeeping is no longer needed once the manifest exists
            sidecar(t.log_path).unlink(missing_ok=True)
        outputs.swap(root)
    return [p[0] for p in plans]
