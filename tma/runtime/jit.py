"""Compiled kernels: ``numba.njit`` with its on-disk cache, kept correct and never fatal.

Every kernel is compiled once and cached (``cache=True``), so worker processes and later runs
load machine code instead of recompiling (numba's first call in a process still costs ~0.5 s
to start its compiler, each cached kernel then a few ms).

A kernel is made when first used (called, or typed inside another kernel), not when its
module is imported: numba itself (~0.2 s to import) loads only in processes that run compiled
code, so the stages that never do (simulate, aggregate, and every command's start-up, which
imports each estimator to register its defaults) do not pay for it.

Two gaps of numba's cache are closed here:

- numba invalidates a cached kernel when *its own* source file changes, not when a kernel it
  calls from another file does, and would go on running stale code. ``depends`` names those
  callees: the files they live in join the kernel's cache stamp.
- numba caches beside the source (``__pycache__``), else in the user-wide cache directory
  (``$XDG_CACHE_HOME/numba``, ``~/.cache/numba``), or where ``NUMBA_CACHE_DIR`` says; when
  none is writable (a read-only install and home) it refuses to decorate the function, which
  would fail with a traceback. The cache then moves to a per-user temporary directory, and if
  even that fails the kernel is compiled in every process, uncached.

And one cost: on a machine whose cache is empty, every worker process that calls a kernel
first would compile it at the same time (two workers: twice the work, on the cores the other
tasks need). A kernel called from Python with argument types it has no machine code for
therefore compiles them under an exclusive file lock beside its cache index (``compiling``,
around numba's ``_compile_for_args``): one process compiles and saves it, the others wait
for the lock and then load it from the cache. So each kernel is compiled once per machine,
and the note that says so is printed once, by the process that compiles
(``tma.runtime.compile_ahead`` compiles a command's kernels ahead, while it
simulates).
"""

import contextlib
import functools
import inspect
import os
import sys
import tempfile
import threading


