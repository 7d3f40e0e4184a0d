"""Wilson intervals and the bearings2d success regions on constructed cases."""

import numpy as np
import pandas as pd
import pytest

from tma.families.bearings2d.metrics import summary_row, track_metrics
from tma.maths.stats import wilson_interval


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(0, 10)
    assert lo == pytest.approx(0.0, abs=1e-12) and hi == pytest.approx(0.27753, abs=1e-5)
    lo, hi = wilson_interval(50, 100)
    assert lo == pytest.approx(0.40383, abs=1e-5) and hi == pytest.approx(0.59617, abs=1e-5)
    lo, hi = wilson_interval(10, 10)
    assert hi == pytest.approx(1.0) and lo == pytest.approx(0.72247, abs=1e-5)


def _case(x_shift=0.0, speed_factor=1.0, course_shift_deg=0.0, true_course_deg=90.0):
    c = np.deg2rad(true_course_deg)
    truth = pd.DataFrame({"track_id": [0], "x0_m": [0.0], "y0_m": [20000.0],
                          "vx_m_s": [10.0 * np.sin(c)], "vy_m_s": [10.0 * np.cos(c)]})
    speed, course = 10.0 * speed_factor, np.deg2rad(true_course_deg + course_shift_deg)
    jtj = {f"jtj_{i}{j}": [float(i == j) * 4.0] for i in range(4) for j in range(i, 4)}
    est = pd.DataFrame({
        "track_id": [0], "x0_m": [x_shift], "y0_m": [20000.0],
        "vx_m_s": [speed * np.sin(course)], "vy_m_s": [speed * np.cos(course)],
        "t_last_s": [0.0], "own_x_last_m": [0.0], "own_y_last_m": [0.0],
        "cost_rad2": [601 * np.deg2rad(0.5) ** 2], "n_bearings": [601],
        "n_f_evals": [12], "n_iter": [9], "converged": [True], "status": ["ok"],
        "sigma_used_deg": [0.5], **jtj,
    })
    return track_metrics(est, truth).iloc[0]


def test_regions_on_constructed_errors():
    exact = _case()
    assert all(exact[r] for r in ("ref1", "ref2", "ref3", "ref4"))
    assert exact["sqrt_ka_deg"] == pytest.approx(0.5)
    # 0.7 deg bearing error at 20 km: outside Ref1 (0.5 deg), inside Ref2..4 (1 deg)
    m = _case(x_shift=20000.0 * np.tan(np.deg2rad(0.7)))
    assert m["bearing_err_deg"] == pytest.approx(0.7, abs=1e-6)
    assert not m["ref1"] and m["ref2"] and m["ref4"]
    # speed 12 % high: only Ref4 (15 %) holds
    m = _case(speed_factor=1.12)
    assert [m[r] for r in ("ref1", "ref2", "ref3", "ref4")] == [False, False, False, True]
    # course error wraps: 359 deg estimated for a true 1 deg is -2 deg, not 358
    m = _case(true_course_deg=1.0, course_shift_deg=-2.0)
    assert m["course_err_deg"] == pytest.approx(-2.0)
    assert _case(course_shift_deg=4.9)["ref1"]


def test_normalised_error_is_the_closed_form():
    # J^T J = 4 I, sigma 0.5 deg: nees = 4 |theta_hat - theta|^2 / sigma^2 (rad)
    assert _case()["nees"] == 0.0
    m = _case(x_shift=30.0)
    assert m["nees"] == pytest.approx(4 * 30.0**2 / np.deg2rad(0.5) ** 2)


def test_summary_row_counts():
    metrics = pd.DataFrame({"ref1": [True, False], "ref2": [True, True], "ref3": [True, True],
                            "ref4": [True, True], "sqrt_ka_deg": [0.1, 0.3],
                            "n_f_evals": [10.0, 12.0], "n_iter": [8.0, 9.0],
                            "converged": [True, False], "status": ["ok", "poor_fit"],
                            "nees": [2.0, 50.0]})
    row = summary_row(metrics, "lm", 0.1)
    assert row["ref1"] == 0.5 and row["ref2"] == 1.0 and row["n_converged"] == 1
    assert (row["n_ok"], row["n_poor_fit"], row["n_unobservable"]) == (1, 1, 0)
    assert row["consistent"] == 1.0  # of the ok tracks only
    assert row["sqrt_ka_mean"] == pytest.approx(0.2) and row["nf_median"] == 11.0
