"""The aggregate stage: finished runs -> per-track metrics (Parquet) -> tables and plots.

Each family's report module (``tma.families.<name>.report``) provides
``aggregate_runs(entries, tables_dir, table_name)`` where ``entries`` are ``RunEntry``
items; it writes per-track metrics into each run directory and returns the table files it
wrote.
"""

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from tma.families import family as family_of
from tma.io.dataset import Dataset
from tma.io.owned import remove_stale_temporaries
from tma.runs import full_config, open_run, run_path


@dataclass
class RunEntry:
    dataset: Dataset
    estimator: str
    run_root: Path
    manifest: dict
    estimates: pd.DataFrame


def aggregate(data_dir, tables_dir, jobs, table=None) -> list[Path]:
    """Aggregate the runs of ``jobs`` (``(Dataset, estimator config)`` pairs)."""
    by_family: dict[str, list[RunEntry]] = {}
    if Path(tables_dir).is_dir():  # what a killed aggregate left; another one may be running
        remove_stale_temporaries(tables_dir, only_dead=True)
    for dataset, est_cfg in jobs:
        dataset.verify()
        est_cfg = full_config(dataset, est_cfg)  # no prepare: aggregate trains nothing
        root = run_path(data_dir, dataset, est_cfg)
        manifest, estimates = open_run(root)
        remove_stale_temporaries(root, only_dead=True)
        by_family.setdefault(dataset.family, []).append(
            RunEntry(dataset, est_cfg["name"], root, manifest, estimates.to_pandas()))
    written = []
    for family, entries in by_family.items():
        module = family_of(family).report
        name = table
        if name is None:
            first = entries[0]
            name = (f"{first.dataset.name}-{first.estimator}" if len(entries) == 1
                    else f"{family}-custom")
        written += module.aggregate_runs(entries, Path(tables_dir), name)
    return written
