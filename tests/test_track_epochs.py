"""The one scatter onto the track x epoch arrays (``tma.io.track_epochs``): values that arrive
one by one put on the (tracks x epochs) array, against a plain loop; a track with two values
at one epoch refused naming it and the time, in the MCAP readers of ``bearings2d``,
``radar2d`` and ``ranges2d`` and at ingest; and the own-ship-off-the-map rule
(``tma.maths.geo.check_mapped``), one for ingest and the log writer."""

import numpy as np
import pandas as pd
import pytest

from tma.errors import InputError
from tma.families.bearings2d.log import (
    BEARINGS_TOPIC,
    CHANNELS,
    OWNSHIP_TOPIC,
    BearingsLog,
    read_bearings_log,
    write_bearings_log,
)
from tma.families.radar2d.log import PLOTS_TOPIC, read_radar_log
from tma.families.radar2d.log import channels as radar_channels
from tma.families.ranges2d.log import RANGES_TOPIC, read_ranges_log
from tma.families.ranges2d.log import channels as ranges_channels
from tma.io.mcap_log import LogWriter
from tma.io.mcap_values import json_record
from tma.io.track_epochs import epochs, scatter
from tma.maths.geo import check_mapped


def test_scatter_puts_each_value_in_its_cell():
    rng = np.random.default_rng(3)
    cells = rng.choice(40 * 25, size=300, replace=False)  # distinct (track, epoch) pairs
    ids = np.array([3, 8, 11, 20, 21] * 8)[cells // 25] * 10 + cells // 25  # 40 track ids
    t = np.round(rng.uniform(0, 100, 25), 3)[cells % 25]
    values = rng.standard_normal((300, 2))
    t_s, col, first = epochs(t)
    track_id, grid = scatter(ids, col, values, t_s.size, "log", "values", t_s.__getitem__)
    expected = {(i, tt): v for i, tt, v in zip(ids.tolist(), t.tolist(), values, strict=True)}
    assert list(t_s) == sorted(set(t.tolist())) and list(track_id) == sorted(set(ids.tolist()))
    assert np.array_equal(t[first], t_s) and all(
        first[k] == min(np.flatnonzero(t == t_s[k])) for k in range(t_s.size))
    for r, i in enumerate(track_id.tolist()):
        for c, tt in enumerate(t_s.tolist()):
            if (i, tt) in expected:
                np.testing.assert_array_equal(grid[r, c], expected[i, tt])
            else:
                assert np.isnan(grid[r, c]).all()
    given = np.r_[track_id, 10**6]  # rows given: every id of the values, and more
    rows, wider = scatter(ids, col, values[:, 0], t_s.size, "log", "values", t_s.__getitem__,
                          track_id=given)
    assert rows is given and np.isnan(wider[-1]).all()
    np.testing.assert_array_equal(wider[:-1], grid[..., 0])


def test_a_track_twice_at_one_time_is_named():
    t_s, col, _ = epochs(np.array([5.0, 1.0, 5.0, 1.0, 2.5]))
    with pytest.raises(InputError, match=r"^log: track 7 has two bearings at one time "
                                         r"\(t = 5 s\)$"):
        scatter(np.array([7, 9, 7, 4, 4]), col, np.arange(5.0), t_s.size, "log", "bearings",
                t_s.__getitem__)


def _bearing_messages(path, ids):
    """A bearing log whose epoch t = 1 s comes as several messages of one bearing each, and
    whose epoch t = 1.5 s holds no bearing."""
    with LogWriter(path, CHANNELS) as w:
        for t in (0.0, 1.0, 2.0):
            w.write(OWNSHIP_TOPIC, t, {"t_s": t, "x_m": 0.0, "y_m": 0.0})
        for t, i in [(0.0, 1), *((1.0, i) for i in ids), (1.5, None), (2.0, 1)]:
            ids = np.array([] if i is None else [i], dtype=np.int64)
            w.write(BEARINGS_TOPIC, t, {"t_s": t, "track_id": ids, "bearing_deg": 10.0 + ids})
    return path


def test_the_readers_put_messages_on_the_grid_and_refuse_a_track_twice(tmp_path):
    log = read_bearings_log(_bearing_messages(tmp_path / "ok.mcap", [2, 1]))
    np.testing.assert_array_equal(log.t_s, [0, 1, 1.5, 2])  # an empty epoch is an epoch
    np.testing.assert_array_equal(log.bearing_deg, [[11, 11, np.nan, 11],
                                                    [np.nan, 12, np.nan, np.nan]])
    with pytest.raises(InputError, match=r"twice.mcap: track 2 has two bearings at one time "
                                         r"\(t = 1 s\)"):
        read_bearings_log(_bearing_messages(tmp_path / "twice.mcap", [2, 1, 2]))
    radar = tmp_path / "radar.mcap"
    with LogWriter(radar, radar_channels("json"), {"tma.sensor": json_record(
            {"noise": "cartesian", "sigma_m": 10.0, "radar_x_m": 0.0, "radar_y_m": 0.0})}) as w:
        for t, ids in ((0.0, [1, 2]), (3.0, [2, 1, 2]), (6.0, [1])):
            w.write(PLOTS_TOPIC, t, {"t_s": t, "track_id": ids, "x_m": [1.0] * len(ids),
                                     "y_m": [2.0] * len(ids)})
    with pytest.raises(InputError, match=r"radar.mcap: track 2 has two plots at one time "
                                         r"\(t = 3 s\)"):
        read_radar_log(radar)
    ranges = tmp_path / "ranges.mcap"
    model = {"sigma_m": 1.0, "prior_mean_m": [0.0, 0.0], "prior_sd_m": [10.0, 10.0]}
    with LogWriter(ranges, ranges_channels("json"), {"tma.model": json_record(model)}) as w:
        for t, lm, ids in ((0.0, 0, [4]), (0.0, 1, [4, 4]), (1.0, 0, [4])):
            w.write(RANGES_TOPIC, t, {"t_s": t, "landmark_id": lm, "landmark_x_m": 100.0 * lm,
                                      "landmark_y_m": 0.0, "track_id": ids,
                                      "range_m": [50.0] * len(ids)})
    with pytest.raises(InputError, match=r"ranges.mcap: track 4 has two ranges of one landmark "
                                         r"at one time \(t = 0 s\)"):
        read_ranges_log(ranges)


def test_own_ship_off_the_map_is_one_rule_for_ingest_and_the_writer(tmp_path):
    x = np.array([0.0, 1e6, 2.5e6, 3e6])
    with pytest.raises(InputError, match=r"^log.csv: own-ship goes farther than 2000 km from "
                                         r"the origin \(2500 km at t = 2 s after the log's "
                                         r"start\): its tangent plane cannot map it; split the "
                                         r"log$"):
        check_mapped(x, np.zeros(4), np.arange(4.0), "log.csv")
    check_mapped(x[:2], np.zeros(2), np.arange(2.0))
    log = BearingsLog(np.arange(4.0), x, np.zeros(4), np.array([1]), np.full((1, 4), 10.0),
                      epoch_utc_ns=int(pd.Timestamp("2026-01-01T00:00Z").value),
                      origin_deg=(59.9, 10.7))
    with pytest.raises(InputError, match=r"^own-ship goes farther than 2000 km from the origin "
                                         r"\(2500 km at t = 2 s"):
        write_bearings_log(tmp_path / "far.mcap", log)
    assert not (tmp_path / "far.mcap").exists()
