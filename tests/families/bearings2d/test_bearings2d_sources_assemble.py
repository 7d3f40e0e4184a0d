"""``tma.sources.align`` and ``bearings2d``'s logs from it: one clock, one east-north plane,
own-ship at every bearing, one epoch grid per own-ship. Checked against the recorded
encounter's exact geometry (own-ship legs are straight, so linear interpolation and end-segment
extrapolation are exact) and against geodesics (Vincenty) for the plane."""

import numpy as np
import pymap3d.vincenty
import pytest

from tests.families.bearings2d.recorded_geometry import (
    EPOCH_NS,
    ORIGIN,
    latlon,
    ownship_en,
    recorded,
    source_options,
)
from tma.errors import InputError
from tma.families.bearings2d import ingest as bearings2d_ingest
from tma.families.bearings2d.log import SENSOR
from tma.io.mcap_values import json_record
from tma.sources.align import align
from tma.sources.base import Contacts, Navigation, Recording
from tma.utc import format_utc


def _recording(labels=("T1",), nav_rows=None, nav_epoch=EPOCH_NS, obs_epoch=EPOCH_NS,
               geographic=True, sigma=None):
    rec = recorded(labels)
    nav = rec.navigation if nav_rows is None else rec.navigation[nav_rows(rec.navigation)]
    b = rec.bearings
    shift_nav = 0.0 if nav_epoch is None else (EPOCH_NS - nav_epoch) / 1e9
    shift_obs = 0.0 if obs_epoch is None else (EPOCH_NS - obs_epoch) / 1e9
    if geographic:
        navigation = Navigation(nav.t_s.to_numpy() + shift_nav, nav_epoch, "nav",
                                lat_deg=nav.lat.to_numpy(), lon_deg=nav.lon.to_numpy())
    else:
        navigation = Navigation(nav.t_s.to_numpy() + shift_nav, nav_epoch, "nav",
                                x_m=nav.east_m.to_numpy(), y_m=nav.north_m.to_numpy())
    contacts = Contacts(b.t_s.to_numpy() + shift_obs, obs_epoch, b.track.to_numpy(dtype=object),
                        b.bearing_deg.to_numpy(), "brg")
    metadata = {} if sigma is None else {SENSOR: json_record({"sigma_deg": sigma})}
    return Recording(navigation, contacts, metadata, notes=["found"]), rec


def _run(recordings, **options):
    aligned = align(recordings, source_options(options), "test")
    logs, _, _ = bearings2d_ingest.logs(aligned, bearings2d_ingest.Settings(), "test")
    return logs, aligned.summary


def test_own_ship_at_every_bearing_in_the_plane_of_the_first_fix():
    one, rec = _recording(("T1", "T2"))
    (lg,), summary = _run([one])
    b = rec.bearings
    t = np.unique(b.t_s)
    np.testing.assert_allclose(lg.t_s, t - t[0], atol=1e-9)
    x, y = ownship_en(t)
    np.testing.assert_allclose(lg.own_x_m, x, atol=1e-6)  # exact geometry, to a micrometre
    np.testing.assert_allclose(lg.own_y_m, y, atol=1e-6)
    np.testing.assert_allclose(summary["origin_deg"], ORIGIN, atol=1e-12)  # the first fix
    # the plane against geodesics from the origin: distance to 3 cm, azimuth to 1e-6 deg
    lat, lon = latlon(x, y)
    dist, azimuth = pymap3d.vincenty.vdist(ORIGIN[0], ORIGIN[1], lat, lon)
    np.testing.assert_allclose(np.hypot(lg.own_x_m, lg.own_y_m), dist, atol=0.03)
    plane_az = np.rad2deg(np.arctan2(lg.own_x_m, lg.own_y_m)) % 360
    np.testing.assert_allclose(plane_az, azimuth, atol=1e-6)
    # one grid: both contacts on every epoch, labels sorted into ids 0, 1
    np.testing.assert_array_equal(lg.track_id, [0, 1])
    assert list(lg.track_label) == ["T1", "T2"] and summary["track_labels"] == {"0": "T1",
                                                                               "1": "T2"}
    # bearings from true north at own-ship turned onto the plane's north there: by the
    # direction of a point 100 m true north of own-ship, on the plane (pymap3d's geodesic)
    n_lat, n_lon, _ = pymap3d.aer2geodetic(0.0, 0.0, 100.0, lat, lon, 0.0)
    ne, nn, _ = pymap3d.geodetic2enu(n_lat, n_lon, 0.0, ORIGIN[0], ORIGIN[1], 0.0)
    pe, pn, _ = pymap3d.geodetic2enu(lat, lon, 0.0, ORIGIN[0], ORIGIN[1], 0.0)
    north = np.rad2deg(np.arctan2(ne - pe, nn - pn))
    assert 0.01 < np.abs(north).max() < 0.2  # own-ship a few km east and west of the origin
    for i, label in enumerate(("T1", "T2")):
        np.testing.assert_allclose(lg.bearing_deg[i], b[b.track == label].bearing_deg + north,
                                   rtol=0, atol=1e-5)
    assert lg.epoch_utc_ns == summary["epoch_utc_ns"] == EPOCH_NS + 500_000_000
    assert summary["start_utc"] == "2025-06-01T08:00:00.5Z"
    assert summary["notes"][0] == "found" and "origin" in summary["notes"][-1]


