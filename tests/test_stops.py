"""Commands stopped or killed (issue 30): Ctrl-C, SIGTERM, SIGHUP, a worker or the command
SIGKILLed. Each is a real command in its own process, signalled while its workers compute;
afterwards no process of it is left, nothing of it stays in /dev/shm that a re-run does not
remove, and what it says is one line that a re-run resumes. Also the environment a command
meets (MPLBACKEND, NUMBA_NUM_THREADS, a deleted working directory) and the number of
workers. A few seconds each (marked ``signals``)."""

import logging
import os
import signal
import subprocess
import sys
import time

import psutil
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import REPO, run_cli
from tests.test_docs import write_logs
from tma.runtime.forkserver import SHM
from tma.runtime.parallel import Engine, run_tasks

pytestmark = pytest.mark.signals
ESTIMATE = ["scenario.n_tracks=24000", "scenario.shard_size=250", "progress=false"]
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"} | {
    "PYTHONWARNINGS": "ignore"}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A dataset of 96 shards: its estimate keeps two workers busy for a few seconds."""
    root = tmp_path_factory.mktemp("stops")
    run_cli("simulate", *ESTIMATE, f"paths.data_dir={root}")
    return root


def _shm() -> set[str]:
    return set(os.listdir(SHM)) if os.path.isdir(SHM) else set()


def _of(names, pids) -> set[str]:
    """The /dev/shm entries named by one of ``pids`` (loky's, joblib's, tma's marker)."""
    marks = {f"-{pid}-" for pid in pids} | {f"_{pid}_" for pid in pids}
    return {n for n in names if any(m in n for m in marks)}


def _workers(command: psutil.Process) -> list[psutil.Process]:
    """The command's workers: processes forked by its fork server."""
    try:
        return [p for p in command.children(recursive=True) if p.ppid() != command.pid]
    except psutil.NoSuchProcess:
        return []


def _gone(processes, within: float = 10.0) -> list[psutil.Process]:
    """Those of ``processes`` still alive (not zombies) after up to ``within`` s."""
    deadline = time.monotonic() + within
    while True:
        alive = []
        for p in processes:
            try:
                if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                    alive.append(p)
            except psutil.NoSuchProcess:
                pass
        if not alive or time.monotonic() > deadline:
            return alive
        time.sleep(0.1)


def _estimate(data, force=True) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "pipeline.estimate", *ESTIMATE, f"paths.data_dir={data}",
         "parallel.n_jobs=2", *(["force=true"] if force else [])],
        cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True)  # its own process group, as a shell's job


def _stopped(data, how: str):
    """Start an estimate, wait until its workers compute, stop it ``how``; returns the
    process, its stderr, every process it had, and the /dev/shm entries of those."""
    proc, command = _estimate(data), None
    command = psutil.Process(proc.pid)
    deadline = time.monotonic() + 120
    while not _workers(command):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    time.sleep(0.3)  # the tasks under way
    tree = [command, *command.children(recursive=True)]
    if how == "worker":
        _workers(command)[0].send_signal(signal.SIGKILL)
    elif how.endswith("-group"):
        os.killpg(proc.pid, getattr(signal, how.removesuffix("-group")))
    else:
        proc.send_signal(getattr(signal, how))
    _, err = proc.communicate(timeout=120)
    return proc, err, tree


def _one_line_resumes(err: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "run the same command again to resume" in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("how", ["SIGINT-group", "SIGINT", "SIGTERM", "SIGTERM-group",
                                 "SIGHUP", "worker"])
def test_a_stopped_command_leaves_nothing_and_says_a_rerun_resumes(data, how):
    before = _shm()
    proc, err, tree = _stopped(data, how)
    line = _one_line_resumes(err)
    number = getattr(signal, how.removesuffix("-group"), None)
    if how == "worker":
        assert proc.returncode == 2 and "a worker process died (SIGKILL(-9))" in line
    elif how.endswith("-group"):  # its workers got the signal too: either is said
        assert proc.returncode in (128 + number, 2), err
    else:
        assert proc.returncode == 128 + number, err
        assert line.startswith(f"error: stopped by {signal.Signals(number).name}")
    assert not _gone(tree)
    deadline = time.monotonic() + 10  # the trackers free what they hold as they end
    while _of(_shm() - before, [p.pid for p in tree]) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _of(_shm() - before, [p.pid for p in tree])
    rerun = _estimate(data, force=False)
    _, err = rerun.communicate(timeout=300)
    assert rerun.returncode == 0, err


@pytest.mark.parametrize("how", ["SIGKILL", "SIGKILL-group"])
def test_a_killed_command_leaves_no_process_and_a_rerun_frees_its_shared_memory(data, how):
    """Killed outright, a command says nothing; its server and workers die with it (a
    parent-death signal), and what its trackers could not free (killed with it) the next
    command removes, by tma's marker, and nothing else."""
    # (its own name per test and process: the parametrisations may run at once in two
    # pytest workers, and one's clean-up must not remove the other's)
    stranger = (os.path.join(SHM, f"sem.loky-1-notours-{how}-{os.getpid()}")
                if os.path.isdir(SHM) else None)
    if stranger:  # not tma's: never touched
        open(stranger, "w").close()
    try:
        before = _shm()
        proc, _, tree = _stopped(data, how)
        assert proc.returncode == -signal.SIGKILL
        assert not _gone(tree)
        rerun = _estimate(data, force=False)
        _, err = rerun.communicate(timeout=300)
        assert rerun.returncode == 0, err
        assert not _of(_shm() - before, [p.pid for p in tree] + [rerun.pid])
        if stranger:
            assert os.path.exists(stranger)
    finally:
        if stranger and os.path.exists(stranger):
            os.unlink(stranger)


def _pid(task):
    return os.getpid()


def _loky_workers() -> list[psutil.Process]:
    """This process's live loky workers (not its resource tracker)."""
    found = []
    for p in psutil.Process().children(recursive=True):
        try:
            line = " ".join(p.cmdline())
        except psutil.Error:  # gone, or a zombie
            continue
        if "loky" in line and "resource_tracker" not in line:
            found.append(p)
    return found


def test_never_more_workers_than_tasks(caplog):
    from joblib.externals.loky import get_reusable_executor

    get_reusable_executor().shutdown(wait=True, kill_workers=True)  # none from before
    with caplog.at_level(logging.INFO, logger="tma.runtime.parallel"):
        pids = run_tasks(_pid, [0, 1], engine=Engine(n_jobs=12), progress=False)
    assert len(set(pids)) <= 2 and os.getpid() not in pids
    assert len(_loky_workers()) <= 2
    assert "parallel.n_jobs=12: 2 worker(s), one per task" in caplog.text


def test_a_deleted_working_directory_is_one_line(tmp_path):
    gone = tmp_path / "gone"
    gone.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.ingest", "input=x.csv"],
                            cwd=gone, env=ENV | {"PYTHONPATH": str(REPO)},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: os.rmdir(gone))  # deleted under it
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2 and err.strip() == (
        "error: the working directory no longer exists (deleted, or its disk unmounted): cd "
        "to a directory that exists and run the command again")


