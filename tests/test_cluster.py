"""Shards on a Dask cluster (a LocalCluster of two worker processes, as ``parallel=dask``
starts one): the same bytes as in this process, and a worker killed mid-run costs only its
shard. A scheduler address that is wrong, or where something else listens, is one line within
the connect timeout; a run prints tma's lines only, unless Dask's are asked for. Sweeps
through the SLURM preset's local twin (submitit's local executor)."""

import contextlib
import http.server
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from pipeline._common import engine, scenario_nodes
from tests.conftest import REPO, compose_cfg, run_cli, run_stage_here
from tests.test_pipeline import GRID, _all_stages, _files
from tma.errors import ConfigError, InputError
from tma.runtime.cluster import close_dask_clients, dask_client
from tma.runtime.parallel import Engine, run_tasks
from tma.stages.simulate import simulate_datasets

pytest.importorskip("distributed")
DASK = Engine(engine="dask", n_workers=2)


@pytest.fixture(scope="module", autouse=True)
def cluster():
    yield dask_client(DASK.address, DASK.n_workers)
    close_dask_clients()


def test_parallel_dask_gives_the_bytes_of_parallel_serial(tmp_path):
    trees = []
    for choice in ("serial", "dask"):
        root = tmp_path / choice
        _all_stages([*GRID, f"paths.data_dir={root}", f"paths.tables_dir={root}/tables",
                     f"parallel={choice}"])
        trees.append(_files(root))
    assert trees[0].keys() == trees[1].keys()
    assert [str(k) for k in trees[0] if trees[0][k] != trees[1][k]] == []
    assert len({k.parent for k in trees[0] if k.parent.name == "estimates"}) == 4


def _kill_when_shards_exist(stage: Path, pid: int, at: int, report: dict):
    deadline = time.monotonic() + 120
    while len(list(stage.glob("log/shard-*.mcap"))) < at and time.monotonic() < deadline:
        time.sleep(0.005)
    report["manifest before kill"] = (stage.parent / stage.name[1:-8] / "manifest.json").exists()
    report["shards before kill"] = len(list(stage.glob("log/shard-*.mcap")))
    os.kill(pid, signal.SIGKILL)


def test_a_worker_killed_mid_run_costs_only_its_shard(tmp_path, cluster):
    nodes = scenario_nodes(compose_cfg(["scenario.n_tracks=900", "scenario.shard_size=15"]))
    victim = next(iter(cluster.run(os.getpid).values()))
    name = simulate_datasets(nodes, tmp_path / "serial", engine=1, progress=False)[0].name
    stage = tmp_path / "dask" / "datasets" / f".{name}.partial"
    report = {}
    killer = threading.Thread(target=_kill_when_shards_exist, args=(stage, victim, 6, report))
    killer.start()
    simulate_datasets(nodes, tmp_path / "dask", engine=DASK, progress=False)
    killer.join()
    assert not report["manifest before kill"] and report["shards before kill"] < 60
    assert victim not in cluster.run(os.getpid).values()  # the nanny started a new worker
    serial, dask = _files(tmp_path / "serial"), _files(tmp_path / "dask")
    assert serial == dask  # nothing half-written, nothing missing, the same bytes
    assert not list((tmp_path / "dask").rglob("*.tmp-*"))


