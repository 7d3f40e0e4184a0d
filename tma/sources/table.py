"""A table's columns -> ``Recording``s: the rows of a CSV file or of a pandas DataFrame
(``tma.sources.csv_layout``: ``CsvFile``, ``Frame``, which find its layout and columns), read
alike (``read_table``).

Times are read by ``tma.utc`` (``time_column``); values in the observation's first unit, or
another when ``<role>.units``, the column's name or the units row says so; own-ship as
``x``/``y`` (metres east/north of any origin) or ``lat``/``lon`` (deg, WGS84); track ids as
written: integers (``12``) stay the ids, any other text (``T1``, ``007``, ``NA``) is a label,
never re-read as a number. Spaces around an id are padding (``a, b`` tables) unless they tell
ids apart: `` 7`` and ``7`` in one table are two contacts, as written. A DataFrame's ids are
written as Python writes them (``str``): ``7`` and ``7.0`` are two contacts. Ids alike but
written differently (`` 7`` and ``7``, ``7`` and ``7.0``, ``007`` and ``7``) are kept apart
and named in a warning (``Caution``).

Everything is vectorised over the rows (pandas' C parser, numpy sorts): a million rows take
about a second. A row with a missing or unreadable time, value, track id or own-ship position
(or a time that is not absolute among absolute ones) is left out and counted with its line
(``bad_rows=drop``), or refuses the file in one line naming the column, the line and the
option (``bad_rows=fail``); a file-wide problem (a column not found, a unit, a time zone) is
always one ``InputError``.
"""

import re

import numpy as np
import pandas as pd

from tma.errors import InputError
from tma.sources.base import Caution, Contacts, Navigation, Recording, line_places
from tma.utc import is_pattern, table_seconds, time_column

MAX_TRACK_ID = 2**53  # an id written as a larger integer is kept as text
NAMED_ALIKE = 3  # groups of alike ids named in the warning
INTEGER_ID = re.compile(r"-?(?:0|[1-9][0-9]{0,15})")  # an id written as a plain integer
SAME_FIX = {"x": 1e-6, "lat": 1e-9}  # m, deg (0.1 mm): rows at one time share one own-ship
MIDNIGHT_DROP_S = (43200.0, 86400.0)  # times that go back by this much: a midnight wrap


