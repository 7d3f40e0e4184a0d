"""Every default table and a sweep of small jobs beside its floor (``make bench``, section
``tables``; issue 24).

A command's floor is what its work costs with nothing around it: the simulation and the
estimation it does, in memory in one process with the compiled kernels loaded (CPU time at
one thread), divided by the workers as if they scaled perfectly, plus the bytes it writes and
reads at this disk's measured speed (write with fsync, read from the page cache, where a stage
finds what the one before it wrote). Everything else is the command's own cost: Python and
Hydra starting, worker start-up, encoding and decoding the logs, hashing, the metrics, the
tables and plots. Both sides are the best of ``repeat`` measurements, interleaved so that a
slow spell of the machine is shared.

Each command's ratio counts its start-up in the floor (issue 32): ``python -m pipeline.table
--cfg job`` (Python, Hydra, tma's imports, the config composed, no stage), measured in the same
run, itself printed beside a bare interpreter importing numpy and pyarrow (target <= 4x).

The in-memory work is measured with the library's own functions on the command's own
configs: the scenario's ``simulate_shard`` (``simulate_raw`` once for the datasets that share
their random draws, as ``pipeline.simulate`` does), each estimator's ``prepare`` (artefacts
such as a training bundle and trained gains, built into a scratch directory in memory) and
``estimate`` over every shard (``tma.stages.estimate.estimate_log``).
"""

import logging
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
WORKERS = 2
LOG_LINE = re.compile(r"^\[(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3})\]\[[^\]]+\]\[\w+\] - (.*)$",
                      re.M)
STAGE = re.compile(r"stage (simulate|estimate|aggregate): ([0-9.]+) s")
ARTEFACT = re.compile(r"artefact (\w+) built in ([0-9.]+) s")
SWEEP_SIGMAS = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0)
SWEEP_ESTIMATORS = ("lm", "nbearings", "mpekf", "iv")
SWEEP = ["-m", "hydra/launcher=parallel", "scenario.n_tracks=1000",
         f"scenario.sigma_deg={','.join(map(str, SWEEP_SIGMAS))}",
         f"estimator={','.join(SWEEP_ESTIMATORS)}"]
# the same points in one command (docs/architecture.md, "Two sweeps")
ONE_COMMAND = ["scenario.n_tracks=1000", f"scenario.sigma_deg=[{','.join(map(str, SWEEP_SIGMAS))}]",
        *(f"+estimator@estimators.{e}={e}" for e in SWEEP_ESTIMATORS)]


@dataclass
class Command:
    """One run of ``python -m pipeline.table``: its wall time, each stage's (as it logs
    them), when each stage ended, and the artefacts it built (kind -> s)."""

    wall: float
    jobs: int = 0  # jobs that ran the stages (a multirun: one per point)
    stages: dict = field(default_factory=dict)
    ends: dict = field(default_factory=dict)
    artefacts: dict = field(default_factory=dict)


def run_table(arguments, workdir: Path) -> Command:
    """``python -m pipeline.table`` (what ``make table`` runs) on fresh data under
    ``workdir``."""
    paths = [f"paths.data_dir={workdir / 'data'}", f"paths.tables_dir={workdir / 'tables'}",
             f"hydra.sweep.dir={workdir / 'multirun'}", f"hydra.run.dir={workdir / 'outputs'}",
             "progress=false"]
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pipeline.table", *arguments, *paths],
                          cwd=REPO, check=True, capture_output=True, text=True)
    command = Command(time.perf_counter() - start)
    for stamp, message in LOG_LINE.findall(proc.stdout + proc.stderr):
        if m := STAGE.search(message):
            command.jobs += m[1] == "simulate"
            command.stages[m[1]] = command.stages.get(m[1], 0.0) + float(m[2])
            command.ends[m[1]] = datetime.strptime(stamp, "%Y-%m-%d %H:%M:%S,%f").timestamp()
        elif m := ARTEFACT.search(message):
            command.artefacts[m[1]] = command.artefacts.get(m[1], 0.0) + float(m[2])
    return command


def compose(overrides):
    """The config a job of ``pipeline.table`` gets from these overrides, with Hydra's record
    of them (tma.plan.points reads it)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from pipeline._common import CONF_DIR

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return hydra_compose("config", overrides=list(overrides), return_hydra_config=True)


def sweep_jobs() -> list[list[str]]:
    """Each job's overrides of the sweep (sigma x estimator)."""
    return [["scenario.n_tracks=1000", f"scenario.sigma_deg={s}", f"estimator={e}"]
            for s in SWEEP_SIGMAS for e in SWEEP_ESTIMATORS]