def _temporary_cache_dir() -> bool:
    from numba.core import config

    user = getattr(os, "getuid", lambda: "user")()
    path = os.path.join(tempfile.gettempdir(), f"tma-numba-cache-{user}")
    try:
        os.makedirs(path, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError:
        return False
    config.CACHE_DIR = path
    return True


def numba_module():
    """numba, imported; a ConfigError naming the ``NUMBA_*`` environment variables set when
    numba refuses to start with them (``NUMBA_NUM_THREADS=0``: "Number of threads specified
    must be > 0"), rather than a traceback from inside numba."""
    try:
        import numba
    except Exception as exc:
        given = {k: v for k, v in os.environ.items() if k.startswith("NUMBA_")}
        if not given:
            raise
        from tma.errors import ConfigError

        names = ", ".join(f"{k}={v!r}" for k, v in sorted(given.items()))
        raise ConfigError(f"numba, which compiles the estimators' kernels, does not start "
                          f"with the environment's {names} ({' '.join(str(exc).split())}): "
                          f"correct or unset {', '.join(sorted(given))}") from None
    return numba


def _compile(function, options):
    numba = numba_module()

    try:
        return numba.njit(cache=True, **options)(function)
    except RuntimeError as exc:  # numba: "cannot cache function ...: no locator available"
        if "no locator available" not in str(exc):
            raise
        if _temporary_cache_dir():
            return numba.njit(cache=True, **options)(function)
        return numba.njit(cache=False, **options)(function)


def _stamp_dependencies(kernel, depends):
    """Add the (path, mtime, size) of each callee's file to the cache stamp of ``kernel``."""
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    if cache_file is None or not hasattr(cache_file, "_source_stamp"):
        return  # uncached, or a numba whose cache has another layout: nothing to extend
    stamps = []
    for callee in depends:
        path = inspect.getsourcefile(getattr(callee, "py_func", callee))
        st = os.stat(path)
        stamps.append((path, st.st_mtime, st.st_size))
    cache_file._source_stamp = (cache_file._source_stamp, tuple(sorted(stamps)))


_ANNOUNCED: set[str] = set()


def _index_path(kernel) -> str | None:
    """Where numba keeps the cache index of ``kernel`` (None: uncached)."""
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    return getattr(cache_file, "_index_path", None)


def _say_compiling(function) -> None:
    """Say once per process and module, on stderr (worker processes' logging is not the
    command's), that a module's kernels are being compiled: the first run on a machine spends
    seconds there, silently otherwise. Later runs load them from numba's cache."""
    module = function.__module__
    if module in _ANNOUNCED:
        return
    _ANNOUNCED.add(module)
    parts = module.split(".")
    name = module.rsplit(".", 1)[-1].removesuffix("_kernel")
    if parts[:2] == ["tma", "families"] and len(parts) > 3:  # "bearings2d lm"
        name = f"{parts[2]} {name}"
    sys.stderr.write(f"note: compiling {name} kernels (numba), once per machine: later runs "
                     "load them from its cache\n")  # one write: processes print side by side
    sys.stderr.flush()


@contextlib.contextmanager
def compiling(kernel, function):
    """Hold the machine-wide lock of ``kernel`` (numba's dispatcher of ``function``), a file
    ``<its cache index>.lock`` locked with ``flock``, while the block compiles it or loads it
    from the cache: a second process compiling the same kernel waits, then finds it cached.
    Without a cache, a lock file or ``flock`` (not POSIX), the block runs unlocked. Announces
    the compilation (``_say_compiling``) when the kernel's cache index is absent."""
    index = _index_path(kernel)
    with contextlib.ExitStack() as stack:
        if index is not None:
            try:
                import fcntl

                handle = stack.enter_context(open(f"{index}.lock", "a"))
                fcntl.flock(handle, fcntl.LOCK_EX)
            except (ImportError, OSError):  # a read-only cache, Windows: compile unlocked
                pass
            if not os.path.exists(index):
                _say_compiling(function)
        yield


def _locked_compilation(kernel, function) -> None:
    """Have ``kernel`` (numba's dispatcher of ``function``) compile, for the argument types
    of a call it has no machine code for, under its machine-wide lock (``compiling``):
    numba's dispatcher calls its ``_compile_for_args`` then, and runs the code it returns
    after, so a process waits for another's compilation, never for its computation."""
    compile_for_args = kernel._compile_for_args

    def locked(*args, **kwargs):
        with compiling(kernel, function):
            return compile_for_args(*args, **kwargs)

    kernel._compile_for_args = locked


_KERNELS: list["Kernel"] = []  # every kernel of the modules imported in this process


def compiled_before(package: str) -> bool:
    """Whether the modules of ``package`` imported in this process have no kernel, or
    numba's cache holds any of their kernels (a module's kernels that no code path calls are
    never cached, so not "all"): False on a machine whose cache is empty, or was emptied.
    Makes their dispatchers (imports numba), compiles none."""
    kernels = [k for k in _KERNELS
               if k.__module__ == package or k.__module__.startswith(f"{package}.")]
    return not kernels or any(
        (index := _index_path(k.dispatcher)) is not None and os.path.exists(index)
        for k in kernels)


class Kernel:
    """A kernel whose numba dispatcher is made on first use. Called from Python it calls the
    dispatcher; inside another kernel numba types it as that dispatcher (``_numba_type_``);
    any other attribute (``stats``, ``signatures``...) is the dispatcher's."""

    def __init__(self, function, options, depends):
        self._dispatcher = None
        self._lock = threading.Lock()
        self._options, self._depends = options, tuple(depends)
        self.py_func = function
        functools.update_wrapper(self, function)
        _KERNELS.append(self)

    @property
    def dispatcher(self):
        if self._dispatcher is None:
            with self._lock:
                if self._dispatcher is None:
                    kernel = _compile(self.py_func, self._options)
                    _stamp_dependencies(kernel, self._depends)
                    _locked_compilation(kernel, self.py_func)
                    self._dispatcher = kernel
        return self._dispatcher

    @property
    def _numba_type_(self):
        return self.dispatcher._numba_type_

    def __call__(self, *args, **kwargs):
        return self.dispatcher(*args, **kwargs)

    def __getattr__(self, name):
        if name.startswith("__"):  # probes of the protocol (copy, pickle...) are not numba's
            raise AttributeError(name)
        return getattr(self.dispatcher, name)

    def __reduce__(self):  # pickled by reference, as a function is
        return self.__qualname__


def njit(depends=(), **options):
    """``numba.njit(cache=True, **options)`` as a decorator, made on first use, with the
    fallbacks above. ``depends``: the compiled functions from other files this kernel calls."""

    def decorate(function):
        return Kernel(function, options, depends)

    return decorate
