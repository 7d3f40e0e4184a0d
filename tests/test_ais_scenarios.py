"""Real ship motion as a scenario (issue 31, item 3): the pairs and windows found in the Solent
AIS recording of ``tests/data/ais`` meet their rules by an independent reference
(``build_cases``: positions interpolated in latitude/longitude, geodesic geometry), the
simulated bearings and plots are those of the vessels' true geometry, and each shard's draws
are its own (reproducible whatever the number of tracks or shards)."""

import numpy as np
import pytest

from tests.families.bearings2d.ais_trial import cases_module
from tma.ais.recording import RealPairs, RealWindows, pairs_of, windows_of
from tma.config_nodes import validate
from tma.errors import ConfigError

RECORDING = "tests/data/ais/positions.csv.gz"


@pytest.fixture(scope="module")
def reference():
    bc = cases_module()
    return bc, bc.tracks_from(bc.load_positions())


@pytest.fixture(autouse=True)
def _at_the_repository(monkeypatch):
    from tests.conftest import REPO

    monkeypatch.chdir(REPO)


def test_every_pair_found_meets_the_case_rules_by_the_reference(reference):
    """Each pair's own-ship turns, its target stays in reach and is of the class found, as
    build_cases measures them; every 20-minute Solent case's pair is among them."""
    bc, tracks = reference
    rec, pairs = pairs_of(RealPairs(file=RECORDING))
    assert len(pairs) >= 30 and {p.kind for p in pairs} == {"steady", "manoeuvring"}
    for p in pairs:
        check = bc.check_case(tracks[p.own_mmsi], tracks[p.target_mmsi],
                              rec.epoch_ns / 1e9 + p.t0_s, p.duration_s)
        assert check["ok"] and check["kind"] == p.kind, (p, check)
        assert abs(check["own_turn_deg"] - p.own_turn_deg) < 1.0, (p, check)
    found = {(p.own_mmsi, p.target_mmsi) for p in pairs}
    cases = {(c.own_mmsi, c.target_mmsi) for c in bc.CASES if c.duration_s == 1200}
    assert cases <= found


def _bearings2d(**real):
    from tma.families.bearings2d.scenario import Config

    return validate(Config, {"n_tracks": 6, "shard_size": 3, "sigma_deg": 0.0,
                             "real": {"file": RECORDING, **real}}, "test")


def test_the_bearings_are_the_vessels_geodesic_geometry(reference):
    """Noise-free bearings from own-ship to the target, on the recording's plane, equal the
    geodesic azimuths between the vessels' interpolated positions once turned by the plane's
    meridian convergence at own-ship ((lon - lon0) sin(lat)); the log is dated by the
    window's start, carries the origin and declares no motion model."""
    from tma.families.bearings2d.scenario import simulate_shard
    from tma.maths.geo import local_to_geodetic

    bc, tracks = reference
    cfg = _bearings2d()
    rec, pairs = pairs_of(cfg.real)
    for shard in (0, 1):
        log, truth = simulate_shard(cfg, shard)
        pair = pairs[shard]
        t_abs = rec.epoch_ns / 1e9 + pair.t0_s + log.t_s
        g = bc.geometry(tracks[pair.own_mmsi], tracks[pair.target_mmsi], t_abs)
        lat, lon = local_to_geodetic(log.own_x_m, log.own_y_m, rec.origin_deg)
        assert np.abs(lat - g["own_lat"]).max() < 1e-6 and np.abs(lon - g["own_lon"]).max() < 1e-6
        convergence = (lon - rec.origin_deg[1]) * np.sin(np.deg2rad(lat))
        diff = (log.bearing_deg + convergence - g["bearing_deg"] + 180) % 360 - 180
        assert np.abs(diff).max() < 0.01, np.abs(diff).max()
        assert log.accel_psd_m2_s3 is None and log.origin_deg == rec.origin_deg
        assert log.epoch_utc_ns == rec.epoch_ns + round(pair.t0_s * 1e9)
        table = truth.to_pandas()
        assert (table["target_mmsi"] == pair.target_mmsi).all()
        assert (table["manoeuvring"] == (pair.kind == "manoeuvring")).all()
        ref = bc.make_case(1, bc.CaseSpec(pair.own_mmsi, pair.target_mmsi,
                                          bc.to_utc(t_abs[0])[0], pair.duration_s),
                           tracks, 0.0, 1)[1]
        assert abs(table["speed_m_s"][0] - ref["speed_m_s"]) < 2e-3 * ref["speed_m_s"] + 1e-3
        assert abs((table["course_deg"][0] - ref["course_deg"] + 180) % 360 - 180) < 0.2


