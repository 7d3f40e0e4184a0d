"""The estimator interface shared by every family."""

from dataclasses import dataclass, field

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


class Estimator:
    """One interface for every estimator, built from its validated ``Config`` dataclass:
    ``estimate(log) -> dict`` of output columns shaped ``(n_tracks, ...)`` (per-step outputs
    ``(n_tracks, n_steps)``). A family's base class implements ``estimate`` and calls the one
    hook a concrete estimator writes, ``solve`` (its arguments are the family's).

    Its name is its module's file name (``module_name``), written nowhere else. Declared, so
    that the core and the reports never test estimator names:

    - ``family``: the scenario family whose logs it reads;
    - ``outputs``: columns it adds beyond its family's common ones (e.g. the fuzzy
      tracker's memory length ``m``, the IMM's model probabilities);
    - ``side_tables``: small tables it returns under ``estimate(log)["extras"]`` (written
      beside the run's estimates, e.g. sample points for a plot, covariances);
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
    data_dir = None  # where artefacts live; set by the estimate stage before ``estimate``

    # what the conformance suite (tests/test_conformance.py) runs it on: keys of a small
    # scenario of its family (besides n_tracks), and settings that keep each check fast
    conformance_scenario: dict = {}
    conformance_config: dict = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "Config" in cls.__dict__:  # a concrete estimator: named as its module
            cls.name = module_name(cls.__module__)

    def __init__(self, config):
        self.config = config

    @classmethod
    def prepare(cls, config: dict, dataset, data_dir, engine=1, progress=False) -> dict:
        return config

    def estimate(self, log) -> dict:
        raise NotImplementedError
