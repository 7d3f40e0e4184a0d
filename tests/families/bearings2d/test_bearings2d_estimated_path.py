"""Drawn as estimated (issue 36, item 8): on a recording, the contact plot and the map draw the
trajectory each answer rests on (the side table ``path``: the smoothed path with its
manoeuvres and its errors), which agrees with the bearings' lines of sight where the
straight line back from the answer now (what they drew before, and still draw without a
kept trajectory) does not; its errors cover the truth along the path; keeping it changes no
answer, and a simulation keeps none."""

import numpy as np
import pandas as pd
import pymap3d
import pytest

import tma
from tests.conftest import data_paths, plain_messages, run_stage_here
from tests.families.bearings2d.test_bearings2d_answers import (
    ORIGIN,
    line_data,
    navigation_export,
)
from tma.families.bearings2d import ncv
from tma.families.bearings2d.drawn_tracks import (
    CHI2_2_P95,
    position_covariance,
    theta_covariance,
)
from tma.families.bearings2d.estimated_path import COLUMNS, decimate
from tma.families.bearings2d.estimators.lm import Config, LevenbergMarquardt
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.manoeuvre_components import component

SIGMA_DEG = 0.5
FIRST = 10  # the first bearings (from when the answer holds) checked against the drawing


def _wrapped_deg(a_rad):
    return np.rad2deg((a_rad + np.pi) % (2 * np.pi) - np.pi)


@pytest.fixture(scope="module")
def turned(tmp_path_factory):
    """A recording (a navigation export read by ``tma.read_log``: no declared motion) of
    targets 5-10 km away that each turned once by 60-120 deg mid-way, seen by the default
    manoeuvring own-ship for 20 minutes; the default ``lm`` results, and those of
    ``path_points=0`` (no trajectory kept: the straight line as before)."""
    sim = tma.simulate("bearings2d", n_tracks=4, shard_size=4, sigma_deg=SIGMA_DEG, seed=4,
                       origin=ORIGIN,
                       population={"distance_min_m": 5000.0, "distance_max_m": 10000.0},
                       target={"manoeuvres": {"prob": 1.0, "start_frac": 0.4, "end_frac": 0.6,
                                              "course_change_min_deg": 60.0,
                                              "course_change_max_deg": 120.0},
                               "declared": False})
    csv = navigation_export(sim.logs[0], tmp_path_factory.mktemp("turned") / "turned.csv",
                            "M")
    rec = tma.read_log(csv)
    assert rec.logs[0].accel_psd_m2_s3 is None  # a recording: its targets' motion unknown
    return rec, tma.estimate(rec), tma.estimate(rec, path_points=0), csv


def _line_of_sight_z(log, row, k, xy):
    """(drawn point's bearing from own-ship - measured bearing) / sigma at epochs ``k``."""
    b = np.arctan2(xy[:, 0] - log.own_x_m[k], xy[:, 1] - log.own_y_m[k])
    return _wrapped_deg(b - np.deg2rad(log.bearing_deg[row, k])) / SIGMA_DEG


def test_the_drawn_track_lies_on_the_first_bearings_lines_of_sight(turned):
    rec, found, straight, _ = turned
    (log,) = rec.logs
    paths = found.tma.tables["path"]
    assert "path" not in straight.tma.tables
    shown = found[found["range_now_m"].notna()]
    assert len(shown) >= 3 and set(shown["status"]) >= {"ok"}
    for r in shown.itertuples(index=False):
        row = list(log.track_id).index(r.track_id)
        kept = paths[paths["track_id"] == r.track_id]
        assert kept["t_s"].iloc[0] == r.leg_start_s and kept["t_s"].iloc[-1] == r.t_now_s
        # what the plot draws: the kept trajectory, its last point the answer now
        x, y = line_data(tma.plot_contact(found, rec, r.label), "estimated track")
        drawn = np.column_stack([x, y]) * 1e3
        np.testing.assert_allclose(drawn[:-1], kept[["x_m", "y_m"]].to_numpy()[:-1],
                                   rtol=1e-12)
        np.testing.assert_allclose(drawn[-1], [r.x_now_m, r.y_now_m], rtol=1e-9)
        k = np.searchsorted(log.t_s, kept["t_s"].to_numpy()[:FIRST])
        z = _line_of_sight_z(log, row, k, drawn[:FIRST])
        assert np.abs(z).max() < 4 and np.sqrt(np.mean(z**2)) < 2, (r.label, z)
        # before: the straight line back from the answer now, kilometres off those bearings
        x, y = line_data(tma.plot_contact(straight, rec, r.label), "estimated track")
        held = np.flatnonzero(np.isfinite(log.bearing_deg[row]) & (log.t_s >= r.leg_start_s))
        z = _line_of_sight_z(log, row, held[:FIRST], np.column_stack([x, y])[:FIRST] * 1e3)
        assert np.abs(z).min() > 10, (r.label, z)


