"""Shared plumbing of the entry points: Hydra wiring, clean errors, grid expansion."""

import copy
import dataclasses
import itertools
import json
import logging
import os
import sys
import traceback
import types
import typing
import uuid
from pathlib import Path

from hydra.core.config_store import ConfigStore
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from tma.config import defaults, to_plain
from tma.errors import ConfigError, TmaError
from tma.families import (
    NAMES,
    build_estimator,
    dataset_name,
    family,
    load_scenario,
    scenario_module,
)
from tma.io.atomic import write_json_atomic
from tma.io.dataset import Dataset, datasets_dir
from tma.io.owned import plain_name
from tma.parallel import Engine, keep_freed_memory, quick_exit

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")
log = logging.getLogger("tma")
_stage_hydra = None  # Hydra's config of the stage run_stage is running (else None)
SWEEP_ENV = "TMA_SWEEP_ID"  # set by SweepTable while a multirun runs
SWEEP_RECORD = "tma-aggregate.json"  # what an aggregate job of a multirun read
PROBE_BYTES = 1 << 16  # more than Hydra writes of its own before the stage starts
# the top-level keys of conf/config.yaml and conf/ingest.yaml and their config groups (+key
# adds none)
KNOWN_KEYS = {key for conf in ("config", "ingest")
              for key in OmegaConf.load(Path(CONF_DIR) / f"{conf}.yaml")} - {"defaults", "hydra"} \
    | {"scenario", "estimator", "parallel"}


def fail(message: str, status: int = 2):
    """Print ``error: message`` as one line on stderr and exit with ``status``."""
    print(f"error: {' '.join(str(message).split())}", file=sys.stderr)
    sys.exit(status)


def os_error_line(exc: OSError) -> str:
    where = f"{exc.filename}: " if exc.filename else ""
    return f"{where}{exc.strerror or exc} (errno {exc.errno}); nothing complete was replaced"


class CheckOutputDir(Callback):
    """Hydra callback: before Hydra writes its logs under ``paths.data_dir``, check that the
    directory can be created, so a read-only or full disk is one line, not a traceback."""

    def _check(self, directory):
        directory = Path(str(directory))
        probe = directory / f".tma-probe-{os.getpid()}"
        try:  # room for Hydra's own files (resolved configs, the log): a full disk fails here
            directory.mkdir(parents=True, exist_ok=True)
            probe.write_bytes(bytes(PROBE_BYTES))
            probe.unlink()
        except OSError as exc:
            probe.unlink(missing_ok=True)
            fail(f"cannot write the output directory: {os_error_line(exc)}")

    def on_run_start(self, config, **kwargs):
        _check_paths(config)
        self._check(config.hydra.run.dir)

    def on_multirun_start(self, config, **kwargs):
        _check_paths(config)
        self._check(config.hydra.sweep.dir)


def _check_paths(cfg: DictConfig):
    """``paths.*`` are directory paths (not null, a number or a list, which Hydra would
    happily turn into a folder named ``None`` in the working directory)."""
    for key in ("data_dir", "tables_dir"):
        value = cfg.paths.get(key)
        if not isinstance(value, str) or not value.strip():
            fail(f"paths.{key} must be a directory path, got '{value}'")


class SweepTable(Callback):
    """Hydra callback: when a multirun of ``aggregate`` ends, one table of all its jobs.

    Each aggregate job of the sweep records the runs it read (``SWEEP_RECORD`` in its Hydra
    output dir, tagged with this sweep's id); the union of those runs is aggregated once more
    into ``tables/<table>.*`` (default ``<family>-sweep``), beside the jobs' own tables."""

    sweep_id = None

    def on_multirun_start(self, config, **kwargs):
        self.sweep_id = uuid.uuid4().hex
        os.environ[SWEEP_ENV] = self.sweep_id  # inherited by the jobs, in or out of process

    def on_multirun_end(self, config, **kwargs):
        os.environ.pop(SWEEP_ENV, None)
        if self.sweep_id is not None:
            guarded(write_sweep_table, config, self.sweep_id)


def sweep_job(cfg: DictConfig):
    """The job number if this stage runs as a job of a multirun, else None."""
    hydra_cfg = cfg.hydra if "hydra" in cfg else _stage_hydra
    if hydra_cfg is None or hydra_cfg.get("mode") != RunMode.MULTIRUN:
        return None
    return int(hydra_cfg.job.num)


