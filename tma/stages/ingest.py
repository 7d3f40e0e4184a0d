"""The ingest stage: a recorded log -> a dataset of a family (no truth; with ``truth=FILE``
the truth of its contacts from the AIS of its trial, ``tma.ais.truth``).

``input=`` holds the contacts (and usually the own-ship): a CSV/TSV table, or an MCAP log
(ROS 2, Foxglove or tma's own schema); ``navigation=`` may give the own-ship from a separate
file (CSV with lat/lon or x/y, NMEA 0183 GGA/RMC, MCAP). The readers (``tma.sources``) return
raw fixes and values, read as the family's observation asks (its ``ingest`` module:
``OBSERVATION``); ``tma.sources.align`` puts them on one clock and one east-north plane, and
the family makes its logs (``logs``), which its scenario module writes. Times are shifted so
the dataset starts at t = 0 at its first value; the UTC time of t = 0, the plane's origin
(lat, lon), text track labels, the dropped values, the navigation gaps and every automatic
choice go into the manifest. Bad rows (``bad_rows=drop``: a missing or unreadable value, time
or fix, an outlier fix) are left out, counted per reason in a log line and the manifest
(``bad_rows``), and a contact left with too few values is skipped (the family says how
many); under ``bad_rows=fail``, and for any other bad input, ``InputError`` names the file,
line or time, and the option that would fix it; nothing is written then. The dataset name
is a plain name; the dataset is built beside its final place and swapped in only when
complete, so a failed ingest (even with ``force=true``) leaves an existing dataset byte-identical.
"""

import dataclasses
import logging
import os
from dataclasses import dataclass, fields
from pathlib import Path

from tma.config import to_plain
from tma.errors import ConfigError, ConfigTypeError, InputError, MissingFileError, TmaError
from tma.families import family as family_named
from tma.io.atomic import sha256_file
from tma.io.dataset import MANIFEST, datasets_dir, file_record, shard_relpath, write_manifest
from tma.io.owned import building, is_owned, plain_name
from tma.sources import read_source, reader, source_kind
from tma.sources.align import align
from tma.sources.base import Caution
from tma.sources.labels import name_room
from tma.sources.options import groups, inapplicable, source_options, unknown_option

log = logging.getLogger(__name__)


def option_groups(family: str) -> tuple[str, ...]:
    """The reading option groups of the ingest config for ``family`` (``columns``,
    ``bearing``, ``ownship``, ``csv``, ``time``, ``nav``, ``origin``)."""
    return groups(family_named(family).ingest.OBSERVATION)


def setting_names(family: str) -> tuple[str, ...]:
    """The family's own ingest settings (``bearings2d``: ``sigma_deg``, ``min_bearings``)."""
    return tuple(f.name for f in fields(family_named(family).ingest.Settings))


def unknown_option_of(key: str, family: str) -> str | None:
    """A one-line complaint if the dotted ``key`` is under a reading group of ``family`` but
    is not an option (``columns.foo``); None otherwise."""
    return unknown_option(key, family_named(family).ingest.OBSERVATION)


def _several(navigation) -> bool:
    """Whether ``navigation`` names several files (a list: one per platform)."""
    return isinstance(navigation, list | tuple) or type(navigation).__name__ == "ListConfig"


def _file(value, option) -> Path:
    """The path of an input file: a regular file (a pipe or a device cannot be read twice, as
    the readers do); MissingFileError when there is none, ConfigTypeError for a value that is
    no path (a DataFrame: ``tma.Recording.from_frames`` reads those)."""
    if not isinstance(value, str | os.PathLike):
        frames = (" (DataFrames are read by tma.Recording.from_frames(bearings, navigation))"
                  if hasattr(value, "columns") else "")
        raise ConfigTypeError(f"{option} must be a file path (str or pathlib.Path), got "
                              f"{type(value).__name__}{frames}")
    if not str(value).strip():
        raise ConfigError(f"{option} must be a file path, got '{value}'")
    path = Path(value)
    if not path.exists():
        raise MissingFileError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: a directory, not a log file; give {option}=<the log's path>")
    if not path.is_file():
        kind = next((name for test, name in ((path.is_char_device, "a character device"),
                                             (path.is_block_device, "a block device"),
                                             (path.is_fifo, "a pipe"),
                                             (path.is_socket, "a socket")) if test()),
                    "not a file")
        raise InputError(f"{path}: not a regular file ({kind}), which tma cannot read twice "
                         f"as its readers do; write the log to a file and give its path")
    return path


