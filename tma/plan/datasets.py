"""The datasets a command reads: those its scenario points make or the one it names, each
estimator config as it runs on each dataset (``dataset_jobs``, ``dataset_config``,
``full_config``), the runs of a dataset a command may name instead (``missing_run_line``) and
a recorded log's dataset for a one-command table (``log_dataset``)."""

import tempfile
from pathlib import Path

from tma.config import to_plain
from tma.errors import ConfigError, InputError, TmaError
from tma.families import build_estimator, dataset_name, estimator_class, load_scenario
from tma.io.dataset import MANIFEST, Dataset, datasets_dir, read_sealed_manifest
from tma.io.owned import plain_name
from tma.io.runs import RUN_FORMAT, RUN_FORMAT_VERSION, run_path, runs_dir
from tma.plan.points import Override, override_text
from tma.version import __version__


def dataset_roots(data_dir, dataset: str | None, scenarios: list[dict]) -> list[Path]:
    """The dataset directories a command refers to: ``dataset=NAME``, else the one each
    scenario point makes."""
    if dataset:
        return [datasets_dir(data_dir) / str(dataset)]
    roots = []
    for node in scenarios:
        module, scenario = load_scenario(node)
        roots.append(datasets_dir(data_dir) / dataset_name(module, scenario))
    return roots


def open_datasets(data_dir, dataset: str | None, scenarios: list[dict],
                  simulate: str = "") -> list[Dataset]:
    """The datasets a command reads, verified; a scenario point's dataset must be the one its
    config makes. A missing one is a ConfigError giving the command that creates it
    (``python -m pipeline.simulate`` + ``simulate``, the command line's overrides)."""
    datasets = []
    expected = [None] if dataset else [to_plain(load_scenario(n)[1]) for n in scenarios]
    for root, config in zip(dataset_roots(data_dir, dataset, scenarios), expected, strict=True):
        if not (root / MANIFEST).exists() and not dataset:
            raise ConfigError(
                f"no dataset {root.name} in {root.parent}: create it first with\n"
                f"  python -m pipeline.simulate {simulate}".rstrip()
            )
        opened = Dataset.open(root)
        if config is not None:  # the dataset this scenario config makes, not another one
            opened.check_simulated_from(config)
        datasets.append(opened)
    return datasets


def dataset_jobs(datasets: list[Dataset], estimators: list[dict],
                 overrides: list[Override]) -> list[tuple[Dataset, dict]]:
    """``(dataset, estimator config)`` of every dataset and estimator, each config as it runs
    on its dataset (``dataset_config``): on a recorded log an estimator's
    ``recorded_defaults`` (``lm``: ``initial_bearing_deg`` null, from the first bearing) replace
    its defaults where the command line sets no value (``estimator.KEY=``,
    ``estimators.NAME.KEY=``)."""
    given = [o.key.split(".") for o in overrides if o.package is None]
    jobs = []
    for dataset in datasets:
        for node in estimators:
            keep = ({".".join(k[1:]) for k in given if k[0] == "estimator" and len(k) > 1}
                    | {".".join(k[2:]) for k in given
                       if k[0] == "estimators" and k[1:2] == [node.get("name")]})
            jobs.append((dataset, dataset_config(dataset, node, keep)))
    return jobs


def check_compatible(dataset: Dataset, estimator_config: dict):
    cls = estimator_class(estimator_config["name"])
    if cls.family != dataset.family:
        raise ConfigError(
            f"estimator '{cls.name}' reads '{cls.family}' datasets, but {dataset.name} is a "
            f"'{dataset.family}' dataset"
        )


def dataset_config(dataset: Dataset, estimator_config: dict, keep=()) -> dict:
    """``estimator_config`` as it runs on ``dataset``: on a recorded log (a dataset that was
    not simulated) the estimator's ``recorded_defaults`` replace its values, except for the
    keys in ``keep`` (those the command line sets)."""
    if dataset.manifest["source"] == "simulate":
        return estimator_config
    recorded = estimator_class(estimator_config["name"]).recorded_defaults
    return {**estimator_config, **{k: v for k, v in recorded.items() if k not in keep}}


