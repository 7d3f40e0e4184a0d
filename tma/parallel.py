"""Run independent shard tasks: in this process, in local joblib workers, or on a Dask cluster.

Results come back in task order whatever the engine and the number of workers, and each task
computes with one BLAS thread, so outputs do not depend on where tasks ran. Tasks carry paths
and configs, never arrays: on a cluster every worker reads and writes the shared data directory
(``paths.data_dir`` on NFS, Lustre...), and each task's writes are atomic, so a worker killed
mid-task leaves no half-written file; Dask runs the task again elsewhere (``retries``), and a
run that stops anyway resumes from its finished shards.
"""

import asyncio
import atexit
import ctypes
import functools
import gc
import logging
import os
import re
import socket
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace
from urllib.parse import urlsplit

from threadpoolctl import threadpool_limits

from tma.config import Form, Params, param
from tma.errors import ConfigError, Interrupted

log = logging.getLogger(__name__)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc mallopt parameters
ENGINES = ("joblib", "dask")
MAX_THREADS = 4  # for in_threads: files checked or read at once
SCHEMES = ("tcp", "tls", "ws", "wss")  # the transports of a Dask scheduler's address
CONNECT_TIMEOUT = 10.0  # s: parallel.connect_timeout's default
ADDRESS_FORM = "a scheduler address looks like tcp://scheduler:8786"


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


# what local workers import before their first task (besides the command's own modules): the
# stages' core and the libraries the families' simulations and estimators load when first used
# (tma.worker_preload imports them)
WORKER_MODULES = ("numpy", "pyarrow.parquet", "tma.simulation", "tma.estimation", "tma.aggregate")
# no thread may run in a process that forks: in the fork server one BLAS or OpenMP thread,
# and no background thread of the jemalloc that pyarrow links (it starts one when loaded)
SINGLE_THREADED = {**{name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                             "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                                             "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")},
                   "JE_ARROW_MALLOC_CONF": "background_thread:false"}
FORK_SERVER = "TMA_FORK_SERVER"  # set in the fork server (and so its workers): no second one
PRELOAD = "TMA_PRELOAD"  # the modules tma.worker_preload imports in the fork server


def preload_workers(modules=()) -> bool:
    """Start this process's local workers (joblib's process pool, loky, and so the joblib
    Hydra launcher's too) as forks of a server process that has imported ``WORKER_MODULES``
    and ``modules`` once (``multiprocessing``'s forkserver, ``set_forkserver_preload``): a
    worker then starts in milliseconds with its imports done, where a fresh interpreter would
    spend a third of a second starting and as long importing. Called as a command starts (the
    first lines of ``pipeline``), the server imports while the command composes its config;
    loky is told to use it when a pool is first made (``workers_from_server``).

    Only on Linux and only for commands: the server forks from a process where no thread runs
    (it imports with one BLAS and OpenMP thread, ``SINGLE_THREADED``, as every task computes
    anyway), which is safe on Linux; macOS's system libraries are not safe to use after a fork,
    so there, and in Python sessions (whose main module, re-run in each forked worker, may be
    unguarded), workers start as loky starts them: a fresh interpreter each. The workers see
    the environment as it is when this is called (a variable set later in the command does
    not reach them), with one BLAS thread; a forked worker re-imports the command's
    ``__main__`` (its imports preloaded: at no cost). A module that fails to import in the
    server is imported again by the worker that needs it (``tma.worker_preload``).
    Idempotent; returns whether workers will start from the server."""
    global _server
    if _server or sys.platform != "linux" or os.environ.get(FORK_SERVER):
        return _server
    import multiprocessing
    from multiprocessing import forkserver

    multiprocessing.set_forkserver_preload(["tma.worker_preload"])  # never imported here
    saved = {k: os.environ.get(k) for k in [*SINGLE_THREADED, FORK_SERVER, PRELOAD]}
    mark_shared_memory()
    os.environ.update({**SINGLE_THREADED, FORK_SERVER: str(os.getpid()),
                       PRELOAD: ",".join([*WORKER_MODULES, *modules])})
    try:
        forkserver.ensure_running()
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key)
            else:
                os.environ[key] = value
    _server = True
    return True


_server = False  # preload_workers started the fork server
PR_SET_PDEATHSIG = 1  # prctl(2)


def die_with_parent(parent: int = 0) -> None:
    """Linux: have this process killed (SIGKILL) when its parent ends, and end it now if
    that parent (pid ``parent``, when known) has already gone; elsewhere nothing. For the fork
    server and its workers (``tma.worker_preload``), so that no worker outlives a command
    killed outright."""
    if sys.platform != "linux":
        return
    import signal

    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        return
    if parent and os.getppid() != parent:  # the parent ended before the signal was set
        os._exit(1)


SHM = "/dev/shm"
SHM_MARK = re.compile(r"tma-command-(\d+)-(\d+)")  # tma-command-<pid>-<start>: tma's marker
# what loky and joblib create there, named by the pid of the process that created it
SHM_OWN = ("sem.loky-{pid}-", "joblib_memmapping_folder_{pid}_")


