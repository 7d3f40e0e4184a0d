"""Shared plumbing of the entry points: Hydra wiring, clean errors, grid expansion."""

import copy
import itertools
import logging
import sys
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from tma.errors import ConfigError, TmaError
from tma.io.dataset import Dataset, datasets_dir
from tma.parallel import keep_freed_memory
from tma.scenarios import dataset_name, load_scenario

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")
log = logging.getLogger("tma")


def run_stage(fn, cfg: DictConfig):
    """Run a stage function; report TmaError as one line on stderr and exit with status 2."""
    keep_freed_memory()  # the main process runs vectorised work too (training, serial shards)
    try:
        return fn(cfg)
    except TmaError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)


def n_jobs(cfg: DictConfig) -> int:
    """Worker processes for shards; 1 inside a joblib-launcher job (one parallel layer)."""
    requested = int(cfg.parallel.n_jobs)
    try:
        launcher = str(HydraConfig.get().launcher.get("_target_", ""))
    except ValueError:  # not running under Hydra (tests calling stage functions)
        launcher = ""
    if "joblib" in launcher.lower() and requested != 1:
        log.info("joblib launcher active: shards run serially inside each job")
        return 1
    if requested < 1:
        raise ConfigError(f"parallel.n_jobs must be >= 1, got {requested}")
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
