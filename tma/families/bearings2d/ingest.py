"""The ingest stage: a recorded bearing log -> a ``bearings2d`` dataset (no truth).

``input=`` holds the bearings (and usually the own-ship): a CSV/TSV table, or an MCAP log
(ROS 2, Foxglove or tma's own schema); ``navigation=`` may give the own-ship from a separate
file (CSV with lat/lon or x/y, NMEA 0183 GGA/RMC, MCAP). The readers (``sources/``) return
raw fixes and bearings; ``sources.assemble`` puts them on one clock and one east-north plane
and builds one log per own-ship (see their docstrings for every rule). Times are shifted so
the dataset starts at t = 0 at its first bearing; the UTC time of t = 0, the plane's origin
(lat, lon), text track labels, the dropped bearings, the navigation gaps and every automatic
choice go into the manifest. Bad input raises ``InputError`` naming the file, line or time,
and the option that would fix it; nothing is written then. The dataset name is a plain name;
the dataset is built beside its final place and swapped in only when complete, so a failed
ingest (even with ``force=true``) leaves an existing dataset byte-identical.
"""

import logging
from pathlib import Path

import numpy as np

from tma.config import to_plain
from tma.errors import ConfigError, InputError
from tma.families.bearings2d.log import write_bearings_log
from tma.families.bearings2d.sources import read_source, source_kind
from tma.families.bearings2d.sources.assemble import assemble
from tma.families.bearings2d.sources.base import source_options
from tma.io.atomic import sha256_file
from tma.io.dataset import MANIFEST, datasets_dir, file_record, shard_relpath, write_manifest
from tma.io.owned import is_owned, locked, plain_name, recover, remove_owned, staging_dir, swap_in

log = logging.getLogger(__name__)
MAX_SPAN_S = 9.2e9  # MCAP log times are nanoseconds in 64 bits: about 292 years


def _check_options(sigma_deg, min_bearings, force):
    if sigma_deg is not None and (isinstance(sigma_deg, bool)
                                  or not isinstance(sigma_deg, int | float)
                                  or not 0 < sigma_deg < 90):
        raise ConfigError(f"sigma_deg must be null or a number in (0, 90) degrees, "
                          f"got '{sigma_deg}'")
    if isinstance(min_bearings, bool) or not isinstance(min_bearings, int) or min_bearings < 5:
        raise ConfigError(f"min_bearings must be a whole number >= 5 (4 unknowns and one "
                          f"degree of freedom for the noise), got '{min_bearings}'")
    if not isinstance(force, bool):
        raise ConfigError(f"force must be true or false, got '{force}'")


def _file(value, option) -> Path:
    if not isinstance(value, str | Path) or not str(value).strip():
        raise ConfigError(f"{option} must be a file path, got '{value}'")
    path = Path(str(value))
    if not path.is_file():
        raise InputError(f"{path}: no such file" + ("" if not path.exists() else
                                                    " (a directory)"))
    return path


def read_recordings(path: Path, fmt, navigation: Path | None, options):
    """The input's (and the navigation file's) recordings, each with own-ship and bearings."""
    kind = source_kind(path, fmt)
    if navigation is None:
        recordings = read_source(path, kind, options, navigation=True, bearings=True)
        for r in recordings:
            _require(r, path, kind)
        return recordings, kind, None
    nav_kind = source_kind(navigation, "auto", option=None)
    found = read_source(path, kind, options, navigation=False, bearings=True)
    nav = read_source(navigation, nav_kind, options, navigation=True, bearings=False)
    if len(found) != 1 or found[0].bearings is None:
        raise InputError(f"{path}: no bearings found in the input")
    if len(nav) != 1 or nav[0].navigation is None:
        raise InputError(f"{navigation}: no own-ship fixes found in the navigation file")
    rec = found[0]
    notes = [*rec.notes, *nav[0].notes]
    if rec.navigation is not None:
        notes.append(f"own-ship from navigation={navigation}; the input's own-ship "
                     f"({rec.navigation.source}) is not used")
    rec.navigation, rec.notes = nav[0].navigation, notes
    return [rec], kind, nav_kind


def _require(rec, path, kind):
    if rec.bearings is None:
        raise InputError(f"{path}: no bearings found ({kind}); name them with "
                         + ("columns.bearing=<column>" if kind == "csv" else
                            "bearing.topic=<topic> [bearing.field=<field>]"))
    if rec.navigation is None:
        raise InputError(f"{path}: no own-ship fixes found ({kind}); name them with "
                         + ("columns.lat/columns.lon or columns.x/columns.y" if kind == "csv"
                            else "ownship.topic=<topic>")
                         + ", or give them in a separate file with navigation=FILE")