def read_table(table, options, *, navigation: bool, contacts: bool) -> list[Recording]:
    """The Recordings of a table: a file's (``tma.sources.csv_layout.CsvFile``: its layout)
    or a DataFrame (``Frame``); arguments as ``tma.sources.csv_table.read_csv_table``'s."""
    path = table.path
    role = options.observation.role
    cols = table.columns(navigation=navigation, contacts=contacts)
    df = table.read(cols)
    line = table.lines(len(df))
    notes = list(table.notes)
    rows, keep = options.dropped(), np.ones(len(df), dtype=bool)

    def drop(bad, reason, refusal):
        keep[:] &= rows.drop(bad & keep, reason, line_places(line), f"{path}: {refusal}")

    tcol = cols["time"]
    t_raw, fmt, t_ok, not_absolute = time_column(
        df[tcol], tcol, options.time.format, path, line, notes,
        lambda: _number_column(df, tcol, path), options.time.zone, options.time.ambiguous)
    drop(~t_ok, "time missing or unreadable",
         f"column {tcol} has missing times or values that are not "
         + ("ISO-8601 times such as 2024-05-01T10:00:00Z; set columns.time or time.format"
            if fmt in ("iso", "iso_utc") else f"times written as time.format='{fmt}'"
            if is_pattern(fmt) else "numbers"))
    unit = fmt.replace("unix_", "")
    drop(not_absolute, "time not absolute among absolute times",
         f"column {tcol} has times that are not Unix times ({unit}) like the others: times "
         "must be all Unix or all relative (time.format=s, unix_s, unix_ms, unix_us, unix_ns)"
         if fmt.startswith("unix") else
         f"column {tcol} has times before 2000 among UTC times")
    if role in cols:
        b_raw = _number_column(df, cols[role], path)
        drop(~np.isfinite(b_raw), f"{role} missing or not a number",
             f"column {cols[role]} has missing, NaN or non-numeric values")
        track_raw = _track_text(df, cols.get("track"))
        if track_raw is not None:
            drop((track_raw == "").to_numpy(), "track id missing",
                 f"column {cols['track']} has missing track ids")
    platform_raw = _track_text(df, cols.get("platform"))
    if platform_raw is not None:
        drop((platform_raw.str.strip() == "").to_numpy(), "platform missing",
             f"column {cols['platform']} has missing platform names")
    geo = "lat" in cols
    if navigation:
        p0, p1 = (_number_column(df, cols[k], path) for k in (("lat", "lon") if geo else "xy"))
        drop(~(np.isfinite(p0) & np.isfinite(p1)), "own-ship position missing or not a number",
             f"columns {', '.join(cols[k] for k in (('lat', 'lon') if geo else 'xy'))} have "
             "missing, NaN or non-numeric values")
    if not keep.any():
        raise InputError(f"{path}: no usable row: {rows.text()}")
    if not keep.all():
        line, t_raw = line[keep], t_raw[keep]
    t, epoch = table_seconds(t_raw, fmt, tcol, path, line)
    if platform_raw is not None:
        platform = platform_raw[keep].str.strip().to_numpy(dtype=object)
        if len(set(platform)) > 1:  # one recording per platform, each read as one own-ship
            return _per_platform(table, cols, options, df[keep].reset_index(drop=True), line,
                                 platform, navigation=navigation, contacts=contacts,
                                 notes=notes, dropped=rows)
        return _named(read_table(_PlatformRows(table, cols, df[keep].reset_index(drop=True),
                                               line, platform[0], False), options,
                                 navigation=navigation,
                                 contacts=contacts), platform[0], notes, rows)
    track = None
    if role in cols:
        b, stated = _values(b_raw[keep], cols[role], options, table, path, line, notes)
        track = _tracks(None if track_raw is None else track_raw[keep], len(t), notes,
                        f"{path}: {cols.get('track')}")
        several = "" if "platform" in cols or isinstance(table, _PlatformRows) else (
            "; rows of several platforms (ships, buoys, stations) at one time? name each "
            "row's platform in a column (platform, or columns.platform=<column>)")
        _check_increasing(t, track, tcol, path, line, table.id_hint or several,
                          options.time.zone, epoch)
    if not navigation:
        return [Recording(None, Contacts(t, epoch, track, b, str(path), stated), notes=notes,
                          dropped=rows)]
    pos = (p0[keep], p1[keep])
    if geo:
        _check_lat_lon(*pos, cols, path, line)
    nav_rows, consistent = _one_fix_per_time(t, pos, SAME_FIX["lat" if geo else "x"])
    if not consistent.all() and not contacts:
        row = nav_rows[int(np.flatnonzero(~consistent)[0])]
        raise InputError(f"{path}: two different own-ship positions at the time of line "
                         f"{line[row]} ({tcol}): one fix per time" + (
                             "" if isinstance(table, _PlatformRows) else
                             "; fixes of several platforms? name each row's platform in a "
                             "column (platform, or columns.platform=<column>)"))
    if not consistent.all() and getattr(table, "one_of_several", False):
        row = nav_rows[int(np.flatnonzero(~consistent)[0])]
        raise InputError(f"{path}: platform {table.name!r} has two different positions at the "
                         f"time of line {line[row]} ({tcol}): one position per platform and "
                         "time (a bad fix? leave the row out)")
    if not contacts:
        return [Recording(_navigation(t, epoch, pos, nav_rows, geo, path, line), None,
                          notes=notes, dropped=rows)]
    if consistent.all():
        return [Recording(_navigation(t, epoch, pos, nav_rows, geo, path, line),
                          Contacts(t, epoch, track, b, str(path), stated), notes=notes,
                          dropped=rows)]
    notes.append("tracks report different own-ship positions at one time: each track gets "
                 "its own own-ship (and dataset shard)")
    recordings = []
    code = _codes(track)
    order = np.argsort(code, kind="stable")
    starts = np.flatnonzero(np.r_[True, code[order][1:] != code[order][:-1]])
    for k, group in enumerate(np.split(order, starts[1:])):  # times increase (checked)
        nav = _navigation(t, epoch, pos, group, geo, path, line)
        recordings.append(Recording(nav, Contacts(t[group], epoch, track[group], b[group],
                                                  str(path), stated), notes=notes,
                                    dropped=rows if k == 0 else options.dropped()))
    return recordings