def test_each_shard_draws_its_own_noise_whatever_the_number_of_tracks():
    from tma.families.bearings2d.scenario import Config, simulate_shard

    cfg = _bearings2d()
    noisy = validate(Config, {**{"n_tracks": 6, "shard_size": 3, "sigma_deg": 0.5},
                              "real": {"file": RECORDING}}, "test")
    more = validate(Config, {"n_tracks": 30, "shard_size": 3, "sigma_deg": 0.5,
                             "real": {"file": RECORDING}}, "test")
    a, _ = simulate_shard(noisy, 1)
    b, _ = simulate_shard(more, 1)
    again, _ = simulate_shard(noisy, 1)
    assert np.array_equal(a.bearing_deg, b.bearing_deg)
    assert np.array_equal(a.bearing_deg, again.bearing_deg)
    clean, _ = simulate_shard(cfg, 1)
    residual = (a.bearing_deg - clean.bearing_deg + 180) % 360 - 180
    assert 0.45 < residual.std() < 0.55  # 3 tracks x 601 bearings of 0.5 deg noise
    other, _ = simulate_shard(noisy, 0)
    assert not np.array_equal(a.own_x_m[:5], other.own_x_m[:5])  # another pair


def test_a_recording_option_that_changes_nothing_or_finds_nothing_is_refused():
    with pytest.raises(ConfigError, match="target.* simulates the targets' motion"):
        from tma.families.bearings2d.scenario import Config

        validate(Config, {"real": {"file": RECORDING},
                          "target": {"accel_psd_m2_s3": 1e-3}}, "test")
    with pytest.raises(ConfigError, match="no own-ship turns by 3000 deg"):
        pairs_of(RealPairs(file=RECORDING, min_turn_deg=3000.0))
    with pytest.raises(ConfigError, match="real.file=nowhere.csv: no such file"):
        pairs_of(RealPairs(file="nowhere.csv"))


def test_the_radar_windows_meet_their_rules_and_the_plots_are_the_vessels(reference):
    """Each window's vessel is underway within reach of the radar with no long AIS gap (as
    build_cases' tracks say), and the noise-free plots are its positions."""
    from tma.families.radar2d.scenario import Config, simulate_shard
    from tma.maths.geo import local_to_geodetic

    bc, tracks = reference
    real = RealWindows(file=RECORDING)
    rec, windows, sensor = windows_of(real, 3.0)
    assert len(windows) > 100 and any(w.course_change_deg > real.turn_deg for w in windows)
    for w in windows[::10]:
        track = tracks[w.mmsi]
        t = rec.epoch_ns / 1e9 + w.t0_s + np.arange(0, w.duration_s + 1e-9, 3.0)
        assert track.max_gap(t[0], t[-1]) <= real.max_gap_s
        lat, lon = track.at(t)
        from pymap3d import geodetic2enu

        e, n, _ = geodetic2enu(lat, lon, 0.0, *rec.origin_deg, 0.0)
        assert np.hypot(e - sensor[0], n - sensor[1]).max() <= real.max_range_m + 1.0
    cfg = validate(Config, {"n_tracks": 4, "shard_size": 4, "sigma_m": 1e-9,
                            "real": {"file": RECORDING}}, "test")
    log, truth = simulate_shard(cfg, 0)
    truth = truth.to_pandas()
    for k in range(4):
        w = windows[k]
        rows = truth[truth.track_id == k]
        assert (rows["mmsi"] == w.mmsi).all()
        t = rec.epoch_ns / 1e9 + w.t0_s + rows["t_s"].to_numpy()
        lat, lon = tracks[w.mmsi].at(t)
        plat, plon = local_to_geodetic(log.plots_m[k, :, 0], log.plots_m[k, :, 1],
                                       rec.origin_deg)
        assert np.abs(plat - lat).max() < 1e-6 and np.abs(plon - lon).max() < 1e-6
