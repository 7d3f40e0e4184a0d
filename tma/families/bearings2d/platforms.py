"""Several platforms (ships, buoys, shore stations) taking one contact's bearings.

A log of several platforms (``BearingsLog.platform``) holds, at each epoch, the position of
the platform that took its bearings: the estimators' model (a bearing from the observer at
its own epoch) is then the same, and the lines of sight of two platforms cross where one
platform would have to manoeuvre. What differs is where the answer is read from: range and
bearing *now* are given from one platform, the reference (``reference_platform``; default
the first), at each track's last bearing time, wherever the platform that took that bearing
was. Its position then is interpolated (linearly, the end segments extended) between its own
epochs; a platform at one place throughout (a buoy, a station) stays there.
"""

import numpy as np

from tma.errors import ConfigError


def reference_index(names: tuple[str, ...] | None, reference: str | None, where: str) -> int:
    """The index of the reference platform named ``reference`` (None: the first)."""
    if reference is None:
        return 0
    if names is None:
        raise ConfigError(f"{where}: reference_platform={reference} names a platform, but the "
                          "log has one own-ship; leave reference_platform unset")
    if reference not in names:
        raise ConfigError(f"{where}: reference_platform={reference} is no platform of the "
                          f"log; its platforms are {', '.join(names)}")
    return names.index(reference)


def position_at(t_s, own_x_m, own_y_m, platform, k: int, times_s):
    """Platform ``k``'s position (x, y in m) at ``times_s`` (s), from its own epochs of the
    log (``t_s``, ``own_x_m``, ``own_y_m``, ``platform``): linear between them, the end
    segments extended; a platform with a single epoch stays where it was. Arrays of
    ``times_s``' shape (a scalar time: of one)."""
    mine = np.flatnonzero(platform == k)
    if mine.size == 0:
        raise ValueError(f"platform {k} took no bearing in the log: it has no position")
    t, x, y = t_s[mine], own_x_m[mine], own_y_m[mine]
    times = np.atleast_1d(np.asarray(times_s, dtype=float))
    if t.size == 1 or t[-1] == t[0]:
        return np.full(times.shape, x[0]), np.full(times.shape, y[0])
    out = []
    for v in (x, y):
        p = np.interp(times, t, v)
        for end, (a, b) in ((times < t[0], (0, 1)), (times > t[-1], (-2, -1))):
            if end.any():
                slope = (v[b] - v[a]) / (t[b] - t[a]) if t[b] > t[a] else 0.0
                p[end] = v[0 if a == 0 else -1] + (times[end] - t[0 if a == 0 else -1]) * slope
        out.append(p)
    return out[0], out[1]


def observer_now(t_s, own_x_m, own_y_m, platform, reference: int, last):
    """Where range and bearing now are read from, per track (``last``: each track's last
    bearing): own-ship there (a log of one platform: ``platform`` None), else the
    reference platform at that time."""
    if platform is None:
        return own_x_m[last], own_y_m[last]
    return position_at(t_s, own_x_m, own_y_m, platform, reference, t_s[last])


def platforms_seen(platform, valid, names) -> list[str]:
    """Per track (rows of ``valid``, n x K; None: every bearing present) the names of the
    platforms that took its bearings, joined by ``+``."""
    n = valid.shape[0] if valid is not None else 0
    if platform is None:
        return [names[0] if names else ""] * n
    took = np.stack([(valid & (platform == k)[None, :]).any(axis=1)
                     for k in range(len(names))], axis=1)
    return ["+".join(nm for nm, t in zip(names, row, strict=True) if t) for row in took]