def read_recordings(path: Path, fmt, navigation, options, own=None):
    """The input's (and the navigation file's) recordings, each with own-ship and contacts.
    ``navigation``: None, a file, or a list of them, one per platform (each the platform its
    stem names, unless the file names its own in a platform column), matched to the input's
    platforms by name. An option set that no file's kind reads is refused (``bearing.topic``
    on a CSV). ``own``: the truth options when own-ship comes from the AIS
    (``truth.own_mmsi``, ``tma.ais.ownship``). Returns ``(recordings, kind, navigation's
    kind or kinds)``."""
    per_platform = isinstance(navigation, list)
    navs = navigation if per_platform else [] if navigation is None else [navigation]
    kind = source_kind(path, fmt)
    kinds = {path: kind, **{p: source_kind(p, "auto", option=None) for p in navs}}
    complaint = inapplicable(options, kinds)
    if complaint:
        raise ConfigError(complaint)
    if own is not None:
        from tma.ais.ownship import ownship_recording, source_text

        if navs:
            raise ConfigError(f"own-ship comes from navigation={navigation} or from "
                              f"truth.own_mmsi={own.own_mmsi}, not both: give one")
        found = _without_own_ship(path, kind, options, own.own_mmsi)
        nav = [ownship_recording(own, options, found, str(path))]
        return _with_navigation(found, nav, path, source_text(own), options), kind, "ais"
    if not navs:
        recordings = read_source(path, kind, options, navigation=True, contacts=True)
        for r in recordings:
            _require(r, path, kind, options)
        return recordings, kind, None
    found = read_source(path, kind, options, navigation=False, contacts=True)
    nav = []
    for p in navs:
        recs = read_source(p, kinds[p], options, navigation=True, contacts=False,
                           date_hint_ns=_first_utc_ns(found))
        if per_platform and len(recs) == 1 and recs[0].platform is None:
            recs[0].platform = p.stem
        nav += recs
    where = ", ".join(str(p) for p in navs)
    if per_platform and len(found) == 1 and found[0].platform is None:
        raise InputError(f"{path}: one own-ship file per platform (navigation={where}), but "
                         "the input names no platform per row: give it a platform column "
                         "(columns.platform=<column>) whose names are the files' stems")
    nav_kinds = [kinds[p] for p in navs]
    return (_with_navigation(found, nav, path, where, options), kind,
            nav_kinds if per_platform else nav_kinds[0])


def _without_own_ship(path, kind, options, own_mmsi):
    """The log's contacts for own-ship from the AIS (``truth.own_mmsi``), read once: where
    the log has own-ship positions of its own (found, not named: named ones are refused,
    ``ownship``), they are left aside, and a warning says so."""
    try:
        found = read_source(path, kind, options, navigation=True, contacts=True)
    except (TmaError, ValueError):  # no own-ship the reader can find: the contacts alone
        return read_source(path, kind, options, navigation=False, contacts=True)
    if any(r.navigation is not None for r in found):
        log.warning("%s: own-ship from its AIS (truth.own_mmsi=%d); the log's own-ship "
                    "positions are left aside (drop truth.own_mmsi to use them)", path,
                    own_mmsi)
    return [dataclasses.replace(r, navigation=None) for r in found]


def _with_navigation(found, nav, where, nav_where, options):
    """The input's recordings with their own-ship from the navigation file's: its one
    recording, or, where both name platforms (a platform column), each platform's with that
    platform's fixes."""
    if len(found) > 1 or len(nav) > 1 or (found and nav and all(r.platform is not None
                                                                for r in found + nav)):
        # (named on both sides, even one each: matched by name, never by count)
        return _per_platform_navigation(found, nav, where, nav_where, options)
    if len(found) != 1 or found[0].contacts is None:
        raise InputError(f"{where}: no {options.observation.plural} found in the input")
    if len(nav) != 1 or nav[0].navigation is None:
        raise InputError(f"{nav_where}: no own-ship fixes found in the navigation file")
    rec = found[0]
    notes = [*rec.notes, *nav[0].notes]
    rec.dropped.merge(nav[0].dropped)
    if rec.navigation is not None:
        notes.append(f"own-ship from navigation={nav_where}; the input's own-ship "
                     f"({rec.navigation.source}) is not used")
    rec.navigation, rec.notes = nav[0].navigation, notes
    return [rec]


