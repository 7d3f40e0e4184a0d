"""The trajectory an answer rests on, as the plots and the map draw it: the side table
``path`` of the estimators that follow a moving target (``lm``, ``last_leg``; written where
``path_points`` > 0, a recording's default).

Per track with a motion fit (``ncv.smooth``; with manoeuvres, the most probable component
of ``manoeuvres.mixture``), its maximum a posteriori positions at the bearing epochs from
when the answer holds (``leg_start_s``) to its last bearing, with their one-sigma errors:
the smoothed ones given every bearing under that trajectory's own manoeuvres
(``kalman.smoothed_positions``), widened by the factor by which the answer's own position
covariance at the last bearing exceeds that trajectory's there (``widening``: the
mixture's spread over when and how the target manoeuvred, and its tails; about 1 without
manoeuvres). The smoothed errors alone are too narrow where the mixture is unsure of the
manoeuvres: for the 48 ``ok`` answers on 120 targets that each turned once
(``tests/families/bearings2d/test_bearings2d_estimated_path.py``), the truth lay within the
95 % ellipse at 94 % of the drawn epochs with them, at 98 % widened (91 and 96 % over the
first third of each path); for the 63 ``ok`` answers on 100 targets of the default scenario
made to turn once at 5-20 km, at 75 % and 86 % (86 % over the first third), about as often
as within the answer's own ellipse now (90 %).

A track of thousands of epochs keeps at most ``points`` of them: half evenly spread in time,
the rest where the drawn line would otherwise cut a corner the most (the top-down split of
Douglas and Peucker, "Algorithms for the reduction of the number of points required to
represent a digitized line", Cartographica 10(2), 1973, run to a count instead of a
tolerance), so that a manoeuvre's bend stays drawn; the first and last epochs are always
kept.

Columns: ``track_id``, ``t_s`` (s, the log's time), ``x_m``, ``y_m`` (m, east and north of
the log's origin), ``x_sd_m``, ``y_sd_m`` (m) and ``xy_corr`` (their correlation).
"""

import heapq

import numpy as np

COLUMNS = ("track_id", "t_s", "x_m", "y_m", "x_sd_m", "y_sd_m", "xy_corr")
RECORDED_POINTS = 200  # points per track a recording's path keeps (``path_points``)


def _worst(xy, a, b):
    """(largest distance (m) of the points strictly between a and b from the chord a-b, the
    index of that point); None when there are none."""
    if b - a < 2:
        return None
    chord = xy[b] - xy[a]
    rel = xy[a + 1:b] - xy[a]
    length = float(np.hypot(*chord))
    dist = (np.abs(chord[0] * rel[:, 1] - chord[1] * rel[:, 0]) / length if length > 0
            else np.hypot(rel[:, 0], rel[:, 1]))
    j = int(np.argmax(dist))
    return float(dist[j]), a + 1 + j


def decimate(xy: np.ndarray, points: int) -> np.ndarray:
    """Indices (sorted) of at most ``points`` (at least 2) of the positions ``xy`` (m, (k,
    2)): all when they are no more; else the first and last and ``points // 2`` evenly
    spread, then one by one the point farthest from the chord of the span it lies in
    (module docstring)."""
    k, points = len(xy), max(points, 2)
    if k <= points:
        return np.arange(k)
    keep = set(np.linspace(0, k - 1, max(points // 2, 2)).round().astype(int).tolist())
    ordered = sorted(keep)
    heap = []
    for a, b in zip(ordered[:-1], ordered[1:], strict=True):
        worst = _worst(xy, a, b)
        if worst is not None:
            heapq.heappush(heap, (-worst[0], worst[1], a, b))
    while len(keep) < points and heap:
        _, j, a, b = heapq.heappop(heap)
        keep.add(j)
        for lo, hi in ((a, j), (j, b)):
            worst = _worst(xy, lo, hi)
            if worst is not None:
                heapq.heappush(heap, (-worst[0], worst[1], lo, hi))
    return np.array(sorted(keep))


def widening(path_cov_last, cov_now) -> np.ndarray:
    """Per track the factor (>= 1) its trajectory's covariances are multiplied by so that at
    the last bearing none is narrower than the answer's ``cov_now`` (r, 2, 2, m^2) in any
    direction: the largest eigenvalue of C^-1 cov_now, C the trajectory's own there
    (``path_cov_last``, (r, 3): xx, xy, yy, m^2); 1 where either is not finite."""
    C = np.stack([path_cov_last[:, [0, 1]], path_cov_last[:, [1, 2]]], axis=1)
    ok = np.isfinite(C).all(axis=(1, 2)) & np.isfinite(cov_now).all(axis=(1, 2))
    factor = np.ones(len(C))
    if ok.any():
        with np.errstate(invalid="ignore", divide="ignore"):
            factor[ok] = np.linalg.eigvals(np.linalg.pinv(C[ok]) @ cov_now[ok]).real.max(axis=1)
    return np.where(np.isfinite(factor), np.maximum(factor, 1.0), 1.0)


def path_table(track_id, t, path_m, path_cov_m2, cov_now, from_k, points: int) -> dict:
    """The ``path`` rows (``COLUMNS``) of the tracks ``track_id`` (r,) from their motion fit's
    positions ``path_m`` (r, K, 2, m; NaN outside the track) and their covariances
    ``path_cov_m2`` (r, K, 3: xx, xy, yy, m^2), widened to the answer's position covariance
    at the last bearing ``cov_now`` (r, 2, 2, m^2; ``widening``), from epoch ``from_k`` (r,:
    where the answer holds) on, at most ``points`` per track (``decimate``). Tracks without
    a finite trajectory there (a failed fit) have no rows."""
    parts = {name: [] for name in COLUMNS}
    for r, i in enumerate(np.asarray(track_id)):
        ks = np.arange(from_k[r], path_m.shape[1])
        ks = ks[np.isfinite(path_m[r, ks]).all(axis=1)]
        if ks.size == 0:
            continue
        ks = ks[decimate(path_m[r, ks], points)]
        cov = path_cov_m2[r, ks] * widening(path_cov_m2[r, ks[-1:]], cov_now[r:r + 1])[0]
        sx, sy = np.sqrt(cov[:, 0]), np.sqrt(cov[:, 2])
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = np.clip(cov[:, 1] / (sx * sy), -1.0, 1.0)
        for name, values in zip(COLUMNS, (np.full(ks.size, i), t[ks], path_m[r, ks, 0],
                                          path_m[r, ks, 1], sx, sy, corr), strict=True):
            parts[name].append(values)
    return _concatenated(parts, np.asarray(track_id).dtype)


def joined(tables, track_id_dtype) -> dict:
    """One ``path`` table of the tables of ``path_table`` (none: an empty one)."""
    return _concatenated({name: [t[name] for t in tables] for name in COLUMNS}, track_id_dtype)


def _concatenated(parts, track_id_dtype) -> dict:
    return {name: (np.concatenate(v) if v else
                   np.empty(0, track_id_dtype if name == "track_id" else float))
            for name, v in parts.items()}