def ingest(input_path, *, data_dir, name=None, fmt="auto", sigma_deg=None, min_bearings=5,
           force=False, navigation=None, options=None) -> Path:
    """Validate a recorded log and write it as a dataset; returns the dataset directory.

    ``fmt``: auto | csv | nmea | mcap (the input's kind); ``navigation``: a separate own-ship
    file or None; ``options``: ``SourceOptions`` or a config node of its groups (``columns``,
    ``bearing``, ``ownship``, ``csv``, ``time``, ``nav``, ``origin``), e.g.
    ``{"bearing": {"units": "rad"}}``."""
    if input_path is None or not str(input_path).strip():
        raise ConfigError("ingest needs input=<path to the bearing log: .csv, .tsv or .mcap>")
    _check_options(sigma_deg, min_bearings, force)
    options = source_options(options)
    if fmt not in ("auto", "csv", "nmea", "mcap"):
        raise ConfigError(f"format must be auto, csv, nmea or mcap, got '{fmt}'")
    path = Path(str(input_path))
    name = plain_name(name if name is not None else path.stem, "name")
    path = _file(input_path, "input")
    nav_path = None if navigation is None else _file(navigation, "navigation")

    recordings, kind, nav_kind = read_recordings(path, fmt, nav_path, options)
    logs, summary = assemble(recordings, options, str(path))
    for note in summary["notes"]:
        log.info("%s", note)
    dropped = summary["dropped_bearings"]
    if dropped["count"]:
        log.warning("%s: dropped %d bearing(s) (%d before, %d after the own-ship fixes): %s",
                    path, dropped["count"], dropped["before_navigation"],
                    dropped["after_navigation"], dropped["why"])
    gaps = summary["nav_gaps"]
    if gaps["count"]:
        log.warning("own-ship navigation has %d gap(s) longer than nav.max_gap_s = %g s "
                    "(longest %.3g s, the first from t = %.3f s): own-ship is interpolated "
                    "across them", gaps["count"], gaps["max_gap_s"], gaps["longest_s"],
                    gaps["gaps"][0]["from_s"])
    all_ids = np.concatenate([lg.track_id for lg in logs])
    if np.unique(all_ids).size != all_ids.size:
        raise InputError(f"{path}: a track id appears with two different own-ship paths")
    for lg in logs:
        if sigma_deg is not None:  # the option overrides what an MCAP log may declare
            lg.sigma_deg = float(sigma_deg)
        if lg.t_s[-1] > MAX_SPAN_S:
            raise InputError(f"{path}: the log spans {lg.t_s[-1]:.3g} s (at most "
                             f"{MAX_SPAN_S:.3g} s): times must be seconds")
        lg.validate(str(path))
        counts = np.isfinite(lg.bearing_deg).sum(axis=1)
        few = counts < min_bearings
        if np.any(few):
            shown = lg.track_id[few] if lg.track_label is None else lg.track_label[few]
            raise InputError(
                f"{path}: track(s) {', '.join(map(str, shown[:10]))} have "
                f"{counts[few].min()} bearing(s); estimating 4 parameters (x0, y0, vx, vy) "
                f"needs at least {min_bearings}")

    sources = {"input": {"path": str(path), "sha256": sha256_file(path), "kind": kind}}
    if nav_path is not None:
        sources["navigation"] = {"path": str(nav_path), "sha256": sha256_file(nav_path),
                                 "kind": nav_kind}
    config = {"format": fmt, "min_bearings": min_bearings, "options": to_plain(options)}
    root = datasets_dir(data_dir) / name
    with locked([root]):
        recover(root)
        if root.exists() and not is_owned(root):
            raise InputError(f"{root} exists and was not created by tma: choose another name=")
        if (root / MANIFEST).exists() and not force:
            raise InputError(f"dataset {root} exists: choose another name= or set force=true")
        stage = staging_dir(root, fresh=True)
        try:
            _write_dataset(stage, name, logs, config, sources, summary)
        except BaseException:
            remove_owned(stage)
            raise
        return swap_in(stage, root)


def _write_dataset(stage, name, logs, config, sources, summary):
    shards = {}
    for i, lg in enumerate(logs):
        rel = shard_relpath(i)
        n_msg = write_bearings_log(stage / rel, lg, {"tma.dataset": {
            "family": "bearings2d", "source": sources["input"]["path"]}})
        shards[rel] = file_record(stage / rel, messages=n_msg, tracks=int(lg.n_tracks))
    write_manifest(
        stage, family="bearings2d", source="ingest", name=name, config=config, shards=shards,
        files={}, extra={**sources, **summary, "sigma_deg": logs[0].sigma_deg},
    )