@pytest.mark.parametrize(("override", "message"), [
    ("parallel.address=nowhere", "parallel.address=nowhere: not a scheduler address; "
                                 "parallel.address must be a Dask scheduler address such as "
                                 "tcp://scheduler:8786"),
    ("parallel.address='foo://bar:1'", "parallel.address=foo://bar:1: unknown scheme 'foo://'"),
    ("parallel.address='tcp://localhost:notaport'", "port 'notaport' is not a number"),
    ("parallel.address='tcp://localhost:99999'", "port '99999' is not a number from 1 to 65535"),
    ("parallel.address='tcp://localhost'", "parallel.address=tcp://localhost: no port"),
    ("parallel.address='tcp://:8786'", "parallel.address=tcp://:8786: no host"),
    ("parallel.address='inproc://x'", "unknown scheme 'inproc://'"),
    ("parallel.address='tcp://h:8786/x'", "unexpected text around host:port"),
    ("parallel.address='tcp://[::1'", "not a scheduler address"),
    ("parallel.n_workers=0", "parallel.n_workers must be >= 1, got 0"),
    ("parallel.n_workers=1.5", "parallel.n_workers must be a whole number >= 1, got the float "
                                  "1.5"),
    ("parallel.retries=-1", "parallel.retries must be >= 0, got -1"),
    ("parallel.connect_timeout=0", "parallel.connect_timeout must be > 0, got 0"),
    ("parallel.connect_timeout=abc", "parallel.connect_timeout must be a number > 0, got 'abc'"),
    ("parallel.verbose=maybe", "parallel.verbose must be true or false, got 'maybe'"),
    ("parallel.engine=ray", "parallel.engine must be one of joblib, dask, got 'ray'"),
    ("+parallel.threads=4", "unknown option(s) parallel.threads"),
])
def test_bad_cluster_options_are_one_clear_line(override, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        engine(compose_cfg(["parallel=dask", override]))


def test_slurm_preset_composes_and_its_local_twin_runs_a_sweep_one_layer_deep(tmp_path):
    slurm = compose_cfg(["hydra/launcher=slurm", f"paths.data_dir={tmp_path}"],
                        return_hydra_config=True).hydra.launcher
    assert slurm._target_.endswith("SlurmLauncher") and slurm.cpus_per_task == 1
    common = [f"paths.data_dir={tmp_path}", "scenario.n_tracks=40", "scenario.shard_size=20",
              "progress=false"]
    proc = run_cli("simulate", "-m", "hydra/launcher=slurm_local", "scenario.sigma_deg=0.1,0.5",
                   *common)
    assert "Submitit 'local' sweep output dir" in proc.stdout + proc.stderr
    datasets = sorted(tmp_path.glob("datasets/*/manifest.json"))
    assert len(datasets) == 2
    logs = list(tmp_path.glob("hydra/simulate-multirun/*/*/simulate.log"))
    assert len(logs) == 2
    assert all(p.read_text().count("shards run serially inside each job") == 1 for p in logs)
    # the jobs' results on the console (issue 22, item 9), in job order; no folder named %j
    shown = [line for line in proc.stdout.splitlines() if "][tma][INFO] - dataset " in line]
    assert [line.split()[0] for line in shown] == ["#0", "#1"]
    assert sorted(line.split()[-1] for line in shown) == [str(p.parent) for p in datasets]
    assert not [p for p in tmp_path.rglob("*") if "%" in p.name]


def _refuse_three(task):
    if task == 3:
        raise InputError(f"shard {task}: bad input")
    return task * 2


def test_a_failing_shard_stops_the_run_with_its_own_error():
    with pytest.raises(InputError, match="shard 3: bad input"):
        run_tasks(_refuse_three, range(40), engine=DASK, progress=False)
    assert run_tasks(_refuse_three, [1, 2], engine=DASK, progress=False) == [2, 4]


# -- a scheduler address where no Dask scheduler answers ----------------------------------------

class _QuietHTTP(http.server.BaseHTTPRequestHandler):
    timeout = 5  # a handler waiting for a request line ends with the test

    def log_message(self, *args):  # not on the stderr the test reads
        pass


@contextlib.contextmanager
def _service(kind, cluster):
    """The address of a service that is not a Dask scheduler, or a bad address as written."""
    if kind == "http":  # Python's HTTP server: reads Dask's first bytes as a request line
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _QuietHTTP)
        server.daemon_threads = True
        threading.Thread(target=server.serve_forever, daemon=True).start()
        try:
            yield f"tcp://127.0.0.1:{server.server_port}"
        finally:
            server.shutdown()
            server.server_close()
        return
    if kind == "worker":  # a Dask worker's own address, not its scheduler's
        yield next(iter(cluster.scheduler_info()["workers"]))
        return
    if "://" in kind:
        yield kind
        return
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        if kind != "refused":  # bound, never listening: the connection is refused
            listener.listen()
            server = threading.Thread(target=_serve, args=(listener, kind), daemon=True)
            server.start()
        try:
            yield f"tcp://127.0.0.1:{listener.getsockname()[1]}"
        finally:
            if kind != "refused":
                listener.shutdown(socket.SHUT_RDWR)  # wakes its accept()
                server.join()


def _serve(listener, kind):
    with contextlib.ExitStack() as held:
        with contextlib.suppress(OSError):  # the listener shut down: the test is over
            while True:
                conn = held.enter_context(listener.accept()[0])
                if kind == "garbage":  # an answer that is not Dask's, then the end
                    conn.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")
                if kind != "silent":  # silent: accepts and says nothing, as in the issue
                    conn.close()


