"""What the per-contact plots (``contact_plots``) and the map MCAP (``map_mcap``) of a
dataset without truth (an ingested log) draw of each track, and the logs they draw over.

Both draw each track's estimated track from when its answer holds (``leg_start_s``) to its
last bearing: the trajectory the answer rests on where the estimator kept it (the side
table ``path``, ``estimated_path``: the smoothed path with its manoeuvres and its one-sigma
errors; ``lm`` and ``last_leg`` on a recording), its last point the answer now; else (an
estimator that assumes constant velocity, a track without a motion fit, an older run) the
straight line of the estimate theta = (x0, y0, vx, vy) (position at the dataset's t = 0 and
velocity; x east, y north, m) with covariance (J^T J)^-1 sigma^2, J^T J and sigma as the
estimator stored them (``jtj_ij``, ``sigma_used_deg``): the position at time t is
p(t) = p0 + v t, its covariance A(t) Sigma A(t)^T with A(t) = [I, t I]. The answer now's
covariance is always the latter (the report's). A 95 % ellipse is
{p : (p - p(t))^T C^-1 (p - p(t)) <= chi-square(2) 95 % point}.

Both draw the lines of sight from the platform that took each bearing: a log of one own-ship
every k-th bearing from it; a log of several platforms (``BearingsLog.platforms``: ships,
buoys, shore stations) each platform's own, every k-th of them, in its colour
(``PLATFORM_COLOURS``), and each platform's track (one that never moved as a point).
"""

import numpy as np
import pandas as pd

from tma.errors import InputError
from tma.families.bearings2d.log import BearingsLog, read_bearings_log
from tma.families.bearings2d.metrics import THETA, jtj_matrices
from tma.families.bearings2d.platforms import position_at
from tma.families.bearings2d.status import heading_undetermined
from tma.maths.linalg import scaled_inverse

CHI2_2_P95 = 5.991464547107979  # chi-square(2) 95 % point: the 95 % position ellipse


# -- covariance ------------------------------------------------------------------------------

def theta_covariance(estimates: pd.DataFrame) -> np.ndarray:
    """(n, 4, 4) covariance of theta = (x0, y0, vx, vy), (J^T J)^-1 sigma_used^2, from the
    run's ``jtj_ij`` (upper triangle) and ``sigma_used_deg``; inverted in the diagonally
    scaled form, as the estimators do. NaN where the estimator found J^T J singular (its
    one-sigma columns are blank there)."""
    jtj = jtj_matrices(estimates).astype(float)
    usable = (np.isfinite(estimates["range_sd_m"].to_numpy(float))
              & np.isfinite(jtj).all(axis=(1, 2)))
    cov, _ = scaled_inverse(np.where(usable[:, None, None], jtj, np.eye(4)), 0.0)
    cov *= np.deg2rad(estimates["sigma_used_deg"].to_numpy(float))[:, None, None] ** 2
    cov[~usable] = np.nan
    return cov


def shown_estimates(report: pd.DataFrame, estimates: pd.DataFrame):
    """``(theta, theta_cov)`` of each track, ``(n, 4)`` and ``(n, 4, 4)``, as the report shows
    them: NaN where it shows no estimate (its range is blank: diverged, collapsed or without
    a one-sigma error, ``status.not_an_answer``), so that no plot or map draws one there."""
    theta = estimates[list(THETA)].to_numpy(float).copy()
    cov = theta_covariance(estimates)
    hidden = ~np.isfinite(report["range_now_m"].to_numpy(float))
    theta[hidden], cov[hidden] = np.nan, np.nan
    return theta, cov


def now_only(report: pd.DataFrame) -> np.ndarray:
    """Per track whether only its position now is drawn: where its status says where it is
    heading is not determined (``status.HEADING_UNDETERMINED``, ``position_only``), the line
    back from now along its velocity would draw a past the bearings do not give."""
    return heading_undetermined(report["status"])


def position_covariance(theta_cov: np.ndarray, t_s) -> np.ndarray:
    """Covariance (m^2, east-north) of p(t) = p0 + v t: ``(n, 2, 2)`` for one time per track
    (``t_s`` shaped (n,)), ``(n, k, 2, 2)`` for ``t_s`` shaped (n, k)."""
    t = np.asarray(t_s, float)[..., None, None]
    c = theta_cov[:, None] if np.ndim(t_s) == 2 else theta_cov
    pp, pv, vv = c[..., :2, :2], c[..., :2, 2:], c[..., 2:, 2:]
    return pp + t * (pv + np.swapaxes(pv, -1, -2)) + t * t * vv


def path_rows(paths: pd.DataFrame | None) -> dict:
    """The side table ``path`` (``estimated_path``) by track id: ``{id: (t_s (k,), xy (k,
    2), cov (k, 2, 2))}``; empty without one (an older run, an estimator that keeps
    none)."""
    if paths is None or paths.empty:
        return {}
    out = {}
    for track_id, rows in paths.groupby("track_id", sort=False):
        sx, sy = rows["x_sd_m"].to_numpy(float), rows["y_sd_m"].to_numpy(float)
        xy = sx * sy * rows["xy_corr"].to_numpy(float)
        cov = np.stack([np.stack([sx * sx, xy], -1), np.stack([xy, sy * sy], -1)], -2)
        out[int(track_id)] = (rows["t_s"].to_numpy(float), rows[["x_m", "y_m"]].to_numpy(float),
                              cov)
    return out