def _number_column(df, col, path) -> np.ndarray:
    """A column as float64, NaN where a cell is missing or not a number (true/false columns
    are refused: no number is meant)."""
    series = df[col]
    if pd.api.types.is_bool_dtype(series):
        raise InputError(f"{path}: column {col} holds true/false, not numbers")
    if pd.api.types.is_numeric_dtype(series):
        return series.to_numpy(dtype=float)
    try:
        return pd.to_numeric(series, errors="coerce").to_numpy(dtype=float)
    except (OverflowError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: column {col} has values that are not numbers of a "
                         f"usable size ({exc})") from None


def _values(values, col, options, table, path, line, notes):
    """The observation's ``values`` (of column ``col``) in its first unit, and whether a unit
    was stated: by ``<role>.units``, or another unit than the first by the units row or the
    column's name. A name or units row saying the first unit is what a column in another unit
    mislabelled would say too, so the family's guard still checks it."""
    observation = options.observation
    plural = observation.plural
    units, stated = options.contact.units, options.contact.units is not None
    if units is None:
        in_row = table.unit_of(col)
        by_row = next((u for u in observation.units[1:] if in_row in u.aliases), None)
        by_name = observation.unit_of_name(col)
        if by_row is not None:
            units, stated = by_row.name, True
            notes.append(f"{path.name}: {plural} in {by_row.words} (units row)")
        elif by_name is not None:
            units, stated = by_name.name, True
            notes.append(f"{path.name}: {plural} in {by_name.words} (column name {col})")
    unit = observation.unit(units or observation.units[0].name)
    observation.check_range(values, unit, f"{path}: {col}", lambda k: f" on line {line[k]}")
    return unit.to_first(values), stated


def _track_text(df, col):
    """The track ids as written (text, spaces included; empty where missing), or None
    without a track column. An id of spaces only is missing."""
    if col is None:
        return None
    text = df[col].fillna("").astype(str)
    return text.where(text.str.strip() != "", "")


def _tracks(text, n: int, notes: list, where: str) -> np.ndarray:
    """Track ids as written: int64 when every id is written as a plain integer (``12``,
    ``-3``: the ids themselves), else the texts (object array), kept as labels: ``007`` and
    ``7``, ``1e3`` and ``1000`` are different contacts, ``NA`` is a name. Spaces around the
    ids are dropped unless they tell ids apart (`` 7`` and ``7``: two contacts, kept as
    written); ids alike but written differently are noted (``_alike_ids``). No track column:
    one contact, 0."""
    if text is None:
        return np.zeros(n, dtype=np.int64)
    text = _unpadded(text)
    _alike_ids(text, notes, where)
    if text.str.fullmatch(INTEGER_ID.pattern).all():
        ids = text.astype(np.int64).to_numpy()
        if np.all(np.abs(ids) <= MAX_TRACK_ID):
            return ids
    return text.to_numpy(dtype=object)


def _unpadded(text: pd.Series) -> pd.Series:
    """The ids without the spaces around them, except the ids that only those spaces tell
    apart (`` 7`` beside ``7``), kept as written."""
    stripped = text.str.strip()
    if (stripped == text).all():
        return text
    codes, written = pd.factorize(text)
    padded_alike = pd.Series(written).str.strip().duplicated(keep=False).to_numpy()
    return stripped.where(~padded_alike[codes], text)


