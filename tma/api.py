"""tma from Python: recorded logs and simulations in, pandas DataFrames out, through the same
code the commands run (``docs/api.md``).

- ``read_log(path, **options)`` reads a recorded log as ``python -m pipeline.ingest`` does
  (``tma.ingest.read_log``) into a ``Recording``; ``Recording.from_frames(bearings,
  navigation=None, **options)`` reads pandas DataFrames through the same CSV reader.
- ``estimate(data, estimator=None, sigma_deg=None, **options)`` runs an estimator over a
  recording or a simulated or stored dataset of any family as ``pipeline.estimate`` does
  (``Estimator.estimate`` on each log) and returns one row per track: the family's per-track
  results (its report module's ``results`` hook), while the estimator's own columns, which
  ``plot_contact`` and ``write_map`` draw from, stay in ``results.tma`` (``Results``).
- ``plot_contact`` and ``write_map`` draw and write what aggregate draws and writes, for the
  families whose report module has those hooks.
- ``open_dataset``, ``runs``, ``runs_dataset`` and ``simulate`` read stored datasets and
  runs, and simulate in memory what ``pipeline.simulate`` would store.

Options are ingest's and an estimator's, named as on the command line: as keyword arguments
by their group (``columns={"time": "tid"}``, ``bearing={"units": "rad"}``) or in a dict of
dotted names (``options={"columns.time": "tid"}``). Recorded logs are those of the family
that reads them (the one with an ``ingest`` module: ``bearings2d``).

Every error is one line of the kind pandas users catch: ``ValueError`` (``tma.errors``),
``TypeError`` for an argument of the wrong kind, ``FileNotFoundError`` for no such file, and
for a map that cannot be written the ``OSError`` the system gave.
"""

import errno
import functools
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from tma.errors import ConfigError, MissingFileError

log = logging.getLogger("tma")


@functools.cache
def _recorded() -> str:
    """The family whose logs a recording holds: the one that reads recorded logs (it has an
    ``ingest`` module; ``bearings2d``)."""
    from importlib.util import find_spec

    from tma.families import NAMES

    (name,) = [n for n in NAMES if find_spec(f"tma.families.{n}.ingest") is not None]
    return name


def _plain(value, key: str):
    """TypeError naming ``key`` for an option value that is no plain value (a number, text,
    list or dict of them, a date): a DataFrame, an array... (whose text spans lines, which no
    one-line message could show)."""
    if isinstance(value, dict):
        for k, v in value.items():
            _plain(v, f"{key}.{k}")
    elif isinstance(value, list | tuple):
        for v in value:
            _plain(v, key)
    elif "\n" in repr(value):
        raise TypeError(f"{key} must be a plain value (a number, text, or a list or dict of "
                        f"them), got {type(value).__name__}")


def _nested(options: dict | None, groups: dict) -> dict:
    """One nested option dict from dotted names (``{"columns.time": "tid"}``) and group
    keyword arguments (``columns={"time": "tid"}``); TypeError for values that are none."""
    if options is not None and not isinstance(options, dict):
        raise TypeError("options must be a dict of dotted names ({'columns.time': 'tid'}), "
                        f"got {type(options).__name__}")
    out: dict = {}
    for key, value in {**(options or {}), **groups}.items():
        _plain(value, str(key))
        node, parts = out, str(key).split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        if isinstance(value, dict) and isinstance(node.get(parts[-1]), dict):
            node[parts[-1]].update(value)
        else:
            node[parts[-1]] = value
    return out


def _split(options: dict) -> tuple[dict, dict]:
    """The family's ingest settings (``bearings2d``: ``sigma_deg``, ``min_bearings``) and the
    reading options of one nested dict."""
    from tma.stages.ingest import setting_names

    return ({k: options.pop(k) for k in setting_names(_recorded()) if k in options}, options)