def _per_platform_navigation(found, nav, where, nav_where, options):
    """Each platform's recording of the input with its fixes from the navigation file, the
    two matched by the platform names (``columns.platform``) of both."""
    plural = options.observation.plural
    unnamed = [w for w, recs in ((where, found), (nav_where, nav))
               if any(r.platform is None for r in recs)]
    if unnamed:
        raise InputError(f"{unnamed[0]}: the {plural} and the own-ship fixes come from several "
                         "platforms, but this file names no platform per row: give both files "
                         "a platform column (columns.platform=<column>) naming the platform "
                         "(ship, buoy, station) of each row")
    fixes = {}
    for r in nav:
        if r.platform in fixes:
            raise InputError(f"{nav_where}: platform {r.platform!r} is named by two navigation "
                             f"sources ({fixes[r.platform].navigation.source} and "
                             f"{r.navigation.source}): give each platform's fixes once")
        fixes[r.platform] = r
    missing = [r.platform for r in found if r.platform not in fixes]
    if missing:
        raise InputError(f"{nav_where}: no own-ship fixes of platform(s) "
                         f"{', '.join(map(repr, missing))} whose {plural} {where} holds "
                         f"(its platforms: {', '.join(map(repr, fixes))}): name each platform's "
                         "file after it (<platform>.csv) or give it a platform column "
                         "(columns.platform=<column>)")
    for rec in found:
        own = fixes[rec.platform]
        rec.dropped.merge(own.dropped)
        rec.notes = list(dict.fromkeys([*rec.notes, *own.notes]))
        rec.navigation = own.navigation
    return found


def _first_utc_ns(recordings) -> int | None:
    """UTC ns of the first contact value, when the contacts have absolute times."""
    times = [r.contacts.epoch_utc_ns + int(round(r.contacts.t_s.min() * 1e9))
             for r in recordings if r.contacts is not None and r.contacts.t_s.size
             and r.contacts.epoch_utc_ns is not None]
    return min(times, default=None)


def _require(rec, path, kind, options):
    """The recording holds contacts and own-ship, else a message naming the options of its
    kind that select them (``Reader.selects_contacts``, ``selects_navigation``)."""
    role, declared = options.observation.role, reader(kind)
    plural = options.observation.plural
    if rec.contacts is None:
        raise InputError(f"{path}: no {plural} found ({kind}); " + (
            f"name them with {declared.selects_contacts.format(role=role)}"
            if declared.selects_contacts else
            f"{declared.name} holds none that tma reads: give the {plural} in a log of "
            "another kind, and this file as navigation=FILE"))
    if rec.navigation is None:
        raise InputError(f"{path}: no own-ship fixes found ({kind}); " + (
            f"name them with {declared.selects_navigation.format(role=role)}, or give them "
            if declared.selects_navigation else "give them ") +
            "in a separate file with navigation=FILE")


@dataclass
class Read:
    """A recorded log read into a family's logs (``logs``: one per own-ship), before it is
    stored: the reading ``config`` and ``sources`` the manifest records, and the ``summary``
    of what was found, noted, dropped and skipped."""

    family: str
    logs: list
    config: dict
    sources: dict
    summary: dict
    truth: object = None  # tma.ais.truth.LogTruth when the log is scored against AIS