class _Artefacts(logging.Handler):
    """Collects ``artefact KIND built in S s`` records (``tma.io.artefacts``)."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.built = []

    def emit(self, record):
        if m := ARTEFACT.search(record.getMessage()):
            self.built.append((m[1], float(m[2])))


@dataclass
class Work:
    """CPU seconds (one thread) of the work of some commands, by stage and part, and the
    bytes their estimate and aggregate stages must at least read."""

    seconds: dict = field(default_factory=lambda: defaultdict(lambda: defaultdict(float)))
    read: dict = field(default_factory=lambda: defaultdict(int))

    def total(self, stage: str) -> float:
        return sum(self.seconds[stage].values())


def _cpu(function, *args):
    start = time.process_time()
    out = function(*args)
    return out, time.process_time() - start


def in_memory_work(job_overrides, data_dir: Path) -> Work:
    """The simulation and estimation of the commands ``job_overrides`` (one list of overrides
    per command), in this process at one thread; ``data_dir`` holds the datasets those
    commands wrote (the estimators read their shards from it)."""
    from omegaconf import open_dict
    from threadpoolctl import threadpool_limits

    from pipeline._common import jobs, scenario_nodes
    from tma.families import build_estimator, dataset_name, estimator_class, load_scenario
    from tma.io.atomic import sha256_json
    from tma.io.runs import run_path
    from tma.plan.datasets import full_config
    from tma.runtime.forkserver import keep_freed_memory
    from tma.runtime.sharding import n_shards
    from tma.stages.estimate import estimate_log

    keep_freed_memory()  # as in the workers
    work, handler = Work(), _Artefacts()
    artefact_log = logging.getLogger("tma.io.artefacts")
    artefact_log.addHandler(handler)
    artefact_log.setLevel(logging.INFO)
    cfgs = [compose(overrides) for overrides in job_overrides]
    memory = "/dev/shm" if os.path.isdir("/dev/shm") else None  # artefacts built in RAM (Linux)
    with threadpool_limits(limits=1), tempfile.TemporaryDirectory(dir=memory) as scratch:
        scenarios, warm = {}, set()
        for cfg in cfgs:
            for node in scenario_nodes(cfg):
                module, config = load_scenario(node)
                scenarios[dataset_name(module, config)] = (module, config)
        groups = defaultdict(list)  # shards that share their random draws: simulated once
        for name, (module, config) in scenarios.items():
            for index in range(n_shards(config)):
                key = (sha256_json(module.simulation_key(config, index))
                       if hasattr(module, "simulation_key") else (name, index))
                groups[key].append((module, config, index))
        for group in groups.values():
            module, config, index = group[0]
            if module not in warm:  # compiled kernels loaded first: the floor is the work
                module.simulate_shard(replace(config, n_tracks=2, shard_size=2), 0)
                warm.add(module)
            if len(group) == 1:
                seconds = _cpu(module.simulate_shard, config, index)[1]
            else:
                raw, seconds = _cpu(module.simulate_raw, config, index)
                seconds += sum(_cpu(module.from_raw, c, i, raw)[1] for _, c, i in group)
            work.seconds["simulate"]["simulation"] += seconds

        done = set()
        for cfg in cfgs:
            with open_dict(cfg):
                cfg.paths.data_dir = str(data_dir)
            by_dataset = defaultdict(list)
            for dataset, est_cfg in jobs(cfg):
                est_cfg = full_config(dataset, est_cfg)
                by_dataset[dataset.root].append((dataset, est_cfg))
            for pairs in by_dataset.values():
                dataset = pairs[0][0]
                module = load_scenario(dataset.manifest["config"])[0]
                # a command reads each shard once for all its estimators, and aggregate reads
                # each run's estimates and the truth
                work.read["estimate"] += sum(dataset.manifest["shards"][s]["bytes"]
                                             for s in dataset.shard_paths)
                truth = Path(dataset.root) / "truth.parquet"
                truth_bytes = truth.stat().st_size if truth.exists() else 0
                estimators = []
                for _, est_cfg in pairs:
                    run = run_path(data_dir, dataset, est_cfg)
                    work.read["aggregate"] += sum(
                        f.stat().st_size for f in run.rglob("*.parquet")
                        if "metrics" not in f.name) + truth_bytes
                    if (dataset.root, run.name) in done:
                        continue
                    done.add((dataset.root, run.name))
                    handler.built.clear()
                    prepared, seconds = _cpu(estimator_class(est_cfg["name"]).prepare,
                                             est_cfg, dataset, scratch, 1, False)
                    for kind, built in handler.built:
                        work.seconds["estimate"][f"{kind} artefact"] += built
                        seconds -= built
                    work.seconds["estimate"][f"{est_cfg['name']} prepare"] += max(seconds, 0.0)
                    estimators.append(build_estimator(prepared, scratch))
                if not estimators:
                    continue
                _, config = load_scenario(dataset.manifest["config"])
                tiny, _ = module.simulate_shard(replace(config, n_tracks=2, shard_size=2), 0)
                for estimator in estimators:
                    estimate_log(estimator, tiny)  # kernels and artefacts loaded
                for shard in dataset.shard_paths:
                    log = module.read_log(Path(dataset.root) / shard)
                    for estimator in estimators:
                        seconds = _cpu(estimate_log, estimator, log)[1]
                        work.seconds["estimate"][f"{estimator.name} over the shards"] += seconds
    artefact_log.removeHandler(handler)
    return work


def disk_speed(directory, size=256 << 20) -> tuple[float, float]:
    """(write bytes/s with fsync, read bytes/s of the file just written)."""
    import numpy as np

    path = Path(directory) / "speed.bin"
    block = np.random.default_rng(0).bytes(16 << 20)
    start = time.perf_counter()
    with open(path, "wb") as f:
        for _ in range(size // len(block)):
            f.write(block)
        f.flush()
        os.fsync(f.fileno())
    write = size / (time.perf_counter() - start)
    start = time.perf_counter()
    with open(path, "rb") as f:
        while f.read(16 << 20):
            pass
    read = size / (time.perf_counter() - start)
    path.unlink()
    return write, read


def written_by_stage(workdir: Path, command: Command) -> dict:
    """Bytes each stage of ``command`` wrote under ``workdir``'s data and tables, by when each
    file was last written (the stages' logged ends); a sweep's jobs overlap: all under
    ``all``."""
    written = defaultdict(int)
    order = sorted(command.ends.items(), key=lambda item: item[1])
    for root in (workdir / "data", workdir / "tables"):
        for f in root.rglob("*"):
            if not f.is_file():
                continue
            stat = f.stat()
            if command.jobs != 1:
                written["all"] += stat.st_size
                continue
            stage = next((s for s, end in order if stat.st_mtime <= end), order[-1][0])
            written[stage] += stat.st_size
    return written


@dataclass
class Floor:
    label: str
    commands: list  # Command of each repeat
    works: list  # Work of each repeat
    written: dict
    speed: tuple

    @property
    def best(self) -> Command:
        return min(self.commands, key=lambda c: c.wall)

    def work(self, stage: str, part: str | None = None) -> float:
        """The best (lowest) in-memory seconds of a stage (or one of its parts) over the
        repeats, per worker."""
        return min(w.total(stage) if part is None else w.seconds[stage][part]
                   for w in self.works) / WORKERS

    def stage(self, stage: str) -> float:
        write_bps, read_bps = self.speed
        read = min(w.read[stage] for w in self.works)
        return self.work(stage) + self.written[stage] / write_bps + read / read_bps

    @property
    def total(self) -> float:
        """The stages' floors summed; a sweep's bytes are not split by stage (``all``)."""
        write_bps, read_bps = self.speed
        stages = ("simulate", "estimate", "aggregate")
        return (sum(self.work(s) for s in stages) + sum(self.written.values()) / write_bps
                + sum(min(w.read[s] for w in self.works) for s in stages) / read_bps)


def measure(label: str, arguments, job_overrides, repeat: int, tmp: Path) -> Floor:
    """``pipeline.table`` with ``arguments`` ``repeat`` times on fresh data and the in-memory
    work of its jobs (``job_overrides``) as often, interleaved; nothing is deleted until the
    end (this disk discards freed blocks: a deletion slows what follows it)."""
    commands, works = [], []
    for k in range(repeat):
        workdir = tmp / f"{label}-{k}"
        commands.append(run_table(arguments, workdir))
        works.append(in_memory_work(job_overrides, workdir / "data"))
    written = written_by_stage(workdir, commands[-1])
    speeds = [disk_speed(tmp) for _ in range(repeat)]
    speed = (max(s[0] for s in speeds), max(s[1] for s in speeds))
    return Floor(label, commands, works, written, speed)


def _ratio(wall: float, floor: float) -> str:
    return f"{wall:6.2f} s   floor {floor:6.2f} s   {wall / floor:5.2f}x"


def _with_start_up(wall: float, floor: float, start_up: float) -> str:
    """A command beside its floor, the command's own start-up counted in it (issue 32)."""
    return (f"{wall:6.2f} s   floor {floor:5.2f} s + start-up {start_up:4.2f} s   "
            f"{wall / (floor + start_up):5.2f}x")


def print_table(floor: Floor, start_up: float):
    best = floor.best
    print(f"    {floor.label}: {_with_start_up(best.wall, floor.total, start_up)}  (target <= "
          "2x; runs " + ", ".join(f"{c.wall:.2f}" for c in floor.commands) + " s)")
    for stage in ("simulate", "estimate", "aggregate"):
        read = min(w.read[stage] for w in floor.works)
        print(f"      {stage:9s} {_ratio(best.stages[stage], floor.stage(stage))}  (in memory "
              f"{floor.work(stage):6.2f} s, {floor.written[stage] / 1e6:5.0f} MB written, "
              f"{read / 1e6:5.0f} MB read)")
        parts = sorted(floor.works[0].seconds[stage], key=lambda p: -floor.work(stage, p))
        if stage == "simulate" or len(parts) < 2:
            continue
        built = sum(best.artefacts.values())
        for part in parts:
            kind = part.removesuffix(" artefact")
            if part.endswith(" artefact"):  # built by the stage's main process, logged
                print(f"        {part:28s} {best.artefacts.get(kind, 0.0):6.2f} s   floor "
                      f"{floor.work(stage, part):6.2f} s")
        rest = best.stages[stage] - built
        shards = sum(floor.work(stage, p) for p in parts if not p.endswith(" artefact"))
        print(f"        {'the shards (and the rest)':28s} {rest:6.2f} s   floor {shards:6.2f} s "
              "(" + ", ".join(f"{p} {floor.work(stage, p):.2f}" for p in parts
                              if not p.endswith(" artefact")) + ")")
    print(f"      start-up and exit {best.wall - sum(best.stages.values()):5.2f} s")


def bench_tables(repeat: int = 3, sweep: bool = True, experiments=None):
    """Section (b): every default table, then the sweep."""
    names = experiments or sorted(p.stem for p in (REPO / "conf" / "experiment").glob(
        "*_table.yaml"))
    print(f"(b) the default tables (`make table`: python -m pipeline.table experiment=NAME, "
          f"{WORKERS} workers, fresh data) and a sweep, beside their floors (in-memory "
          f"simulation and estimation / {WORKERS} workers + bytes at this disk's speed); best "
          f"of {repeat}")
    if os.environ.pop("PYTHONDONTWRITEBYTECODE", None):  # inherited by every command run here
        print("    (PYTHONDONTWRITEBYTECODE was set: unset for these commands, which would "
              "otherwise compile every module of tma at each start, ~0.4 s)")
    start_up, bare = start_up_beside_bare(repeat)
    print(f"    start-up (python -m pipeline.table --cfg job: Python, Hydra, tma's imports, the "
          f"config composed, no stage): {start_up:.2f} s; a bare interpreter importing numpy "
          f"and pyarrow: {bare:.2f} s; {start_up / bare:.2f}x  (target <= 4x)")
    with tempfile.TemporaryDirectory() as tmp:
        floors = []
        for name in names:
            arguments = [f"experiment={name}"]
            floors.append(measure(name, arguments, [arguments], repeat, Path(tmp)))
            if len(floors) == 1:
                write_bps, read_bps = floors[0].speed
                print(f"    disk: write {write_bps / 1e6:.0f} MB/s (fsync), read "
                      f"{read_bps / 1e6:.0f} MB/s (page cache)")
            print_table(floors[-1], start_up)
        if sweep:
            for label, arguments, jobs in (
                    (f"sweep of {len(sweep_jobs())} jobs", SWEEP, sweep_jobs()),
                    ("the same points in one command", ONE_COMMAND, [ONE_COMMAND])):
                floor = measure(label.split()[0], arguments, jobs, repeat, Path(tmp))
                print(f"    {label} (python -m pipeline.table {' '.join(arguments)}; "
                      f"bearings2d): {_with_start_up(floor.best.wall, floor.total, start_up)}  "
                      "(target <= 2x; runs " + ", ".join(f"{c.wall:.2f}" for c in
                                                          floor.commands) + " s)")
                written = sum(floor.written.values())
                print(f"      in memory: simulate {floor.work('simulate'):.2f} s, estimate "
                      f"{floor.work('estimate'):.2f} s; {written / 1e6:.0f} MB written; the "
                      "jobs' stages: " + ", ".join(f"{k} {v:.2f} s" for k, v in
                                                    floor.best.stages.items()))


START_UP = ["-m", "pipeline.table", "--cfg", "job"]  # Python, Hydra, tma, the config; no stage
BARE = ["-c", "import numpy, pyarrow"]  # what any tool of this kind starts with


def start_up_beside_bare(repeat: int) -> tuple[float, float]:
    """(the command's start-up, a bare interpreter importing numpy and pyarrow): wall
    seconds, each the best of ``repeat``, interleaved."""
    times = {"start_up": [], "bare": []}
    for _ in range(repeat):
        for key, arguments in (("start_up", START_UP), ("bare", BARE)):
            start = time.perf_counter()
            subprocess.run([sys.executable, *arguments], cwd=REPO, check=True,
                           capture_output=True)
            times[key].append(time.perf_counter() - start)
    return min(times["start_up"]), min(times["bare"])
