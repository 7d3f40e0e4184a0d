"""Docs that cannot rot: every command in README.md and docs/*.md runs here against a small
config, every repository path and ``tma.``/``pipeline.`` name they cite exists, and the code
they quote (the recipe's diff, the protobuf messages, the file layouts) is what the code is.

Commands are taken from the docs themselves: each fenced ``bash`` block runs in order in one
working directory (a block is a session: simulate before estimate), each inline command
(```make table```) on its own. "Small" means: 20 tracks in shards of 20, the estimators' own
fast settings (``Estimator.conformance_scenario``/``conformance_config``), serial shards
(unless the command chooses an engine), 2 Dask workers instead of 8, a local Dask scheduler
for ``tcp://scheduler:8786``. A command no rule below knows how to run fails the test: a new
command in the docs comes with its way to run it. Commands that only show a syntax
(``python -m pipeline.<verb>``, ``ARGS="..."``) have the modules or options they name
checked instead; ``make test`` is the suite running this file.
"""

import importlib
import importlib.util
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf

from pipeline import cli
from pipeline._common import estimator_nodes
from tests.conftest import REPO, compose_cfg, run_cli, run_stage_here
from tma import options
from tma.families import NAMES, estimator_class
from tma.io.proto_columns import proto_schema

DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
SMALL = ["scenario.n_tracks=20", "scenario.shard_size=20", "progress=false"]
STAGES = ("simulate", "estimate", "aggregate", "table", "ingest")


def _rel(doc: Path) -> str:
    return str(doc.relative_to(REPO))


def fenced(doc: Path, lang: str | None = None) -> list[tuple[int, str, str]]:
    """``(line, language, text)`` of the fenced blocks of ``doc`` (of ``lang`` only)."""
    text = doc.read_text()
    return [(text[:m.start()].count("\n") + 1, m.group(1), m.group(2))
            for m in re.finditer(r"```(\w*)\n(.*?)```", text, re.S)
            if lang is None or m.group(1) == lang]


def shell_commands(block: str) -> list[str]:
    """The commands of a shell block: continuation lines joined, comments dropped."""
    joined = re.sub(r"\\\n\s*", " ", block)
    commands = []
    for line in joined.splitlines():
        command = " ".join(shlex.split(line, comments=True))
        if command:
            commands.append(command)
    return commands


def inline_commands(doc: Path) -> list[str]:
    """Commands quoted inline in the prose (``make ...``, ``python -m ...``, ...)."""
    prose = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)
    return [" ".join(m.group(1).split())
            for m in re.finditer(r"`((?:python -m|make|pytest|pip install|tma) [^`]*)`", prose)]


def is_syntax(command: str) -> bool:
    """A command that shows a form rather than one to run (placeholders in it)."""
    return bool(re.search(r"<\w+>|\[|\.\.\.|\bFILE\b", command))


BLOCKS = [(f"{_rel(doc)}:{line}", shell_commands(text))
          for doc in DOCS for line, _, text in fenced(doc, "bash")]
INLINE = sorted({c for doc in DOCS for c in inline_commands(doc)} - {
    c for _, commands in BLOCKS for c in commands})


# -- small configs and inputs ------------------------------------------------------------------

def small_for(overrides: list[str]) -> list[str]:
    """Small-config overrides for a stage command: the shared ones, and for an experiment
    its estimators' fast settings (each in its own ``estimators`` entry: one estimator's
    setting may be another's invalid value) and their family's small scenario (declared by them)."""
    chosen = next((o.split("=", 1)[1] for o in overrides if o.startswith("experiment=")), None)
    if chosen is None:
        return SMALL
    cfg = compose_cfg([f"experiment={chosen}"])
    estimators = OmegaConf.to_container(cfg.estimators, resolve=True) or {}
    entries = [(entry, node["name"]) for entry, node in estimators.items()] or [
        (None, node["name"]) for node in estimator_nodes(cfg)]
    given = {o.split("=", 1)[0] for o in overrides}
    scenario, settings = {}, []
    for entry, name in entries:
        cls = estimator_class(name)
        scenario.update(cls.conformance_scenario)
        prefix = "estimator" if entry is None else f"estimators.{entry}"
        settings += [f"{prefix}.{k}={v}" for k, v in cls.conformance_config.items()
                     if f"estimator.{k}" not in given]
    return SMALL + [f"scenario.{k}={v}" for k, v in scenario.items()
                    if f"scenario.{k}" not in given] + settings


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    return write_logs(tmp_path_factory.mktemp("logs"))