# -- the environment ---------------------------------------------------------------------------

DRAW = ("import sys; from tma.tables.write import plots_to_files; plots_to_files(); "
        "import matplotlib; matplotlib.use('Agg'); import matplotlib.pyplot as plt; "
        "plt.figure().savefig(sys.argv[1])")
ENV_TEXT = st.text(st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",)),
                   min_size=1, max_size=10)


@settings(max_examples=6, deadline=None, suppress_health_check=[
    HealthCheck.function_scoped_fixture])
@given(backend=st.one_of(ENV_TEXT, st.sampled_from(["bogus", "agg", "pdf", "tkagg", "qtagg",
                                                    "module://nope"])))
def test_any_mplbackend_lets_tma_draw_into_files(backend, tmp_path):
    out = tmp_path / "f.png"
    proc = subprocess.run([sys.executable, "-c", DRAW, str(out)], env=ENV | {
        "MPLBACKEND": backend}, capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0 and out.stat().st_size > 0, proc.stderr


NUMBA = ("from tma.runtime.jit import numba_module\ntry:\n    numba_module()\n"
         "except ValueError as e:\n"
         "    print('error:', e); raise SystemExit(2)")


@settings(max_examples=6, deadline=None)
@given(threads=st.one_of(st.integers(-3, 0).map(str), st.sampled_from(["abc", "1.5", "2"]),
                         ENV_TEXT))
def test_numba_num_threads_is_accepted_or_named_in_one_line(threads):
    proc = subprocess.run([sys.executable, "-c", NUMBA], env=ENV | {
        "NUMBA_NUM_THREADS": threads}, capture_output=True, text=True, timeout=120, cwd=REPO)
    if proc.returncode == 0:
        return
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    line = proc.stdout.strip()
    assert "\n" not in line and "NUMBA_NUM_THREADS" in line, proc.stdout


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    return write_logs(tmp_path_factory.mktemp("env"))


@pytest.mark.parametrize("variable, value, flags", [("MPLBACKEND", "bogus", []),
                                                    ("MPLBACKEND", "bogus", ["-m"]),
                                                    ("NUMBA_NUM_THREADS", "0", [])])
def test_a_table_under_a_bad_environment(logs, tmp_path, variable, value, flags):
    """Also as a multirun, whose jobs fork from the server that preloads matplotlib."""
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline.table", *flags, f"input={logs / 'nav_export.csv'}",
         f"paths.data_dir={tmp_path / 'data'}", f"paths.tables_dir={tmp_path / 'tables'}",
         "progress=false", "parallel=serial", *(["estimator=lm,nbearings"] if flags else [])],
        env=ENV | {variable: value}, capture_output=True, text=True, timeout=300, cwd=REPO)
    if variable == "MPLBACKEND":  # tma draws into files: Agg, said once
        assert proc.returncode == 0, proc.stderr
        for estimator in ["lm", "nbearings"] if flags else ["lm"]:
            assert (tmp_path / "tables" / f"nav_export-{estimator}-T1.png").stat().st_size > 0
        assert "MPLBACKEND=bogus is no matplotlib backend" in proc.stdout + proc.stderr
    else:
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.strip().splitlines()[-1] == (
            "error: numba, which compiles the estimators' kernels, does not start with the "
            "environment's NUMBA_NUM_THREADS='0' (Number of threads specified must be > 0.): "
            "correct or unset NUMBA_NUM_THREADS")
