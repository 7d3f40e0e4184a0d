"""The ingest stage: an externally recorded bearing log -> a ``bearings2d`` dataset.

Inputs:

- CSV with columns ``time_s, own_x_m, own_y_m, bearing_deg`` and optionally ``track_id``
  (x east, y north, metres; bearing in degrees clockwise from north; one row per bearing).
- MCAP in tma's own schema (topics ``/ownship/navigation`` and ``/sonar/bearings``).

Times are shifted so the dataset starts at t = 0 (the origin is kept in the manifest).
Tracks that share one own-ship (same own-ship position at every common time) go into one
shard; otherwise each track gets its own shard. Bad input raises ``InputError`` naming the
file, the line or time, and what is wrong; nothing is written then. The dataset name is a
plain name; the dataset is built beside its final place and swapped in only when complete,
so a failed ingest (even with ``force=true``) leaves an existing dataset byte-identical.
"""

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from tma.errors import ConfigError, InputError
from tma.families.bearings2d.log import BearingsLog, read_bearings_log, write_bearings_log
from tma.io.atomic import sha256_file
from tma.io.dataset import MANIFEST, datasets_dir, file_record, shard_relpath, write_manifest
from tma.io.owned import is_owned, locked, plain_name, recover, remove_owned, staging_dir, swap_in

log = logging.getLogger(__name__)
CSV_COLUMNS = ("time_s", "own_x_m", "own_y_m", "bearing_deg")
OWN_SHIP_ATOL_M = 1e-6
MAX_SPAN_S = 9.2e9  # MCAP log times are nanoseconds in 64 bits: about 292 years
MAX_TRACK_ID = 2**53  # integers beyond this are not exact in a numeric CSV column


def read_bearings_csv(path) -> list[BearingsLog]:
    """Parse and validate a bearing CSV; returns one log per own-ship."""
    path = Path(path)
    try:
        df = pd.read_csv(path, skipinitialspace=True)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a readable CSV ({exc})") from None
    df.columns = [str(c).strip() for c in df.columns]
    missing = [c for c in CSV_COLUMNS if c not in df.columns]
    if missing:
        raise InputError(f"{path}: missing column(s) {', '.join(missing)}; expected "
                         f"{', '.join(CSV_COLUMNS)} [, track_id]; found {', '.join(df.columns)}")
    if df.empty:
        raise InputError(f"{path}: no rows")
    if "track_id" not in df.columns:
        df["track_id"] = 0
    for col in (*CSV_COLUMNS, "track_id"):
        if pd.api.types.is_bool_dtype(df[col]):
            raise InputError(f"{path}: column {col} holds true/false, not numbers")
        try:
            values = pd.to_numeric(df[col], errors="coerce").astype(float)
        except (OverflowError, ValueError, TypeError) as exc:
            raise InputError(f"{path}: column {col} has values that are not numbers of a "
                             f"usable size ({exc})") from None
        bad = values.isna() | ~np.isfinite(values)
        if bad.any():
            lines = ", ".join(str(i + 2) for i in np.flatnonzero(bad)[:5])
            raise InputError(f"{path}: column {col} has missing, NaN or non-numeric values "
                             f"(line {lines})")
        df[col] = values
    ids = df["track_id"].to_numpy()
    if (ids != np.round(ids)).any() or (np.abs(ids) > MAX_TRACK_ID).any():
        line = int(np.argmax((ids != np.round(ids)) | (np.abs(ids) > MAX_TRACK_ID))) + 2
        raise InputError(f"{path}: track_id {ids[line - 2]:g} on line {line} is not an integer "
                         f"within +-2^53")
    df["track_id"] = df["track_id"].astype(np.int64)
    t = df["time_s"].to_numpy()
    if t.max() - t.min() > MAX_SPAN_S:
        far = int(np.argmax(np.abs(t - np.median(t)))) + 2
        raise InputError(f"{path}: time_s {t[far - 2]:g} on line {far} makes the log span "
                         f"{t.max() - t.min():.3g} s (at most {MAX_SPAN_S:.3g} s): "
                         "time_s must be seconds")
    b = df["bearing_deg"].to_numpy()
    if np.any(np.abs(b) > 360):
        line = int(np.argmax(np.abs(b) > 360)) + 2
        raise InputError(f"{path}: bearing_deg {b[line - 2]:g} on line {line} is outside "
                         "[-360, 360]; bearings must be in degrees")

    df["line"] = np.arange(len(df)) + 2
    for track, rows in df.groupby("track_id", sort=True):
        dt = np.diff(rows["time_s"].to_numpy())
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            kind = "duplicate" if dt[k] == 0 else "non-increasing"
            raise InputError(f"{path}: {kind} time_s for track {track} on line "
                             f"{rows['line'].iloc[k + 1]} (time_s must increase within a track)")

    own = df.groupby("time_s")[["own_x_m", "own_y_m"]]
    shared = (own.max() - own.min()).to_numpy().max()
    groups = ([df] if shared <= OWN_SHIP_ATOL_M
              else [rows for _, rows in df.groupby("track_id", sort=True)])
    return [_log_from_rows(rows) for rows in groups]


def _log_from_rows(rows: pd.DataFrame) -> BearingsLog:
    own = rows.groupby("time_s", sort=True)[["own_x_m", "own_y_m"]].first()
    t = own.index.to_numpy(dtype=float)
    track_id = np.unique(rows["track_id"].to_numpy())
    bearing = np.full((track_id.size, t.size), np.nan)
    bearing[np.searchsorted(track_id, rows["track_id"]), np.searchsorted(t, rows["time_s"])] = (
        rows["bearing_deg"].to_numpy())
    return BearingsLog(t_s=t, own_x_m=own["own_x_m"].to_numpy(), own_y_m=own["own_y_m"].to_numpy(),
                       track_id=track_id, bearing_deg=bearing)


