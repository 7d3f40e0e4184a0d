"""``bearings2d`` on real ship motion (``scenario.real.file``): own-ship and target from an AIS
recording (``tma.ais.recording.RealPairs``: the pairs ``tma.ais.pairs`` finds, own-ship
turning, the target within reach), the bearings simulated as the scenario's own are.

Shard k is pair k (cycling through the pairs), over its window: bearings every
``sample_period_s`` from own-ship's position to the target's (both linear between their AIS
reports, on the recording's plane) plus N(0, ``sigma_deg``^2) noise (and ``outliers.prob``),
one Monte Carlo draw per track, from ``SeedSequence(seed, spawn_key=(shard,))``. The log is
dated by the window's UTC start, holds the recording's origin and declares no motion model:
a recording in spirit, so the estimators test for manoeuvres and assume real-ship wander as on
an ingested log. The truth is the target's state at the last bearing as a simulated moving
target's is (``x0_m``.. the straight line through it), its velocity the mean over the last
``TRUTH_SPAN_S`` (120 s, as the Solent cases' truth), and besides: ``manoeuvring`` (the
target's class over the window, ``tma.ais.pairs.classify``), ``pair``, ``own_mmsi``,
``target_mmsi``, ``own_turn_deg``, ``start_utc``.
"""

import numpy as np

from tma.ais.recording import label_of, pairs_of
from tma.config import require
from tma.io import arrow
from tma.maths.angles import bearing_from_north, course_from_velocity, wrap_to_pi
from tma.runtime.sharding import shard_rng, shard_track_ids
from tma.utc import format_utc

TRUTH_SPAN_S = 120.0


def check(cfg):
    """The scenario's options that the recording replaces are not set."""
    if cfg.real.file is not None:
        require(not cfg.target.moving, cfg.where, "target.* simulates the targets' motion; "
                "with real.file the AIS recording gives it: leave target.* unset")
        require(cfg.real.min_range_m < cfg.real.max_range_m, cfg.where,
                "real.min_range_m must be below real.max_range_m")


def label(cfg) -> str:
    return f"{label_of(cfg.real.file)}-sigma{cfg.sigma_deg:g}-n{cfg.n_tracks}"


def simulate_shard(cfg, shard_index: int, with_outliers):
    """``(BearingsLog, truth)`` of shard ``shard_index`` (module docstring); ``with_outliers``:
    the scenario's outliers (``scenario.with_outliers``), drawn as it draws them."""
    from tma.families.bearings2d.log import BearingsLog

    rec, pairs = pairs_of(cfg.real)
    k = shard_index % len(pairs)
    pair = pairs[k]
    own, target = rec.ships[pair.own_mmsi], rec.ships[pair.target_mmsi]
    t = np.arange(int(np.floor(pair.duration_s / cfg.sample_period_s + 1e-9)) + 1) * (
        cfg.sample_period_s)
    own_x, own_y = own.at(pair.t0_s + t)
    x, y = target.at(pair.t0_s + t)
    track_id = shard_track_ids(cfg, shard_index)
    n = track_id.size
    noise = shard_rng(cfg, shard_index).standard_normal((n, t.size))
    measured = wrap_to_pi(bearing_from_north(x - own_x, y - own_y)
                          + np.deg2rad(cfg.sigma_deg) * noise)
    if cfg.outliers.prob > 0:
        measured = with_outliers(measured, cfg, shard_index)
    epoch = rec.epoch_ns + int(round(pair.t0_s * 1e9))
    log = BearingsLog(t_s=t, own_x_m=own_x, own_y_m=own_y, track_id=track_id,
                      bearing_deg=np.rad2deg(measured) % 360.0, sigma_deg=cfg.sigma_deg,
                      epoch_utc_ns=epoch, origin_deg=rec.origin_deg, accel_psd_m2_s3=None)
    t1 = float(t[-1])
    vx, vy = (float(v) for v in target.mean_velocity(pair.t0_s + t1 - TRUTH_SPAN_S,
                                                     pair.t0_s + t1))
    same = np.ones(n)
    truth = arrow.table({
        "track_id": track_id, "x0_m": (x[-1] - vx * t1) * same, "y0_m": (y[-1] - vy * t1) * same,
        "vx_m_s": vx * same, "vy_m_s": vy * same,
        "distance0_m": np.hypot(x[0] - own_x[0], y[0] - own_y[0]) * same,
        "course_deg": np.rad2deg(course_from_velocity(vx, vy)) * same,
        "speed_m_s": np.hypot(vx, vy) * same,
        "manoeuvring": np.full(n, pair.kind == "manoeuvring"),
        "pair": np.full(n, k, dtype=np.int64),
        "own_mmsi": np.full(n, pair.own_mmsi, dtype=np.int64),
        "target_mmsi": np.full(n, pair.target_mmsi, dtype=np.int64),
        "own_turn_deg": pair.own_turn_deg * same,
        "start_utc": np.array([format_utc(epoch)] * n, dtype=object),
    })
    return log, truth


# -- a target seen from two platforms (issue 39) ----------------------------------------------