def _alike(text: str):
    """What two ids written differently may both mean: the number they write, else the text
    without its spaces."""
    stripped = text.strip()
    try:
        return float(stripped)
    except ValueError:
        return stripped


def _alike_ids(text: pd.Series, notes: list, where: str) -> None:
    """Note (as a warning) the ids alike but written differently (`` 7`` and ``7``, ``7``
    and ``7.0``, ``007`` and ``7``): they are kept apart, as written."""
    written = pd.unique(text)
    if len(written) < 2 or len(written) > 100_000:  # ids by the row: nothing to tell apart
        return
    groups: dict = {}
    for w in written:
        groups.setdefault(_alike(w), []).append(w)
    alike = [sorted(g) for g in groups.values() if len(g) > 1]
    if alike:
        shown = "; ".join(" and ".join(repr(w) for w in g) for g in alike[:NAMED_ALIKE])
        notes.append(Caution(
            f"{where}: {len(alike)} group(s) of contact ids alike but written differently "
            f"({shown}{' ...' if len(alike) > NAMED_ALIKE else ''}) are kept as different "
            "contacts (ids are kept as written): write each contact's id alike if they are "
            "one"))


def _codes(track: np.ndarray) -> np.ndarray:
    """Integer codes of the tracks (labels factorised: sorting numbers is faster)."""
    return pd.factorize(track)[0] if track.dtype == object else track


class _PlatformRows:
    """The rows of one platform of a table (``table``'s, already read: ``df``, their file
    lines ``lines``), as ``read_table`` reads a table: the same columns but the platform's."""

    def __init__(self, table, cols, df, lines, name: str, one_of_several: bool):
        self._table, self.notes = table, []
        self.name, self.one_of_several = name, one_of_several
        self._cols = {r: c for r, c in cols.items() if r != "platform"}
        self._df, self._lines = df, lines

    def __getattr__(self, name):  # the table's layout: path, units, id_hint
        return getattr(self._table, name)

    def columns(self, *, navigation: bool, contacts: bool) -> dict[str, str]:
        return self._cols

    def read(self, cols):
        return self._df

    def lines(self, n: int) -> np.ndarray:
        return self._lines


def _named(recordings, name, notes, dropped) -> list[Recording]:
    """A table's recordings of one platform (``name``: its platform column's one value),
    named by it where it is one own-ship; the notes and the rows left out so far go with
    the first."""
    for rec in recordings:
        rec.platform = name if len(recordings) == 1 else None
    first = recordings[0]
    first.notes = list(dict.fromkeys([*notes, *first.notes]))
    dropped.merge(first.dropped)
    first.dropped = dropped
    return recordings


def _per_platform(table, cols, options, df, line, platform, *, navigation, contacts, notes,
                  dropped) -> list[Recording]:
    """One Recording per platform named in the rows (``platform``: each row's of ``df``, the
    rows kept, ``line`` their lines), in the order they first appear (the first is the
    reference range and bearing now are read from), each read from its own rows as a table
    of one own-ship is and named by it; the rows left out so far (``dropped``) and the notes
    go with the first."""
    out = []
    for name in dict.fromkeys(platform):
        mine = platform == name
        part = _PlatformRows(table, cols, df[mine].reset_index(drop=True), line[mine], name,
                             True)
        out += _named(read_table(part, options, navigation=navigation, contacts=contacts),
                      name, [] if out else notes, options.dropped() if out else dropped)
    return out


