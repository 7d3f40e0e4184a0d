"""Metrics of the ``bearings2d`` family (see the spec's "Metrics per track").

Bearing and distance are compared at the end of each track's observation (its last bearing
epoch, from own-ship then); course and speed are constant. Errors of angles are wrapped to
[-180, 180) degrees; distance and speed errors are relative to the truth.
"""

import numpy as np
import pandas as pd

from tma.angles import bearing_from_north, course_from_velocity, wrap_to_180
from tma.metrics.stats import wilson_interval

# region: (bearing deg, distance relative, course deg, speed relative), all with <=
REGIONS = {
    "ref1": (0.5, 0.05, 5.0, 0.05),
    "ref2": (1.0, 0.10, 10.0, 0.10),
    "ref3": (1.0, 0.15, 10.0, 0.10),
    "ref4": (1.0, 0.15, 10.0, 0.15),
}


def kinematics_at(x0, y0, vx, vy, t, own_x, own_y):
    """Bearing (rad), distance (m), course (rad), speed (m/s) at time t from own-ship."""
    dx, dy = x0 + vx * t - own_x, y0 + vy * t - own_y
    return (bearing_from_north(dx, dy), np.hypot(dx, dy), course_from_velocity(vx, vy),
            np.hypot(vx, vy))


def track_metrics(estimates: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """One row per track: errors, region successes, sqrt(Ka) (deg), Nf, Iter, converged."""
    df = estimates.merge(truth, on="track_id", how="left", suffixes=("", "_true"),
                         validate="one_to_one")
    if df["x0_m_true"].isna().any():
        raise ValueError("estimates hold track ids that the truth table lacks")
    at_end = (df["t_last_s"].to_numpy(), df["own_x_last_m"].to_numpy(),
              df["own_y_last_m"].to_numpy())
    est = kinematics_at(*(df[c].to_numpy() for c in ("x0_m", "y0_m", "vx_m_s", "vy_m_s")), *at_end)
    tru = kinematics_at(*(df[c].to_numpy() for c in ("x0_m_true", "y0_m_true", "vx_m_s_true",
                                                     "vy_m_s_true")), *at_end)
    out = pd.DataFrame({
        "track_id": df["track_id"],
        "bearing_err_deg": wrap_to_180(np.rad2deg(est[0] - tru[0])),
        "distance_rel_err": (est[1] - tru[1]) / tru[1],
        "course_err_deg": wrap_to_180(np.rad2deg(est[2] - tru[2])),
        "speed_rel_err": (est[3] - tru[3]) / tru[3],
        "sqrt_ka_deg": np.rad2deg(np.sqrt(df["cost_rad2"] / df["n_bearings"])),
        "n_f_evals": df["n_f_evals"].astype(float),
        "n_iter": df["n_iter"].astype(float),
        "converged": df["converged"].astype(bool),
    })
    for name, (bearing, distance, course, speed) in REGIONS.items():
        out[name] = (
            (out["bearing_err_deg"].abs() <= bearing)
            & (out["distance_rel_err"].abs() <= distance)
            & (out["course_err_deg"].abs() <= course)
            & (out["speed_rel_err"].abs() <= speed)
        )
    return out


def summary_row(metrics: pd.DataFrame, estimator: str, sigma_deg: float) -> dict:
    """One table row: region success rates with 95 % Wilson intervals, sqrt(Ka), Nf, Iter."""
    n = len(metrics)
    row = {"estimator": estimator, "sigma_deg": sigma_deg, "n_tracks": n}
    for name in REGIONS:
        k = int(metrics[name].sum())
        lo, hi = wilson_interval(k, n)
        row.update({name: k / n, f"{name}_lo": float(lo), f"{name}_hi": float(hi)})
    ka = metrics["sqrt_ka_deg"]
    row.update({
        "sqrt_ka_mean": float(ka.mean()), "sqrt_ka_median": float(ka.median()),
        "nf_median": float(metrics["n_f_evals"].median()),
        "iter_median": float(metrics["n_iter"].median()),
        "n_converged": int(metrics["converged"].sum()),
    })
    return row


TABLE_COLUMNS = [
    "estimator", "sigma_deg", "n_tracks",
    *[f"{r}{s}" for r in REGIONS for s in ("", "_lo", "_hi")],
    "sqrt_ka_mean", "sqrt_ka_median", "nf_median", "iter_median", "n_converged",
]
