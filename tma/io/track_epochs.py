"""Values that arrive one by one (a time or a message, a contact, a value) put on the
track x epoch arrays every family's log holds in memory: one row per track, one column per epoch,
NaN where a track has no value at an epoch. Written once, for the MCAP log readers (messages:
``bearings2d``, ``radar2d``, ``ranges2d``) and for ingest (a recorded log's rows: ``bearings2d``
``ingest.py``); a track with two values at one epoch is refused here, naming it and the time.
"""

import numpy as np

from tma.errors import InputError


def epochs(t: np.ndarray, platform: np.ndarray | None = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t_s, col, first)`` of the times ``t`` of the values: the epochs (the distinct times,
    increasing), each value's epoch, and each epoch's first value (in the values' order:
    where a row of a table, say, gives the own-ship of its epoch). ``platform``: each value's
    platform (ints) of a log of several: an epoch per distinct (time, platform), ordered by
    time then platform."""
    t = np.asarray(t)
    if platform is None:
        order = np.argsort(t, kind="stable")
        new = np.r_[True, t[order][1:] != t[order][:-1]]
    else:
        order = np.lexsort((platform, t))
        new = np.r_[True, (t[order][1:] != t[order][:-1])
                    | (platform[order][1:] != platform[order][:-1])]
    col = np.empty(t.size, dtype=np.int64)
    col[order] = np.cumsum(new) - 1
    first = order[new]
    return t[first], col, first


def scatter(track: np.ndarray, col: np.ndarray, values: np.ndarray, n_epochs: int, where: str,
            what: str, epoch_time, track_id: np.ndarray | None = None):
    """``(track_id, array)``: ``values`` (one per entry of ``track``, the track ids, and of
    ``col``, their epochs; a value may be a vector: ``values`` shaped ``(n, ...)``) on the
    array ``(tracks, n_epochs, ...)``, NaN where a track has no value at an epoch. Its rows are
    ``track_id`` (sorted; holding every id of ``track``), by default the distinct ids. A track
    with two values at one epoch is an InputError naming it and the time there
    (``epoch_time(k)``: of epoch k, in s) as ``<where>: track <id> has two <what> at one time
    (t = ... s)``."""
    track, col, values = np.asarray(track), np.asarray(col), np.asarray(values)
    track_id = np.unique(track) if track_id is None else track_id
    row = np.searchsorted(track_id, track)
    cell = row * n_epochs + col
    unique, once = np.unique(cell, return_index=True)
    if unique.size != cell.size:
        twice = np.setdiff1d(np.arange(cell.size), once)
        k = int(twice[np.argmin(cell[twice])])  # the first in (track, epoch) order
        raise InputError(f"{where}: track {track[k]} has two {what} at one time "
                         f"(t = {epoch_time(int(col[k])):.9g} s)")
    array = np.full((track_id.size, n_epochs, *values.shape[1:]), np.nan)
    array[row, col] = values
    return track_id, array
