"""Local workers that start in milliseconds: forks of a server process that has imported what
they need (``preload_workers``, ``workers_from_server``; ``tma.runtime.worker_preload`` is what
the server imports), which end with their command (``die_with_parent``) and whose shared
memory a killed command leaves is freed by the next (``mark_shared_memory``); and what every
process that computes sets first (``keep_freed_memory``, ``quick_exit``).
"""

import atexit
import ctypes
import functools
import gc
import logging
import os
import re
import sys

log = logging.getLogger(__name__)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc mallopt parameters


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
# (tma.runtime.worker_preload imports them)
WORKER_MODULES = ("numpy", "pyarrow.parquet", "tma.stages.simulate", "tma.stages.estimate",
                  "tma.stages.aggregate")
# no thread may run in a process that forks: in the fork server one BLAS or OpenMP thread,
# and no background thread of the jemalloc that pyarrow links (it starts one when loaded)
SINGLE_THREADED = {**{name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                             "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                                             "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")},
                   "JE_ARROW_MALLOC_CONF": "background_thread:false"}
FORK_SERVER = "TMA_FORK_SERVER"  # set in the fork server (and so its workers): no second one
PRELOAD = "TMA_PRELOAD"  # the modules tma.runtime.worker_preload imports in the fork server


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
    server is imported again by the worker that needs it (``tma.runtime.worker_preload``).
    Idempotent; returns whether workers will start from the server."""
    global _server
    if _server or sys.platform != "linux" or os.environ.get(FORK_SERVER):
        return _server
    import multiprocessing
    from multiprocessing import forkserver

    multiprocessing.set_forkserver_preload(["tma.runtime.worker_preload"])  # never imported here
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


def server_started() -> bool:
    """Whether ``preload_workers`` started this command's fork server."""
    return _server
PR_SET_PDEATHSIG = 1  # prctl(2)


def die_with_parent(parent: int = 0) -> None:
    """Linux: have this process killed (SIGKILL) when its parent ends, and end it now if
    that parent (pid ``parent``, when known) has already gone; elsewhere nothing. For the fork
    server and its workers (``tma.runtime.worker_preload``), so that no worker outlives a command
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

