"""``ranges2d`` metrics: per run, the error against the ``quadrature`` reference (and the truth
of a population dataset) and whether it lies within the estimator's own stated error; per
estimator, one table row over the runs (``COLUMNS``).

Each run's ``status`` is its estimator's verdict (``tma.families.ranges2d.estimators.base``: ok,
not_converged, box_too_small, failed); a row counts runs per status (``n_<status>``) and
computes its statistics over the runs with an estimate (errors: where the reference has one
too)."""

import numpy as np
import pandas as pd
from scipy.special import ndtri  # norm.ppf; scipy.stats takes 0.5 s to import

from tma.families.ranges2d.estimators.base import STATUSES

COLUMNS = [
    "estimator", "n_runs", "x_mean_m", "y_mean_m", "err_x_rms_m", "err_y_rms_m",
    "err_abs_max_m", "within_stated_error", "re_x_mean", "re_x_sd", "re_y_mean", "re_y_sd",
    "corr_x_mean", "corr_y_mean", "samples_mean", "samples_sd", "samples_median",
    "evaluations_mean", "reached_accuracy", "truth_rms_m", "seconds_per_run",
    *[f"n_{s}" for s in STATUSES],
]


def track_metrics(estimates: pd.DataFrame, reference: pd.DataFrame, truth, confidence):
    """Per run: error against the quadrature reference (``err_x_m``, ``err_y_m``) and whether
    it lies within the estimator's own stated error (z x SE per coordinate); with a truth,
    the distance to it (``position_err_m``)."""
    ref = reference.set_index("track_id").loc[estimates["track_id"]]
    z = ndtri(0.5 + confidence / 2)
    out = pd.DataFrame({"track_id": estimates["track_id"].to_numpy()})
    out["err_x_m"] = estimates["x_m"].to_numpy() - ref["x_m"].to_numpy()
    out["err_y_m"] = estimates["y_m"].to_numpy() - ref["y_m"].to_numpy()
    out["within_stated_error"] = ((np.abs(out["err_x_m"]) <= z * estimates["se_x_m"].to_numpy()
                                   + 1e-9)
                                  & (np.abs(out["err_y_m"]) <= z * estimates["se_y_m"].to_numpy()
                                     + 1e-9))
    if truth is not None:
        t = truth.set_index("track_id").loc[estimates["track_id"]]
        out["position_err_m"] = np.hypot(estimates["x_m"].to_numpy() - t["x_m"].to_numpy(),
                                      estimates["y_m"].to_numpy() - t["y_m"].to_numpy())
    for col in ("re_x", "re_y", "corr_x", "corr_y", "samples_used", "n_evaluations",
                "reached_accuracy", "x_m", "y_m", "status"):
        out[col] = estimates[col].to_numpy()
    return out


def summary_row(name, m: pd.DataFrame, seconds_per_run) -> dict:
    counts = {f"n_{s}": int((m["status"] == s).sum()) for s in STATUSES}
    all_runs = m
    m = m[np.isfinite(m["x_m"]) & np.isfinite(m["y_m"])]  # runs with an estimate
    err = m[np.isfinite(m["err_x_m"]) & np.isfinite(m["err_y_m"])]  # ... and a reference
    return {
        "estimator": name, "n_runs": len(all_runs),
        "x_mean_m": m["x_m"].mean(), "y_mean_m": m["y_m"].mean(),
        "err_x_rms_m": np.sqrt((err["err_x_m"] ** 2).mean()),
        "err_y_rms_m": np.sqrt((err["err_y_m"] ** 2).mean()),
        "err_abs_max_m": err[["err_x_m", "err_y_m"]].abs().max().max(),
        "within_stated_error": err["within_stated_error"].mean(),
        "re_x_mean": m["re_x"].mean(), "re_x_sd": m["re_x"].std(),
        "re_y_mean": m["re_y"].mean(), "re_y_sd": m["re_y"].std(),
        "corr_x_mean": m["corr_x"].mean(), "corr_y_mean": m["corr_y"].mean(),
        "samples_mean": m["samples_used"].mean(), "samples_sd": m["samples_used"].std(),
        "samples_median": m["samples_used"].median(),
        "evaluations_mean": m["n_evaluations"].mean(),
        "reached_accuracy": float((all_runs["status"] == "ok").mean()),
        "truth_rms_m": (np.sqrt((m["position_err_m"] ** 2).mean())
                        if "position_err_m" in m else np.nan),
        "seconds_per_run": seconds_per_run,
        **counts,
    }