def record_sweep_job(cfg: DictConfig, jobs) -> None:
    """Record, for ``SweepTable``, the runs this aggregate job read (a multirun job only)."""
    number = sweep_job(cfg)
    hydra_cfg = cfg.hydra if "hydra" in cfg else _stage_hydra
    if number is None or not hydra_cfg.runtime.get("output_dir"):
        return
    write_json_atomic(Path(hydra_cfg.runtime.output_dir) / SWEEP_RECORD, {
        "sweep": os.environ.get(SWEEP_ENV), "job": number,
        "data_dir": str(Path(cfg.paths.data_dir).resolve()),
        "tables_dir": str(Path(cfg.paths.tables_dir).resolve()),
        "runs": [{"dataset": str(Path(ds.root).resolve()), "estimator": est}
                 for ds, est in jobs],
    })


def write_sweep_table(config: DictConfig, sweep_id: str) -> list[Path]:
    """The combined table of the aggregate jobs of sweep ``sweep_id`` (see ``SweepTable``)."""
    from tma.aggregate import aggregate

    records = []
    for path in Path(str(config.hydra.sweep.dir)).rglob(SWEEP_RECORD):
        record = json.loads(path.read_text())
        if record.get("sweep") == sweep_id:
            records.append(record)
    groups: dict[tuple, dict] = {}
    for record in sorted(records, key=lambda r: r["job"]):
        runs = groups.setdefault((record["data_dir"], record["tables_dir"]), {})
        for run in record["runs"]:
            runs.setdefault((run["dataset"], json.dumps(run["estimator"], sort_keys=True)), run)
    table = config.get("table")
    if table is not None:
        plain_name(table, "table")
    written = []
    for (data_dir, tables_dir), runs in groups.items():
        jobs = [(Dataset.open(r["dataset"]), r["estimator"]) for r in runs.values()]
        written += aggregate(data_dir, tables_dir, jobs, table=table, default_suffix="sweep")
    for path in written:
        log.info("sweep table: wrote %s", path)
    return written


def register_estimator_keys():
    """ConfigStore group ``estimator_keys``, one option per family: every key of the family's
    estimators (their dataclass defaults, ``name`` left out). An experiment merges it into
    ``estimator`` (``- /estimator_keys@estimator: <family>``) so that Hydra lets the command
    line set any of them with ``estimator.KEY=VALUE``; ``estimator_nodes`` then copies the
    value into the experiment's estimators that have KEY. These values are never run."""
    store = ConfigStore.instance()
    for name in NAMES:
        fam = family(name)
        keys = {}
        for estimator in fam.estimators:
            keys.update(defaults(fam.estimator_class(estimator).Config))
        keys.pop("name", None)
        store.store(group="estimator_keys", name=name, node=keys)


register_estimator_keys()


def run_stage(fn, cfg: DictConfig):
    """Run a stage function. A TmaError (bad input or config) or an OSError (read-only or
    full disk, permissions) is one line on stderr and exit status 2; anything else is a bug:
    one line naming the file that holds its traceback, exit status 1."""
    global _stage_hydra
    keep_freed_memory()  # the main process runs vectorised work too (training, serial shards)
    quick_exit()
    logging.raiseExceptions = False  # a full disk must not turn log writes into tracebacks
    _stage_hydra = HydraConfig.get() if HydraConfig.initialized() else None
    try:
        return guarded(_checked_stage, fn, cfg)
    finally:
        _stage_hydra = None


def _checked_stage(fn, cfg):
    check_stage_options(cfg)
    return fn(cfg)


def guarded(fn, *args):
    """``fn(*args)``, its user-caused failures as one line and exit status 2."""
    try:
        return fn(*args)
    except TmaError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(os_error_line(exc))
    except OmegaConfBaseException as exc:  # e.g. an interpolation that cannot be resolved
        fail(f"config: {exc}")
    except Exception as exc:  # the last line of defence against tracebacks
        fail(f"internal error ({type(exc).__name__}: {exc}); please report it with "
             f"{_save_traceback()}", status=1)


def _save_traceback() -> str:
    try:
        path = Path(HydraConfig.get().runtime.output_dir) / "traceback.txt"
        path.write_text(traceback.format_exc())
        return f"the traceback in {path}"
    except Exception:  # no Hydra output dir, or the disk refuses it
        return "the command that caused it"


def check_stage_options(cfg: DictConfig):
    """Options every stage shares: no unknown top-level key, booleans are booleans, paths
    are text, names are plain names."""
    unknown = sorted(set(cfg) - KNOWN_KEYS)
    if unknown:
        raise ConfigError(f"unknown option(s) {', '.join(unknown)} (known: "
                          f"{', '.join(sorted(set(cfg) & KNOWN_KEYS))})")
    _check_paths(cfg)
    grid = cfg.get("grid")
    if grid is not None and not (isinstance(grid, DictConfig) and all(
            isinstance(v, DictConfig) for v in (grid.get("estimators") or {}).values())):
        shown = OmegaConf.to_yaml(grid).strip() if OmegaConf.is_config(grid) else grid
        raise ConfigError(f"grid must be null or {{estimators: {{name: estimator config}}}}, "
                          f"got '{shown}'")
    for key in ("force", "progress"):
        if key in cfg and not isinstance(cfg[key], bool):
            raise ConfigError(f"{key} must be true or false, got '{cfg[key]}'")
    for key in ("dataset", "table", "name"):
        if cfg.get(key) is not None:
            plain_name(cfg[key], key)
    engine_requested(cfg)


