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