def write_logs(d: Path) -> Path:
    """The logs the README's ingest commands name, written into ``d`` as recorders write
    them (the reader tests' writers and the recorded encounter of ``recorded_geometry``)."""
    from tests.families.bearings2d.recorded_geometry import EPOCH_NS, iso, recorded
    from tests.families.bearings2d.test_bearings2d_sources_foxglove import write_foxglove
    from tests.families.bearings2d.test_bearings2d_sources_nmea import write_nmea
    from tests.families.bearings2d.test_bearings2d_sources_ros2 import (
        float64_messages,
        navsatfix_messages,
        vector_messages,
        write_ros2,
    )
    from tma.families.bearings2d.log import write_bearings_log
    from tma.families.bearings2d.scenario import Config, simulate_shard

    log, _ = simulate_shard(Config(n_tracks=3, shard_size=3, sigma_deg=0.2, seed=11), 0)
    pd.DataFrame([{"time_s": t + 1.7e9, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
                   "bearing_deg": log.bearing_deg[i, k], "track_id": int(log.track_id[i])}
                  for k, t in enumerate(log.t_s) for i in range(3)]).to_csv(d / "my_log.csv",
                                                                             index=False)
    write_bearings_log(d / "my_log.mcap", log)
    rec = recorded(("T1", "T2"))
    b = rec.bearings
    nav_export = pd.DataFrame({"timestamp_utc": iso(b.t_s), "latitude_deg": b.lat,
                               "longitude_deg": b.lon, "bearing_deg": b.bearing_deg,
                               "contact": b.track, "note": "ok, steady"})
    nav_export.to_csv(d / "nav_export.csv", index=False, lineterminator="\r\n")
    nav_export.to_csv(d / "nav.csv", index=False)
    nav_export.to_csv(d / "export.tsv", index=False, sep="\t")
    pd.DataFrame({"tid": EPOCH_NS // 10**6 + np.round(b.t_s * 1000).astype(np.int64),
                  "breite": b.lat, "laenge": b.lon, "peilung": np.deg2rad(b.bearing_deg),
                  "kontakt": b.track}).to_csv(d / "log.csv", index=False, sep=";", decimal=",")
    write_nmea(d / "gps.nmea", rec.navigation)
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "track": b.track,
                  "bearing_deg": b.bearing_deg}).to_csv(d / "bearings.csv", index=False)
    one = recorded()
    write_ros2(d / "run.mcap", ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                                navsatfix_messages(one.navigation)),
               ("/bearing", "std_msgs/msg/Float64", float64_messages(one.bearings)),
               ("/bearing_vec", "geometry_msgs/msg/Vector3Stamped",
                vector_messages(one.bearings)),
               *[(f"/sonar/contact/{c}", "std_msgs/msg/Float64",
                  float64_messages(one.bearings)) for c in "ab"])  # one topic per contact
    write_foxglove(d / "foxglove.mcap", one)
    from tests.families.bearings2d.test_bearings2d_platforms import (
        two_platform_export,
        write_namespaced,
    )
    from tma import read_log

    two = two_platform_export()  # a ship and a buoy: platform column, asynchronous
    two.to_csv(d / "two_ships.csv", index=False)
    two[["timestamp_utc", "platform", "contact", "bearing_deg"]].to_csv(
        d / "platform_bearings.csv", index=False)
    fixes = two[["timestamp_utc", "platform", "latitude_deg", "longitude_deg"]]
    pd.concat([fixes[fixes["platform"] == "ship A"].drop_duplicates("timestamp_utc"),
               fixes[fixes["platform"] == "buoy 7"].iloc[:1]]).to_csv(d / "platforms.csv",
                                                                      index=False)
    write_namespaced(d / "platforms.mcap", read_log(d / "two_ships.csv").logs[0],
                     ("/ship_a", "/buoy"))
    from tests.families.bearings2d.ais_trial import write_trial

    write_trial(d)  # trial.csv and its AIS: trial_ais.csv, trial_ais.nmea
    shutil.copytree(REPO / "tests" / "data" / "trials", d / "tests" / "data" / "trials",
                    ignore=shutil.ignore_patterns("*.py", "__pycache__"))  # named by path
    return d


