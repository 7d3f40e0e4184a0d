"""Metrics of the ``bearings2d`` family (see the spec's "Metrics per track").

Bearing and distance are compared at the end of each track's observation (its last bearing
epoch, from own-ship then); course and speed are constant. Errors of angles are wrapped to
[-180, 180) degrees; distance and speed errors are relative to the truth.
"""

import numpy as np
import pandas as pd
from scipy.stats import chi2

from tma.angles import wrap_to_180
from tma.families.bearings2d.status import STATUSES, kinematics_now
from tma.stats import wilson_interval

THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")
NEES_95 = float(chi2.ppf(0.95, 4))  # an ok track's normalised error lies below this 95 % of runs

# region: (bearing deg, distance relative, course deg, speed relative), all with <=
REGIONS = {
    "ref1": (0.5, 0.05, 5.0, 0.05),
    "ref2": (1.0, 0.10, 10.0, 0.10),
    "ref3": (1.0, 0.15, 10.0, 0.10),
    "ref4": (1.0, 0.15, 10.0, 0.15),
}


def jtj_matrices(estimates: pd.DataFrame) -> np.ndarray:
    """The stored upper triangle ``jtj_ij`` as full matrices ``(n, 4, 4)``."""
    jtj = np.empty((len(estimates), 4, 4))
    for i in range(4):
        for j in range(i, 4):
            jtj[:, i, j] = jtj[:, j, i] = estimates[f"jtj_{i}{j}"].to_numpy()
    return jtj


def normalised_error(df: pd.DataFrame) -> np.ndarray:
    """(theta_hat - theta)^T Sigma^-1 (theta_hat - theta) with Sigma = (J^T J)^-1 sigma^2,
    i.e. e^T J^T J e / sigma^2 (no inverse needed); NaN where sigma is 0. ``df``: estimates
    merged with the truth (truth columns suffixed ``_true``)."""
    e = df[list(THETA)].to_numpy() - df[[f"{c}_true" for c in THETA]].to_numpy()
    sigma2 = np.deg2rad(df["sigma_used_deg"].to_numpy()) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        nees = np.einsum("ni,nij,nj->n", e, jtj_matrices(df), e) / sigma2
    return np.where(sigma2 > 0, nees, np.nan)


def track_metrics(estimates: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """One row per track: errors, region successes, sqrt(Ka) (deg), Nf, Iter, converged,
    status and the normalised error of theta (NEES, chi-square(4) for a consistent fit)."""
    df = estimates.merge(truth, on="track_id", how="left", suffixes=("", "_true"),
                         validate="one_to_one")
    if df["x0_m_true"].isna().any():
        raise ValueError("estimates hold track ids that the truth table lacks")
    at_end = (df["t_last_s"].to_numpy(), df["own_x_last_m"].to_numpy(),
              df["own_y_last_m"].to_numpy())
    # (range, bearing, course, speed) at the last bearing
    est, _ = kinematics_now(df[list(THETA)].to_numpy(), *at_end)
    tru, _ = kinematics_now(df[[f"{c}_true" for c in THETA]].to_numpy(), *at_end)
    out = pd.DataFrame({
        "track_id": df["track_id"],
        "bearing_err_deg": wrap_to_180(np.rad2deg(est[1] - tru[1])),
        "distance_rel_err": (est[0] - tru[0]) / tru[0],
        "course_err_deg": wrap_to_180(np.rad2deg(est[2] - tru[2])),
        "speed_rel_err": (est[3] - tru[3]) / tru[3],
        "sqrt_ka_deg": np.rad2deg(np.sqrt(df["cost_rad2"] / df["n_bearings"])),
        "n_f_evals": df["n_f_evals"].astype(float),
        "n_iter": df["n_iter"].astype(float),
        "converged": df["converged"].astype(bool),
        "status": df["status"],
        "nees": normalised_error(df),
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
        **{f"n_{s}": int((metrics["status"] == s).sum()) for s in STATUSES},
    })
    ok = metrics["status"] == "ok"
    nees = metrics.loc[ok, "nees"]
    k, m = int((nees <= NEES_95).sum()), int(nees.notna().sum())
    lo, hi = wilson_interval(k, m)
    row.update({"consistent": k / m if m else np.nan, "consistent_lo": float(lo),
                "consistent_hi": float(hi)})
    return row


TABLE_COLUMNS = [
    "estimator", "sigma_deg", "n_tracks",
    *[f"{r}{s}" for r in REGIONS for s in ("", "_lo", "_hi")],
    "sqrt_ka_mean", "sqrt_ka_median", "nf_median", "iter_median", "n_converged",
    *[f"n_{s}" for s in STATUSES], "consistent", "consistent_lo", "consistent_hi",
]
