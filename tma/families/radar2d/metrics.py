"""Metrics of the ``radar2d`` family (the spec's "Metrics").

Per scan: the position error norm. Per segment (first straight after the window fills,
the turn, the second straight): the mean over runs and scans, and the median and 95th
percentile over runs of each run's maximum. The selected memory m (fuzzy tracker): median,
the per-run minimum in the turn, P(m = J) on the straight legs, the time to recover m = J
after the turn. sigma_hat at given times.

Per run, ``status``: ``track_lost`` when the error exceeds the gate, or is not finite (no
estimate), at any scan from the first segment on, or when the tracker flagged the run
(``status`` other than ``ok`` in its estimates); else ``ok``. Track loss is the share of runs
``track_lost``. A segment the scans do not reach (a shorter scenario) gives NaN statistics.
"""

import numpy as np
import pandas as pd

SEGMENTS = {"straight1": (27.0, 42.0), "turn": (45.0, 90.0), "straight2": (93.0, 120.0)}
TURN_END_S = 90.0
SIGMA_TIMES_S = (60.0, 90.0, 120.0)
GATE_M = 30.0
STATUSES = ("ok", "track_lost")


def per_scan_errors(estimates: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    df = estimates.merge(truth[["track_id", "step", "x_m", "y_m"]], on=["track_id", "step"],
                         suffixes=("", "_true"), validate="one_to_one")
    df["error_m"] = np.hypot(df["x_m"] - df["x_m_true"], df["y_m"] - df["y_m_true"])
    late = df["t_s"] >= SEGMENTS["straight1"][0] - 1e-9
    lost = (~(df["error_m"] <= GATE_M) & late) | (df["status"] != "ok")  # NaN: no estimate
    lost_runs = lost.groupby(df["track_id"]).transform("any")
    df["status"] = np.where(lost_runs, "track_lost", "ok")
    keep = ["track_id", "step", "t_s", "error_m"] + [c for c in ("m", "sigma_hat_m", "p_turn")
                                                     if c in df] + ["status"]
    return df[keep].sort_values(["track_id", "step"], kind="stable").reset_index(drop=True)


def _matrix(per_scan: pd.DataFrame, column: str):
    """(n_runs, n_scans) array of a per-scan column and the scan times."""
    wide = per_scan.pivot(index="track_id", columns="step", values=column)
    t = per_scan.groupby("step")["t_s"].first().to_numpy()
    return wide.to_numpy(), t


def summary_row(per_scan: pd.DataFrame, estimator: str, speed: float, memory=None) -> dict:
    err, t = _matrix(per_scan, "error_m")
    row = {"estimator": estimator, "speed_m_s": speed, "n_runs": err.shape[0]}
    for name, (a, b) in SEGMENTS.items():
        seg = err[:, (t >= a - 1e-9) & (t <= b + 1e-9)]
        per_run_max = seg.max(axis=1) if seg.size else np.full(err.shape[0], np.nan)
        row[f"{name}_mean_m"] = seg.mean() if seg.size else np.nan
        row[f"{name}_max_median_m"] = np.median(per_run_max)
        row[f"{name}_max_p95_m"] = np.percentile(per_run_max, 95)
    status = per_scan.groupby("track_id")["status"].first()
    row["track_loss"] = float(np.mean(status == "track_lost"))
    row.update(memory_stats(per_scan, memory))
    if "p_turn" in per_scan:
        p, _ = _matrix(per_scan, "p_turn")
        a, b = SEGMENTS["turn"]
        row["p_turn_model_in_turn"] = np.nanmean(p[:, (t >= a) & (t <= b)])
    else:
        row["p_turn_model_in_turn"] = np.nan
    return row


def memory_stats(per_scan: pd.DataFrame, memory) -> dict:
    names = ["m_median", "m_min_turn_median", "p_m_max_straight", "recover_s_median",
             *[f"sigma_hat_{int(s)}s_m" for s in SIGMA_TIMES_S]]
    if "m" not in per_scan or memory is None:
        return dict.fromkeys(names, np.nan)
    m, t = _matrix(per_scan, "m")
    sigma, _ = _matrix(per_scan, "sigma_hat_m")
    turn = (t >= SEGMENTS["turn"][0]) & (t <= SEGMENTS["turn"][1])
    straight = np.zeros_like(turn)
    for name in ("straight1", "straight2"):
        a, b = SEGMENTS[name]
        straight |= (t >= a) & (t <= b)
    after = t >= TURN_END_S
    at_max = (m[:, after] == memory)
    first = np.where(at_max.any(axis=1), np.argmax(at_max, axis=1), -1)
    recover = np.where(first >= 0, t[after][np.maximum(first, 0)] - TURN_END_S, np.nan)
    out = {
        "m_median": np.nanmedian(m),
        "m_min_turn_median": np.median(np.nanmin(m[:, turn], axis=1)) if turn.any() else np.nan,
        "p_m_max_straight": float(np.mean(m[:, straight] == memory)),
        "recover_s_median": np.nanmedian(recover) if np.isfinite(recover).any() else np.nan,
    }
    for s in SIGMA_TIMES_S:
        out[f"sigma_hat_{int(s)}s_m"] = float(np.mean(sigma[:, np.argmin(np.abs(t - s))]))
    return out


TABLE_COLUMNS = [
    "estimator", "speed_m_s", "n_runs",
    *[f"{s}_{k}" for s in SEGMENTS for k in ("mean_m", "max_median_m", "max_p95_m")],
    "track_loss", "m_median", "m_min_turn_median", "p_m_max_straight", "recover_s_median",
    *[f"sigma_hat_{int(s)}s_m" for s in SIGMA_TIMES_S], "p_turn_model_in_turn",
]
