"""What ``tma.estimate`` keeps beside its results (``results.tma``), and what draws from it
(``tma.plot_contact``, ``tma.write_map``)."""

import errno
import os
from pathlib import Path

import numpy as np
import pandas as pd

from tma.api.datasets import _data, _sources


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
    """``(hook, report rows, estimate rows, logs, recording, side tables)`` of a plot or map
    of ``results`` over ``recording`` (the side tables: the estimator's other tables, their
    rows of those tracks, e.g. ``path``, the trajectory each answer rests on); ValueError
    where the family has no such hook or the recording is of another family."""
    from tma.families import NAMES, family

    held = _held(results, what)
    aggregate_module = family(held.family).aggregate
    if not hasattr(aggregate_module, hook):
        able = " and ".join(n for n in NAMES if hasattr(family(n).aggregate, hook))
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
    sides = {name: held.table(name, results, what) for name in held.tables
             if name != "estimates"}
    return (getattr(aggregate_module, hook), report, held.table("estimates", results, what),
            list(data.logs), data, sides)


def plot_contact(results: pd.DataFrame, recording, label):
    """The matplotlib Figure of one contact (own-ship's whole path, every bearing's line, the
    estimated track from where its solution holds, the trajectory its answer rests on where
    the estimator kept it (``results.tma.tables["path"]``), and its 95 % ellipse now; no
    track where the results show no estimate), as aggregate draws ``<table>-<label>.png``:
    ``results`` from ``estimate`` (or rows of them), ``recording`` what it was estimated
    from, ``label`` the contact's (ValueError naming the contacts when there is no such
    one). For the families whose aggregate module draws contacts (``plot_contact``:
    ``bearings2d``)."""
    hook, report, estimates, logs, _, sides = _drawn(results, recording, "plot_contact",
                                                     "plot_contact")
    if isinstance(label, bool) or not isinstance(label, str | int | np.integer):
        raise TypeError(f"label must be a contact's label (str) or track id (int), got "
                        f"{type(label).__name__}")
    return hook(report, estimates, logs, label, sides)


def write_map(results: pd.DataFrame, recording, path) -> Path:
    """Write the estimated tracks and own-ship as Foxglove ``LocationFix`` messages (the map
    MCAP aggregate writes) to ``path``, a file in an existing directory (written whole or not
    at all); needs a log with a geographic origin and UTC times (the families whose aggregate
    module writes a map, ``write_map``: ``bearings2d``). Contacts whose results show no
    estimate are left out (a warning names them). A path that cannot be written raises the
    OSError the system gave (PermissionError, FileNotFoundError...), naming ``path``."""
    hook, report, estimates, logs, data, sides = _drawn(results, recording, "write_map",
                                                        "write_map")
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
        return hook(path, report, estimates, logs, _sources(data)[1], sides)
    except OSError as exc:  # named by the temporary file it was writing: name the user's
        message = (f"cannot write the map to {path}: {exc.strerror or exc}; choose a path "
                   "you can write to")
        raise (type(exc)(message) if exc.errno is None
               else type(exc)(exc.errno, message)) from None
