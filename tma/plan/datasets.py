"""The datasets a command reads: those its scenario points make or the one it names, each
estimator config as it runs on each dataset (``dataset_jobs``), and a recorded log's dataset
for a one-command table (``log_dataset``)."""

import tempfile
from pathlib import Path

from tma.config import to_plain
from tma.errors import ConfigError, InputError
from tma.families import dataset_name, load_scenario
from tma.io.dataset import MANIFEST, Dataset, datasets_dir
from tma.io.owned import plain_name
from tma.plan.points import Override
from tma.stages.estimate import dataset_config


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
    on its dataset (``tma.stages.estimate.dataset_config``): on a recorded log an estimator's
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

