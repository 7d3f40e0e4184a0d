"""Run independent shard tasks: in this process, in local joblib workers, or on a Dask cluster.

Results come back in task order whatever the engine and the number of workers, and each task
computes with one BLAS thread, so outputs do not depend on where tasks ran. Tasks carry paths
and configs, never arrays: on a cluster every worker reads and writes the shared data directory
(``paths.data_dir`` on NFS, Lustre...), and each task's writes are atomic, so a worker killed
mid-task leaves no half-written file; Dask runs the task again elsewhere (``retries``), and a
run that stops anyway resumes from its finished shards.
"""

import logging
import os
import re
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace

from threadpoolctl import threadpool_limits

from tma.config import Form, Params, param
from tma.errors import ConfigError, Interrupted
from tma.runtime.cluster import CONNECT_TIMEOUT, address_problem, dask_client
from tma.runtime.forkserver import keep_freed_memory, quick_exit, workers_from_server

log = logging.getLogger(__name__)
ENGINES = ("joblib", "dask")
MAX_THREADS = 4  # for in_threads: files checked or read at once


def _address_problem(address) -> str | None:
    return address_problem(address) or None


@dataclass(frozen=True)
class Engine(Params):
    """Where shard tasks run: the ``parallel`` config group (``conf/parallel/*.yaml`` are
    presets of these keys), each option declared once (``python -m tma.options parallel``)
    and checked as declared (``Params``: one line naming ``parallel.<key>``). A task whose
    worker died is run again on another worker by Dask itself, up to
    ``distributed.scheduler.allowed-failures`` (3) times, besides ``retries``."""

    engine: str = param("joblib", "where shards run: joblib (local worker processes, or this "
                        "process) or dask (a Dask cluster)", choices=ENGINES)
    n_jobs: int = param(1, "joblib: worker processes (1: in this process), at most one per "
                        "task", "[1, inf)")
    address: str | None = param(None, "dask: the scheduler of an existing cluster; null: a "
                                "LocalCluster of n_workers processes on this machine",
                                form=Form("a Dask scheduler address such as "
                                          "tcp://scheduler:8786", _address_problem))
    n_workers: int = param(2, "dask, LocalCluster only: worker processes (one thread each)",
                           "[1, inf)")
    retries: int = param(2, "dask: re-runs of a task that raised (e.g. an OSError of a flaky "
                         "shared disk)", "[0, inf)")
    connect_timeout: float = param(CONNECT_TIMEOUT, "dask: seconds (s) to wait for the "
                                   "scheduler at address to accept a connection, then as long "
                                   "for it to answer", "(0, inf)")
    verbose: bool = param(False, "dask: true shows Dask's own INFO logging (scheduler, "
                          "nannies, workers); false its warnings only, nothing from the "
                          "workers of a LocalCluster")

    @property
    def where(self) -> str:
        return ""

    @property
    def key_prefix(self) -> str:
        return "parallel."

    @property
    def in_process(self) -> bool:
        return self.engine == "joblib" and self.n_jobs == 1


def engine_from(node, launcher: str = "") -> Engine:
    """The ``parallel`` config group (a dict) as an ``Engine``; unknown keys and bad values
    are one ConfigError. Inside a job of a parallel Hydra launcher (``launcher`` names its
    target: joblib, submitit) shards run serially in the job: one parallel layer only."""
    if not isinstance(node, dict):
        raise ConfigError(f"parallel must be a config group entry (default, serial, dask), "
                          f"got '{node}'")
    known = {f.name for f in fields(Engine)}
    unknown = sorted(set(node) - known)
    if unknown:
        raise ConfigError(f"unknown option(s) parallel.{', parallel.'.join(unknown)} (known: "
                          f"{', '.join(sorted(known))})")
    requested = Engine(**node)
    launcher = launcher.lower()
    if ("joblib" in launcher or "submitit" in launcher) and requested.engine == "joblib" \
            and requested.n_jobs != 1:
        log.info("parallel launcher active: shards run serially inside each job")
        return replace(requested, n_jobs=1)
    return requested


