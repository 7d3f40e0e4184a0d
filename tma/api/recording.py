"""A recorded log read into memory (``tma.read_log``, ``Recording.from_frames``)."""

import logging
import os
from pathlib import Path

import numpy as np
import pandas as pd

from tma.api.options import _nested, _plain, _recorded, _split

log = logging.getLogger("tma")


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
                    truth=None, options: dict | None = None, **groups) -> "Recording":
        """A Recording of pandas DataFrames: ``bearings`` with a time (datetime64, Unix
        epoch or seconds), a bearing (deg, or radians said so) and a contact column, and
        the own-ship (latitude/longitude or x/y, as a navigation export has them) unless
        ``navigation`` gives it; columns are found as in a CSV file, and named with
        ``columns={...}`` where they are not. Options and ``truth`` (the AIS to score the
        contacts against: a path or the ``truth.*`` options, also dotted in ``options``) as
        ``read_log``'s; own-ship from the AIS (``truth.own_mmsi``) is ``read_log``'s only."""
        from tma.stages.ingest import read_frames, with_truth

        for name, frame in (("bearings", bearings), ("navigation", navigation)):
            if not isinstance(frame, pd.DataFrame) and (name == "bearings" or frame is not None):
                hint = (" (a file is read by tma.read_log)" if isinstance(frame, str | Path)
                        else "")
                raise TypeError(f"{name} must be a pandas DataFrame, got "
                                f"{type(frame).__name__}{hint}")
        if not (truth is None or isinstance(truth, str | os.PathLike | dict)):
            raise TypeError("truth must be the AIS file's path or a dict of truth.* options, "
                            f"got {type(truth).__name__}")
        nested = _nested(options, groups)
        truth = _with_dotted_truth(truth, nested.pop("truth", None))
        own = truth.get("own_mmsi") if isinstance(truth, dict) else None
        if own is not None:
            raise TypeError(f"truth.own_mmsi={own} takes own-ship from the AIS for a log file "
                            "(tma.read_log(path, truth=...)); a frame gives its own-ship in "
                            "its columns or navigation=")
        settings, reading = _split(nested)
        read = read_frames(bearings, navigation, family=_recorded(), options=reading,
                           **settings)
        return cls(with_truth(read, truth, read.sources["input"]["path"]))

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
        origin ``lat_deg``/``lon_deg``; a log of several platforms says whose position each
        is (``platform``)."""
        from tma.maths.geo import local_to_geodetic

        frames = []
        for k, lg in enumerate(self.logs):
            frame = {"log": k, **self._times(lg.t_s), "x_m": lg.own_x_m, "y_m": lg.own_y_m}
            if lg.platforms is not None:
                frame["platform"] = np.asarray(lg.platforms, dtype=object)[lg.platform]
            if lg.origin_deg is not None:
                frame["lat_deg"], frame["lon_deg"] = local_to_geodetic(lg.own_x_m, lg.own_y_m,
                                                                       lg.origin_deg)
            frames.append(pd.DataFrame(frame))
        return pd.concat(frames, ignore_index=True)

    @property
    def bearings(self) -> pd.DataFrame:
        """One row per bearing: ``log``, ``t_s``, ``time_utc``, ``track_id``, ``label`` (the
        contact as written) and ``bearing_deg`` (clockwise from north); with several
        platforms the one that took it (``platform``)."""
        frames = []
        for k, lg in enumerate(self.logs):
            row, col = np.nonzero(np.isfinite(lg.bearing_deg))
            labels = (lg.track_label if lg.track_label is not None
                      else lg.track_id.astype(str))
            frame = {"log": k, **self._times(lg.t_s[col]), "track_id": lg.track_id[row],
                     "label": np.asarray(labels, dtype=object)[row],
                     "bearing_deg": lg.bearing_deg[row, col]}
            if lg.platforms is not None:
                frame["platform"] = np.asarray(lg.platforms, dtype=object)[lg.platform[col]]
            frames.append(pd.DataFrame(frame))
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
    truth = _with_dotted_truth(truth, options.pop("truth", None))
    return Recording(read(path, family=_recorded(), fmt=format, navigation=navigation,
                          options=options, sigma_deg=sigma_deg, min_bearings=min_bearings,
                          truth=truth))


def _with_dotted_truth(truth, dotted: dict | None):
    """The ``truth`` argument with the ``truth.*`` options given dotted in ``options``
    (``{"truth.max_gap_s": 700}``), as the command line takes them beside ``truth=FILE``."""
    if dotted is None:
        return truth
    if not isinstance(dotted, dict):  # options={"truth": "ais.csv"}: the file
        dotted = {"file": dotted}
    if truth is None:
        return dotted
    node = dict(truth) if isinstance(truth, dict) else {"file": truth}
    for key, value in dotted.items():
        if isinstance(value, dict) and isinstance(node.get(key), dict):
            node[key] = {**node[key], **value}
        else:
            node[key] = value
    return node
