"""radar2d input: missed plots through the log, bad scan times, impossible configs."""

import numpy as np
import pytest

from tma.errors import ConfigError, InputError
from tma.families import build_estimator
from tma.families.radar2d.log import RadarLog, read_radar_log, write_radar_log
from tma.families.radar2d.scenario import Config, simulate_shard


def _log(n):
    return simulate_shard(Config(n_tracks=n, shard_size=n), 0)[0]


def test_missing_plots_skip_the_scan_and_keep_the_track(tmp_path):
    log = _log(4)
    log.plots_m[1, 20, :] = np.nan
    log.plots_m[2, 10:12, 0] = np.nan
    write_radar_log(tmp_path / "r.mcap", log)
    back = read_radar_log(tmp_path / "r.mcap")
    assert np.isnan(back.plots_m[1, 20]).all()
    for name in ("alphabeta", "fuzzy_mm", "imm"):
        out = build_estimator({"name": name}).estimate(back)
        assert np.all(np.isfinite(out["x_m"][:, 2:])), name


def test_bad_scan_times_and_contradicting_period():
    log = _log(2)
    with pytest.raises(InputError, match=r"scan_period_s = 2 s in the config contradicts .* 3 s"):
        build_estimator({"name": "fuzzy_mm", "scan_period_s": 2.0}).estimate(log)
    bad = RadarLog(log.t_s.copy(), log.track_id, log.plots_m, log.sensor)
    bad.t_s[5] = bad.t_s[4]
    with pytest.raises(InputError, match="not increasing"):
        bad.validate("log")
    gap = RadarLog(np.delete(log.t_s, 7), log.track_id, np.delete(log.plots_m, 7, axis=1),
                   log.sensor)
    with pytest.raises(InputError, match="not uniform"):
        build_estimator({"name": "imm"}).estimate(gap)


@pytest.mark.parametrize(("node", "key"), [
    ({"name": "imm", "initial_probs": [-1.0, 2.0]}, "initial_probs"),
    ({"name": "imm", "cv_accel_psd": -0.01}, "cv_accel_psd"),
    ({"name": "imm", "p_stay": float("nan")}, "p_stay"),
    ({"name": "fuzzy_mm", "bad_centre": 4.0}, "bad_centre"),
    ({"name": "alphabeta", "scan_period_s": -3.0}, "scan_period_s"),
])
def test_impossible_tracker_configs_are_refused(node, key):
    with pytest.raises(ConfigError, match=key):
        build_estimator(node)


def test_impossible_scenarios_are_refused():
    with pytest.raises(ConfigError, match=r"legs\[1\]"):
        Config(legs=[{"duration_s": 45.0}, {"turn_radius_m": -300.0, "duration_s": 45.0,
                                            "direction": "left"}])
    with pytest.raises(ConfigError, match="scan_period_s"):
        Config(scan_period_s=100.0)  # a 120 s path seen in 2 scans