# -- how each documented command runs ----------------------------------------------------------

class Session:
    """One working directory (the logs copied in) and one data directory, where the commands
    of a block run in order; what ran, for the preconditions of the next."""

    def __init__(self, root: Path, logs: Path):
        self.root, self.ran = root, []
        for path in logs.iterdir():
            if path.is_dir():  # files the docs name by their path (tests/data/trials/)
                shutil.copytree(path, root / path.name)
            else:
                (root / path.name).write_bytes(path.read_bytes())
        self.paths = [f"paths.data_dir={root / 'data'}", f"paths.tables_dir={root / 'tables'}"]

    def run(self, command: str, monkeypatch):
        tokens = shlex.split(command)
        monkeypatch.chdir(self.root)  # inputs named as in the docs, relative to here
        if tokens[:2] == ["python", "-m"] and tokens[2].startswith("pipeline."):
            self.stage(tokens[2].removeprefix("pipeline."), tokens[3:])
        elif tokens[:2] == ["python", "-m"] and tokens[2] == "tma.options":
            assert options.main(tokens[3:]) == 0
        elif tokens[0] == "make":
            self.make(tokens[1], dict(t.split("=", 1) for t in tokens[2:]))
        elif tokens == ["tma", "--help"]:
            assert cli.main(["--help"]) == 0
        elif tokens[0] == "tma":  # the app of python -m pipeline.<verb> (the installed script
            self.stage(tokens[1], tokens[2:])  # itself: tests/test_tma_command.py)
        else:
            raise AssertionError(f"no rule runs the documented command {command!r}")
        self.ran.append(tokens)

    def stage(self, verb: str, overrides: list[str], hydra=None):
        assert verb in STAGES, verb
        overrides = [self.adjust(o) for o in overrides]
        if "--cfg" in overrides:  # prints the composed config, runs nothing
            proc = run_stage_here(verb, *overrides)
            assert "estimator:" in proc.stdout
            return
        given = {o.split("=", 1)[0] for o in overrides}
        extra = [p for p in self.paths if p.split("=", 1)[0] not in given]
        from_log = verb == "table" and any(o.startswith(("input=", "dataset=")) or "=" not in o
                                           for o in overrides)
        extra += (["progress=false", "force=true"] if verb == "ingest" else
                  ["progress=false"] if from_log else small_for(overrides))
        if not any(o.startswith("parallel") for o in overrides):
            extra.append("parallel=serial")
        stored = [o.split("=", 1)[1] for o in overrides if o.startswith("dataset=")]
        if verb == "table" and stored and not self.ran:  # a log stored under that name
            run_stage_here("ingest", "input=my_log.csv", f"name={stored[0]}", *self.paths,
                           "progress=false")
        if verb in ("estimate", "aggregate") and not any(o.startswith("dataset=")
                                                         for o in overrides):
            self.needs(overrides, extra, "simulate" if verb == "estimate" else "estimate")
        launcher = any(o.startswith("hydra/launcher=") for o in overrides)
        if any(o == "hydra/launcher=slurm" for o in overrides):
            # no SLURM here: a job of the sweep composes as written (every key and launcher
            # option known) and the sweep's local twin runs (tests/test_cluster.py)
            job = [re.sub(r"=([^\[\],]+),.*", r"=\1", o) for o in overrides if o != "-m"]
            cfg = compose_cfg(job + extra, return_hydra_config=True)
            assert cfg.hydra.launcher._target_.endswith("SlurmLauncher")
            return
        run = run_cli if launcher else run_stage_here
        run(verb, *overrides, *extra)

    def needs(self, overrides, extra, verb):
        """The dataset (and run) an estimate or aggregate reads, unless this block made it."""
        if not any(t[2] in (f"pipeline.{verb}", "pipeline.table") for t in self.ran):
            keep = [o for o in overrides if o.startswith(("scenario.", "experiment=", "-m"))
                    or (verb == "estimate" and o.startswith("estimator"))]
            run_stage_here(verb, *keep, *[e for e in extra if not e.startswith("parallel")],
                           "parallel=serial")

    def adjust(self, override: str) -> str:
        """The small config's version of an override: 2 Dask workers, a real scheduler's
        address, this session's data directory."""
        if override.startswith("parallel.n_workers="):
            return "parallel.n_workers=2"
        if override == "parallel.address=tcp://scheduler:8786":
            return f"parallel.address={self.scheduler()}"
        if override.startswith("paths.data_dir="):
            return self.paths[0]
        return override

    def scheduler(self) -> str:
        from distributed import LocalCluster

        self.cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                    dashboard_address=":0")  # any free port
        return self.cluster.scheduler_address

    def make(self, target: str, variables: dict):
        args = variables.get("ARGS", "")
        if target == "test":
            return  # the suite running this test
        if target == "table":
            chosen = variables.get("EXPERIMENT")
            names = [chosen] if chosen else sorted(
                p.stem for p in (REPO / "conf" / "experiment").glob("*_table.yaml"))
            for name in names:
                overrides = [f"experiment={name}", *shlex.split(args)]
                small = " ".join([*small_for(overrides), *self.paths, *shlex.split(args)])
                self.make_here(["table", f"EXPERIMENT={name}", f"ARGS={small}"])
                table = compose_cfg([f"experiment={name}"]).table
                assert (self.root / "tables" / f"{table}.md").exists(), name
            return
        if target == "bench":  # the manoeuvres section if named, else the first; few tracks
            if "--only manoeuvres" in args:
                check_manoeuvre_bench(self.make_here(
                    ["bench", "ARGS=--only manoeuvres --manoeuvre-tracks 2 --repeat 1"]))
                return
            self.make_here(["bench", "ARGS=--only lm --tracks 20"])
            return
        if target == "clean":  # here, not in the repository
            for name in ("data", "tables", "outputs"):
                (self.root / name).mkdir(exist_ok=True)
            subprocess.run(["make", "-f", str(REPO / "Makefile"), "clean"], cwd=self.root,
                           check=True, capture_output=True)
            assert not (self.root / "data").exists() and not (self.root / "tables").exists()
            return
        if target in ("lint", "help", "options"):
            out = self.make_here([target, *(f"{k}={v}" for k, v in variables.items())])
            if target == "options":  # one estimator's, ingest's or parallel's; or all
                header = {"ingest": "ingest family=", "parallel": "parallel ("}.get(
                    args, f"estimator={args}")
                assert header in out if args else "scenario=bearings2d" in out
            return
        raise AssertionError(f"no rule runs make {target}")

    @staticmethod
    def make_here(arguments: list[str]) -> str:
        proc = subprocess.run(["make", *arguments], cwd=REPO, capture_output=True, text=True,
                              timeout=1200)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        return proc.stdout


