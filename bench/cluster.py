"""Benchmark (not a test) of where shards run: ``make bench`` section (g), or
``python bench/cluster.py [--tracks N] [--shard-size N] [--noop N]``.

One stored ``bearings2d`` dataset (default 12,000 tracks in 60 shards, sigma 0.5 deg) is
estimated with ``lm`` (``force``, so every shard runs) in this process (the baseline), with
joblib on 2 local processes, and on a Dask LocalCluster of 1 and 2 worker processes: shards
per second and the speed-up over the baseline. The scheduler's own cost per task is measured
with tasks that do nothing: wall time per task on the cluster minus the same loop in process.
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from floors import compose  # noqa: E402 (bench/floors.py, beside this script)

from pipeline._common import estimator_nodes, scenario_nodes  # noqa: E402
from tma.io.dataset import Dataset  # noqa: E402
from tma.runtime.cluster import close_dask_clients, dask_client  # noqa: E402
from tma.runtime.parallel import Engine, run_tasks  # noqa: E402
from tma.stages.estimate import estimate_runs  # noqa: E402
from tma.stages.simulate import simulate_datasets  # noqa: E402


def _nothing(task):
    return task


def bench_cluster(n_tracks: int = 12_000, shard_size: int = 200, n_noop: int = 2000):
    cfg = compose([f"scenario.n_tracks={n_tracks}", f"scenario.shard_size={shard_size}",
                   "estimator=lm"])
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        t0 = time.perf_counter()
        root = simulate_datasets(scenario_nodes(cfg), data, engine=1, progress=False)[0]
        simulate_s = time.perf_counter() - t0
        dataset = Dataset.open(root)
        dataset_bytes = sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
        jobs = [(dataset, node) for node in estimator_nodes(cfg)]
        n_shards = len(dataset.manifest["shards"])
        engines = {"in process (baseline)": Engine(n_jobs=1), "joblib, 2 processes":
                   Engine(n_jobs=2), "dask LocalCluster, 1 worker": Engine("dask", n_workers=1),
                   "dask LocalCluster, 2 workers": Engine("dask", n_workers=2)}
        rates = {}
        for label, engine in engines.items():
            if engine.engine == "dask":
                close_dask_clients()
                dask_client(None, engine.n_workers)  # cluster start-up is not shard time
                estimate_runs(data, jobs, engine=engine, progress=False, force=True)  # warm
            t0 = time.perf_counter()
            estimate_runs(data, jobs, engine=engine, progress=False, force=True)
            rates[label] = n_shards / (time.perf_counter() - t0)
        base = rates["in process (baseline)"]
        run_bytes = sum(p.stat().st_size for p in (data / "runs").rglob("*") if p.is_file())
        print(f"(g) simulate in process: {n_shards / simulate_s:.1f} shards/s "
              f"({1e3 * simulate_s / n_tracks:.2f} ms per track); dataset "
              f"{dataset_bytes / n_tracks:.0f} bytes per track, lm run {run_bytes / n_tracks:.0f}")
        print(f"    lm over {n_tracks:,} tracks in {n_shards} shards of {shard_size}:")
        for label, rate in rates.items():
            print(f"    {label:<30} {rate:7.1f} shards/s   {rate / base:5.2f}x the baseline")
        client = dask_client(None, 2)
        t0 = time.perf_counter()
        run_tasks(_nothing, range(n_noop), engine=1, progress=False)
        local = (time.perf_counter() - t0) / n_noop
        t0 = time.perf_counter()
        run_tasks(_nothing, range(n_noop), engine=Engine("dask", n_workers=2), progress=False)
        remote = (time.perf_counter() - t0) / n_noop
        print(f"    scheduler overhead: {1e3 * (remote - local):.2f} ms per task "
              f"({n_noop} empty tasks on {len(client.scheduler_info()['workers'])} workers; "
              f"the same empty task in process: {1e6 * local:.0f} us)")
        close_dask_clients()
        return rates, remote - local


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=12_000)
    parser.add_argument("--shard-size", type=int, default=200)
    parser.add_argument("--noop", type=int, default=2000)
    args = parser.parse_args()
    bench_cluster(args.tracks, args.shard_size, args.noop)