def test_a_given_origin_and_local_metres():
    one, rec = _recording(geographic=False)
    (lg,), summary = _run([one])
    assert summary["origin_deg"] is None and lg.origin_deg is None
    x, _ = ownship_en(np.unique(rec.bearings.t_s))
    np.testing.assert_allclose(lg.own_x_m, x, atol=1e-9)
    one, _ = _recording(geographic=False)
    (lg,), summary = _run([one], origin={"lat": 60.0, "lon": 11.0})
    assert summary["origin_deg"] == [60.0, 11.0] and lg.origin_deg == (60.0, 11.0)
    one, _ = _recording()
    (lg,), summary = _run([one], origin={"lat": ORIGIN[0], "lon": ORIGIN[1] + 0.01})
    east_shift = pymap3d.vincenty.vdist(ORIGIN[0], ORIGIN[1], ORIGIN[0], ORIGIN[1] + 0.01)[0]
    np.testing.assert_allclose(lg.own_x_m[0] - x[0], -east_shift, atol=0.01)


def test_clocks_with_different_epochs_are_aligned():
    """Navigation timed from 10 s before the encounter, bearings from 2 s after: same UTC."""
    one, rec = _recording(nav_epoch=EPOCH_NS - 10**10, obs_epoch=EPOCH_NS + 2 * 10**9)
    (lg,), summary = _run([one])
    x, y = ownship_en(np.unique(rec.bearings.t_s))
    np.testing.assert_allclose(lg.own_x_m, x, atol=1e-6)
    assert summary["epoch_utc_ns"] == EPOCH_NS + 500_000_000
    assert summary["time_origin_s"] == summary["epoch_utc_ns"] / 1e9


def test_relative_clocks_keep_the_first_bearing_time():
    one, _ = _recording(nav_epoch=None, obs_epoch=None)
    (lg,), summary = _run([one])
    assert summary["epoch_utc_ns"] is None and summary["start_utc"] is None
    assert summary["time_origin_s"] == 0.5 and lg.t_s[0] == 0.0


def test_mixed_clocks_are_refused_naming_time_format():
    one, _ = _recording(nav_epoch=None)
    with pytest.raises(InputError, match=r"nav has relative times .* brg has absolute UTC "
                                         r"times \(time.format=auto\).*time.format=unix_s"):
        _run([one])


AT_ORIGIN = {"origin": {"lat": ORIGIN[0], "lon": ORIGIN[1]}}  # the truth's plane


def test_navigation_starting_late_extrapolates_within_the_limit_and_drops_beyond():
    # fixes from 1 s (first bearing at 0.5 s: 0.5 s outside, extrapolated)
    one, rec = _recording(nav_rows=lambda n: n.t_s >= 1.0)
    (lg,), summary = _run([one], **AT_ORIGIN)
    x, y = ownship_en(np.unique(rec.bearings.t_s))
    np.testing.assert_allclose(lg.own_x_m, x, atol=1e-6)
    np.testing.assert_allclose(lg.own_y_m, y, atol=1e-6)
    assert summary["dropped_bearings"]["count"] == 0
    # fixes from 2 s to 2390 s: the bearings at 0.5 s and 2394.5 s are dropped
    one, rec = _recording(("T1", "T2"), nav_rows=lambda n: (n.t_s >= 2.0) & (n.t_s <= 2390))
    (lg,), summary = _run([one])
    assert summary["dropped_bearings"] == {
        "count": 4, "before_navigation": 2, "after_navigation": 2, "in_navigation_gaps": 0,
        "why": "more than nav.max_extrapolation_s = 1 s outside the own-ship fixes' time span"}
    assert lg.t_s.size == 398 and summary["epoch_utc_ns"] == EPOCH_NS + 6_500_000_000
    # a wider limit keeps them, extrapolated exactly along the straight first and last legs
    one, rec = _recording(nav_rows=lambda n: (n.t_s >= 2.0) & (n.t_s <= 2390))
    (lg,), summary = _run([one], nav={"max_extrapolation_s": 5.0}, **AT_ORIGIN)
    x, _ = ownship_en(np.unique(rec.bearings.t_s))
    assert summary["dropped_bearings"]["count"] == 0
    np.testing.assert_allclose(lg.own_x_m, x, atol=1e-6)


def test_navigation_gaps_are_reported():
    one, rec = _recording(nav_rows=lambda n: (n.t_s < 300) | (n.t_s > 340))
    (lg,), summary = _run([one])
    gaps = summary["nav_gaps"]
    assert gaps["count"] == 1 and gaps["max_gap_s"] == 10.0 and gaps["longest_s"] == 42.0
    (gap,) = gaps["gaps"]
    assert gap["from_s"] == 299.0 - 0.5 and gap["to_s"] == 341.0 - 0.5
    assert gap["bearings_inside"] == 7  # 302.5, 308.5, ... 338.5
    x, _ = ownship_en(np.unique(rec.bearings.t_s))  # a straight leg: exact across the gap
    np.testing.assert_allclose(lg.own_x_m, x, atol=1e-6)
    _, summary = _run([_recording(nav_rows=lambda n: (n.t_s < 300) | (n.t_s > 340))[0]],
                      nav={"max_gap_s": 60.0})
    assert summary["nav_gaps"]["count"] == 0