def engine_requested(cfg: DictConfig) -> Engine:
    """The ``parallel`` group as an ``Engine``; unknown keys and bad values are one line."""
    node = cfg.get("parallel")
    if not isinstance(node, DictConfig):
        raise ConfigError(f"parallel must be a config group entry (default, serial, dask), "
                          f"got '{node}'")
    known = {f.name for f in dataclasses.fields(Engine)} - {"kind"} | {"engine"}
    unknown = sorted(set(node) - known)
    if unknown:
        raise ConfigError(f"unknown option(s) parallel.{', parallel.'.join(unknown)} (known: "
                          f"{', '.join(sorted(known))})")
    values = OmegaConf.to_container(node, resolve=True)
    return Engine(kind=values.pop("engine", "joblib"), **values)


def engine(cfg: DictConfig) -> Engine:
    """Where shards run; in this process inside a job of a parallel launcher (joblib,
    submitit): one parallel layer only."""
    requested = engine_requested(cfg)
    try:
        launcher = str(HydraConfig.get().launcher.get("_target_", "")).lower()
    except ValueError:  # not running under Hydra (tests calling stage functions)
        launcher = ""
    parallel_launcher = "joblib" in launcher or "submitit" in launcher
    if parallel_launcher and requested.kind == "joblib" and requested.n_jobs != 1:
        log.info("parallel launcher active: shards run serially inside each job")
        return dataclasses.replace(requested, n_jobs=1)
    return requested


def task_overrides(cfg: DictConfig) -> list[str]:
    """The command line's overrides of the app config, as Hydra records them
    (``hydra.overrides.task``): from ``cfg.hydra`` when composed with it, else from the
    running stage's Hydra config; empty for a bare ``compose``."""
    if "hydra" in cfg:
        return list(cfg.hydra.overrides.task)
    return list(_stage_hydra.overrides.task) if _stage_hydra is not None else []


def _parsed(overrides: list[str]):
    return OverridesParser.create().parse_overrides(overrides) if overrides else []


# -- scenarios: a list where the scenario expects one value is an axis of the grid ----------

def _holds_a_list(annotation) -> bool:
    """True if a field of this type may hold a list (then a list is its value, not an axis)."""
    if annotation is typing.Any:
        return True
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return any(_holds_a_list(a) for a in typing.get_args(annotation) if a is not type(None))
    return (origin or annotation) in (list, tuple, set, frozenset)


def _axes(node: dict, schema, prefix: str = "") -> list[tuple[str, list]]:
    """``(dotted key, values)`` of every list in ``node`` where ``schema`` (a dataclass)
    declares a single value, in the order of the config."""
    hints = typing.get_type_hints(schema)
    axes = []
    for key, value in node.items():
        if key not in hints:
            continue  # an unknown key: validation names it
        tp = hints[key]
        if isinstance(value, dict) and dataclasses.is_dataclass(tp):
            axes += _axes(value, tp, f"{prefix}{key}.")
        elif isinstance(value, list) and not _holds_a_list(tp):
            if not value:
                raise ConfigError(f"scenario.{prefix}{key}: an empty list of values")
            axes.append((f"{prefix}{key}", value))
    return axes


def scenario_nodes(cfg: DictConfig) -> list[dict]:
    """The scenario config, expanded into one node per point of its grid. A list given where
    the scenario expects a single value is an axis (``scenario.sigma_deg=[0.1,0.5]``: two
    datasets); several axes give their cartesian product, the last one varying fastest."""
    extra = sorted(set(cfg.get("grid") or {}) - {"estimators"})
    if extra:
        raise ConfigError(
            f"grid.{extra[0]}: grids take only 'estimators'; sweep a scenario value by "
            "giving the scenario key a list, e.g. scenario.sigma_deg=[0.1,0.5]")
    base = OmegaConf.to_container(cfg.scenario, resolve=True)
    try:
        schema = scenario_module(base.get("family")).Config
    except ConfigError:
        return [base]  # an unknown or missing family: load_scenario says so
    axes = _axes(base, schema)
    nodes = []
    for values in itertools.product(*(v for _, v in axes)):
        node = copy.deepcopy(base)
        for (dotted, _), value in zip(axes, values, strict=True):
            *path, last = dotted.split(".")
            parent = node
            for key in path:
                parent = parent[key]
            parent[last] = value
        nodes.append(node)
    return nodes


# -- estimators: an experiment's estimators, edited by the command line ----------------------