def _check_radians(logs, path, bearing_units):
    """Convert bearings given in radians; refuse a log of unstated units whose bearings all
    lie within +-2 pi (radians read as degrees fit a far, slow target with a tiny residual:
    no statistic can tell it afterwards)."""
    if bearing_units == "rad":
        for lg in logs:
            lg.bearing_deg = np.rad2deg(lg.bearing_deg)
        return
    b = np.concatenate([lg.bearing_deg[np.isfinite(lg.bearing_deg)] for lg in logs])
    if bearing_units is None and b.size >= 10 and np.all(np.abs(b) <= 2 * np.pi):
        raise InputError(f"{path}: every bearing lies within +-2 pi ({b.min():.3g} to "
                         f"{b.max():.3g}): they look like radians. Set bearing_units=rad to "
                         "convert them, or bearing_units=deg if they really are degrees")


def _check_options(sigma_deg, min_bearings, bearing_units, force):
    if sigma_deg is not None and (isinstance(sigma_deg, bool)
                                  or not isinstance(sigma_deg, int | float)
                                  or not 0 < sigma_deg < 90):
        raise ConfigError(f"sigma_deg must be null or a number in (0, 90) degrees, "
                          f"got '{sigma_deg}'")
    if isinstance(min_bearings, bool) or not isinstance(min_bearings, int) or min_bearings < 5:
        raise ConfigError(f"min_bearings must be a whole number >= 5 (4 unknowns and one "
                          f"degree of freedom for the noise), got '{min_bearings}'")
    if bearing_units not in (None, "deg", "rad"):
        raise ConfigError(f"bearing_units must be null, deg or rad, got '{bearing_units}'")
    if not isinstance(force, bool):
        raise ConfigError(f"force must be true or false, got '{force}'")


def ingest(input_path, *, data_dir, name=None, fmt="auto", sigma_deg=None, min_bearings=5,
           bearing_units=None, force=False) -> Path:
    """Validate an external log and write it as a dataset; returns the dataset directory.
    ``bearing_units``: ``deg``, ``rad``, or None (degrees, refusing a log that looks like
    radians)."""
    if not input_path:
        raise ConfigError("ingest needs input=<path to a .csv or .mcap bearing log>")
    path = Path(str(input_path))
    name = plain_name(name if name is not None else path.stem, "name")
    if fmt == "auto":
        fmt = {".csv": "csv", ".mcap": "mcap"}.get(path.suffix.lower())
        if fmt is None:
            raise ConfigError(f"cannot tell the format of {path} from its extension: "
                              "set format=csv or format=mcap")
    if fmt not in ("csv", "mcap"):
        raise ConfigError(f"format must be auto, csv or mcap, got '{fmt}'")
    _check_options(sigma_deg, min_bearings, bearing_units, force)
    if not path.is_file():
        raise InputError(f"{path}: no such file")

    logs = read_bearings_csv(path) if fmt == "csv" else [read_bearings_log(path)]
    if any(lg.n_tracks == 0 for lg in logs):
        raise InputError(f"{path}: the log holds no bearing")
    _check_radians(logs, path, bearing_units)
    origin = min(float(lg.t_s[0]) for lg in logs)
    all_ids = np.concatenate([lg.track_id for lg in logs])
    if np.unique(all_ids).size != all_ids.size:
        raise InputError(f"{path}: a track id appears with two different own-ship paths")
    for lg in logs:
        lg.t_s = lg.t_s - origin
        if sigma_deg is not None:  # the option overrides what an MCAP log may declare
            lg.sigma_deg = float(sigma_deg)
        if lg.t_s[-1] > MAX_SPAN_S:
            raise InputError(f"{path}: the log spans {lg.t_s[-1]:.3g} s (at most "
                             f"{MAX_SPAN_S:.3g} s): times must be seconds")
        lg.validate(str(path))
        counts = np.isfinite(lg.bearing_deg).sum(axis=1)
        few = counts < min_bearings
        if np.any(few):
            raise InputError(
                f"{path}: track(s) {', '.join(map(str, lg.track_id[few][:10]))} have "
                f"{counts[few].min()} bearing(s); estimating 4 parameters (x0, y0, vx, vy) "
                f"needs at least {min_bearings}")

    root = datasets_dir(data_dir) / name
    with locked([root]):
        recover(root)
        if root.exists() and not is_owned(root):
            raise InputError(f"{root} exists and was not created by tma: choose another name=")
        if (root / MANIFEST).exists() and not force:
            raise InputError(f"dataset {root} exists: choose another name= or set force=true")
        stage = staging_dir(root, fresh=True)
        try:
            _write_dataset(stage, name, path, fmt, logs, origin, sigma_deg, min_bearings)
        except BaseException:
            remove_owned(stage)
            raise
        return swap_in(stage, root)


def _write_dataset(stage, name, path, fmt, logs, origin, sigma_deg, min_bearings):
    shards = {}
    for i, lg in enumerate(logs):
        rel = shard_relpath(i)
        n_msg = write_bearings_log(stage / rel, lg, {"tma.dataset": {"family": "bearings2d",
                                                                      "source": str(path)}})
        shards[rel] = file_record(stage / rel, messages=n_msg, tracks=int(lg.n_tracks))
    write_manifest(
        stage, family="bearings2d", source="ingest", name=name,
        config={"format": fmt, "min_bearings": min_bearings}, shards=shards, files={},
        extra={"input": {"path": str(path), "sha256": sha256_file(path)},
               "time_origin_s": origin, "sigma_deg": logs[0].sigma_deg},
    )