def check_manoeuvre_bench(out: str):
    """``make bench``'s section (k): a point per sample period (20 minutes of the default
    legs) and per duration (own-ship's zig-zag at a bearing every 10 s), each with the
    bearings that make, and growth exponents that are the slopes of the costs printed."""
    from scipy.stats import linregress

    points = re.findall(r"(\d+) min(?: zig-zag)?, a bearing every (\d+) s \( *(\d+) bearings\)"
                        r", +\d+ tracks: aware +([\d.]+) +NCV +([\d.]+) +([\d.]+)x", out)
    got = [(int(m), int(p), int(n)) for m, p, n, *_ in points]
    assert got == [(20, 8, 151), (20, 4, 301), (20, 2, 601), (20, 1, 1201), (20, 10, 121),
                   (40, 10, 241), (80, 10, 481), (160, 10, 961)], out
    aware, ncv, ratio = (np.array([float(p[k]) for p in points]) for k in (3, 4, 5))
    assert np.allclose(ratio, aware / ncv, rtol=0.05, atol=0.1), out
    exponents = re.findall(r"growth exponent with the (?:bearings|duration).*: aware "
                           r"(-?[\d.]+), NCV smoother (-?[\d.]+)", out)
    assert len(exponents) == 2, out
    for (printed_aware, printed_ncv), sizes, rows in (
            (exponents[0], [151, 301, 601, 1201], slice(0, 4)),
            (exponents[1], [20, 40, 80, 160], slice(4, 8))):
        for printed, cost in ((printed_aware, aware[rows]), (printed_ncv, ncv[rows])):
            slope = linregress(np.log(sizes), np.log(cost)).slope  # of the rounded costs
            assert abs(float(printed) - slope) < 0.05, (printed, slope, out)