def triple_times(t0_s: float, duration_s: float, period_s: float, offset_s: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Bearing times (s on the recording's clock) and platform (0, 1) of each epoch of a
    two-platform window [t0_s, t0_s + duration_s]: the reference (0) every ``period_s`` from
    t0_s to the end (both included), the other (1) every ``period_s`` from t0_s +
    ``offset_s`` (0 <= offset < period: 0 takes both at once) up to the end; ordered by (time,
    platform), as a ``BearingsLog`` of several platforms is. The window ends on a bearing of
    the reference, so range and bearing now are read from one of its own fixes."""
    if not 0.0 <= offset_s < period_s:
        raise ValueError(f"offset_s={offset_s!r}: the second platform's offset must be in "
                         f"[0, {period_s:g}) s")
    n = int(np.floor(duration_s / period_s + 1e-9)) + 1
    t_ref = t0_s + period_s * np.arange(n)
    t_other = t0_s + offset_s + period_s * np.arange(n)
    t_other = t_other[t_other <= t0_s + duration_s + 1e-9]
    t = np.concatenate([t_ref, t_other])
    platform = np.concatenate([np.zeros(t_ref.size, np.int64), np.ones(t_other.size, np.int64)])
    order = np.lexsort((platform, t))
    return t[order], platform[order]


def triple_log(rec, triple, noise, sigma_deg: float, period_s: float = 10.0,
               offset_s: float = 0.0, platforms: int = 2, sigma_declared: float | None = None):
    """``(BearingsLog, truth)`` of ``triple`` (``tma.ais.triples.Triple``) of the AIS
    recording ``rec`` (``tma.ais.recording.AisRecording``): bearings from each platform's
    position to the target's (both linear between their AIS reports, on the recording's plane)
    at ``triple_times`` plus ``sigma_deg`` times ``noise`` (deg; ``noise``: (n_tracks,
    n_epochs) standard normal draws, one track per draw; with ``platforms=1`` only the
    columns of the reference's epochs are used, so the same draws give both logs).

    ``platforms``: 2, a log of both platforms (``platform`` per epoch, ``platforms`` their
    MMSIs as text, the reference first), or 1, the reference alone (a log of one own-ship).
    The log is dated by the window's start, holds the recording's origin, declares no motion
    model (a recording) and declares ``sigma_declared`` as its nominal noise (None: the
    estimators estimate it). ``truth`` (a dict) at the last bearing t1 (the reference's):
    the target's range (m) and bearing (deg) from the reference, its course (deg) and speed
    (m/s) as the mean velocity over the last ``TRUTH_SPAN_S``, and of each epoch's line of
    sight crossing the other platform's at the same time ``max_cross_deg``."""
    from tma.families.bearings2d.log import BearingsLog

    if platforms not in (1, 2):
        raise ValueError(f"platforms={platforms!r}: 1 (the reference alone) or 2")
    t_abs, platform = triple_times(triple.t0_s, triple.duration_s, period_s, offset_s)
    noise = np.atleast_2d(np.asarray(noise, dtype=float))
    if noise.shape[1] != t_abs.size:
        raise ValueError(f"noise has {noise.shape[1]} columns; the window has {t_abs.size} "
                         "epochs")
    ships = [rec.ships[m] for m in triple.platforms]
    own_x, own_y = np.empty(t_abs.size), np.empty(t_abs.size)
    for k, ship in enumerate(ships):
        own_x[platform == k], own_y[platform == k] = ship.at(t_abs[platform == k])
    target = rec.ships[triple.target_mmsi]
    x, y = target.at(t_abs)
    measured = wrap_to_pi(bearing_from_north(x - own_x, y - own_y)
                          + np.deg2rad(sigma_deg) * noise)
    keep = np.ones(t_abs.size, bool) if platforms == 2 else platform == 0
    t = t_abs - triple.t0_s
    n = noise.shape[0]
    log = BearingsLog(
        t_s=t[keep], own_x_m=own_x[keep], own_y_m=own_y[keep],
        track_id=np.arange(n, dtype=np.int64),
        bearing_deg=np.rad2deg(measured[:, keep]) % 360.0, sigma_deg=sigma_declared,
        epoch_utc_ns=rec.epoch_ns + int(round(triple.t0_s * 1e9)), origin_deg=rec.origin_deg,
        accel_psd_m2_s3=None,
        platform=platform.copy() if platforms == 2 else None,
        platforms=tuple(str(m) for m in triple.platforms) if platforms == 2 else None)
    t1 = float(t_abs[-1])
    vx, vy = (float(v) for v in target.mean_velocity(t1 - TRUTH_SPAN_S, t1))
    tx, ty = (float(v[-1]) for v in (x, y))
    rx, ry = (float(v[0]) for v in ships[0].at(np.array([t1])))
    truth = {"range_m": float(np.hypot(tx - rx, ty - ry)),
             "bearing_deg": float(np.rad2deg(course_from_velocity(tx - rx, ty - ry))),
             "course_deg": float(np.rad2deg(course_from_velocity(vx, vy))),
             "speed_m_s": float(np.hypot(vx, vy)), "max_cross_deg": triple.max_cross_deg}
    return log, truth
