"""``tma.runtime.jit``: a cached kernel is recompiled when a kernel it calls from another file
changes, and a read-only install with a read-only home still imports and runs (real numba, fresh
processes)."""

import os
import shutil
import subprocess
import sys
import textwrap
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