def test_no_bearing_within_the_fixes_names_the_clock_and_the_option():
    one, _ = _recording(nav_rows=lambda n: n.t_s < 0.2)  # 1 fix
    with pytest.raises(InputError, match="1 own-ship fix"):
        _run([one])
    one, _ = _recording()
    one.contacts.epoch_utc_ns += 10**13  # bearings three hours later than the fixes
    with pytest.raises(InputError, match="no bearing lies within the own-ship fixes' time span"
                                         ".*time.format.*nav.max_extrapolation_s"):
        _run([one])


def test_two_positions_at_one_time_are_refused():
    one, _ = _recording()
    nav = one.navigation
    nav.t_s = np.r_[nav.t_s[:5], nav.t_s[4], nav.t_s[5:]]
    nav.lat_deg = np.r_[nav.lat_deg[:5], nav.lat_deg[4] + 1e-4, nav.lat_deg[5:]]
    nav.lon_deg = np.r_[nav.lon_deg[:5], nav.lon_deg[4], nav.lon_deg[5:]]
    with pytest.raises(InputError, match="two different own-ship positions at one time"):
        _run([one])


def test_contacts_at_different_times_share_one_grid():
    one, rec = _recording(("T1", "T2"))
    keep = np.ones(one.contacts.t_s.size, bool)
    keep[1::4] = False  # T2 misses every other epoch
    for name in ("t_s", "track", "values"):
        setattr(one.contacts, name, getattr(one.contacts, name)[keep])
    (lg,), _ = _run([one])
    assert lg.bearing_deg.shape == (2, 400)
    assert np.isfinite(lg.bearing_deg[0]).all() and np.isnan(lg.bearing_deg[1]).sum() == 200


def test_a_huge_grid_is_split_into_logs_of_one_own_ship(monkeypatch):
    """Contacts at their own times would make a (tracks x epochs) grid too large: groups of
    tracks get their own (smaller) grids, and no bearing is lost."""
    one, rec = _recording(("T1", "T2", "T3"))
    one.contacts.t_s = one.contacts.t_s + np.tile([0.0, 0.1, 0.2], 400)  # all epochs distinct
    monkeypatch.setattr(bearings2d_ingest, "MAX_CELLS", 1000)  # below 2 tracks x 800 epochs
    logs, summary = _run([one])
    assert len(logs) == 3 and [lg.track_id.tolist() for lg in logs] == [[0], [1], [2]]
    assert sum(np.isfinite(lg.bearing_deg).sum() for lg in logs) == 1200
    assert all(lg.epoch_utc_ns == summary["epoch_utc_ns"] for lg in logs)
    assert min(lg.t_s[0] for lg in logs) == 0.0


def test_radians_of_unstated_units_are_refused():
    one, _ = _recording()
    one.contacts.values = np.deg2rad(one.contacts.values)
    with pytest.raises(InputError, match="look like radians. Set bearing.units=rad"):
        _run([one])
    one.contacts.units_stated = True
    _run([one])


def test_start_utc_is_written_as_the_logs_write_it():
    assert format_utc(EPOCH_NS + 1) == "2025-06-01T08:00:00.000000001Z"
    assert format_utc(EPOCH_NS + 500_000_000) == "2025-06-01T08:00:00.5Z"


def test_values_in_a_long_navigation_gap_are_dropped_not_bridged():
    """Own-ship's fixes missing for 10 minutes (it may have turned meanwhile): the bearings
    inside are left out and counted; with nav.max_bridge_s above the gap's length they are
    interpolated across it (the gap still reported)."""
    one, rec = _recording(nav_rows=lambda n: (n.t_s < 600) | (n.t_s > 1200))
    (lg,), summary = _run([one])
    t = rec.bearings.t_s.to_numpy()
    inside = (t > 599.0) & (t < 1201.0)  # the fixes' gap: 599 s to 1201 s
    assert inside.sum() > 100
    assert summary["dropped_bearings"]["in_navigation_gaps"] == inside.sum()
    assert summary["dropped_bearings"]["count"] == inside.sum()
    assert "nav.max_bridge_s = 300 s" in summary["dropped_bearings"]["why"]
    kept_t = lg.t_s + 0.5  # (the log's t = 0 is the first bearing, at 0.5 s)
    assert not ((kept_t > 599.0) & (kept_t < 1201.0)).any()
    assert np.unique(kept_t).size == np.unique(t[~inside]).size
    (bridged,), summary = _run([one], nav={"max_bridge_s": 900.0})
    assert summary["dropped_bearings"]["count"] == 0
    assert np.unique(bridged.t_s).size == np.unique(t).size
    assert summary["nav_gaps"]["count"] == 1  # still reported