def drawn_path(kept, theta, cov_now, t_from, t_now):
    """``(t_s, xy, cov)`` of a track's kept trajectory (a ``path_rows`` entry) from
    ``t_from`` on, its point at the last bearing ``t_now`` the answer now: ``theta``'s
    position then, with ``cov_now``, the report's (where the answer is a mixture over the
    manoeuvres, its most probable trajectory ends within its errors); None without a kept
    trajectory, or where ``theta`` is not finite (no estimate shown)."""
    if kept is None or not np.isfinite(theta).all():
        return None
    t, xy, cov = kept
    held = t >= t_from
    t, xy, cov = t[held], xy[held].copy(), cov[held].copy()
    if t.size == 0:
        return None
    if t[-1] == t_now:
        xy[-1] = theta[:2] + theta[2:] * t_now
        cov[-1] = cov_now
    return t, xy, cov


BAND_ELLIPSES = 6  # 95 % ellipses drawn along a kept trajectory (besides the one now)


def ellipse_points(center, cov, n=90) -> np.ndarray:
    """(n, 2) points of the 95 % ellipse of a 2x2 covariance around ``center``."""
    w, V = np.linalg.eigh(cov)
    s = np.linspace(0.0, 2 * np.pi, n)
    unit = np.stack([np.cos(s), np.sin(s)])
    return np.asarray(center) + (V @ (np.sqrt(np.maximum(w, 0) * CHI2_2_P95)[:, None] * unit)).T


# -- the platforms and their lines of sight ------------------------------------------------

BEARING_LINES = 40  # at most about this many lines of sight per contact and platform
NOMINAL_REACH_M = 20_000.0  # lines of sight of a contact without an estimate to reach
SIGHT_REACH = 1.3  # lines of sight reach this many times the farthest the track is from them
# one colour per platform of a log of several (the k-th platform's, cycled), none of them the
# estimate's red or the grey of a single own-ship's lines of sight; hex, as GeoJSON styles
PLATFORM_COLOURS = ("#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2",
                    "#bcbd22", "#17becf")


def platform_colour(k: int) -> str:
    return PLATFORM_COLOURS[k % len(PLATFORM_COLOURS)]


def platform_epochs(lg: BearingsLog) -> list[np.ndarray]:
    """Per platform of a log of several the indices of its epochs (its own positions)."""
    return [np.flatnonzero(lg.platform == k) for k in range(lg.n_platforms)]


def is_fixed(lg: BearingsLog, epochs: np.ndarray) -> bool:
    """Whether a platform stayed at one place at its ``epochs`` (a buoy, a shore station)."""
    return bool(np.ptp(lg.own_x_m[epochs]) == 0 and np.ptp(lg.own_y_m[epochs]) == 0)


def drawn_bearings(lg: BearingsLog, valid: np.ndarray) -> list[tuple[int | None, np.ndarray,
                                                                     int]]:
    """The lines of sight drawn of a contact whose bearings are at epochs ``valid``:
    ``(platform, epochs, step)`` per platform that took any of them (None: the one own-ship
    of a log of one), every ``step``-th of its bearings, about ``BEARING_LINES`` at most."""
    groups = ([(None, valid)] if lg.platform is None else
              [(k, valid[lg.platform[valid] == k]) for k in range(lg.n_platforms)])
    out = []
    for k, mine in groups:
        if mine.size:
            step = max(1, int(np.ceil(mine.size / BEARING_LINES)))
            out.append((k, mine[::step], step))
    return out


def sight_ends(lg: BearingsLog, row: int, epochs: np.ndarray, reach) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """``(start, end)`` (k, 2) m of the lines of sight of track ``row`` at ``epochs``: from
    the platform that took each bearing, ``reach`` m along it (clockwise from north)."""
    b = np.deg2rad(lg.bearing_deg[row, epochs])
    start = np.column_stack([lg.own_x_m[epochs], lg.own_y_m[epochs]])
    return start, start + reach * np.column_stack([np.sin(b), np.cos(b)])


def sight_reach(starts: np.ndarray, track: np.ndarray) -> float:
    """How far lines of sight from ``starts`` (k, 2) reach to pass the drawn ``track`` (m,
    2): ``SIGHT_REACH`` times the farthest a track point is from any of them;
    ``NOMINAL_REACH_M`` without a finite track."""
    if not track.size or not np.isfinite(track).all():
        return NOMINAL_REACH_M
    gap = np.hypot(*(track[None, :, :] - starts[:, None, :]).transpose(2, 0, 1))
    return float(gap.max() * SIGHT_REACH)


def platform_now(lg: BearingsLog, k: int, t_s: float) -> np.ndarray:
    """Platform ``k``'s position (x, y m) at ``t_s`` (``platforms.position_at``)."""
    x, y = position_at(lg.t_s, lg.own_x_m, lg.own_y_m, lg.platform, k, [t_s])
    return np.array([x[0], y[0]])


# -- the dataset's logs ----------------------------------------------------------------------

def read_logs(dataset) -> list[BearingsLog]:
    """The bearing logs of every shard of ``dataset`` (each verified against the manifest)."""
    return [read_bearings_log(dataset.verified_path(rel)) for rel in dataset.shard_paths]


def reference(logs: list[BearingsLog], where: str):
    """``(epoch_utc_ns, origin_deg, labels)`` shared by the shards (labels: track id ->
    text, the id itself when unlabelled); InputError if the shards disagree."""
    epochs = {lg.epoch_utc_ns for lg in logs}
    origins = {None if lg.origin_deg is None else tuple(map(float, lg.origin_deg))
               for lg in logs}
    if len(epochs) > 1 or len(origins) > 1:
        raise InputError(f"{where}: the shards disagree on their UTC epoch or geographic "
                         "origin; ingest the log again")
    labels = {}
    for lg in logs:
        names = lg.track_label if lg.track_label is not None else lg.track_id.astype(str)
        labels.update(zip(lg.track_id.tolist(), map(str, names), strict=True))
    return next(iter(epochs), None), next(iter(origins), None), labels

