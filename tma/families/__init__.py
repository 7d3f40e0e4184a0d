"""Scenario families, one package each: ``tma/families/<name>/`` holds a family's scenario,
model, log format, metrics, aggregate (its tables) and ``estimators/`` (one file each), and
exports one ``FAMILY`` object. The core finds families only here: a new family is one package
plus one entry in ``NAMES``.

A family's scenario module provides ``Config`` (with ``n_tracks``, ``shard_size``, ``seed``),
``label(cfg)`` (a short tag in dataset names), ``simulate_shard(cfg, index) -> (log, truth
table or None)``, ``write_log(path, log, metadata) -> n_messages`` and ``read_log(path)``;
optionally ``simulation_key``/``simulate_raw``/``from_raw`` when datasets of different
configs share their random draws. Its aggregate module provides ``aggregate_runs(entries,
tables_dir, table_name)``; an ``ingest`` module, when the family reads recorded logs,
``OBSERVATION``, ``Settings`` and ``logs`` (``tma.stages.ingest``).
"""

import functools
import importlib
from dataclasses import dataclass

from tma.config import to_plain
from tma.config_nodes import defaults, validate
from tma.errors import ConfigError
from tma.estimator import module_name
from tma.io.atomic import sha256_json

NAMES = ("bearings2d", "ranges2d", "radar2d", "bearing_doppler3d")


@dataclass(frozen=True)
class Family:
    """What the core knows of a family: its name, where its scenario and aggregate live, and
    its estimators (``"module:Class"`` each; an estimator's name is its module's file name,
    ``tma.estimator.module_name``); modules are imported when first used."""

    name: str
    estimator_paths: tuple[str, ...] = ()

    @functools.cached_property
    def estimators(self) -> dict[str, str]:
        """name -> ``"module:Class"``, read off the paths without importing them."""
        return {module_name(path.split(":")[0]): path for path in self.estimator_paths}

    @property
    def scenario(self):
        return importlib.import_module(f"tma.families.{self.name}.scenario")

    @property
    def aggregate(self):
        """The family's side of the aggregate stage and of the Python API: its ``aggregate``
        module, with ``aggregate_runs`` (optionally ``TABLE_KINDS``, ``results``,
        ``plot_contact``, ``write_map``)."""
        from tma.tables.write import plots_to_files

        plots_to_files()  # a bad MPLBACKEND would fail matplotlib's import
        return importlib.import_module(f"tma.families.{self.name}.aggregate")

    @property
    def ingest(self):
        """What the family reads from a recorded log (``tma.stages.ingest``): its ``ingest`` module,
        with ``OBSERVATION``, ``Settings`` and ``logs``."""
        try:
            return importlib.import_module(f"tma.families.{self.name}.ingest")
        except ModuleNotFoundError as exc:
            if exc.name != f"tma.families.{self.name}.ingest":
                raise
            raise ConfigError(f"family {self.name} does not ingest recorded logs (it has no "
                              "ingest module)") from None

    def estimator_class(self, name: str):
        module, cls = self.estimators[name].split(":")
        return getattr(importlib.import_module(module), cls)


def family(name: str) -> Family:
    """The family called ``name``; a clear error for unknown names."""
    if name not in NAMES:
        raise ConfigError(f"unknown scenario family '{name}' (known: {', '.join(sorted(NAMES))})")
    return importlib.import_module(f"tma.families.{name}").FAMILY


@functools.cache
def _estimator_families() -> dict[str, Family]:
    owners = {}
    for name in NAMES:
        for estimator in family(name).estimators:
            if estimator in owners:
                raise RuntimeError(f"estimator '{estimator}' is declared by two families")
            owners[estimator] = family(name)
    return owners


def estimator_names() -> list[str]:
    """Every registered estimator, sorted."""
    return sorted(_estimator_families())


def estimator_class(name: str):
    """The estimator class called ``name`` (whatever its family); a clear error if unknown."""
    owners = _estimator_families()
    if name not in owners:
        raise ConfigError(f"unknown estimator '{name}' (known: {', '.join(sorted(owners))})")
    return owners[name].estimator_class(name)


def build_estimator(node, data_dir=None):
    """Validate an estimator config node (must hold ``name``) and build the estimator, given
    where its artefacts live (``data_dir``; None: nowhere, for an estimator that needs none)."""
    name = node.get("name") if node is not None else None
    if name is None:
        raise ConfigError("estimator: missing 'name'")
    cls = estimator_class(name)
    return cls(validate(cls.Config, node, f"estimator '{name}'"), data_dir)


def scenario_module(name: str):
    """The scenario module of family ``name``."""
    return family(name).scenario


def load_scenario(node):
    """Validate a scenario config node; return ``(scenario module, config instance)``."""
    name = node.get("family") if node is not None else None
    if name is None:
        raise ConfigError("scenario: missing 'family'")
    module = scenario_module(name)
    return module, validate(module.Config, node, f"scenario '{name}'")


def register_configs():
    """Register every scenario and estimator ``Config`` dataclass's defaults with Hydra's
    ConfigStore as ``scenario/<family>`` and ``estimator/<name>``: the dataclass is the one
    source of every default (no YAML copy). The nodes are plain (untyped), so a bad value
    reaches ``tma.config_nodes.validate`` and fails in one line naming the key.

    Every command runs this first, so it imports every scenario and estimator module: their
    top-level imports stay light (numba, scipy, pandas and matplotlib load where they are
    used; ``tests/test_startup.py``).

    Also the group ``estimator_keys``, one option per family: every key of the family's
    estimators (their defaults, ``name`` left out). An experiment merges it into
    ``estimator`` (``- /estimator_keys@estimator: <family>``) so that Hydra lets the command
    line set any of them with ``estimator.KEY=VALUE``; ``tma.plan.points.estimator_configs``
    then copies the value into the experiment's estimators that have KEY. These values are
    never run.

    And the group ``reading``, one option per family that reads recorded logs: its ingest
    options (``ingest_defaults``), which ``conf/ingest.yaml`` takes as its own keys
    (``- reading@_here_: <family>``)."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    for name in NAMES:
        fam = family(name)
        store.store(group="scenario", name=name, node=defaults(fam.scenario.Config))
        if reads_logs(name):
            store.store(group="reading", name=name, node=ingest_defaults(name))
        keys = {}
        for estimator in fam.estimators:
            node = defaults(fam.estimator_class(estimator).Config)
            store.store(group="estimator", name=estimator, node=node)
            keys.update(node)
        keys.pop("name", None)
        store.store(group="estimator_keys", name=name, node=keys)


def reads_logs(name: str) -> bool:
    """Family ``name`` reads recorded logs (it has an ``ingest`` module)."""
    try:
        return family(name).ingest is not None
    except ConfigError:
        return False


def ingest_defaults(name: str) -> dict:
    """Every ingest option of family ``name`` with its default, as the command line sets it:
    its own settings (its ``ingest.Settings``: ``sigma_deg``, ``min_bearings``), the reading
    options (``tma.sources.options``: ``columns.*``, ``bearing.*``, ..., ``bad_rows``) and the
    truth options (``truth.*``, ``tma.ais.options``); declared there, written nowhere else."""
    from tma.ais.options import TruthOptions
    from tma.sources.options import options_schema

    reader = family(name).ingest
    return {**defaults(reader.Settings), **defaults(options_schema(reader.OBSERVATION)),
            "truth": defaults(TruthOptions)}


def dataset_name(module, cfg) -> str:
    """Directory name of the dataset a scenario config produces: family, label, config hash."""
    return f"{module.FAMILY}-{module.label(cfg)}-{sha256_json(to_plain(cfg))[:10]}"
