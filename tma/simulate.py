"""The simulate stage: scenario configs -> datasets (MCAP shards, truth, manifest).

Every shard of every requested dataset is one task, so all shards share one worker pool.
A shard whose MCAP and truth part are finished (sidecar with matching key and hash) is reused,
so a killed run resumes; a dataset whose manifest exists is skipped unless ``force``.
"""

import shutil
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from tma import __version__
from tma.config import to_plain
from tma.io.atomic import sha256_json, write_parquet_atomic
from tma.io.dataset import MANIFEST, datasets_dir, file_record, shard_relpath, write_manifest
from tma.io.shards import finished_record, is_finished, mark_finished
from tma.parallel import run_tasks
from tma.scenarios import dataset_name, load_scenario, n_shards

PARTS = "parts"


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
    if is_finished(task.log_path, task.key):
        record = finished_record(task.log_path)
        if not record["truth_rows"] or is_finished(task.truth_path, task.key):
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


def simulate_datasets(scenario_nodes, data_dir, *, n_jobs=2, force=False, progress=True):
    """Create the dataset of each scenario config node; returns the dataset directories."""
    plans, tasks = [], []
    for node in scenario_nodes:
        module, cfg = load_scenario(node)
        root = datasets_dir(data_dir) / dataset_name(module, cfg)
        plain = to_plain(cfg)
        if (root / MANIFEST).exists() and not force:
            plans.append((root, module, plain, None))
            continue
        if force and root.exists():
            shutil.rmtree(root)
        shard_tasks = [ShardTask(str(root), plain, i) for i in range(n_shards(cfg))]
        plans.append((root, module, plain, shard_tasks))
        tasks += shard_tasks
    groups = {}  # shards of different datasets that share their random draws run together
    for t in tasks:
        module, cfg = load_scenario(t.config)
        key = (sha256_json(module.simulation_key(cfg, t.index))
               if hasattr(module, "simulation_key") else (t.root, t.index))
        groups.setdefault(key, []).append(t)
    done = {}
    for group, records in zip(groups.values(), run_tasks(
            simulate_group, list(groups.values()), n_jobs=n_jobs, desc="simulate",
            progress=progress), strict=True):
        done.update({(t.root, t.index): r for t, r in zip(group, records, strict=True)})
    results = iter(done[(t.root, t.index)] for t in tasks)
    for root, module, plain, shard_tasks in plans:
        if shard_tasks is None:
            continue
        records = [next(results) for _ in shard_tasks]
        shards = {
            shard_relpath(t.index): {"sha256": r["sha256"], "messages": r["messages"],
                                     "tracks": r["tracks"]}
            for t, r in zip(shard_tasks, records, strict=True)
        }
        files = {}
        if any(r["truth_rows"] for r in records):
            truth = pa.concat_tables(pq.read_table(t.truth_path) for t in shard_tasks)
            write_parquet_atomic(root / "truth.parquet", truth)
            files["truth.parquet"] = file_record(root / "truth.parquet", rows=truth.num_rows)
        write_manifest(root, family=module.FAMILY, source="simulate", config=plain,
                       shards=shards, files=files,
                       extra={"seed": plain.get("seed"), "time_origin_s": 0.0})
        shutil.rmtree(root / PARTS, ignore_errors=True)
        for t in shard_tasks:  # resume bookkeeping is no longer needed once the manifest exists
            t.log_path.with_name(t.log_path.name + ".done.json").unlink(missing_ok=True)
    return [p[0] for p in plans]