class Recording:
    """A recorded log read into memory, as ``ingest`` reads it: one own-ship and its
    contacts' bearings per log (``logs``: ``BearingsLog``, several when the contacts came with
    different own-ships), and what reading it found, noted and left out.

    ``ownship`` and ``bearings`` show it as DataFrames; ``origin_deg`` (the local plane's
    WGS84 origin, or None), ``start_utc`` (ISO-8601 UTC of its time 0, or None for relative
    times), ``dropped`` (rows and bearings left out, contacts skipped) and ``notes`` (every
    choice made by itself) as the dataset manifest would record them."""

    recorded = True

    def __init__(self, read):
        self._read = read
        self.logs = list(read.logs)
        self.family = read.family

    @classmethod
    def from_frames(cls, bearings: pd.DataFrame, navigation: pd.DataFrame | None = None, *,
                    options: dict | None = None, **groups) -> "Recording":
        """A Recording of pandas DataFrames: ``bearings`` with a time (datetime64, Unix
        epoch or seconds), a bearing (deg, or radians said so) and a contact column, and
        the own-ship (latitude/longitude or x/y, as a navigation export has them) unless
        ``navigation`` gives it; columns are found as in a CSV file, and named with
        ``columns={...}`` where they are not. Options as ``read_log``'s."""
        from tma.stages.ingest import read_frames

        for name, frame in (("bearings", bearings), ("navigation", navigation)):
            if not isinstance(frame, pd.DataFrame) and (name == "bearings" or frame is not None):
                hint = (" (a file is read by tma.read_log)" if isinstance(frame, str | Path)
                        else "")
                raise TypeError(f"{name} must be a pandas DataFrame, got "
                                f"{type(frame).__name__}{hint}")
        settings, reading = _split(_nested(options, groups))
        return cls(read_frames(bearings, navigation, family=_recorded(), options=reading,
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

    if path is None:
        raise TypeError("input must be a file path (str or pathlib.Path), got NoneType")
    if not (truth is None or isinstance(truth, str | os.PathLike | dict)):
        raise TypeError("truth must be the AIS file's path or a dict of truth.* options, got "
                        f"{type(truth).__name__}")
    options = _nested(options, groups)
    _plain({"sigma_deg": sigma_deg, "min_bearings": min_bearings, "truth": truth}, "read_log")
    return Recording(read(path, family=_recorded(), fmt=format, navigation=navigation,
                          options=options, sigma_deg=sigma_deg, min_bearings=min_bearings,
                          truth=truth))


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


@dataclass(frozen=True)
class Estimated:
    """An estimate in memory, what a family's ``report.results`` hook turns into the results
    of ``tma.estimate``: ``estimator`` (built, with its ``config``), ``estimates`` (its
    table over every log: a row per track, or per track and step), ``side_tables`` (name ->
    DataFrame, those it declares), the ``logs``, ``recorded`` (a recording, not a
    simulation), ``truth`` (a simulation's, or the AIS truth of a recording; None without),
    ``truth_track`` (a recording's ships from their AIS, or None) and ``scenario`` (the
    simulated scenario's config as plain values; None for a recording)."""

    family: str
    estimator: object
    estimates: pd.DataFrame
    side_tables: dict
    logs: list
    recorded: bool
    truth: pd.DataFrame | None
    truth_track: pd.DataFrame | None
    scenario: dict | None


def _estimator_for(family_name: str, estimator, recorded: bool, options: dict):
    """The estimator ``estimator`` (None: the family's first) built from ``options`` as the
    command line builds it (on a recording, its ``recorded_defaults`` first); ValueError for
    one of another family or one that trains an artefact first."""
    from tma.estimator import Estimator, name_set_error
    from tma.families import build_estimator, estimator_class, estimator_names, family

    if "name" in options:  # as the command line's estimator.name= (tma.experiment)
        raise name_set_error(f"name={options['name']!r}", repr(options["name"]))
    known = list(family(family_name).estimators)
    name = known[0] if estimator is None else estimator
    if not isinstance(name, str):
        raise TypeError(f"estimator must be an estimator's name (a str: {', '.join(known)}), "
                        f"got {type(name).__name__}")
    if name not in estimator_names():
        raise ConfigError(f"unknown estimator {name!r}: {family_name}'s are "
                          f"{', '.join(known)}")
    cls = estimator_class(name)
    if cls.family != family_name:
        raise ConfigError(f"estimator {name!r} reads {cls.family} logs, these are "
                          f"{family_name}'s: choose one of {', '.join(known)}")
    if cls.prepare.__func__ is not Estimator.prepare.__func__:  # trains an artefact first
        runs_here = [k for k in known if family(family_name).estimator_class(k).prepare
                     .__func__ is Estimator.prepare.__func__]
        raise ConfigError(f"estimator {name!r} trains an artefact under data/artefacts before "
                          "it runs, which tma.estimate does not write: run it with python -m "
                          f"pipeline.table scenario={family_name} estimator={name} "
                          "[scenario.KEY=VALUE ...] (then tma.runs reads its metrics), or "
                          f"choose one of {', '.join(runs_here)}")
    node = {"name": name, **(cls.recorded_defaults if recorded else {}), **options}
    return build_estimator(node)


def _sources(data) -> tuple[pd.DataFrame | None, pd.DataFrame | None, dict | None]:
    """``(truth, truth track, scenario config)`` of what ``tma.estimate`` reads."""
    from tma.config import to_plain

    if isinstance(data, Recording):
        return data.truth, data.truth_track, None
    if isinstance(data, SimulatedDataset):
        return data.truth, None, to_plain(data.config)
    return data.truth, data.truth_track, None if data.recorded else data.manifest["config"]


def estimate(data, estimator: str | None = None, sigma_deg: float | None = None,
             **options) -> pd.DataFrame:
    """Estimate every track of ``data`` (a ``Recording``, a DataFrame as
    ``Recording.from_frames`` reads it, or a dataset of ``simulate``/``open_dataset``, of any
    family) with ``estimator`` (default: its family's first, ``lm`` for bearings) and its
    ``options`` (``max_iter=50``, ``accel_psd_m2_s3=0``: the keys of ``python -m tma.options
    <estimator>``); ``sigma_deg``: the bearings' nominal noise, for logs that have one
    (default: the log's, else estimated).

    Returns one row per track, the family's results (its report module's ``results``):
    ``bearings2d`` the per-contact report ``pipeline.aggregate`` writes (label, time_now_utc,
    range/bearing/course/speed now with their one-sigma errors, x/y and lat/lon now, status
    and note, sqrt_ka_deg, fit and trend-test p-values, leg_start_s/_utc...), with a
    recording's AIS (``truth=``) the truth, errors, z-scores and ``covered``, with a
    simulation's truth its metrics; ``radar2d``, ``ranges2d``, ``bearing_doppler3d`` each
    track's state at its end and status, with its errors against the truth. An estimate that
    is no answer is blank, with its status and a note. The estimator's own columns (what
    ``plot_contact`` and ``write_map`` draw from) are ``results.tma.estimates``."""
    from tma.families import family
    from tma.stages.estimate import estimate_log

    data = _data(data, "estimate")
    _plain({"sigma_deg": sigma_deg, **options}, "estimate")
    fam = family(data.family)
    est = _estimator_for(fam.name, estimator, data.recorded, options)
    logs = list(data.logs)
    if sigma_deg is not None:
        logs = _with_sigma(logs, sigma_deg, fam.name)
    tables, sides = [], {}
    for lg in logs:
        table, extras, _ = estimate_log(est, lg)
        tables.append(table.to_pandas())
        for name, side in extras.items():
            sides.setdefault(name, []).append(pd.DataFrame(side))
    estimates = pd.concat(tables, ignore_index=True)
    truth, truth_track, scenario = _sources(data)
    report, held = fam.report.results(Estimated(
        fam.name, est, estimates, {k: pd.concat(v, ignore_index=True) for k, v in sides.items()},
        logs, data.recorded, truth, truth_track, scenario))
    report.attrs["tma"] = Results(fam.name, est.name, report.copy(), held)
    return report


def _with_sigma(logs, sigma_deg, family_name: str) -> list:
    """``logs`` with the bearings' nominal noise ``sigma_deg`` (checked as ingest's)."""
    from dataclasses import replace

    from tma.families import family

    if not hasattr(logs[0], "sigma_deg"):
        raise ConfigError(f"sigma_deg is the bearing noise of a bearing log; a {family_name} "
                          f"dataset's noise is its scenario's: tma.simulate({family_name!r}, "
                          "...) sets it (python -m tma.options "
                          f"{family_name} lists its keys)")
    family(family_name).ingest.Settings(sigma_deg=sigma_deg)  # ingest's sigma_deg= check
    return [replace(lg, sigma_deg=float(sigma_deg)) for lg in logs]


class Results(dict):
    """What ``tma.estimate`` keeps beside its results, in ``results.attrs["tma"]``: the
    family, the estimator, the report as returned (``report``) and the estimator's own tables
    (``tables``: name -> DataFrame, ``estimates`` first). pandas carries ``attrs`` through
    what selects rows or columns of a frame (filters, ``query``, ``sort_values``, ``head``,
    ``loc``/``iloc``, ``copy``, ``reset_index``, ``assign``, pickling), so a selection of the
    results still plots; not through ``merge``, a ``concat`` with other frames or a file.
    Shared, never copied, by the frames derived from one result (equal only to itself). A
    dict of its family and estimator, so that what writes ``attrs`` as JSON (``to_parquet``)
    writes those and no table."""

    def __init__(self, family: str, estimator: str, report: pd.DataFrame, tables: dict):
        super().__init__(family=family, estimator=estimator)
        self.family, self.estimator, self.report, self.tables = family, estimator, report, tables

    def __eq__(self, other):
        return self is other

    def __ne__(self, other):
        return self is not other

    __hash__ = object.__hash__

    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self

    def __reduce__(self):  # pickled with its tables (dict's own pickling would drop them)
        return (Results, (self.family, self.estimator, self.report, self.tables))

    def __repr__(self) -> str:
        return (f"<tma results: {len(self.report)} {self.family} track(s) by "
                f"{self.estimator}>")

    def rows(self, frame: pd.DataFrame, what: str) -> np.ndarray:
        """Positions in ``report`` of the tracks of ``frame`` (a selection of the results), in
        its order, found by ``track_id`` (else ``label``)."""
        key = next((k for k in ("track_id", "label") if k in frame.columns), None)
        if key is None:
            raise ValueError(f"{what}: these results have neither a track_id nor a label "
                             "column: keep one of them to say which tracks they hold")
        known = pd.Index(self.report[key].astype(str))
        at = known.get_indexer(frame[key].astype(str))
        if (at < 0).any():
            raise ValueError(f"{what}: {key} {frame[key].iloc[int(np.argmax(at < 0))]!r} is "
                             "not one of these results' tracks: pass what tma.estimate "
                             "returned, or rows of it")
        return at

    def table(self, name: str, frame: pd.DataFrame, what: str) -> pd.DataFrame:
        """The rows of table ``name`` of the tracks of ``frame``, in its order."""
        ids = self.report["track_id"].to_numpy()[self.rows(frame, what)]
        table = self.tables[name]
        if "track_id" not in table.columns:
            return table
        order = pd.Index(ids).get_indexer(table["track_id"])
        keep = np.flatnonzero(order >= 0)
        return table.iloc[keep[np.argsort(order[keep], kind="stable")]].reset_index(drop=True)


def _held(results, what: str) -> Results:
    if not isinstance(results, pd.DataFrame):
        raise TypeError(f"{what} needs the results DataFrame tma.estimate returned, got "
                        f"{type(results).__name__}")
    held = results.attrs.get("tma")
    if not isinstance(held, Results):
        raise ValueError(f"{what}: these results carry no estimate (results.attrs['tma'] is "
                         "kept through filters, sorting and column selection, not through a "
                         "merge, a concat with other frames or a file): pass what "
                         "tma.estimate returned, or rows of it")
    return held


@pd.api.extensions.register_dataframe_accessor("tma")
class ResultsAccessor:
    """``results.tma``: what ``tma.estimate`` keeps beside the results frame, for its rows:
    ``estimates`` (the estimator's own columns: ``x0_m``.., ``jtj_ij``, per-step states...),
    ``tables`` (every table it keeps, e.g. ``covariance``), ``family`` and ``estimator``."""

    def __init__(self, frame: pd.DataFrame):
        self._frame = frame

    @property
    def _results(self) -> Results:
        return _held(self._frame, "results.tma")

    @property
    def family(self) -> str:
        return self._results.family

    @property
    def estimator(self) -> str:
        return self._results.estimator

    @property
    def estimates(self) -> pd.DataFrame:
        """The estimator's own table for the tracks of these results, in their order."""
        return self._results.table("estimates", self._frame, "results.tma.estimates")

    @property
    def tables(self) -> dict:
        held = self._results
        return {name: held.table(name, self._frame, "results.tma.tables") for name in held.tables}


def _drawn(results, recording, what: str, hook: str):
    """``(hook, report rows, estimate rows, logs, recording)`` of a plot or map of
    ``results`` over ``recording``; ValueError where the family has no such hook or the
    recording is of another family."""
    from tma.families import NAMES, family

    held = _held(results, what)
    report_module = family(held.family).report
    if not hasattr(report_module, hook):
        able = " and ".join(n for n in NAMES if hasattr(family(n).report, hook))
        does = {"plot_contact": f"draws the contacts of {able} estimates (own-ship, bearings, "
                "track)", "write_map": f"maps the contacts of {able} estimates (in latitude/"
                "longitude, at UTC times)"}[hook]
        raise ValueError(f"{what} {does}; these are {held.family}'s, which it cannot draw: "
                         "their estimates are results.tma.estimates, to plot with pandas")
    data = _data(recording, what)
    if data.family != held.family:
        raise ValueError(f"these results are of {held.family} logs, the recording given is a "
                         f"{data.family} one: pass the recording given to tma.estimate")
    rows = held.rows(results, what)
    report = held.report.iloc[rows].reset_index(drop=True)
    return (getattr(report_module, hook), report, held.table("estimates", results, what),
            list(data.logs), data)


def plot_contact(results: pd.DataFrame, recording, label):
    """The matplotlib Figure of one contact (own-ship's whole path, every bearing's line, the
    estimated track from where its solution holds and its 95 % ellipse now; no track where
    the results show no estimate), as aggregate draws ``<table>-<label>.png``: ``results``
    from ``estimate`` (or rows of them), ``recording`` what it was estimated from, ``label``
    the contact's (ValueError naming the contacts when there is no such one). For the
    families whose report module draws contacts (``plot_contact``: ``bearings2d``)."""
    hook, report, estimates, logs, _ = _drawn(results, recording, "plot_contact",
                                              "plot_contact")
    if isinstance(label, bool) or not isinstance(label, str | int | np.integer):
        raise TypeError(f"label must be a contact's label (str) or track id (int), got "
                        f"{type(label).__name__}")
    return hook(report, estimates, logs, label)


def write_map(results: pd.DataFrame, recording, path) -> Path:
    """Write the estimated tracks and own-ship as Foxglove ``LocationFix`` messages (the map
    MCAP aggregate writes) to ``path``, a file in an existing directory (written whole or not
    at all); needs a log with a geographic origin and UTC times (the families whose report
    module writes a map, ``write_map``: ``bearings2d``). Contacts whose results show no
    estimate are left out (a warning names them). A path that cannot be written raises the
    OSError the system gave (PermissionError, FileNotFoundError...), naming ``path``."""
    hook, report, estimates, logs, data = _drawn(results, recording, "write_map", "write_map")
    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"path must be a file path (str or pathlib.Path), got "
                        f"{type(path).__name__}")
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, f"cannot write the map to {path}: it is a "
                                f"directory; give a file name, e.g. {path / 'contacts.mcap'}")
    if not path.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, f"cannot write the map to {path}: there is no "
                                f"directory {path.parent}; create it or choose another path")
    try:
        return hook(path, report, estimates, logs, _sources(data)[1])
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


def _path(value, what: str):
    """``value`` if it is a path (str or os.PathLike); TypeError naming ``what`` else."""
    if isinstance(value, str | os.PathLike):
        return value
    raise TypeError(f"{what} must be a path (str or pathlib.Path), got {type(value).__name__}")


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
