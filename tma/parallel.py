"""Run independent shard tasks: in this process, in local joblib workers, or on a Dask cluster.

Results come back in task order whatever the engine and the number of workers, and each task
computes with one BLAS thread, so outputs do not depend on where tasks ran. Tasks carry paths
and configs, never arrays: on a cluster every worker reads and writes the shared data directory
(``paths.data_dir`` on NFS, Lustre...), and each task's writes are atomic, so a worker killed
mid-task leaves no half-written file; Dask runs the task again elsewhere (``retries``), and a
run that stops anyway resumes from its finished shards.
"""

import atexit
import ctypes
import functools
import gc
import logging
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace

from threadpoolctl import threadpool_limits

from tma.errors import ConfigError

log = logging.getLogger(__name__)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc mallopt parameters
ENGINES = ("joblib", "dask")
MAX_THREADS = 4  # for in_threads: files checked or read at once


@dataclass(frozen=True)
class Engine:
    """Where shard tasks run (the ``parallel`` config group).

    kind: ``joblib`` (``n_jobs`` local worker processes; 1 = in this process) or ``dask``.
    address: dask only; None starts a ``distributed.LocalCluster`` of ``n_workers`` worker
    processes here, ``tcp://host:8786`` uses the scheduler of an existing cluster.
    retries: dask only; how often a task that raised (e.g. an OSError of a flaky shared disk)
    is run again. A task whose worker died is run again on another worker by Dask itself, up
    to ``distributed.scheduler.allowed-failures`` (3) times.
    """

    kind: str = "joblib"
    n_jobs: int = 1
    address: str | None = None
    n_workers: int = 2
    retries: int = 2

    def __post_init__(self):
        if self.kind not in ENGINES:
            raise ConfigError(f"parallel.engine must be one of {', '.join(ENGINES)}, "
                              f"got '{self.kind}'")
        for key in ("n_jobs", "n_workers"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"parallel.{key} must be a whole number >= 1, got '{value}'")
        if isinstance(self.retries, bool) or not isinstance(self.retries, int) \
                or self.retries < 0:
            raise ConfigError(f"parallel.retries must be a whole number >= 0, "
                              f"got '{self.retries}'")
        if self.address is not None and (not isinstance(self.address, str)
                                         or "://" not in self.address):
            raise ConfigError(f"parallel.address must be null or a scheduler address such as "
                              f"tcp://host:8786, got '{self.address}'")

    @property
    def in_process(self) -> bool:
        return self.kind == "joblib" and self.n_jobs == 1


def engine_from(node, launcher: str = "") -> Engine:
    """The ``parallel`` config group (a dict) as an ``Engine``; unknown keys and bad values
    are one ConfigError. Inside a job of a parallel Hydra launcher (``launcher`` names its
    target: joblib, submitit) shards run serially in the job: one parallel layer only."""
    if not isinstance(node, dict):
        raise ConfigError(f"parallel must be a config group entry (default, serial, dask), "
                          f"got '{node}'")
    known = {f.name for f in fields(Engine)} - {"kind"} | {"engine"}
    unknown = sorted(set(node) - known)
    if unknown:
        raise ConfigError(f"unknown option(s) parallel.{', parallel.'.join(unknown)} (known: "
                          f"{', '.join(sorted(known))})")
    values = dict(node)
    requested = Engine(kind=values.pop("engine", "joblib"), **values)
    launcher = launcher.lower()
    if ("joblib" in launcher or "submitit" in launcher) and requested.kind == "joblib" \
            and requested.n_jobs != 1:
        log.info("parallel launcher active: shards run serially inside each job")
        return replace(requested, n_jobs=1)
    return requested


def as_engine(engine) -> Engine:
    """An ``Engine``; a whole number ``n`` means ``n`` local joblib workers."""
    return engine if isinstance(engine, Engine) else Engine(n_jobs=engine)


@functools.cache
def keep_freed_memory(limit_bytes: int = 1 << 30) -> bool:
    """Ask glibc to keep freed blocks up to ``limit_bytes`` instead of unmapping them.

    By default glibc serves blocks above 128 KiB with mmap and returns them on free, so each
    temporary array of a vectorised filter step (a few hundred KiB) costs fresh page faults;
    the 3D filters ran 1.6x slower for it. No effect (False) off glibc.
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(M_MMAP_THRESHOLD, limit_bytes)
                    and libc.mallopt(M_TRIM_THRESHOLD, limit_bytes))
    except (OSError, AttributeError):
        return False


@functools.cache
def quick_exit() -> None:
    """Let this process skip, when it exits, the garbage collections of Python's shutdown.

    With numpy, pyarrow, pandas, numba or matplotlib loaded those collections cost ~0.35 s per
    process: in every command, and in each worker when the pool shuts down. At exit
    ``gc.freeze`` moves every object out of the collector's reach; the memory goes back to the
    OS with the process. Nothing written is affected: tma closes (and renames) each file as
    it writes it, and atexit handlers (logging's flush among them) still run.
    """
    atexit.register(gc.freeze)


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
        if engine.kind == "dask":
            yield from _on_dask(engine, fn, tasks, bar)
            return
        if engine.in_process or len(tasks) == 1:
            for task in tasks:
                yield _single_threaded(fn, task)
                bar.update()
            return
        from joblib import Parallel, delayed

        parallel = Parallel(n_jobs=engine.n_jobs, return_as="generator")
        for result in parallel(delayed(_single_threaded)(fn, t) for t in tasks):
            bar.update()
            yield result
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

    client = dask_client(engine.address, engine.n_workers)
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


def close_dask_clients():
    """Close the clients (and local clusters) ``dask_client`` started."""
    for client in _clients:
        client.close()
        if client.cluster is not None:
            client.cluster.close()
    _clients.clear()
    dask_client.cache_clear()


_clients = []


@functools.cache
def dask_client(address: str | None, n_workers: int):
    """A client of the scheduler at ``address``, or of a LocalCluster of ``n_workers``
    single-threaded worker processes started once per process (closed at exit)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError("parallel=dask needs Dask: pip install 'tma[dask]'") from None
    if address is None:
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        try:
            client = Client(address, timeout="10s")
        except OSError as exc:
            raise ConfigError(f"parallel.address={address}: no Dask scheduler answers "
                              f"({exc})") from None
    if not _clients:
        atexit.register(close_dask_clients)
    _clients.append(client)
    log.info("dask: %s", client)
    return client
