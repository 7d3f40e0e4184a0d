"""Compiled kernels: ``numba.njit`` with its on-disk cache, kept correct and never fatal.

Every kernel is compiled once and cached (``cache=True``), so worker processes and later runs
load machine code instead of recompiling (numba's first call in a process still costs ~0.5 s
to start its compiler, each cached kernel then a few ms).

Two gaps of numba's cache are closed here:

- numba invalidates a cached kernel when *its own* source file changes, not when a kernel it
  calls from another file does, and would go on running stale code. ``depends`` names those
  callees: the files they live in join the kernel's cache stamp.
- numba caches beside the source (``__pycache__``), else in the user-wide cache directory
  (``$XDG_CACHE_HOME/numba``, ``~/.cache/numba``), or where ``NUMBA_CACHE_DIR`` says; when
  none is writable (a read-only install and home) it refuses to decorate the function, which
  would fail the import with a traceback. The cache then moves to a per-user temporary
  directory, and if even that fails the kernel is compiled in every process, uncached.
"""

import inspect
import os
import tempfile

import numba
from numba.core import config


def _temporary_cache_dir() -> bool:
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


def _compile(function, options):
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


def njit(depends=(), **options):
    """``numba.njit(cache=True, **options)`` as a decorator, with the fallbacks above.
    ``depends``: the compiled functions from other files this kernel calls."""

    def decorate(function):
        kernel = _compile(function, options)
        _stamp_dependencies(kernel, depends)
        return kernel

    return decorate
