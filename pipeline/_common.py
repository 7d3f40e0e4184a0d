"""Shared plumbing of the entry points: Hydra wiring, clean errors, grid expansion."""

import copy
import itertools
import logging
import sys
import traceback
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from tma.errors import ConfigError, TmaError
from tma.families import build_estimator, dataset_name, load_scenario
from tma.io.dataset import Dataset, datasets_dir
from tma.io.owned import plain_name
from tma.parallel import keep_freed_memory

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")
log = logging.getLogger("tma")


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
        try:
            Path(str(directory)).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            fail(f"cannot write the output directory: {os_error_line(exc)}")

    def on_run_start(self, config, **kwargs):
        self._check(config.hydra.run.dir)

    def on_multirun_start(self, config, **kwargs):
        self._check(config.hydra.sweep.dir)


def run_stage(fn, cfg: DictConfig):
    """Run a stage function. A TmaError (bad input or config) or an OSError (read-only or
    full disk, permissions) is one line on stderr and exit status 2; anything else is a bug:
    one line naming the file that holds its traceback, exit status 1."""
    keep_freed_memory()  # the main process runs vectorised work too (training, serial shards)
    logging.raiseExceptions = False  # a full disk must not turn log writes into tracebacks
    try:
        check_stage_options(cfg)
        return fn(cfg)
    except TmaError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(os_error_line(exc))
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
    """Options every stage shares: booleans are booleans, names are plain names."""
    for key in ("force", "progress"):
        if key in cfg and not isinstance(cfg[key], bool):
            raise ConfigError(f"{key} must be true or false, got '{cfg[key]}'")
    for key in ("dataset", "table", "name"):
        if cfg.get(key) is not None:
            plain_name(cfg[key], key)
    n_jobs_requested(cfg)


def n_jobs_requested(cfg: DictConfig) -> int:
    value = cfg.parallel.n_jobs
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"parallel.n_jobs must be a whole number >= 1, got '{value}'")
    return value


def n_jobs(cfg: DictConfig) -> int:
    """Worker processes for shards; 1 inside a joblib-launcher job (one parallel layer)."""
    requested = n_jobs_requested(cfg)
    try:
        launcher = str(HydraConfig.get().launcher.get("_target_", ""))
    except ValueError:  # not running under Hydra (tests calling stage functions)
        launcher = ""
    if "joblib" in launcher.lower() and requested != 1:
        log.info("joblib launcher active: shards run serially inside each job")
        return 1
    return requested


def scenario_nodes(cfg: DictConfig) -> list[dict]:
    """The scenario config, expanded over ``grid.scenario`` (a cartesian product)."""
    base = OmegaConf.to_container(cfg.scenario, resolve=True)
    grid = (cfg.grid or {}).get("scenario") or {}
    grid = OmegaConf.to_container(grid, resolve=True) if isinstance(grid, DictConfig) else grid
    nodes = []
    for values in itertools.product(*grid.values()):
        node = copy.deepcopy(base)
        for dotted, value in zip(grid, values, strict=True):
            parent = node
            *path, last = dotted.split(".")
            for key in path:
                parent = parent[key]
            if last not in parent:
                raise ConfigError(f"grid.scenario: '{dotted}' is not a scenario key")
            parent[last] = value
        nodes.append(node)
    return nodes


def estimator_nodes(cfg: DictConfig) -> list[dict]:
    """Estimator configs: ``grid.estimators`` (experiments) or the single ``estimator``."""
    grid = (cfg.grid or {}).get("estimators")
    if grid:
        return [OmegaConf.to_container(node, resolve=True) for node in grid.values()]
    return [OmegaConf.to_container(cfg.estimator, resolve=True)]


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
    for root in dataset_roots(cfg):
        if not (root / "manifest.json").exists() and not cfg.dataset:
            overrides = (" ".join(HydraConfig.get().overrides.task)
                         if HydraConfig.initialized() else "")
            raise ConfigError(
                f"no dataset {root.name} in {root.parent}: create it first with\n"
                f"  python -m pipeline.simulate {overrides}".rstrip()
            )
        datasets.append(Dataset.open(root))
    return datasets
