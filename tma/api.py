"""tma from Python: recorded logs and simulations in, pandas DataFrames out, through the same
code the commands run (``docs/api.md``).

- ``read_log(path, **options)`` reads a recorded log as ``python -m pipeline.ingest`` does
  (``tma.ingest.read_log``) into a ``Recording``; ``Recording.from_frames(bearings,
  navigation=None, **options)`` reads pandas DataFrames through the same CSV reader.
- ``estimate(recording_or_frame, estimator="lm", sigma_deg=None, **options)`` runs an
  estimator over it as ``pipeline.estimate`` does (``Estimator.estimate`` on each own-ship's
  log) and returns the per-contact report ``pipeline.aggregate`` writes
  (``bearings2d.report.contact_report``), with the estimate's own columns.
- ``plot_contact`` and ``write_map`` draw and write what aggregate draws and writes.
- ``open_dataset``, ``runs`` and ``simulate`` read stored datasets and runs, and simulate in
  memory what ``pipeline.simulate`` would store.

Options are ingest's and an estimator's, named as on the command line: as keyword arguments
by their group (``columns={"time": "tid"}``, ``bearing={"units": "rad"}``) or in a dict of
dotted names (``options={"columns.time": "tid"}``). Recorded logs are ``bearings2d``'s (the
one family that ingests them).
"""

import errno
import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from tma.errors import ConfigError

FAMILY = "bearings2d"  # the family of recorded bearing logs
THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")
log = logging.getLogger("tma")


def _nested(options: dict | None, groups: dict) -> dict:
    """One nested option dict from dotted names (``{"columns.time": "tid"}``) and group
    keyword arguments (``columns={"time": "tid"}``)."""
    out: dict = {}
    for key, value in {**(options or {}), **groups}.items():
        node, parts = out, str(key).split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        if isinstance(value, dict) and isinstance(node.get(parts[-1]), dict):
            node[parts[-1]].update(value)
        else:
            node[parts[-1]] = value
    return out


def _split(options: dict, settings=("sigma_deg", "min_bearings")) -> tuple[dict, dict]:
    """The family's ingest settings and the reading options of one nested dict."""
    return ({k: options.pop(k) for k in settings if k in options}, options)