@pytest.mark.parametrize("where, commands", BLOCKS, ids=[w for w, _ in BLOCKS])
def test_every_documented_block_runs(where, commands, logs, tmp_path, monkeypatch):
    session = Session(tmp_path, logs)
    try:
        for command in commands:
            session.run(command, monkeypatch)
    finally:
        if hasattr(session, "cluster"):
            session.cluster.close()
    if any(c.startswith("python -m pipeline.ingest") for c in commands):
        assert list((tmp_path / "data" / "datasets").glob("*/manifest.json"))


@pytest.mark.parametrize("command", INLINE)
def test_every_documented_command_runs(command, logs, tmp_path, monkeypatch):
    if not is_syntax(command) and not command.startswith(("pytest", "pip")):
        Session(tmp_path, logs).run(command, monkeypatch)
        return
    tokens = command.split()
    if command.startswith("python -m "):  # a form: the entry points it stands for exist
        module = tokens[2]
        names = ([f"pipeline.{p.stem}" for p in (REPO / "pipeline").glob("[a-z]*.py")]
                 if "<verb>" in module else [module])
        assert names and all(importlib.util.find_spec(n) for n in names), command
    elif command.startswith("make "):
        assert re.search(rf"^{tokens[1]}:", (REPO / "Makefile").read_text(), re.M), command
    elif command.startswith("tma "):  # a form of the installed command: its verbs exist
        assert tokens[1] == "<verb>" or tokens[1] in STAGES, command
    elif command.startswith("pytest "):  # a test file of the suite, and the marker it uses
        assert (REPO / tokens[-1]).is_file() and "slow:" in (REPO / "pyproject.toml").read_text()
    elif command.startswith("pip install "):
        extra = re.search(r"\[(\w+)\]", command).group(1)
        project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
        assert extra in project["optional-dependencies"], command
    else:
        raise AssertionError(f"no rule checks the documented command {command!r}")


# -- what the docs quote -----------------------------------------------------------------------

def test_the_recipes_diffs_are_the_code():
    """Every line the recipes add or keep (``...`` elisions aside) is in the file named."""
    for doc in DOCS:
        for _, _, diff in fenced(doc, "diff"):
            for part in re.split(r"^--- .*\n", diff, flags=re.M)[1:]:
                path, body = part.split("\n", 1)
                text = (REPO / path.removeprefix("+++ b/")).read_text()
                for line in body.splitlines():
                    code = line[1:].strip()
                    if line.startswith("-") or not code or "..." in code:
                        continue
                    assert code in text, (path, code)


def test_the_documented_messages_are_the_schemas():
    (proto,) = [text for doc in DOCS for _, _, text in fenced(doc, "proto")]
    messages = re.findall(r"message (\w+) \{(.*?)\}", proto, re.S)
    assert len(messages) == len(list((REPO / "tma" / "io" / "schemas").glob("*.json")))
    for name, body in messages:
        declared = [(m.group(3), int(m.group(4)), m.group(2), bool(m.group(1)))
                    for m in re.finditer(r"(repeated )?(\w+) (\w+) = (\d+);", body)]
        schema = proto_schema(f"tma.{name}")
        assert declared == [(f.name, f.number, f.kind, f.repeated) for f in schema.fields], name


def test_the_documented_layouts_are_what_the_stages_write(tmp_path):
    args = [*SMALL, "parallel=serial", f"paths.data_dir={tmp_path}",
            f"paths.tables_dir={tmp_path}/tables"]
    for verb in ("simulate", "estimate", "aggregate"):
        run_stage_here(verb, *args)
    (dataset,) = [p for p in (tmp_path / "datasets").iterdir() if not p.name.startswith(".")]
    (run,) = [p for p in (tmp_path / "runs" / dataset.name).iterdir()
              if not p.name.startswith(".")]
    written = {str(p.relative_to(root)) for root in (dataset, run) for p in root.rglob("*")}
    (formats,) = [d for d in DOCS if d.name == "formats.md"]
    listed = [name for _, lang, text in fenced(formats) if not lang for line in text.splitlines()
              for name in re.findall(r"^([\w./-]+\.\w+)", line.split("|")[0].strip())]
    assert listed and set(listed) <= written, set(listed) - written