def as_engine(engine) -> Engine:
    """An ``Engine``; a whole number ``n`` means ``n`` local joblib workers."""
    return engine if isinstance(engine, Engine) else Engine(n_jobs=engine)



def _single_threaded(fn, task):
    keep_freed_memory()
    quick_exit()
    with threadpool_limits(limits=1):
        return fn(task)


def run_tasks(fn, tasks, *, engine=1, desc: str = "", progress: bool = True) -> list:
    """Apply ``fn`` to each task on ``engine`` (an ``Engine`` or a number of local joblib
    workers); return the results in task order. ``fn`` and the tasks must be picklable."""
    return list(iter_tasks(fn, tasks, engine=engine, desc=desc, progress=progress))


def iter_tasks(fn, tasks, *, engine=1, desc: str = "", progress: bool = True):
    """``run_tasks``, its results yielded in task order as they come: the caller can finish
    with the first tasks' results while the workers run the others."""
    engine, tasks = as_engine(engine), list(tasks)
    if not tasks:  # e.g. a re-run whose every shard is done: nothing to show or start
        return
    from tqdm.auto import tqdm  # here, as joblib below: many commands run no task

    bar = tqdm(total=len(tasks), desc=desc, unit="shard", disable=not progress)
    try:
        if engine.engine == "dask":
            yield from _on_dask(engine, fn, tasks, bar)
            return
        if engine.in_process or len(tasks) == 1:
            for task in tasks:
                yield _single_threaded(fn, task)
                bar.update()
            return
        from joblib import Parallel, delayed
        from joblib.externals.loky.process_executor import BrokenProcessPool

        workers_from_server()
        n_jobs = min(engine.n_jobs, len(tasks))
        if n_jobs < engine.n_jobs:
            log.info("parallel.n_jobs=%d: %d worker(s), one per task", engine.n_jobs, n_jobs)
        # tasks carry paths, never arrays: nothing to share through memory-mapped files
        parallel = Parallel(n_jobs=n_jobs, return_as="generator", max_nbytes=None)
        try:
            for result in parallel(delayed(_single_threaded)(fn, t) for t in tasks):
                bar.update()
                yield result
        except BrokenProcessPool as exc:  # loky's TerminatedWorkerError among them
            codes = re.search(r"exit codes of the workers are \{(.*?)\}", str(exc))
            how = f" ({codes.group(1)})" if codes else ""
            raise Interrupted(f"a worker process died{how}: killed, or it ran out of "
                              "memory; the tasks finished are kept and nothing complete was "
                              "replaced: run the same command again to resume (fewer "
                              "workers, parallel.n_jobs, need less memory)") from None
    finally:
        bar.close()


def in_threads(fn, items) -> list:
    """``[fn(item) for item in items]``, a few items at a time in threads of this process:
    for work that releases the GIL (hashing files, reading Parquet), e.g. verifying every
    dataset of a stage. Results in item order; an exception is raised as the loop would
    (the first in item order), once every item is done."""
    items = list(items)
    threads = min(MAX_THREADS, len(items), os.cpu_count() or 1)
    if threads <= 1:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(threads) as pool:
        return list(pool.map(fn, items))


def _on_dask(engine: Engine, fn, tasks, bar):
    from distributed import as_completed

    client = dask_client(engine.address, engine.n_workers,
                         connect_timeout=engine.connect_timeout, verbose=engine.verbose)
    # pure=False: a task is a side effect (it writes its shard), never deduplicated by Dask
    futures = client.map(_single_threaded, [fn] * len(tasks), tasks, pure=False,
                         retries=engine.retries)
    try:
        for future in as_completed(futures):
            if future.status == "error":  # e.g. bad input in one shard: stop at once
                future.result()
            bar.update()
        return client.gather(futures)  # in task order
    except BaseException:  # the shards still queued need not run on
        client.cancel(futures)
        raise