class Recording:
    """A recorded log read into memory, as ``ingest`` reads it: one own-ship and its
    contacts' bearings per log (``logs``: ``BearingsLog``, several when the contacts came with
    different own-ships), and what reading it found, noted and left out.

    ``ownship`` and ``bearings`` show it as DataFrames; ``origin_deg`` (the local plane's
    WGS84 origin, or None), ``start_utc`` (ISO-8601 UTC of its time 0, or None for relative
    times), ``dropped`` (rows and bearings left out, contacts skipped) and ``notes`` (every
    choice made by itself) as the dataset manifest would record them."""

    def __init__(self, read):
        self._read = read
        self.logs = list(read.logs)

    @classmethod
    def from_frames(cls, bearings: pd.DataFrame, navigation: pd.DataFrame | None = None, *,
                    options: dict | None = None, **groups) -> "Recording":
        """A Recording of pandas DataFrames: ``bearings`` with a time (datetime64, Unix
        epoch or seconds), a bearing (deg, or radians said so) and a contact column, and
        the own-ship (latitude/longitude or x/y, as a navigation export has them) unless
        ``navigation`` gives it; columns are found as in a CSV file, and named with
        ``columns={...}`` where they are not. Options as ``read_log``'s."""
        from tma.stages.ingest import read_frames

        settings, reading = _split(_nested(options, groups))
        return cls(read_frames(bearings, navigation, family=FAMILY, options=reading,
                               **settings))

    @property
    def _summary(self) -> dict:
        return self._read.summary

    @property
    def epoch_utc_ns(self) -> int | None:
        return self.logs[0].epoch_utc_ns

    @property
    def start_utc(self) -> str | None:
        from tma.utc import format_utc

        return None if self.epoch_utc_ns is None else format_utc(self.epoch_utc_ns)

    @property
    def origin_deg(self) -> tuple[float, float] | None:
        origin = self.logs[0].origin_deg
        return None if origin is None else tuple(map(float, origin))

    @property
    def sigma_deg(self) -> float | None:
        return self.logs[0].sigma_deg

    @property
    def notes(self) -> list[str]:
        return list(self._summary.get("notes", []))

    @property
    def dropped(self) -> dict:
        """What was left out: ``bad_rows`` (per reason: count and first places), the
        bearings outside the own-ship fixes, the contacts skipped for too few bearings."""
        s = self._summary
        return {key: s[key] for key in ("bad_rows", "dropped_bearings", "skipped_contacts")
                if key in s}

    def _times(self, t_s) -> dict:
        if self.epoch_utc_ns is None:
            return {"t_s": t_s}
        return {"t_s": t_s, "time_utc": pd.to_datetime(
            self.epoch_utc_ns + np.round(t_s * 1e9).astype(np.int64), utc=True)}

    @property
    def ownship(self) -> pd.DataFrame:
        """Own-ship at each bearing epoch: ``log`` (which own-ship), ``t_s`` (from the log's
        time 0), ``time_utc``, ``x_m``/``y_m`` (east, north of ``origin_deg``), and with an
        origin ``lat_deg``/``lon_deg``."""
        from tma.maths.geo import local_to_geodetic

        frames = []
        for k, lg in enumerate(self.logs):
            frame = {"log": k, **self._times(lg.t_s), "x_m": lg.own_x_m, "y_m": lg.own_y_m}
            if lg.origin_deg is not None:
                frame["lat_deg"], frame["lon_deg"] = local_to_geodetic(lg.own_x_m, lg.own_y_m,
                                                                       lg.origin_deg)
            frames.append(pd.DataFrame(frame))
        return pd.concat(frames, ignore_index=True)

    @property
    def bearings(self) -> pd.DataFrame:
        """One row per bearing: ``log``, ``t_s``, ``time_utc``, ``track_id``, ``label`` (the
        contact as written) and ``bearing_deg`` (clockwise from north)."""
        frames = []
        for k, lg in enumerate(self.logs):
            row, col = np.nonzero(np.isfinite(lg.bearing_deg))
            labels = (lg.track_label if lg.track_label is not None
                      else lg.track_id.astype(str))
            frames.append(pd.DataFrame({
                "log": k, **self._times(lg.t_s[col]), "track_id": lg.track_id[row],
                "label": np.asarray(labels, dtype=object)[row],
                "bearing_deg": lg.bearing_deg[row, col]}))
        return pd.concat(frames, ignore_index=True).sort_values(
            ["log", "t_s", "track_id"], kind="stable").reset_index(drop=True)

    @property
    def truth(self) -> pd.DataFrame | None:
        """The truth of its contacts from the AIS of its trial (``read_log(..., truth=FILE)``:
        one row per contact with a truth, ``tma.ais.truth``), or None."""
        return None if self._read.truth is None else self._read.truth.truth

    @property
    def truth_track(self) -> pd.DataFrame | None:
        """Each contact's ship from its AIS at its bearing times, or None."""
        return None if self._read.truth is None else self._read.truth.track

    @property
    def matches(self) -> pd.DataFrame | None:
        """Per contact which ship it was matched to, how well it fits and why (or why not)."""
        if self._read.truth is None:
            return None
        return pd.DataFrame([m.record() for m in self._read.truth.matches]).astype(
            {"mmsi": "Int64"})

    def __repr__(self) -> str:
        n = sum(lg.n_tracks for lg in self.logs)
        span = max(lg.t_s[-1] for lg in self.logs)
        return (f"<Recording of {self._read.sources['input']['path']}: {n} contact(s), "
                f"{len(self.logs)} own-ship log(s), {span:g} s from "
                f"{self.start_utc or 'relative time 0'}>")


def read_log(path, *, navigation=None, format: str = "auto", sigma_deg: float | None = None,
             min_bearings: int = 5, truth=None, options: dict | None = None,
             **groups) -> Recording:
    """Read a recorded bearing log (CSV/TSV, NMEA navigation, ROS 2, Foxglove or tma's own
    MCAP) as ``python -m pipeline.ingest input=<path>`` does, without storing it. Reading
    options by group (``columns={"time": "tid"}``, ``bearing={"topic": "/sonar/*"}``,
    ``time={"start_utc": "2025-06-01T08:00:00Z"}``, ``bad_rows="fail"``) or dotted in
    ``options``; ``sigma_deg``: the sensor's nominal bearing noise, when known; ``truth``: the
    AIS of the trial, a path or the ``truth.*`` options (``{"file": ..., "match": {"T1":
    235031617}}``): ``estimate`` then scores each contact against it."""
    from tma.stages.ingest import read_log as read

    return Recording(read(path, family=FAMILY, fmt=format, navigation=navigation,
                          options=_nested(options, groups), sigma_deg=sigma_deg,
                          min_bearings=min_bearings, truth=truth))