def read_log(input_path, *, family: str, fmt="auto", navigation=None, options=None,
             truth=None, **settings) -> Read:
    """Read and check a recorded log as ``ingest`` does, without storing it: ``fmt``: auto |
    csv | nmea | mcap (the input's kind); ``navigation``: a separate own-ship file or None;
    ``options``: the family's reading options or a config node of their groups
    (``columns``, ``bearing``, ``ownship``, ``csv``, ``time``, ``nav``, ``origin``), e.g.
    ``{"bearing": {"units": "rad"}}``; ``settings``: the family's own (``bearings2d``:
    ``sigma_deg``, ``min_bearings``); ``truth``: the AIS of the trial (a path, or the
    ``truth.*`` options: ``tma.ais.options``), the truth of its contacts (``tma.ais.truth``)."""
    reader = family_named(family).ingest
    if input_path is None or not str(input_path).strip():
        raise ConfigError(f"ingest needs input=<path to the {reader.OBSERVATION.role} log: "
                          ".csv, .tsv or .mcap>")
    settings = reader.Settings(**settings)
    options = source_options(options, reader.OBSERVATION)
    from tma.ais.options import truth_options

    truth = truth_options(truth)
    path = _file(input_path, "input")
    own = truth if truth.own_mmsi is not None else None
    if _several(navigation):  # one file per platform
        if not len(navigation):
            raise ConfigError("navigation=[] names no file: give the own-ship file, or one per "
                              "platform (navigation=[ship_a.csv,buoy_7.csv])")
        navigation = [_file(p, "navigation") for p in navigation]
    elif navigation is not None:
        navigation = _file(navigation, "navigation")
    recordings, kind, nav_kind = read_recordings(path, fmt, navigation, options, own)
    sources = {"input": {"path": str(path), "sha256": sha256_file(path), "kind": kind}}
    if isinstance(navigation, list):
        sources["navigation"] = [{"path": str(p), "sha256": sha256_file(p), "kind": k}
                                 for p, k in zip(navigation, nav_kind, strict=True)]
    elif navigation is not None:
        sources["navigation"] = {"path": str(navigation), "sha256": sha256_file(navigation),
                                 "kind": nav_kind}
    elif own is not None:  # own-ship from the AIS of the trial (tma.ais.ownship)
        sources["navigation"] = {"path": str(own.file), "sha256": sha256_file(own.file),
                                 "kind": "ais", "mmsi": own.own_mmsi}
    return with_truth(_read(family, recordings, options, settings, {"format": fmt}, sources,
                            str(path)), truth, str(path))


def with_truth(read: Read, truth, where: str) -> Read:
    """``read`` with the truth of its contacts from the AIS ``truth`` names (none: as it
    is); the truth options go into its config, the file into its sources."""
    from tma.ais.options import truth_options

    options = truth_options(truth)
    if options.file is None:
        return read
    from tma.ais.truth import log_truth

    lg = read.logs[0]
    read.truth = log_truth(family_named(read.family).ingest.contacts(read.logs), lg.origin_deg,
                           lg.epoch_utc_ns, options, where)
    read.config["truth"] = options.record()
    read.sources["truth"] = read.truth.record
    return read


def read_frames(bearings, navigation=None, *, family: str, options=None, **settings) -> Read:
    """``read_log`` of pandas DataFrames: ``bearings`` (time, the observation and, unless
    ``navigation`` gives them, own-ship fixes: the columns a CSV table would have), read by
    the CSV reader (``tma.sources.csv_table.read_frame``)."""
    from tma.sources.csv_table import read_frame

    reader = family_named(family).ingest
    settings = reader.Settings(**settings)
    options = source_options(options, reader.OBSERVATION)
    complaint = inapplicable(options, {"frame": "csv"})
    if complaint:
        raise ConfigError(complaint)
    name = f"{reader.OBSERVATION.plural} frame"
    if navigation is None:
        recordings = read_frame(bearings, name, options, navigation=True, contacts=True)
        for r in recordings:
            _require(r, name, "csv", options)
    else:
        found = read_frame(bearings, name, options, navigation=False, contacts=True)
        nav = read_frame(navigation, "navigation frame", options, navigation=True,
                         contacts=False)
        recordings = _with_navigation(found, nav, name, "navigation frame", options)
    return _read(family, recordings, options, settings, {"format": "frame"},
                 {"input": {"path": name, "kind": "frame"}}, name)


