"""``radar2d`` on real vessel motion (``scenario.real.file``): the tracked vessel is one of an
AIS recording, over a window in which it is underway within the radar's reach
(``tma.ais.recording.RealWindows``), the plots simulated as the scenario's own are.

Run (track) i is window i modulo the number of windows, with its own noise: the vessel's
position at every scan (linear between its AIS reports, on the recording's plane), plus the
scenario's noise (isotropic ``sigma_m``, or ``polar`` at the radar, which stands at
``real.sensor_lat``/``sensor_lon``, by default the middle of the recording), drawn from
``SeedSequence(seed, spawn_key=(shard,))``. The truth is the position at each scan and the
velocity over the scan period around it, and per run its ``window``, ``mmsi``,
``course_change_deg`` over the window, ``turning`` (more than ``real.turn_deg``) and
``start_utc``.
"""

import numpy as np

from tma.ais.recording import label_of, windows_of
from tma.io import arrow
from tma.runtime.sharding import shard_rng, shard_track_ids
from tma.utc import format_utc


def label(cfg) -> str:
    return f"{label_of(cfg.real.file)}-w{cfg.real.window_s:g}-{cfg.noise}-n{cfg.n_tracks}"


def simulate_shard(cfg, shard_index: int, sensor: dict):
    """``(RadarLog, truth)`` of shard ``shard_index`` (module docstring); ``sensor``: the
    scenario's record of the radar (``scenario.sensor_metadata``), here at the recording's
    radar position."""
    from tma.families.radar2d.log import RadarLog

    rec, windows, position = windows_of(cfg.real, cfg.scan_period_s)
    track_id = shard_track_ids(cfg, shard_index)
    n = track_id.size
    t = np.arange(int(np.floor(cfg.real.window_s / cfg.scan_period_s + 1e-9)) + 1) * (
        cfg.scan_period_s)
    chosen = [windows[i % len(windows)] for i in track_id.tolist()]
    xy, v = np.empty((n, t.size, 2)), np.empty((n, t.size, 2))
    half = cfg.scan_period_s / 2
    for k, w in enumerate(chosen):
        ship = rec.ships[w.mmsi]
        xy[k, :, 0], xy[k, :, 1] = ship.at(w.t0_s + t)
        ta = np.clip(w.t0_s + t - half, ship.t_s[0], None)
        tb = np.clip(w.t0_s + t + half, None, ship.t_s[-1])
        v[k, :, 0], v[k, :, 1] = ship.mean_velocity(ta, tb)
    noise = shard_rng(cfg, shard_index).standard_normal((n, t.size, 2))
    rx, ry = (float(c) for c in position)
    if cfg.noise == "cartesian":
        plots = xy + cfg.sigma_m * noise
    else:
        rng_m = np.hypot(xy[..., 0] - rx, xy[..., 1] - ry) + cfg.range_sd_m * noise[..., 0]
        bearing = (np.arctan2(xy[..., 0] - rx, xy[..., 1] - ry)
                   + np.deg2rad(cfg.bearing_sd_deg) * noise[..., 1])
        plots = np.stack([rx + rng_m * np.sin(bearing), ry + rng_m * np.cos(bearing)], axis=-1)
    metadata = {**sensor, "radar_x_m": rx, "radar_y_m": ry}
    log = RadarLog(t, track_id, plots, metadata, cfg.epoch_ns)
    per_run = {
        "window": track_id % len(windows),
        "mmsi": np.array([w.mmsi for w in chosen], dtype=np.int64),
        "course_change_deg": np.array([w.course_change_deg for w in chosen]),
        "turning": np.array([w.course_change_deg > cfg.real.turn_deg for w in chosen]),
        "start_utc": np.array([format_utc(rec.epoch_ns + int(round(w.t0_s * 1e9)))
                               for w in chosen], dtype=object),
    }
    truth = arrow.table({
        "track_id": np.repeat(track_id, t.size), "step": np.tile(np.arange(t.size), n),
        "t_s": np.tile(t, n), "x_m": xy[..., 0].ravel(), "y_m": xy[..., 1].ravel(),
        "vx_m_s": v[..., 0].ravel(), "vy_m_s": v[..., 1].ravel(),
        **{name: np.repeat(values, t.size) for name, values in per_run.items()},
    })
    return log, truth