def _truth_of(data):
    """``(truth, truth track)`` of a Recording or stored dataset scored against AIS, else
    ``(None, None)``."""
    if isinstance(data, Recording):
        return data.truth, data.truth_track
    if isinstance(data, StoredDataset) and data.recorded:
        from tma.families.bearings2d.truth_report import dataset_truth

        return dataset_truth(data.dataset)
    return None, None


def _logs_of(data, sigma_deg, what="estimate"):
    """(logs, recorded?) of a Recording, a DataFrame (read as ``Recording.from_frames``), a
    simulated or stored dataset; ``sigma_deg`` replaces the logs' nominal noise."""
    if isinstance(data, pd.DataFrame):
        data = Recording.from_frames(data)
    if isinstance(data, Recording):
        logs, recorded = data.logs, True
    elif hasattr(data, "logs"):
        logs, recorded = list(data.logs), getattr(data, "recorded", False)
    else:
        hint = (" (read a log file with tma.read_log first)" if isinstance(data, str | Path)
                else "")
        raise TypeError(f"{what} needs a Recording, a pandas DataFrame, or a dataset of "
                        f"tma.simulate / tma.open_dataset, got {type(data).__name__}{hint}")
    family = getattr(data, "family", FAMILY)
    if family != FAMILY:
        raise ConfigError(f"tma.{what} reads {FAMILY} logs (a Recording, a DataFrame, a "
                          f"{FAMILY} simulation or dataset), got a {family} dataset: its stages "
                          f"estimate it (python -m pipeline.table scenario={family})")
    if sigma_deg is not None:
        from dataclasses import replace

        from tma.families import family as family_named

        family_named(FAMILY).ingest.Settings(sigma_deg=sigma_deg)  # ingest's sigma_deg= check
        logs = [replace(lg, sigma_deg=float(sigma_deg)) for lg in logs]
    return logs, recorded


def estimate(data, estimator: str = "lm", sigma_deg: float | None = None,
             **options) -> pd.DataFrame:
    """Estimate every contact of ``data`` (a ``Recording``, a DataFrame as
    ``Recording.from_frames`` reads it, or a dataset of ``simulate``/``open_dataset``) with
    ``estimator`` and its ``options`` (``max_iter=50``, ``accel_psd_m2_s3=0``: the keys of
    ``python -m tma.options <estimator>``); ``sigma_deg``: the bearings' nominal noise
    (default: the log's, else estimated). Returns one row per contact: the per-track report
    ``pipeline.aggregate`` writes (label, time_now_utc, range/bearing/course/speed now with
    their one-sigma errors, x/y and lat/lon now, status and note, sqrt_ka_deg, fit and
    trend-test p-values, leg_start_s/_utc...), for a log read with its AIS (``truth=``) the
    truth, errors, z-scores and ``covered`` (``bearings2d.truth_report``), followed by the
    estimate's own columns (``x0_m``.., ``jtj_ij``: what ``plot_contact`` and ``write_map``
    draw from). An estimate that is no answer (diverged, collapsed, or without a one-sigma
    error: ``bearings2d.status.not_an_answer``) is blank there, ``x0_m``.. included, with its
    status and a note that says so."""
    from tma.families import build_estimator, estimator_class
    from tma.report.tables import plots_to_files
    from tma.stages.estimate import estimate_log

    plots_to_files()  # the report module loads matplotlib
    from tma.families.bearings2d.report import contact_report

    if "name" in options:  # as the command line's estimator.name= (tma.experiment)
        from tma.estimator import name_set_error

        raise name_set_error(f"name={options['name']!r}", repr(options["name"]))
    logs, recorded = _logs_of(data, sigma_deg)
    node = {"name": estimator, **options}
    if recorded:  # as on a recorded dataset: the estimator's defaults for a recording
        node = {"name": estimator, **estimator_class(estimator).recorded_defaults, **options}
    est = build_estimator(node)
    if est.family != FAMILY:
        raise ValueError(f"estimator {estimator!r} is {est.family}'s; recorded logs are "
                         f"{FAMILY}'s")
    estimates = pd.concat([estimate_log(est, lg)[0].to_pandas() for lg in logs],
                          ignore_index=True)
    report = contact_report(estimates, logs, "estimate",
                            getattr(est.config, "max_range_rel_sd", None), recorded)
    truth, _ = _truth_of(data)
    if truth is not None:  # the columns against the AIS truth, as aggregate writes them
        from tma.families.bearings2d.truth_report import with_truth

        report = with_truth(report, estimates, truth)
    extra = [c for c in estimates.columns if c not in report.columns]
    results = pd.concat([report, estimates[extra]], axis=1)
    results.loc[~np.isfinite(report["range_now_m"].to_numpy(float)), list(THETA)] = np.nan
    return results