def full_config(dataset: Dataset, estimator_config: dict) -> dict:
    """The estimator config with every default filled in (the run key hashes it, so it
    changes with them), checked against the dataset's family."""
    check_compatible(dataset, estimator_config)
    return to_plain(build_estimator(estimator_config).config)


def missing_run_line(data_dir, dataset: Dataset, config: dict) -> str:
    """One line for a run of ``config`` (full, as ``run_path`` hashes it) on ``dataset`` that
    does not exist: the finished runs of ``dataset`` that do, each with the overrides that
    select it (``estimator=NAME`` and the values that differ from NAME's on this dataset)."""
    found, stale = [], 0
    for path in sorted((runs_dir(data_dir) / dataset.name).glob(f"*/{MANIFEST}")):
        try:
            manifest = read_sealed_manifest(path, "run", RUN_FORMAT, RUN_FORMAT_VERSION, "")
            name = manifest["config"]["name"]
            base = full_config(dataset, dataset_config(dataset, {"name": name}))
        except (TmaError, OSError, KeyError, TypeError):
            continue  # not a run this tma can read: not one to offer
        if (manifest.get("dataset", {}).get("content_hash") != dataset.content_hash
                or manifest.get("package", {}).get("version") != __version__):
            stale += 1  # of another content of the dataset, or another tma: not selectable
            continue
        selected = [f"estimator={name}"] + [
            override_text(f"estimator.{key}", value) for key, value in
            _differing(manifest["config"], base)]
        found.append(f"{path.parent.name} ({' '.join(selected)})")
    line = (f"no finished run of {config['name']} on dataset {dataset.name} with these "
            f"settings ({run_path(data_dir, dataset, config).name}): make it with "
            "`python -m pipeline.estimate` and the same overrides")
    if found:
        line += f", or aggregate a run that exists: {'; '.join(found)}"
    if stale:
        line += (f" ({stale} other run(s) of {dataset.name} were made from another content "
                 "of the dataset or by another tma version)")
    return line


def _differing(config: dict, base: dict, prefix: str = ""):
    """``(dotted key, value)`` of ``config`` that differ from ``base``, for keys ``base`` has
    (a prepared config's records, e.g. an artefact's hash, are no option)."""
    for key, value in config.items():
        if key not in base:
            continue
        if isinstance(value, dict) and isinstance(base[key], dict):
            yield from _differing(value, base[key], f"{prefix}{key}.")
        elif value != base[key]:
            yield f"{prefix}{key}", value


def log_dataset(input_path, *, data_dir, name=None, force=False, **options) -> tuple[Path, bool]:
    """The dataset of a recorded log for a one-command table (``tma.stages.ingest.ingest`` with
    these arguments): ingested, or, when a dataset of that name exists and ``force`` is false,
    reused if ingesting the log again gives the same dataset (content and reading config; it is
    ingested into a scratch directory under ``data_dir`` to be compared), else refused. Returns
    the dataset directory and whether it was reused."""
    from tma.stages.ingest import ingest

    if input_path is not None and str(input_path).strip() and name is None:
        name = Path(str(input_path)).stem
    root = datasets_dir(data_dir) / plain_name(name, "name") if name is not None else None
    if force or root is None or not (root / MANIFEST).exists():
        try:
            return ingest(input_path, data_dir=data_dir, name=name, force=force, **options), False
        except InputError:
            if force or root is None or not (root / MANIFEST).exists():
                raise  # else another process (a job of the sweep) made it meanwhile: compare
    existing = Dataset.open(root)
    with tempfile.TemporaryDirectory(dir=data_dir, prefix=".tma-log-check-") as scratch:
        again = Dataset.open(ingest(input_path, data_dir=scratch, name=name, **options))
    if (again.content_hash, again.manifest["config"]) != (existing.content_hash,
                                                          existing.manifest["config"]):
        raise InputError(f"dataset {root} exists and is not what {input_path} gives with "
                         "these options (another log, or other reading options): choose "
                         "another name= or set force=true to replace it")
    return root, True