def _check_increasing(t, track, col, path, line, hint="", zone=None, epoch_ns=None):
    """Times must increase strictly within each track, in file order. ``zone``, ``epoch_ns``:
    the local times' zone and the times' epoch, to tell a log that crosses the
    daylight-saving change back."""
    code = _codes(track)
    order = np.argsort(code, kind="stable")
    ts, tr = t[order], code[order]
    bad = (tr[1:] == tr[:-1]) & (np.diff(ts) <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        kind = "duplicate" if ts[k + 1] == ts[k] else "non-increasing"
        back = _clocks_back(ts[k], ts[k + 1], zone, epoch_ns) or _midnight(ts[k], ts[k + 1])
        raise InputError(f"{path}: {kind} {col} for track {track[order[k + 1]]} on line "
                         f"{line[order[k + 1]]} ({col} must increase within a track)"
                         f"{back or hint}")


def _midnight(before_s, after_s) -> str:
    """What to say when times go back by half a day to a day (a clock of the time of day,
    seconds of the day or hh:mm:ss without a date, wrapping at midnight); else ""."""
    drop = before_s - after_s
    if not MIDNIGHT_DROP_S[0] <= drop <= MIDNIGHT_DROP_S[1]:
        return ""
    return (f"; the times go back by {drop / 3600:.1f} h there: a clock of the time of day "
            "wraps at midnight, and the times carry no date to tell the days apart. Write "
            "each time with its date (2024-05-01T23:59:50Z, or a time.format pattern with "
            "%Y-%m-%d), or cut the log at midnight")


def _clocks_back(before_s, after_s, zone, epoch_ns) -> str:
    """What to say when local times (``zone``) go back by up to an hour into a time of day
    the daylight-saving change back repeats: the log crosses the change, and no
    ``time.ambiguous`` reads it (it reads every repeated time as one instant); else ""."""
    from datetime import UTC, datetime
    from zoneinfo import ZoneInfo

    if zone is None or epoch_ns is None or not -3600 <= after_s - before_s < 0:
        return ""
    at = datetime.fromtimestamp(epoch_ns / 1e9 + after_s, UTC).astimezone(ZoneInfo(zone))
    local = at.replace(tzinfo=None)
    offsets = {local.replace(fold=f, tzinfo=ZoneInfo(zone)).utcoffset() for f in (0, 1)}
    if len(offsets) < 2:
        return ""
    return (f": the log crosses the daylight-saving change back in {zone} (its times go "
            f"back to {local:%H:%M:%S}, a time of day that happened twice), so its local times "
            "are ambiguous and no time.ambiguous reads both sides of the change; give its "
            "times in UTC or with their offset (e.g. +02:00 before, +01:00 after)")


def _check_lat_lon(lat, lon, cols, path, line):
    for values, name, limit in ((lat, cols["lat"], 90), (lon, cols["lon"], 360)):
        outside = (values < -limit) | (values > limit) if limit == 90 else \
            (values < -180) | (values > 360)
        if outside.any():
            k = int(np.argmax(outside))
            raise InputError(f"{path}: {name} {values[k]:g} on line {line[k]} is not a "
                             f"{'latitude' if limit == 90 else 'longitude'} in degrees; are "
                             "columns.lat and columns.lon right?")


def _one_fix_per_time(t, pos, tolerance):
    """Rows of the first occurrence of each distinct time (sorted by time), and per distinct
    time whether every row there gives the same own-ship position (within ``tolerance``)."""
    order = np.argsort(t, kind="stable")
    ts = t[order]
    starts = np.flatnonzero(np.r_[True, ts[1:] != ts[:-1]])
    same = np.ones(starts.size, dtype=bool)
    for values in pos:
        v = values[order]
        same &= np.maximum.reduceat(v, starts) - np.minimum.reduceat(v, starts) <= tolerance
    return order[starts], same


def _navigation(t, epoch, pos, rows, geo, path, line) -> Navigation:
    """Own-ship fixes of ``rows`` (their times distinct), sorted by time."""
    rows = rows[np.argsort(t[rows], kind="stable")]
    a, b = pos[0][rows], pos[1][rows]
    if geo:
        return Navigation(t[rows], epoch, str(path), lat_deg=a, lon_deg=b, lines=line[rows])
    return Navigation(t[rows], epoch, str(path), x_m=a, y_m=b, lines=line[rows])
