"""Each stage as one call from a command's config, so that the way from the command line to a
row of a table goes down once per stage (CLI -> here -> the stage engine -> the family):
``pipeline/`` hands over the composed config as plain values (``Command``), and these
functions decide what it covers (``tma.plan.points``, ``tma.plan.datasets``) and run the stage
engine (``tma.stages``).
"""

import functools
from dataclasses import dataclass
from pathlib import Path

from tma.errors import ConfigError
from tma.io.atomic import write_json_atomic
from tma.plan.datasets import dataset_jobs, log_dataset, open_datasets
from tma.plan.points import checked_estimator_configs, estimator_configs, scenario_points
from tma.plan.renamed import renamed_config
from tma.runtime.parallel import Engine, engine_from


@dataclass(frozen=True)
class Command:
    """A command as the stages see it: ``config``, its composed config as plain values
    (without Hydra's node); ``overrides``, the command line's (``tma.plan.points.Override``);
    ``launcher``, the target of the sweep's launcher ('' outside one: a parallel launcher runs
    each job's shards serially); ``simulate``, the command line's overrides as text (for the
    command that creates a missing dataset). Keys renamed after 0.6.0 are read in their new
    spelling (``settings``, ``tma.plan.renamed``: the command line's were before Hydra
    composed it)."""

    config: dict
    overrides: tuple = ()
    launcher: str = ""
    simulate: str = ""

    @functools.cached_property
    def settings(self) -> dict:
        """``config`` with the keys renamed after 0.6.0 in their new spelling."""
        return renamed_config(self.config)

    def get(self, key: str, default=None):
        return self.settings.get(key, default)

    @property
    def data_dir(self) -> str:
        return self.config["paths"]["data_dir"]

    def engine(self) -> Engine:
        """Where shards run (``tma.runtime.parallel.engine_from``)."""
        return engine_from(self.get("parallel"), self.launcher)

    def scenarios(self) -> list[dict]:
        """The scenario points of the command (a list value is an axis)."""
        return scenario_points(self.get("scenario"))

    def estimators(self, checked: bool = False) -> list[dict]:
        """The estimator configs; ``checked``: each built once, a bad value failing here."""
        make = checked_estimator_configs if checked else estimator_configs
        return make(self.get("estimator"), self.get("estimators"), list(self.overrides))

    def datasets(self):
        """The datasets the command reads, verified (``tma.plan.datasets.open_datasets``)."""
        scenarios = [] if self.get("dataset") else self.scenarios()
        return open_datasets(self.data_dir, self.get("dataset"), scenarios, self.simulate)

    def jobs(self) -> list:
        """The ``(dataset, estimator config)`` pairs; a bad estimator config fails before
        any I/O."""
        estimators = self.estimators(checked=True)
        return dataset_jobs(self.datasets(), estimators, list(self.overrides))


def run_simulate(command: Command) -> list[Path]:
    """The simulate stage: the datasets of the command's scenario points."""
    from tma.stages.simulate import simulate_datasets

    if command.get("dataset"):
        raise ConfigError("simulate creates datasets from the scenario config; "
                          "'dataset=' names an existing one (use it with estimate, aggregate or "
                          "table)")
    command.estimators()  # the command line's estimator overrides fail here too, not later
    return simulate_datasets(command.scenarios(), command.data_dir, engine=command.engine(),
                             force=command.get("force"), progress=command.get("progress"))


def run_estimate(command: Command) -> list[tuple[Path, bool]]:
    """The estimate stage: ``(run directory, reused)`` of each job."""
    from tma.stages.estimate import estimate_runs

    return estimate_runs(command.data_dir, command.jobs(), engine=command.engine(),
                         progress=command.get("progress"), force=command.get("force"))


@dataclass(frozen=True)
class SweepRecord:
    """Where an aggregate job of a multirun records the runs it read (``path``), for the
    sweep's table: the sweep's id and the job's number."""

    path: Path
    sweep: str | None
    job: int


def run_aggregate(command: Command, table: str | None, default_suffix: str = "custom",
                  record: SweepRecord | None = None, tables: bool = True):
    """The aggregate stage: the paths written, as they are (``tma.stages.aggregate``);
    ``record``: a job of a multirun records what it read when it is done; ``tables``: False
    for such a job without a table of its own, which only checks that its runs are finished
    (the sweep's table, when it ends, measures them)."""
    from tma.stages.aggregate import aggregate, check_runs, sweep_record

    jobs, paths = command.jobs(), command.config["paths"]
    if tables:
        yield from aggregate(paths["data_dir"], paths["tables_dir"], jobs, table=table,
                             default_suffix=default_suffix, progress=command.get("progress"),
                             table_kind=command.get("table_kind"))
    else:
        check_runs(paths["data_dir"], jobs)
    if record is not None:
        write_json_atomic(record.path, sweep_record(
            record.sweep, record.job, paths["data_dir"], paths["tables_dir"], jobs,
            command.get("table_kind")))


def ingest_arguments(config: dict) -> dict:
    """``tma.stages.ingest.ingest``'s arguments from an ingest config (``conf/ingest.yaml``):
    the input, the family's reading options and settings, the truth options."""
    from tma.stages.ingest import option_groups, setting_names

    family = config["family"]
    return dict(input_path=config["input"], data_dir=config["paths"]["data_dir"],
                family=family, name=config["name"], fmt=config["format"],
                force=config["force"], navigation=config["navigation"],
                options={group: config[group] for group in option_groups(family)},
                truth=config.get("truth"), **{key: config[key] for key in setting_names(family)})


def run_ingest(config: dict) -> Path:
    """The ingest stage: the dataset of the log ``config`` names."""
    from tma.stages.ingest import ingest

    return ingest(**ingest_arguments(config))


def run_log_dataset(config: dict) -> tuple[Path, bool]:
    """The first stage of ``table input=LOG``: the log's dataset, ingested or reused
    (``tma.plan.datasets.log_dataset``), and whether it was reused."""
    if config.get("dataset") is not None:
        raise ConfigError(f"dataset={config['dataset']}: input={config['input']} makes its own "
                          "dataset (named by name=, by default the log's stem); give "
                          "input=FILE [name=NAME] or dataset=NAME, not both")
    return log_dataset(**ingest_arguments(config))
