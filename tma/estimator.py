"""The estimator interface shared by every family: ``Estimator`` (built from its ``Config``
and what it needs, ``estimate(log) -> Estimates``) and ``Estimates``, the one type the core
receives from every estimator of every family."""

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tma.config import Params, param
from tma.errors import ConfigError


def module_name(module: str) -> str:
    """An estimator's name: the name of its module's file (``.../estimators/lm.py``: ``lm``),
    where it is written once; the registry, its class and its ``Config`` read it there."""
    return module.rpartition(".")[2]


@dataclass
class EstimatorConfig(Params):
    """Base of every estimator's ``Config`` (the base of its family's, if any): ``name``,
    whose default is the estimator's name (``module_name``), and every parameter's checks."""

    name: str = param("", "the estimator's name (its module's file name)")

    def __init_subclass__(cls, **kwargs):
        if "__annotations__" not in cls.__dict__:
            cls.__annotations__ = {}
        cls.__annotations__.setdefault("name", str)
        cls.name = field(default=module_name(cls.__module__),
                         metadata=EstimatorConfig.__dataclass_fields__["name"].metadata)
        super().__init_subclass__(**kwargs)

    @property
    def where(self) -> str:
        return f"estimator '{self.name}'"


def name_set_error(given: str, name: str) -> ConfigError:
    """The refusal of ``name`` given as an estimator's option (``estimator.name=lm`` on the
    command line, ``name="lm"`` to ``tma.estimate``): an estimator is chosen, never renamed."""
    return ConfigError(f"{given}: name is not an option of an estimator; choose the estimator "
                       f"with estimator={name}")


@dataclass(frozen=True)
class Estimates(Mapping):
    """What every estimator's ``estimate(log)`` returns to the core, whatever its family.

    ``columns``: its output by column name, each an array whose first axis is the log's
    tracks: ``(n_tracks,)``, or ``(n_tracks, n_steps)`` for a per-step output (filter
    estimates at every scan; then the run's table is long, a row per track and step, and the
    per-track columns repeat on each of their rows). ``side_tables``: the small tables it
    declares in ``Estimator.side_tables`` (sample points for a plot, covariances, a
    trajectory), each columns by name of one length, written beside the run's estimates as
    ``<name>.parquet``; a shard may hold none of them.

    Read as a mapping, it is its columns (``out["status"]``, ``out.keys()``)."""

    columns: dict[str, np.ndarray]
    side_tables: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __iter__(self):
        return iter(self.columns)

    def __len__(self) -> int:
        return len(self.columns)

    def check(self, estimator: "Estimator", n_tracks: int) -> None:
        """RuntimeError (an estimator's bug, not the user's) unless these are estimates of
        ``n_tracks`` tracks as the contract says: every column's first axis the tracks, at
        most one number of steps, the side tables declared by ``estimator`` and each of one
        length."""
        who = f"estimator '{estimator.name}'"
        steps = set()
        for name, values in self.columns.items():
            shape = np.shape(values)
            if len(shape) not in (1, 2) or shape[0] != n_tracks:
                raise RuntimeError(f"{who}: column {name} is shaped {shape}, not (n_tracks,) or "
                                   f"(n_tracks, n_steps) with n_tracks = {n_tracks}")
            steps |= set(shape[1:])
        if len(steps) > 1:
            raise RuntimeError(f"{who}: per-step columns disagree on the number of steps: "
                               f"{sorted(steps)}")
        if not set(self.side_tables) <= set(estimator.side_tables):
            raise RuntimeError(f"{who} returned side tables {sorted(self.side_tables)}, "
                               f"declared {sorted(estimator.side_tables)}")
        for name, table in self.side_tables.items():
            if len({np.shape(c)[:1] for c in table.values()}) > 1 or any(
                    np.ndim(c) != 1 for c in table.values()):
                raise RuntimeError(f"{who}: the columns of side table {name} are not of one "
                                   "length")


class Estimator:
    """One interface for every estimator, built from its validated ``Config`` dataclass and
    what it needs from outside (``data_dir``: where its artefacts live, ``tma.io.artefacts``;
    None where it needs none): ``estimate(log) -> Estimates``, vectorised over the log's
    tracks. A family's base class implements ``estimate``, reading the log into the family's
    typed input, and calls the one hook a concrete estimator writes, ``solve``, which returns
    the family's typed result (``bearings2d``: ``Bearings``, ``TargetMotion`` -> ``Solution``;
    ``radar2d``: ``Scans`` -> ``Solution``; ``ranges2d``: ``TrackRanges`` ->
    ``PosteriorMean``; ``bearing_doppler3d``: ``AuvModel``, ``Readings`` -> ``Solution``).

    Its name is its module's file name (``module_name``), written nowhere else. Declared, so
    that the core and the reports never test estimator names:

    - ``family``: the scenario family whose logs it reads;
    - ``outputs``: columns it adds beyond its family's common ones (e.g. the fuzzy
      tracker's memory length ``m``, the IMM's model probabilities);
    - ``side_tables``: small tables it returns in ``Estimates.side_tables`` (written beside
      the run's estimates, e.g. sample points for a plot, covariances);
    - ``reference``: True for the exact estimator others are measured against;
    - ``prepare(config, dataset, data_dir, engine, progress)``: a step run once before the
      shards (e.g. training an artefact), returning the config the run records;
    - ``recorded_defaults``: config values that replace its defaults on a recorded log (a
      dataset not simulated) where the command line sets none
      (``tma.plan.datasets.dataset_config``), e.g. a start from the first bearing instead of
      the simulated scenario's prior.
    """

    family = ""
    name = ""
    outputs: tuple[str, ...] = ()
    side_tables: tuple[str, ...] = ()
    reference = False
    recorded_defaults: dict = {}

    # what the conformance suite (tests/test_conformance.py) runs it on: keys of a small
    # scenario of its family (besides n_tracks), and settings that keep each check fast
    conformance_scenario: dict = {}
    conformance_config: dict = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "Config" in cls.__dict__:  # a concrete estimator: named as its module
            cls.name = module_name(cls.__module__)

    def __init__(self, config, data_dir=None):
        self.config = config
        self.data_dir = None if data_dir is None else Path(data_dir)

    @classmethod
    def prepare(cls, config: dict, dataset, data_dir, engine=1, progress=False) -> dict:
        return config

    def estimate(self, log) -> Estimates:
        raise NotImplementedError
