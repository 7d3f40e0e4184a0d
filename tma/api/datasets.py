"""Stored and simulated datasets and runs from Python (``tma.open_dataset``, ``tma.runs``,
``tma.runs_dataset``, ``tma.simulate``), and what ``tma.estimate`` reads."""

import logging
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from tma.api.options import _nested, _path
from tma.api.recording import Recording
from tma.errors import MissingFileError

log = logging.getLogger("tma")


def _data(data, what: str):
    """``data`` as ``tma.estimate`` reads it: a Recording, a DataFrame (read as
    ``Recording.from_frames``), or a dataset of ``simulate`` / ``open_dataset``; TypeError
    naming what it takes for anything else."""
    if isinstance(data, pd.DataFrame):
        return Recording.from_frames(data)
    if isinstance(data, Recording | SimulatedDataset | StoredDataset):
        return data
    hint = (" (read a log file with tma.read_log first, a stored dataset with "
            "tma.open_dataset)" if isinstance(data, str | Path) else "")
    raise TypeError(f"{what} needs a Recording, a pandas DataFrame, or a dataset of "
                    f"tma.simulate / tma.open_dataset, got {type(data).__name__}{hint}")


def _sources(data) -> tuple[pd.DataFrame | None, pd.DataFrame | None, dict | None]:
    """``(truth, truth track, scenario config)`` of what ``tma.estimate`` reads."""
    from tma.config import to_plain

    if isinstance(data, Recording):
        return data.truth, data.truth_track, None
    if isinstance(data, SimulatedDataset):
        return data.truth, None, to_plain(data.config)
    return data.truth, data.truth_track, None if data.recorded else data.manifest["config"]


class _LazyLogs(Sequence):
    """The logs of a stored dataset's shards, each read (and verified) when first asked."""

    def __init__(self, dataset):
        self._dataset, self._read = dataset, {}

    def __len__(self) -> int:
        return len(self._dataset.shard_paths)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(len(self))[i]]
        from tma.families import scenario_module

        if i not in self._read:
            rel = self._dataset.shard_paths[i]
            self._read[i] = scenario_module(self._dataset.family).read_log(
                self._dataset.verified_path(rel))
        return self._read[i]


class StoredDataset:
    """A dataset under ``data/datasets`` (``open_dataset``): its ``name``, ``family``,
    ``manifest`` (config, seeds, hashes), ``logs`` (one per shard, read when first asked),
    ``truth`` (a DataFrame: a simulation's, or the AIS truth of a log ingested with
    ``truth=FILE``; None without) and ``truth_track`` (that log's ships from their AIS)."""

    def __init__(self, dataset):
        self.dataset = dataset
        self.name, self.family = dataset.name, dataset.family
        self.manifest = dataset.manifest
        self.logs = _LazyLogs(dataset)
        self.recorded = dataset.manifest["source"] != "simulate"

    @property
    def truth(self) -> pd.DataFrame | None:
        return self.dataset.read_truth()

    @property
    def truth_track(self) -> pd.DataFrame | None:
        from tma.ais.truth import TRUTH_TRACK
        from tma.io import arrow

        if TRUTH_TRACK not in self.manifest["files"]:
            return None
        return arrow.read_table(self.dataset.verified_path(TRUTH_TRACK)).to_pandas()

    def __repr__(self) -> str:
        return f"<StoredDataset {self.name} ({self.family}, {len(self.logs)} shard(s))>"


def open_dataset(name_or_path, data_dir="data") -> StoredDataset:
    """A stored dataset by name (under ``<data_dir>/datasets``) or path, verified as the stages
    verify it (its manifest; each shard's sha256 when read)."""
    from tma.io.dataset import Dataset, datasets_dir

    path = Path(_path(name_or_path, "name_or_path"))
    root = path if path.is_dir() else datasets_dir(_path(data_dir, "data_dir")) / str(
        name_or_path)
    if root.is_dir() and not (root / "manifest.json").exists():
        raise MissingFileError(f"{root}: not a dataset (it holds no manifest.json); give a "
                               "dataset's name (under <data_dir>/datasets) or its directory")
    if not root.exists():
        there = sorted(p.name for p in root.parent.glob("*")
                       if p.is_dir() and not p.name.startswith("."))
        listed = (f"datasets there: {', '.join(there[:10])}{', ...' * (len(there) > 10)}"
                  if there else f"{root.parent} holds none" if root.parent.is_dir()
                  else f"there is no directory {root.parent}: give data_dir")
        raise MissingFileError(f"no dataset at {root} ({listed})")
    return StoredDataset(Dataset.open(root))


