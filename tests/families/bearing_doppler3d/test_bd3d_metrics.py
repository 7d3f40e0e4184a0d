"""``bearing_doppler3d`` metrics: divergence and per-path status on constructed errors."""

import numpy as np

from tma.families.bearing_doppler3d.metrics import divergent_paths, path_metrics


def test_divergence_counting_on_a_constructed_case():
    t = np.arange(0.0, 21.0)
    e = np.zeros((5, t.size, 6))
    e[0, 12, 0] = 1500.0  # late and large: divergent
    e[1, 5, :2] = 2000.0  # large but before 10 s: not divergent
    e[2, 15, :2] = 800.0  # horizontal 1131 m at t = 15: divergent
    e[3, 18, 1] = np.nan  # lost: divergent
    ok = np.array([True, True, True, True, False])  # 4: non-finite covariance
    np.testing.assert_array_equal(divergent_paths(e, t, ok), [True, False, True, True, True])


def test_path_metrics_count_nan_and_flagged_paths_as_lost():
    t = np.arange(0.0, 21.0)
    e = np.zeros((4, t.size, 6))
    e[1, 15:, :2] = np.nan  # no estimate from 15 s on
    e[2, 12, 0] = 1500.0
    ok = np.array([True, True, True, False])
    m = path_metrics([10, 11, 12, 13], e, t, ok)
    assert list(m["track_lost"]) == [False, True, True, True]
    assert list(m["track_id"]) == [10, 11, 12, 13]
    assert m["horizontal_err_max_m"].iloc[2] == 1500.0 and np.isnan(m["horizontal_err_max_m"][1])