def _estimates(results, what: str) -> pd.DataFrame:
    if not isinstance(results, pd.DataFrame):
        raise TypeError(f"{what} needs the results DataFrame tma.estimate returned, got "
                        f"{type(results).__name__}")
    missing = [c for c in ("label", "track_id", "status", "range_now_m", "t_now_s",
                           "time_now_utc", "leg_start_s", *THETA, "t_last_s", "own_x_last_m",
                           "own_y_last_m", "jtj_00", "sigma_used_deg", "range_sd_m")
               if c not in results.columns]
    if missing:
        raise ValueError(f"these results lack the estimate's columns ({', '.join(missing)}): "
                         "pass what tma.estimate returned")
    return results


SAME_TIME_S = 1e-6  # a contact's last bearing time in the results and in its recording
SAME_PLACE_M = 1e-3  # own-ship there


def _recording_of(results: pd.DataFrame, recording, what: str) -> list:
    """The logs of ``recording``, checked to be those ``results`` were estimated from: each
    contact's track id in them, its last bearing at the same time from the same own-ship
    position, and its UTC the same where both are dated; ValueError naming the first
    contact that differs."""
    logs, _ = _logs_of(recording, None, what)
    where = {int(i): (lg, row) for lg in logs for row, i in enumerate(lg.track_id)}
    epoch = logs[0].epoch_utc_ns
    from tma.utc import format_utc

    for r in results.itertuples(index=False):
        place = where.get(int(r.track_id))
        if place is None:
            why = f"track id {r.track_id} is not in this recording"
        else:
            lg, row = place
            last = np.flatnonzero(np.isfinite(lg.bearing_deg[row]))[-1]
            why = ""
            if not (abs(lg.t_s[last] - r.t_last_s) <= SAME_TIME_S
                    and abs(lg.own_x_m[last] - r.own_x_last_m) <= SAME_PLACE_M
                    and abs(lg.own_y_m[last] - r.own_y_last_m) <= SAME_PLACE_M):
                why = "its last bearing is at another time or own-ship position here"
            elif isinstance(r.time_now_utc, str) and epoch is not None and (
                    r.time_now_utc != format_utc(epoch + round(r.t_now_s * 1e9))):
                why = f"its last bearing is at {r.time_now_utc} there, at another UTC here"
        if why:
            raise ValueError(f"these results were not estimated from this recording (contact "
                             f"{r.label!r}: {why}); pass the recording given to tma.estimate")
    return logs


def plot_contact(results: pd.DataFrame, recording, label):
    """The matplotlib Figure of one contact (own-ship's whole path, every bearing's line, the
    estimated track from where its solution holds and its 95 % ellipse now; no track where
    the results show no estimate), as aggregate draws ``<table>-<label>.png``: ``results``
    from ``estimate``, ``recording`` what it was estimated from, ``label`` the contact's
    (ValueError naming the contacts when there is no such one)."""
    from tma.families.bearings2d.map_outputs import contact_figure

    results = _estimates(results, "plot_contact")
    logs = _recording_of(results, recording, "plot_contact")
    return contact_figure(results, results, logs, label)