def _has_key(node: dict, dotted: str) -> bool:
    for key in dotted.split("."):
        if not isinstance(node, dict) or key not in node:
            return False
        node = node[key]
    return True


def _set_key(node: dict, dotted: str, value):
    *path, last = dotted.split(".")
    for key in path:
        node = node[key]
    node[last] = value


def estimator_nodes(cfg: DictConfig) -> list[dict]:
    """Estimator configs: the single ``estimator``, or an experiment's ``grid.estimators``
    as the command line edits them (``task_overrides``):

    - ``estimator=NAME`` runs NAME alone (one of the experiment's estimators);
    - ``estimator.KEY=VALUE`` sets KEY in each of them that has it; none has it: ConfigError
      (``estimator`` holds every key of the family's estimators: ``register_estimator_keys``);
    - ``grid.estimators.NAME.KEY=VALUE`` sets it in NAME only.

    An override that would change nothing fails (ConfigError naming it), never is ignored.
    """
    grid = (cfg.get("grid") or {}).get("estimators")
    if not grid:
        return [OmegaConf.to_container(cfg.estimator, resolve=True)]
    nodes = {name: OmegaConf.to_container(node, resolve=True) for name, node in grid.items()}
    overrides = _parsed(task_overrides(cfg))
    chosen = [o.value() for o in overrides if o.key_or_group == "estimator"
              and o.package is None and not o.is_delete()]
    if chosen:
        if chosen[-1] not in nodes:
            raise ConfigError(f"estimator={chosen[-1]}: not an estimator of this experiment "
                              f"(estimators: {', '.join(nodes)})")
        nodes = {chosen[-1]: nodes[chosen[-1]]}
    in_grid = {}  # (estimator, key) -> override, for grid.estimators.NAME.KEY=...
    for o in overrides:
        parts = o.key_or_group.split(".")
        if parts[:2] == ["grid", "estimators"] and len(parts) > 2 and o.package is None:
            if parts[2] not in nodes:
                raise ConfigError(f"{o.input_line}: '{parts[2]}' is not run "
                                  f"(estimators: {', '.join(nodes)})")
            in_grid[parts[2], ".".join(parts[3:])] = o.input_line
    for o in overrides:
        if not o.key_or_group.startswith("estimator.") or o.package is not None:
            continue
        key = o.key_or_group.removeprefix("estimator.")
        if o.is_delete() or key == "name":
            raise ConfigError(f"{o.input_line}: with an experiment, choose estimators with "
                              "estimator=NAME and set their values with estimator.KEY=VALUE")
        value = OmegaConf.select(cfg, o.key_or_group)
        if isinstance(value, DictConfig | ListConfig):
            value = OmegaConf.to_container(value, resolve=True)
        takers = [n for n, node in nodes.items() if _has_key(node, key)]
        if not takers:
            raise ConfigError(f"{o.input_line}: no estimator of this run has '{key}' "
                              f"(estimators: {', '.join(nodes)})")
        for name in takers:
            clash = in_grid.get((name, key))
            if clash:
                raise ConfigError(f"{o.input_line} and {clash} both set '{key}' of {name}: "
                                  "give one")
            _set_key(nodes[name], key, value)
    return list(nodes.values())


def checked_estimator_nodes(cfg: DictConfig) -> list[dict]:
    """``estimator_nodes`` after building each once, so a bad value fails naming its key."""
    nodes = estimator_nodes(cfg)
    for node in nodes:
        build_estimator(node)
    return nodes


def dataset_roots(cfg: DictConfig) -> list[Path]:
    """Dataset directories the config refers to (``dataset=`` or the scenario grid)."""
    if cfg.dataset:
        return [datasets_dir(cfg.paths.data_dir) / str(cfg.dataset)]
    roots = []
    for node in scenario_nodes(cfg):
        module, scenario = load_scenario(node)
        roots.append(datasets_dir(cfg.paths.data_dir) / dataset_name(module, scenario))
    return roots


def open_datasets(cfg: DictConfig) -> list[Dataset]:
    datasets = []
    expected = ([None] if cfg.dataset else
                [to_plain(load_scenario(node)[1]) for node in scenario_nodes(cfg)])
    for root, config in zip(dataset_roots(cfg), expected, strict=True):
        if not (root / "manifest.json").exists() and not cfg.dataset:
            overrides = (" ".join(HydraConfig.get().overrides.task)
                         if HydraConfig.initialized() else "")
            raise ConfigError(
                f"no dataset {root.name} in {root.parent}: create it first with\n"
                f"  python -m pipeline.simulate {overrides}".rstrip()
            )
        dataset = Dataset.open(root)
        if config is not None:  # the dataset this scenario config makes, not another one
            dataset.check_simulated_from(config)
        datasets.append(dataset)
    return datasets
