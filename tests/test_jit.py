"""``tma.runtime.jit``: a cached kernel is recompiled when a kernel it calls from another file
changes, and a read-only install with a read-only home still imports and runs (real numba, fresh
processes)."""

import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

CALLEE = """
from tma.runtime.jit import njit

@njit()
def scale(x):
    return {factor} * x
"""
KERNEL = """
from tma.runtime.jit import njit
from callee import scale

@njit(depends=(scale,))
def total(n):
    acc = 0.0
    for i in range(n):
        acc += scale(i)
    return acc
"""
RUN = "from kernel import total; print(total(4), sum(total.stats.cache_hits.values()))"


def _run(cwd, env=None):
    env = {**os.environ, "PYTHONPATH": f"{cwd}{os.pathsep}{REPO}", **(env or {})}
    out = subprocess.run([sys.executable, "-c", RUN], cwd=cwd, env=env, capture_output=True,
                         text=True, check=True)
    return out.stdout.split()


def test_a_changed_callee_in_another_file_invalidates_the_cached_kernel(tmp_path):
    (tmp_path / "callee.py").write_text(CALLEE.format(factor=1.0))
    (tmp_path / "kernel.py").write_text(KERNEL)
    assert _run(tmp_path) == ["6.0", "0"]  # compiled
    assert _run(tmp_path) == ["6.0", "1"]  # loaded from the cache
    (tmp_path / "callee.py").write_text(CALLEE.format(factor=2.0) + "\n# longer\n")
    assert _run(tmp_path) == ["12.0", "0"]  # recompiled, not the stale 6.0


@pytest.mark.skipif(os.name != "posix" or os.geteuid() != 0 or not shutil.which("unshare"),
                    reason="needs root and unshare to mount the package read-only")
def test_a_read_only_install_and_home_still_import_and_run(tmp_path):
    """Without the fallback numba raises 'cannot cache function ...: no locator available'
    at import."""
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "callee.py").write_text(CALLEE.format(factor=1.0))
    (package / "kernel.py").write_text(KERNEL)
    temp = tmp_path / "tmp"
    temp.mkdir()
    script = textwrap.dedent(f"""
        mount --bind {package} {package} && mount -o remount,ro,bind {package} || exit 77
        cd {package} && HOME={package} XDG_CACHE_HOME={package} TMPDIR={temp} \\
            PYTHONPATH={package}:{REPO} {sys.executable} -c "{RUN}"
    """)
    out = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True)
    if out.returncode == 77:
        pytest.skip("this machine cannot mount read-only")
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[0] == "6.0"
    assert any(p.name.startswith("tma-numba-cache-") for p in temp.iterdir())


RACE = """
import os, sys, time
import numba  # imported before the start: the processes race to compile, not to import
from kernel import total
open(f"ready-{os.getpid()}", "w").close()
while not os.path.exists("go"):
    time.sleep(0.001)
print(total(4), sum(total.stats.cache_misses.values()))
"""


def test_processes_starting_at_once_compile_a_kernel_once(tmp_path):
    """Issue 32: two processes calling the same kernel at the same moment with an empty cache
    (two workers of a fresh machine's first ``make table``): one compiles it and says so, the
    other waits for it and loads it from the cache. Before, both compiled (and said so)."""
    (tmp_path / "callee.py").write_text(CALLEE.format(factor=1.0))
    (tmp_path / "kernel.py").write_text(KERNEL)
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{REPO}",
           "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    procs = [subprocess.Popen([sys.executable, "-c", RACE], cwd=tmp_path, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    while len(list(tmp_path.glob("ready-*"))) < 2 and all(p.poll() is None for p in procs):
        time.sleep(0.01)
    (tmp_path / "go").touch()
    outs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    assert sorted(out.split()[1] for out, _ in outs) == ["0", "1"]  # compiled once, loaded once
    assert all(out.split()[0] == "6.0" for out, _ in outs)
    notes = "".join(err for _, err in outs)
    assert notes.count("note: compiling kernel kernels (numba), once per machine") == 1, notes


AHEAD = """
from tma.runtime import compile_ahead
run = compile_ahead.run_ahead
def traced(estimator, log):
    import sys
    sys.stdout.write(estimator.name + "\\n")  # one write: the processes run side by side
    sys.stdout.flush()  # flushed: the forked processes end with os._exit
    return run(estimator, log)
compile_ahead.run_ahead = traced
compile_ahead._compile_ahead([{"family": "bearings2d", "sigma_deg": 0.5}],
                        [{"name": "lm"}, {"name": "nbearings"}])
"""


def test_a_commands_kernels_are_compiled_ahead_then_only_loaded(tmp_path):
    """Issue 32: with an empty cache, compiling ahead runs each estimator of a command on a
    small log of its scenario (side by side), which compiles every kernel the command's
    workers then need: the table that follows compiles nothing. With the cache warm,
    compiling ahead runs nothing."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONWARNINGS": "ignore"}

    def ahead():
        return subprocess.run([sys.executable, "-c", AHEAD], cwd=REPO, env=env, check=True,
                              capture_output=True, text=True, timeout=600)

    cold = ahead()
    assert sorted(cold.stdout.split()) == ["lm", "nbearings"], cold.stdout
    assert "note: compiling bearings2d marquardt kernels" in cold.stderr
    assert ahead().stdout == ""  # warm: nothing to do ahead
    table = subprocess.run(
        [sys.executable, "-m", "pipeline.table", "experiment=bearings2d_table",
         "scenario.n_tracks=40", "scenario.shard_size=20", "scenario.sigma_deg=[0.0,0.5]",
         f"paths.data_dir={tmp_path / 'data'}", f"paths.tables_dir={tmp_path / 'tables'}",
         f"hydra.run.dir={tmp_path / 'outputs'}", "progress=false"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert table.returncode == 0, table.stderr
    assert "compiling" not in table.stderr, table.stderr