def _warn_without_metrics(data_dir, family) -> list[str]:
    """The runs under ``data_dir`` without ``metrics.parquet``, named in one warning."""
    from tma.stages.aggregate import runs_without_metrics

    root = Path(_path(data_dir, "data_dir"))
    if not (root / "runs").is_dir():
        what = "no such directory" if not root.is_dir() else "no runs/ in it"
        raise MissingFileError(f"{root}: {what}; give data_dir, the directory the commands "
                               "wrote their runs into (paths.data_dir, by default data)")
    missing = runs_without_metrics(root, family)
    if missing:
        log.warning("%d run(s) without metrics.parquet (aggregate them first): %s",
                    len(missing), ", ".join(missing[:10]) + (" ..." if len(missing) > 10
                                                              else ""))
    return missing


def runs(data_dir="data", family: str | None = None, **unexpected) -> pd.DataFrame:
    """Every run's per-track metrics under ``<data_dir>/runs`` as one DataFrame, with each
    run's family, dataset, estimator and config values as columns
    (``tma.stages.aggregate.metrics_dataset``; ``runs_dataset`` gives the same as a pyarrow
    dataset). Runs that hold no ``metrics.parquet`` (never aggregated, or recomputed since)
    are named in a warning and in ``attrs["without_metrics"]``, not left out silently."""
    if unexpected:
        key = next(iter(unexpected))
        hint = ("; the pyarrow dataset is tma.runs_dataset(data_dir, family)"
                if key == "as_dataset" else " (it takes data_dir and family)")
        raise TypeError(f"tma.runs() got an unexpected keyword argument {key!r}{hint}")
    from tma.stages.aggregate import metrics_dataset

    missing = _warn_without_metrics(data_dir, family)
    frame = metrics_dataset(data_dir, family=family).to_table().to_pandas()
    frame.attrs["without_metrics"] = missing
    return frame


def runs_dataset(data_dir="data", family: str | None = None):
    """What ``runs`` gives, as the ``pyarrow.dataset`` itself, nothing loaded yet: filters on
    the run columns (``pyarrow.compute.field("scenario.sigma_deg") == 0.5``) skip whole
    files. Runs without ``metrics.parquet`` are named in a warning."""
    from tma.stages.aggregate import metrics_dataset

    _warn_without_metrics(data_dir, family)
    return metrics_dataset(data_dir, family=family)


class SimulatedDataset:
    """A dataset simulated in memory (``simulate``): ``config`` (the validated scenario),
    ``logs`` (one per shard) and ``truth`` (a DataFrame): the numbers ``pipeline.simulate``
    stores for the same config."""

    recorded = False

    def __init__(self, config, logs, truth):
        self.config, self.logs, self.truth = config, logs, truth
        self.family = config.family

    def __repr__(self) -> str:
        return (f"<SimulatedDataset {self.family}: {len(self.truth)} track(s), "
                f"{len(self.logs)} shard(s)>")


def simulate(family: str = "bearings2d", options: dict | None = None, **overrides
             ) -> SimulatedDataset:
    """Simulate the scenario of ``family`` with ``overrides`` (``n_tracks=200``,
    ``sigma_deg=1.0``, ``target={"manoeuvres": {"prob": 1.0}}``, or dotted names in
    ``options``) in memory, shard by shard as ``pipeline.simulate`` does (the same random
    streams, so the same numbers as its dataset of that config)."""
    from tma.families import NAMES, load_scenario
    from tma.runtime.sharding import n_shards

    if not isinstance(family, str):
        raise TypeError(f"family must be a family's name (a str: {', '.join(NAMES)}), got "
                        f"{type(family).__name__}")
    module, config = load_scenario({"family": family, **_nested(options, overrides)})
    logs, truths = [], []
    for shard in range(n_shards(config)):
        lg, truth = module.simulate_shard(config, shard)
        logs.append(lg)
        truths.append(truth.to_pandas() if hasattr(truth, "to_pandas") else truth)
    truth = pd.concat(truths, ignore_index=True) if truths and truths[0] is not None else None
    return SimulatedDataset(config, logs, truth)