def write_map(results: pd.DataFrame, recording, path) -> Path:
    """Write the estimated tracks and own-ship as Foxglove ``LocationFix`` messages (the map
    MCAP aggregate writes) to ``path``, a file in an existing directory (written whole or not
    at all); needs a log with a geographic origin and UTC times. Contacts whose results show
    no estimate are left out (a warning names them). A path that cannot be written raises
    the OSError the system gave (PermissionError, FileNotFoundError...), naming ``path``."""
    from tma.families.bearings2d.map_outputs import write_map_mcap

    results = _estimates(results, "write_map")
    logs = _recording_of(results, recording, "write_map")
    epoch, origin = logs[0].epoch_utc_ns, logs[0].origin_deg
    if origin is None or epoch is None:
        raise ValueError("a map needs own-ship in latitude/longitude and UTC times (a log "
                         "with relative times: read it with time={'start_utc': ...})")
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, f"cannot write the map to {path}: it is a "
                                f"directory; give a file name, e.g. {path / 'contacts.mcap'}")
    if not path.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, f"cannot write the map to {path}: there is no "
                                f"directory {path.parent}; create it or choose another path")
    try:
        return write_map_mcap(path, results, results, logs, epoch, origin,
                              {"estimator": "tma.estimate"},
                              truth_track=_truth_of(recording)[1])
    except OSError as exc:  # named by the temporary file it was writing: name the user's
        message = (f"cannot write the map to {path}: {exc.strerror or exc}; choose a path "
                   "you can write to")
        raise (type(exc)(message) if exc.errno is None
               else type(exc)(exc.errno, message)) from None


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
    ``manifest`` (config, seeds, hashes), ``logs`` (one per shard, read when first asked)
    and ``truth`` (a DataFrame, None for an ingested log)."""

    def __init__(self, dataset):
        self.dataset = dataset
        self.name, self.family = dataset.name, dataset.family
        self.manifest = dataset.manifest
        self.logs = _LazyLogs(dataset)
        self.recorded = dataset.manifest["source"] != "simulate"

    @property
    def truth(self) -> pd.DataFrame | None:
        return self.dataset.read_truth()

    def __repr__(self) -> str:
        return f"<StoredDataset {self.name} ({self.family}, {len(self.logs)} shard(s))>"


def open_dataset(name_or_path, data_dir="data") -> StoredDataset:
    """A stored dataset by name (under ``<data_dir>/datasets``) or path, verified as the stages
    verify it (its manifest; each shard's sha256 when read)."""
    from tma.io.dataset import Dataset, datasets_dir

    path = Path(name_or_path)
    root = path if path.is_dir() else datasets_dir(data_dir) / str(name_or_path)
    return StoredDataset(Dataset.open(root))


def runs(data_dir="data", family: str | None = None, as_dataset: bool = False):
    """Every run's per-track metrics under ``<data_dir>/runs`` as one DataFrame (with each
    run's family, dataset, estimator and config values as columns,
    ``tma.aggregate.metrics_dataset``), or the pyarrow dataset itself (``as_dataset``). Runs
    that hold no ``metrics.parquet`` (never aggregated, or recomputed since) are named in a
    warning and in ``attrs["without_metrics"]``, not left out silently."""
    from tma.stages.aggregate import metrics_dataset, runs_without_metrics

    missing = runs_without_metrics(data_dir, family)
    if missing:
        log.warning("%d run(s) without metrics.parquet (aggregate them first): %s",
                    len(missing), ", ".join(missing[:10]) + (" ..." if len(missing) > 10
                                                              else ""))
    dataset = metrics_dataset(data_dir, family=family)
    if as_dataset:
        return dataset
    frame = dataset.to_table().to_pandas()
    frame.attrs["without_metrics"] = missing
    return frame


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


def simulate(family: str = FAMILY, options: dict | None = None, **overrides
             ) -> SimulatedDataset:
    """Simulate the scenario of ``family`` with ``overrides`` (``n_tracks=200``,
    ``sigma_deg=1.0``, ``target={"manoeuvres": {"prob": 1.0}}``, or dotted names in
    ``options``) in memory, shard by shard as ``pipeline.simulate`` does (the same random
    streams, so the same numbers as its dataset of that config)."""
    from tma.families import load_scenario
    from tma.runtime.sharding import n_shards

    module, config = load_scenario({"family": family, **_nested(options, overrides)})
    logs, truths = [], []
    for shard in range(n_shards(config)):
        lg, truth = module.simulate_shard(config, shard)
        logs.append(lg)
        truths.append(truth.to_pandas() if hasattr(truth, "to_pandas") else truth)
    truth = pd.concat(truths, ignore_index=True) if truths and truths[0] is not None else None
    return SimulatedDataset(config, logs, truth)