def _started(pid: int) -> str | None:
    """When process ``pid`` started (clock ticks since boot, /proc), None if none runs."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rpartition(b")")[2].split()[19].decode()
    except (OSError, IndexError):
        return None


def mark_shared_memory() -> None:
    """Mark this command's shared memory as tma's, and free what killed commands of tma left.

    joblib's workers share named semaphores (``sem.loky-<pid>-*``) and folders
    (``joblib_memmapping_folder_<pid>_*``) in ``/dev/shm``; their resource trackers free them
    when the command ends, even when it is killed, unless the trackers are killed with it
    (SIGKILL to its process group). A command marks the shared memory it will create with
    ``tma-command-<pid>-<start>`` (its pid and start time), removed when it ends; a marker
    whose command no longer runs (no process with that pid started then) names what that
    command left: entries of its pid created after it started, removed with the marker.
    Nothing else is touched. Linux only."""
    if not os.path.isdir(SHM):
        return
    for name in os.listdir(SHM):
        found = SHM_MARK.fullmatch(name)
        if found and _started(int(found.group(1))) != found.group(2):
            _free_left_over(os.path.join(SHM, name), int(found.group(1)))
    started = _started(os.getpid())
    if started is None:
        return
    marker = os.path.join(SHM, f"tma-command-{os.getpid()}-{started}")
    try:
        open(marker, "x").close()
    except OSError:  # read-only or full: the trackers still free what they can
        return
    atexit.register(_remove_path, marker)


def _free_left_over(marker: str, pid: int) -> None:
    try:
        since = os.stat(marker).st_mtime - 1  # a second of slack for the clocks' grain
    except OSError:
        return  # another command freed it
    prefixes = tuple(p.format(pid=pid) for p in SHM_OWN)
    for name in os.listdir(SHM):
        path = os.path.join(SHM, name)
        try:
            if name.startswith(prefixes) and os.lstat(path).st_mtime >= since:
                _remove_path(path)
        except OSError:
            continue
    _remove_path(marker)


def _remove_path(path: str) -> None:
    import shutil

    try:
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            os.unlink(path)
    except OSError:
        pass


def workers_from_server() -> bool:
    """Have loky (joblib's pool) fork its workers from ``preload_workers``'s server, if it was
    started and no other start method was chosen; whether it does."""
    if not _server:
        return False
    from joblib.externals.loky.backend import context as loky_context

    if loky_context.get_start_method() is None:
        loky_context.set_start_method("forkserver")
    forked = loky_context.get_start_method() == "forkserver"
    if forked:
        log.debug("local workers fork from the server that preloaded their modules")
    return forked


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


def address_problem(address) -> str:
    """What is wrong with a Dask scheduler address as written ('' if nothing): its scheme,
    host and port, checked before any connection."""
    if not isinstance(address, str) or "://" not in address:
        return "not a scheduler address"
    scheme, _, rest = address.partition("://")
    if scheme not in SCHEMES:
        return f"unknown scheme '{scheme}://' (Dask's are {', '.join(f'{s}://' for s in SCHEMES)})"
    try:
        parts = urlsplit(address)
    except ValueError as exc:  # e.g. an unclosed [ of an IPv6 host
        return f"not a scheduler address ({exc})"
    if parts.path or parts.query or parts.fragment or parts.username is not None:
        return f"unexpected text around host:port in '{rest}'"
    if not parts.hostname:
        return "no host"
    port = parts.netloc.rpartition("]")[2].rpartition(":")[2] if ":" in parts.netloc else ""
    if not port:
        return "no port (a Dask scheduler listens on 8786 unless told otherwise)"
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        return f"port '{port}' is not a number from 1 to 65535"
    return ""


async def _dask_identity(address: str, connection_args: dict) -> dict:
    from distributed.comm import connect

    # connect() bounds the TCP connection by its timeout, but then waits for the other end's
    # handshake with no bound at all: the caller bounds the whole exchange
    comm = await connect(address, **connection_args)
    try:
        await comm.write({"op": "identity"})
        return await comm.read()
    finally:
        comm.abort()


def _tcp_reachable(address: str, timeout: float) -> None:
    """Return once something at ``address`` accepts a TCP connection; retried (a scheduler
    may be starting) until ``timeout`` s, then a ConfigError with the last reason."""
    parts = urlsplit(address)
    host, port = parts.hostname, parts.port
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        try:
            socket.create_connection((host, port), timeout=max(left, 0.01)).close()
            return
        except socket.gaierror as exc:
            reason = f"host '{host}' not found ({exc.strerror})"
        except ConnectionRefusedError:
            reason = f"nothing listens on port {port} of {host} (connection refused)"
        except TimeoutError:
            reason = f"{host}:{port} accepts no connection"
        except OSError as exc:
            reason = f"cannot connect to {host}:{port} ({exc.strerror or exc})"
        if time.monotonic() + 0.1 > deadline:
            raise ConfigError(f"parallel.address={address}: {reason} after "
                              f"{timeout:g} s (parallel.connect_timeout)")
        time.sleep(0.1)


def check_scheduler(address: str, timeout: float, connection_args: dict) -> None:
    """Make sure a Dask scheduler answers at ``address``: a ConfigError naming the address and
    what is wrong, within about twice ``timeout`` s, whatever listens there.

    ``distributed.Client(address, timeout=...)`` alone would wait forever for a service that
    accepts the connection and never speaks Dask's protocol (its handshake read is unbounded);
    an HTTP server reads Dask's first frame as a request line and waits for its end."""
    _tcp_reachable(address, timeout)
    probe = asyncio.wait_for(_dask_identity(address, connection_args), timeout)
    try:
        with ThreadPoolExecutor(1) as thread:  # its own event loop, whatever runs in this one
            reply = thread.submit(asyncio.run, probe).result()
    except TimeoutError:
        reason = (f"something there accepts connections but sends no Dask handshake within "
                  f"{timeout:g} s: not a Dask scheduler (or one too busy to answer: "
                  f"parallel.connect_timeout)")
    except OSError:  # CommClosedError among them
        reason = ("something there accepts connections but closes them without a Dask "
                  "handshake: not a Dask scheduler")
    except Exception:  # bytes that are no Dask message (e.g. an absurd frame length)
        reason = "something there answers, but not in Dask's protocol: not a Dask scheduler"
    else:
        kind = reply.get("type") if isinstance(reply, dict) else None
        if kind == "Scheduler" or isinstance(reply, dict) and "n_workers" in reply:
            return
        reason = (f"that is a Dask {kind.lower()}, not the scheduler" if kind in {"Worker", "Nanny"}
                  else f"it speaks Dask's protocol but is not a scheduler ({kind or reply!r})")
    raise ConfigError(f"parallel.address={address}: {reason}")


def close_dask_clients():
    """Close the clients (and local clusters) ``dask_client`` started."""
    for client in _clients:
        client.close()
        if client.cluster is not None:
            client.cluster.close()
    _clients.clear()
    _dask_client.cache_clear()


_clients = []


def dask_client(address: str | None = None, n_workers: int = 2, *,
                connect_timeout: float = CONNECT_TIMEOUT, verbose: bool = False):
    """A client of the scheduler at ``address``, or of a LocalCluster of ``n_workers``
    single-threaded worker processes started once per process (closed at exit); a scheduler
    that does not answer in ``connect_timeout`` s, or a service that is not one, is a
    ConfigError. ``verbose``: Dask's own INFO logging (else its warnings only)."""
    try:
        import distributed  # noqa: F401 (sets the level of its logger when first imported)
    except ImportError:
        raise ConfigError("parallel=dask needs Dask: pip install 'tma[dask]'") from None
    # distributed sets its logger to INFO and, under Hydra (the root logger has handlers),
    # adds no handler of its own: every record reaches Hydra's console and log file, and
    # LocalCluster's silence_logs, which sets the level of that missing handler, has no effect
    logging.getLogger("distributed").setLevel(logging.INFO if verbose else logging.WARNING)
    return _dask_client(address, n_workers, float(connect_timeout), bool(verbose))


@functools.cache
def _dask_client(address: str | None, n_workers: int, connect_timeout: float, verbose: bool):
    from distributed import Client, LocalCluster
    from distributed.security import Security

    if address is None:
        # silence_logs (a level) goes to every worker process: a worker that closes while its
        # heartbeat to the scheduler is in flight logs that CommClosedError with its traceback
        # at ERROR (a race in distributed's Worker.close); task errors reach the client anyway.
        # The scheduler's HTTP server on a free port of 127.0.0.1, not 8787: a second cluster
        # on this machine would print "Port 8787 is already in use"
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                               dashboard_address=None,
                               scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                               silence_logs=False if verbose else logging.CRITICAL)
        client = Client(cluster)
    else:
        problem = address_problem(address)
        if problem:
            raise ConfigError(f"parallel.address={address}: {problem}; {ADDRESS_FORM}")
        connection_args = Security().get_connection_args("client")
        if address.startswith(("tls://", "wss://")) and connection_args["ssl_context"] is None:
            raise ConfigError(f"parallel.address={address}: TLS needs Dask's TLS settings "
                              f"(distributed.comm.tls.ca-file, .client.cert, .client.key in "
                              f"Dask's configuration)")
        check_scheduler(address, connect_timeout, connection_args)
        try:
            client = Client(address, timeout=connect_timeout)
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"parallel.address={address}: the Dask scheduler stopped "
                              f"answering ({exc})") from None
    if not _clients:
        atexit.register(close_dask_clients)
    _clients.append(client)
    log.info("dask: %s", client)
    return client