def _read(family, recordings, options, settings, config, sources, where) -> Read:
    """Align ``recordings``, make the family's logs, log what was noted and dropped."""
    reader = family_named(family).ingest
    aligned = align(recordings, options, where)
    summary = aligned.summary
    for note in summary["notes"]:
        log.log(logging.WARNING if isinstance(note, Caution) else logging.INFO, "%s", note)
    dropped = summary[f"dropped_{options.observation.plural}"]
    if dropped["count"]:
        log.warning("%s: dropped %d %s(s) (%d before, %d after the own-ship fixes, %d in "
                    "gaps between them): %s", where, dropped["count"],
                    options.observation.role, dropped["before_navigation"],
                    dropped["after_navigation"], dropped["in_navigation_gaps"],
                    dropped["why"])
    if aligned.epoch_utc_ns is None and aligned.origin_deg is not None:
        log.warning("%s: relative times: the outputs give no UTC and no map MCAP is written (it "
                    "would be dated 1970); give time.start_utc=<ISO-8601 UTC of the log's time "
                    "0> to date them", where)
    gaps = summary["nav_gaps"]
    if gaps["count"]:
        log.warning("own-ship navigation has %d gap(s) longer than nav.max_gap_s = %g s "
                    "(longest %.3g s, the first from t = %.3f s): own-ship is interpolated "
                    "across them", gaps["count"], gaps["max_gap_s"], gaps["longest_s"],
                    gaps["gaps"][0]["from_s"])
    logs, family_config, extra = reader.logs(aligned, settings, where)
    bad = aligned.dropped
    if bad.count:
        log.warning("%s: left out %d bad row(s) (bad_rows=%s): %s", where, bad.count,
                    bad.policy, bad.text())
    summary["bad_rows"] = bad.record()
    config = {**config, **family_config, "options": to_plain(options)}
    return Read(family, logs, config, sources, {**summary, **extra})


def ingest(input_path, *, data_dir, family: str, name=None, fmt="auto", force=False,
           navigation=None, options=None, truth=None, **settings) -> Path:
    """Validate a recorded log and write it as a dataset of ``family`` (``read_log``, whose
    arguments these are); returns the dataset directory."""
    if not isinstance(force, bool):
        raise ConfigError(f"force must be true or false, got '{force}'")
    if input_path is not None and str(input_path).strip():
        name = plain_name(name if name is not None else Path(str(input_path)).stem, "name")
        room = name_room(family_named(family).estimators)
        if len(name.encode()) > room:
            raise ConfigError(f"name={name[:40]}... is too long: its tables are named "
                              "<name>-<estimator>-<contact>.png and must fit a file name; "
                              f"give name= of at most {room} characters")
    read = read_log(input_path, family=family, fmt=fmt, navigation=navigation,
                    options=options, truth=truth, **settings)
    root = datasets_dir(data_dir) / name
    with building([root], resume=False) as outputs:  # a failure leaves nothing behind
        if root.exists() and not is_owned(root):
            raise InputError(f"{root} exists and was not created by tma: choose another name=")
        if (root / MANIFEST).exists() and not force:
            raise InputError(f"dataset {root} exists: choose another name= or set force=true")
        _write_dataset(outputs.stage(root, fresh=True), family, name, read.logs, read.config,
                       read.sources, read.summary, read.truth)
        return outputs.swap(root)


def _write_dataset(stage, family, name, logs, config, sources, extra, truth=None):
    write_log = family_named(family).scenario.write_log
    shards, files = {}, {}
    if truth is not None:  # the AIS truth of its contacts (tma.ais.truth)
        from tma.ais.truth import TRUTH, TRUTH_TRACK
        from tma.io import arrow
        from tma.io.atomic import write_parquet_atomic

        for rel, frame in ((TRUTH, truth.truth), (TRUTH_TRACK, truth.track)):
            write_parquet_atomic(stage / rel, arrow.table(
                {c: frame[c].to_numpy() for c in frame.columns}))
            files[rel] = file_record(stage / rel, rows=len(frame))
    for i, lg in enumerate(logs):
        rel = shard_relpath(i)
        n_msg = write_log(stage / rel, lg, {"tma.dataset": {
            "family": family, "source": sources["input"]["path"]}})
        shards[rel] = file_record(stage / rel, messages=n_msg, tracks=int(lg.n_tracks))
    write_manifest(stage, family=family, source="ingest", name=name, config=config,
                   shards=shards, files=files, extra={**sources, **extra})