def _within(seconds, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` in a thread; fails the test (instead of hanging it) after
    ``seconds``."""
    outcome = {}

    def call():
        try:
            outcome["value"] = fn(*args, **kwargs)
        except BaseException as exc:  # re-raised in the test's thread
            outcome["error"] = exc

    thread = threading.Thread(target=call, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"still waiting after {seconds} s"
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]


@pytest.mark.parametrize(("kind", "message"), [
    ("silent", "something there accepts connections but sends no Dask handshake within "
               "0.5 s: not a Dask scheduler"),
    ("http", "not a Dask scheduler"),
    ("garbage", "something there answers, but not in Dask's protocol: not a Dask scheduler"),
    # (distributed's connect retries a closed connection until the timeout: on a loaded
    # machine the probe may see the timeout first, which names no scheduler as well)
    ("closes", ("accepts connections but closes them without a Dask handshake",
                "accepts connections but sends no Dask handshake within 5 s")),
    ("refused", "(connection refused) after 0.5 s (parallel.connect_timeout)"),
    ("worker", "that is a Dask worker, not the scheduler"),
    ("foo://bar:1", "unknown scheme 'foo://'"),
    ("tcp://localhost:notaport", "port 'notaport' is not a number from 1 to 65535"),
    ("tls://127.0.0.1:8786", "TLS needs Dask's TLS settings"),
])
def test_a_scheduler_address_where_no_scheduler_answers_is_one_line(tmp_path, cluster, kind,
                                                                    message):
    t0 = time.monotonic()
    with _service(kind, cluster) as address:
        # a bad address as the issue gave it; a service within half a second (one that
        # closes the connection: within 5 s, so that a loaded machine still sees it close
        # before the timeout)
        wait = 5 if kind == "closes" else 0.5
        timeout = [] if "://" in kind else [f"parallel.connect_timeout={wait}"]
        proc = _within(60, run_stage_here, "simulate", f"paths.data_dir={tmp_path}",
                       "scenario.n_tracks=4", "scenario.shard_size=2", "progress=false",
                       "parallel=dask", f"parallel.address='{address}'", *timeout, check=False)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith(f"error: parallel.address={address}: ")
    messages = message if isinstance(message, tuple) else (message,)
    assert proc.stderr.count("\n") == 1 and any(m in proc.stderr for m in messages)
    assert time.monotonic() - t0 < 15


def _prints_errors(name="distributed.worker") -> bool:
    """Whether this process would print (on a stream) an ERROR record of the logger ``name``
    (distributed also keeps the records in memory, for ``Client.get_worker_logs``)."""
    logger = node = logging.getLogger(name)
    if not logger.isEnabledFor(logging.ERROR):
        return False
    handlers = []
    while node is not None:
        handlers += node.handlers
        node = node.parent if node.propagate else None
    return any(isinstance(h, logging.StreamHandler) and h.level <= logging.ERROR
               for h in handlers or [logging.lastResort])


def test_dask_logging_is_quiet_unless_asked_for(cluster):
    # a LocalCluster's worker that closes while its heartbeat is in flight logs that
    # CommClosedError at ERROR with its traceback: quiet workers print nothing
    assert not any(cluster.run(_prints_errors).values())
    # no HTTP server on 8787: a second cluster on this machine would print a UserWarning
    assert cluster.scheduler_info()["services"].get("dashboard") != 8787
    dask_client(cluster.scheduler.address, 1, connect_timeout=5, verbose=True)
    assert logging.getLogger("distributed.scheduler").getEffectiveLevel() == logging.INFO
    dask_client(cluster.scheduler.address, 1, connect_timeout=5)  # a real scheduler answers
    assert logging.getLogger("distributed.scheduler").getEffectiveLevel() == logging.WARNING


def _cli(verb, *overrides):
    """``python -m pipeline.<verb>`` as a user runs it (Python's default warning filters)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    return subprocess.run([sys.executable, "-m", f"pipeline.{verb}", *overrides], cwd=REPO,
                          capture_output=True, text=True, env=env, timeout=300)


def test_a_dask_run_prints_tma_lines_only_and_a_failing_shard_one_error(tmp_path):
    common = [f"paths.data_dir={tmp_path}", "scenario.n_tracks=12", "scenario.shard_size=2",
              "progress=false", "parallel=dask"]
    proc = _cli("simulate", *common, "parallel.n_workers=4")  # its LocalCluster's shutdown
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # no worker's log, no traceback, no warning
    assert [line for line in proc.stdout.splitlines() if "][tma" not in line] == []
    shard = sorted(tmp_path.glob("datasets/*/log/shard-*.mcap"))[0]
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(data)
    proc = _cli("estimate", *common)  # the shard fails on a worker, and again on each retry
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: ") and proc.stderr.count("\n") == 1
    assert "does not match the manifest" in proc.stderr