def test_the_documented_kinds_are_the_registered_readers():
    """Where the docs list the kinds of log (``format=auto|csv|...``) and what says each
    (README: the extensions, kind by kind), they list the readers' registry
    (``tma.sources.READERS``), in its order: a new reader is named in the docs or fails
    here."""
    from tma.sources import readers

    lists = [(doc, m.group(1)) for doc in DOCS
             for m in re.finditer(r"`format=([a-z0-9_]+(?:\|[a-z0-9_]+)+)`", doc.read_text())]
    assert {doc.name for doc, _ in lists} >= {"README.md", "formats.md"}
    for doc, listed in lists:
        assert listed.removeprefix("auto|").split("|") == [r.kind for r in readers()], doc.name
    readme = (REPO / "README.md").read_text()
    (said,) = re.findall(r"else the extension \(([^)]*)\)", " ".join(readme.split()))
    assert [re.findall(r"`(\.\w+)`", part) for part in said.split(";")] == [
        list(r.extensions) for r in readers()]


# -- what architecture.md draws and walks through ---------------------------------------------

ARCHITECTURE = REPO / "docs" / "architecture.md"
BOTTOM = ("tma.io", "tma.maths", "tma.runtime", "tma.sources", "tma.tables")


def test_the_layers_drawn_are_the_imports():
    """The drawing of the layers holds: no module of the bottom layer imports a family, the
    plan, a stage, the API or the command line (save ``tma.runtime.compile_ahead``, which
    builds the families' estimators, as the page says), and no family imports the plan, a
    stage, the API or the command line."""
    from tests.test_imports import _imports, _modules

    (drawing,) = [text for text in drawings(ARCHITECTURE) if "pipeline/<verb>.py" in text]
    assert all(f"{layer.replace('.', '/')}/" in drawing for layer in BOTTOM)
    edges = _imports(_modules())

    def upward(modules, above) -> dict:
        return {m: sorted(e for e in edges[m] if e.startswith(above)) for m in modules
                if any(e.startswith(above) for e in edges[m])}

    upper = ("tma.families", "tma.plan", "tma.stages", "tma.api", "pipeline")
    assert upward([m for m in edges if m.startswith(BOTTOM)], upper) == {
        "tma.runtime.compile_ahead": ["tma.families"]}
    assert upward([m for m in edges if m.startswith("tma.families.")], upper[1:]) == {}


def test_the_contract_drawn_is_the_code():
    """Every class the drawing of the contracts names is a class of tma (a family's row: of
    that family), and every registered family has its row."""
    (drawing,) = [text for text in drawings(ARCHITECTURE) if "tma/estimator.py" in text]
    classes = {path: set(re.findall(r"^class (\w+)", path.read_text(), re.M))
               for path in (REPO / "tma").rglob("*.py")}
    rows = {line.split()[0]: line for line in drawing.splitlines()
            if line.split() and line.split()[0] in NAMES}
    assert sorted(rows) == sorted(NAMES)
    for line in drawing.splitlines():
        family = next((name for name, row in rows.items() if row == line), None)
        package = REPO / "tma" / "families" / family if family else REPO / "tma"
        declared = set().union(*(names for path, names in classes.items()
                                 if path.is_relative_to(package)))
        named = re.findall(r"\b[A-Z][A-Za-z0-9]*[a-z][A-Za-z0-9]*\b", line)
        assert set(named) <= declared, (line, set(named) - declared)