def test_the_map_holds_the_path(turned, tmp_path):
    rec, found, _, _ = turned
    (log,) = rec.logs
    paths = found.tma.tables["path"]
    messages = {}
    for channel, message, fix in plain_messages(tma.write_map(found, rec, tmp_path / "m.mcap")):
        messages.setdefault(channel.topic, []).append((message.log_time, fix))
    shown = found[found["range_now_m"].notna()]
    assert set(messages) == {"/ownship/location_fix",
                             *(f"/tma/estimate/{label}" for label in shown["label"])}
    for r in shown.itertuples(index=False):
        kept = paths[paths["track_id"] == r.track_id]
        times, fixes = zip(*messages[f"/tma/estimate/{r.label}"], strict=True)
        assert len(fixes) == len(kept)  # a fix per point of the trajectory, at its time
        np.testing.assert_array_equal(
            times, log.epoch_utc_ns + np.round(kept["t_s"].to_numpy() * 1e9).astype(np.int64))
        lat = np.array([f["latitude"] for f in fixes])
        lon = np.array([f["longitude"] for f in fixes])
        east, north, _ = pymap3d.geodetic2enu(lat, lon, 0.0, *log.origin_deg, 0.0)
        np.testing.assert_allclose(east[:-1], kept["x_m"].to_numpy()[:-1], rtol=0, atol=0.5)
        np.testing.assert_allclose(north[:-1], kept["y_m"].to_numpy()[:-1], rtol=0, atol=0.5)
        np.testing.assert_allclose([lat[-1], lon[-1]], [r.lat_now_deg, r.lon_now_deg],
                                   rtol=0, atol=1e-9)
        cov = np.array([f["position_covariance"] for f in fixes]).reshape(-1, 3, 3)
        sx, sy, c = (kept[k].to_numpy() for k in ("x_sd_m", "y_sd_m", "xy_corr"))
        np.testing.assert_allclose(cov[:-1, 0, 0], sx[:-1] ** 2, rtol=1e-9)
        np.testing.assert_allclose(cov[:-1, 1, 1], sy[:-1] ** 2, rtol=1e-9)
        np.testing.assert_allclose(cov[:-1, 0, 1], (c * sx * sy)[:-1], rtol=1e-9, atol=1e-9)


def test_the_command_draws_and_maps_the_path(turned, tmp_path):
    """``pipeline.table input=LOG``: the run keeps the path ``tma.estimate`` gives, and its
    map MCAP holds a fix per point of it."""
    _, found, _, csv = turned
    run_stage_here("table", f"input={csv}", "name=turned", *data_paths(tmp_path),
                   "progress=false", "parallel=serial")
    (kept,) = (tmp_path / "data" / "runs" / "turned").glob("lm-*/path.parquet")
    pd.testing.assert_frame_equal(pd.read_parquet(kept), found.tma.tables["path"],
                                  check_exact=False, rtol=1e-12)
    counts = {}
    for channel, _, _ in plain_messages(tmp_path / "tables" / "turned-lm.mcap"):
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
    shown = found[found["range_now_m"].notna()]
    sizes = found.tma.tables["path"].groupby("track_id").size()
    assert {t: n for t, n in counts.items() if t.startswith("/tma/estimate/")} == {
        f"/tma/estimate/{r.label}": sizes[r.track_id] for r in shown.itertuples()}
    assert {f"turned-lm-{label}.png" for label in found["label"]} <= {
        p.name for p in (tmp_path / "tables").iterdir()}


def test_the_path_changes_no_answer_and_a_simulation_keeps_none(turned):
    _, found, straight, _ = turned
    pd.testing.assert_frame_equal(found, straight)  # every column, the estimates' too
    pd.testing.assert_frame_equal(found.tma.estimates, straight.tma.estimates)
    paths = found.tma.tables["path"]
    assert list(paths.columns) == list(COLUMNS)
    assert paths.groupby("track_id").size().max() <= 200  # a recording's path_points
    simulated = tma.estimate(tma.simulate("bearings2d", n_tracks=3, shard_size=3,
                                          sigma_deg=SIGMA_DEG, seed=4))
    assert list(simulated.tma.tables) == ["estimates"]


# -- its errors --------------------------------------------------------------------------------