def test_the_walk_through_runs_as_written(tmp_path):
    """The walk-through of architecture.md (a new estimator and a new reader, run), as its
    reader follows it: each python block whose first line is ``# file: PATH`` saved there,
    the others run in order as one script in a new interpreter started in that directory
    (so the registries are fresh, and the files importable), nothing mocked; the blocks'
    own asserts check what they give."""
    script, saved = [], []
    for _, _, text in fenced(ARCHITECTURE, "python"):
        if named := re.fullmatch(r"# file: ([\w/]+\.py)", text.splitlines()[0]):
            path = tmp_path / named.group(1)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            saved.append(path.read_text())
        else:
            script.append(text)
    assert any("(BearingsEstimator)" in code for code in saved)  # an estimator
    assert any("READER = Reader(" in code for code in saved)  # and a reader
    (tmp_path / "walk_through.py").write_text("\n".join(script))
    proc = subprocess.run([sys.executable, "walk_through.py"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert (tmp_path / "contacts.jsonl").stat().st_size > 0


# -- what the docs cite ------------------------------------------------------------------------

def drawings(doc: Path) -> list[str]:
    """The drawings of ``doc`` (its ``text`` blocks), whose paths and names count as cited."""
    return [text for _, _, text in fenced(doc, "text")]


def cited_code(doc: Path) -> list[str]:
    """What ``doc`` quotes as code in its prose (fenced blocks aside), and its drawings'
    lines."""
    prose = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)
    return [*re.findall(r"`([^`\n]+)`", prose),
            *(line for text in drawings(doc) for line in text.splitlines())]


def cited_paths(doc: Path) -> list[str]:
    found = []
    for code in cited_code(doc):
        found += re.findall(r"(?<![\w/])((?:\.\./shared/|tma/|tests/|conf/|docs/|bench/|"
                            r"pipeline/)[\w./<>*-]*)", code)
    return found


def _expand(path: str) -> list[str]:
    """A cited path with its placeholders (``<family>``, ``<verb>``) as every value."""
    if "<family>" in path:
        return [p for name in NAMES for p in _expand(path.replace("<family>", name))]
    if "<verb>" in path:
        return [path.replace("<verb>", verb) for verb in STAGES]
    return [path]


@pytest.mark.parametrize("doc", DOCS, ids=_rel)
def test_every_path_and_name_the_docs_cite_exists(doc):
    missing = []
    for cited in cited_paths(doc):
        if "<" in cited.replace("<family>", "").replace("<verb>", ""):
            cited = cited.split("<")[0]  # a file of that directory: the directory exists
        for path in _expand(cited):
            module, attribute = path, None
            if re.search(r"/\w+\.[A-Za-z_]\w*$", path) and not path.endswith(
                    (".py", ".md", ".yaml", ".json", ".toml")):  # tma/io/mcap_read.McapFile
                module, attribute = path.rsplit(".", 1)
                module += ".py"
            matches = list(REPO.glob(module)) if "*" in module else [REPO / module]
            if not matches or not all(m.exists() for m in matches):
                missing.append(path)
            elif attribute:
                source = (REPO / module).read_text()
                if not re.search(rf"^(?:class|def) {attribute}\b|^{attribute} =", source, re.M):
                    missing.append(path)
    names = re.findall(r"`((?:tma|pipeline)(?:\.[A-Za-z_]\w*)+)`", doc.read_text()) + [
        name for text in drawings(doc)
        for name in re.findall(r"(?<![\w/.])((?:tma|pipeline)(?:\.[A-Za-z_]\w*)+)", text)]
    for name in names:
        if not _resolves(name):
            missing.append(name)
    assert not missing, missing


FILE_NAME = re.compile(r"(?<![\w/.<>*-])((?:[\w.-]+/)*[\w-]+\.(?:py|yaml))(?![\w.])")


@pytest.mark.parametrize("doc", DOCS, ids=_rel)
def test_every_file_name_the_docs_mention_exists(doc):
    """Every code file a doc names (``.py``, ``.yaml``), even without its directory
    (``csv_table.py``, ``sources/align.py``, ``estimators/lm.py``), is a file of the
    repository: the whole path, or its end (placeholders such as ``<name>.py`` aside)."""
    ours = {p.relative_to(REPO).as_posix() for root in ("tma", "pipeline", "conf", "tests",
                                                          "bench", "examples", "docs")
            for p in (REPO / root).rglob("*") if p.is_file()}
    named = {name for code in cited_code(doc)
             for name in FILE_NAME.findall(code) if not name.startswith("../")}
    missing = sorted(n for n in named if n not in ours
                     and not any(path.endswith("/" + n) for path in ours))
    assert not missing, missing


def _resolves(name: str) -> bool:
    """A module, or an attribute of one (``tma.io.owned.building``); a schema
    (``tma.BearingBatch``: ``tma/io/schemas``) or a name the code writes in its files (the
    metadata record ``tma.time``, the manifest format ``tma.run``...)."""
    if (REPO / "tma" / "io" / "schemas" / f"{name}.json").exists():
        return True
    if any(f'"{name}"' in p.read_text() or f'"{name}-' in p.read_text()
           for p in (REPO / "tma").rglob("*.py")):
        return True
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attribute in parts[cut:]:
            if not hasattr(obj, attribute):
                return False
            obj = getattr(obj, attribute)
        return True
    return False