def _turning_log(n, seed, dt=4.0, duration_s=1200.0):
    """``n`` targets 4-12 km away at 4-8 m/s that each turn by 60-120 deg at 0.5 deg/s once,
    at 400-800 s, seen by an own-ship zig-zagging every 4 minutes at 6 m/s; a recording (no
    declared motion) and the true positions (n, K) at its epochs. Written here, independent
    of the scenario's simulator."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s + 1e-9, dt)
    fine = np.arange(0.0, duration_s + 1e-9, 0.5)
    heading = np.deg2rad(np.where((t // 240) % 2 == 0, 30.0, 120.0))
    ox = np.concatenate([[0.0], np.cumsum(6.0 * np.sin(heading[:-1]) * np.diff(t))])
    oy = np.concatenate([[0.0], np.cumsum(6.0 * np.cos(heading[:-1]) * np.diff(t))])
    X, Y = np.empty((n, t.size)), np.empty((n, t.size))
    for i in range(n):
        b0, d0 = rng.uniform(0, 2 * np.pi), rng.uniform(4e3, 12e3)
        c0, v = rng.uniform(0, 2 * np.pi), rng.uniform(4.0, 8.0)
        turn = np.deg2rad(rng.uniform(60, 120)) * rng.choice([-1, 1])
        start = rng.uniform(400, 800)
        course = c0 + np.sign(turn) * np.clip((fine - start) * np.deg2rad(0.5), 0, abs(turn))
        for out, p0, u in ((X, d0 * np.sin(b0), v * np.sin(course)),
                           (Y, d0 * np.cos(b0), v * np.cos(course))):
            p = p0 + np.concatenate([[0.0], np.cumsum((u[1:] + u[:-1]) / 2 * 0.5)])
            out[i] = np.interp(t, fine, p)
    z = np.rad2deg(np.arctan2(X - ox, Y - oy)) + SIGMA_DEG * rng.standard_normal(X.shape)
    log = BearingsLog(t_s=t, own_x_m=ox, own_y_m=oy, track_id=np.arange(n),
                      bearing_deg=z % 360.0, sigma_deg=SIGMA_DEG)
    return log, X, Y


def test_the_path_errors_cover_the_truth_along_the_track():
    """On 120 targets that turned, the truth lies within the 95 % ellipse of the kept
    trajectory of the ``ok`` answers at 95-99 % of their epochs, early in the track as late
    (the smoothed errors of the most probable trajectory alone: 93.7 %, 91.3 % over the
    first third, too narrow where the mixture is unsure when the target turned; widened to
    the answer's covariance now, as ``estimated_path`` does: 97.6 %, 95.8 %); the drawn
    track lies on the first bearings' lines of sight."""
    log, X, Y = _turning_log(120, seed=2)
    out = LevenbergMarquardt(Config(initial_bearing_deg=None, path_points=200)).estimate(log)
    paths = pd.DataFrame(out.side_tables["path"])
    ok = np.flatnonzero((out["status"] == "ok") & np.isfinite(out["range_sd_m"]))
    assert ok.size >= 40
    inside, early, z_first = [], [], []
    for i in ok:
        kept = paths[paths["track_id"] == i]
        k = np.searchsorted(log.t_s, kept["t_s"].to_numpy())
        d = np.column_stack([kept["x_m"] - X[i, k], kept["y_m"] - Y[i, k]])
        sx, sy, c = (kept[key].to_numpy() for key in ("x_sd_m", "y_sd_m", "xy_corr"))
        cov = np.stack([np.stack([sx * sx, c * sx * sy], -1),
                        np.stack([c * sx * sy, sy * sy], -1)], -2)
        inside.append(np.einsum("ki,kij,kj->k", d, np.linalg.inv(cov), d) <= CHI2_2_P95)
        early.append(np.arange(k.size) < k.size / 3)
        z_first.append(_line_of_sight_z(log, i, k[:FIRST],
                                        kept[["x_m", "y_m"]].to_numpy()[:FIRST]))
    inside, early = np.concatenate(inside), np.concatenate(early)
    assert 0.95 <= inside.mean() <= 0.99, inside.mean()
    assert 0.94 <= inside[early].mean() <= 0.995, inside[early].mean()
    z_first = np.concatenate(z_first)
    assert np.sqrt(np.mean(z_first**2)) < 1.5 and np.abs(z_first).max() < 5
    # at the last bearing the trajectory's errors hold the answer's: none narrower
    e = pd.DataFrame({k: v for k, v in out.items() if np.ndim(v) == 1})
    now = position_covariance(theta_covariance(e), e["t_last_s"].to_numpy())
    last = paths.groupby("track_id").tail(1).set_index("track_id")
    for i in ok:
        sx, sy, c = last.loc[i, ["x_sd_m", "y_sd_m", "xy_corr"]]
        cov = np.array([[sx * sx, c * sx * sy], [c * sx * sy, sy * sy]])
        assert np.linalg.eigvalsh(cov - now[i]).min() > -1e-6 * np.trace(cov)


def test_smoothed_covariances_are_the_batch_posterior():
    """``ncv.smooth``'s trajectory covariances (Rauch-Tung-Striebel about the MAP trajectory)
    equal the marginals of the inverse of the whole trajectory's information matrix (the
    bearings' Gauss-Newton term, the wander's and the weak prior's), built here directly."""
    rng = np.random.default_rng(1)
    K, q, sigma = 80, 1e-3, np.deg2rad(SIGMA_DEG)
    t = np.arange(K) * 15.0
    ox, oy = np.where(t < 600, 3.5 * t, 4200 - 3.5 * t), 4.0 * t
    x = np.empty((K, 4))
    x[0] = [6000.0, 8000.0, -4.0, 2.0]
    for k in range(1, K):
        T = t[k] - t[k - 1]
        L = np.linalg.cholesky(q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]]))
        for a in range(2):
            w = L @ rng.standard_normal(2)
            x[k, a] = x[k - 1, a] + T * x[k - 1, a + 2] + w[0]
            x[k, a + 2] = x[k - 1, a + 2] + w[1]
    z = np.arctan2(x[:, 0] - ox, x[:, 1] - oy) + sigma * rng.standard_normal(K)
    theta = x[:1].copy()
    out = ncv.smooth(t, ox, oy, z[None], None, np.array([0]), np.array([K - 1]), theta, q,
                     np.array([sigma]), path_cov=True)
    path = out.path_m[0]
    # the MAP velocities: from the positions' fit again (the kernel keeps positions only)
    _, _, _, nom = component(t, ox, oy, z, theta[0], np.full(K, q), sigma)
    np.testing.assert_allclose(nom[:, :2], path, rtol=0, atol=0.05)
    H = np.zeros((4 * K, 4 * K))
    for k in range(K):
        dx, dy = nom[k, 0] - ox[k], nom[k, 1] - oy[k]
        h = np.zeros(4 * K)
        h[4 * k], h[4 * k + 1] = dy / (dx * dx + dy * dy), -dx / (dx * dx + dy * dy)
        H += np.outer(h, h) / sigma**2
    for k in range(K - 1):
        T = t[k + 1] - t[k]
        F, Q = np.eye(4), np.zeros((4, 4))
        F[0, 2] = F[1, 3] = T
        for a in range(2):
            Q[np.ix_([a, a + 2], [a, a + 2])] = q * np.array([[T**3 / 3, T**2 / 2],
                                                              [T**2 / 2, T]])
        A = np.zeros((4, 4 * K))
        A[:, 4 * k:4 * k + 4], A[:, 4 * k + 4:4 * k + 8] = -F, np.eye(4)
        H += A.T @ np.linalg.solve(Q, A)
    p0 = max(ncv.PRIOR_RANGES * np.hypot(theta[0, 0] - ox[0], theta[0, 1] - oy[0]),
             ncv.MIN_PRIOR_M)
    H[[0, 1], [0, 1]] += 1 / p0**2
    H[[2, 3], [2, 3]] += 1 / ncv.PRIOR_SPEED_M_S**2
    C = np.linalg.inv(H)
    ref = np.array([[C[4 * k, 4 * k], C[4 * k, 4 * k + 1], C[4 * k + 1, 4 * k + 1]]
                    for k in range(K)])
    got = out.path_cov_m2[0]
    scale = np.sqrt(ref[:, [0, 0, 2]] * ref[:, [0, 2, 2]])
    np.testing.assert_array_less(np.abs(got - ref) / scale, 1e-5)
    # their sd widens away from the well-observed middle, as the drawing shows
    sd = np.sqrt(got[:, 0] + got[:, 2])
    assert sd[0] > 1.2 * sd.min() and sd[-1] > 1.2 * sd.min()


def test_decimation_keeps_the_ends_and_the_bend():
    """2,000 epochs of a path that turns once by 90 deg at epoch 1,234, kept to 200 points:
    the first, the last and the bend's corner are among them, and the drawn line is within
    a metre of every epoch left out."""
    s = np.arange(2000.0)
    corner = 1234
    xy = np.where(s[:, None] <= corner, np.column_stack([5.0 * s, np.zeros_like(s)]),
                  np.column_stack([np.full_like(s, 5.0 * corner), 5.0 * (s - corner)]))
    xy += np.random.default_rng(0).normal(0.0, 0.01, xy.shape)
    keep = decimate(xy, 200)
    assert keep.size == 200 and keep[0] == 0 and keep[-1] == 1999
    assert np.all(np.diff(keep) > 0) and np.min(np.abs(keep - corner)) == 0
    line = np.column_stack([np.interp(s, keep, xy[keep, a]) for a in range(2)])
    assert np.hypot(*(line - xy).T).max() < 1.0
    np.testing.assert_array_equal(decimate(xy[:150], 200), np.arange(150))
