"""Metrics of the ``radar2d`` family (the spec's "Metrics").

Per scan: the position error norm. Per segment (first straight after the window fills,
the turn, the second straight): the mean over runs and scans, and the median and 95th
percentile over runs of each run's maximum. The selected memory m (fuzzy tracker): median,
the per-run minimum in the turn, P(m = J) on the straight legs, the time to recover m = J
after the turn. sigma_hat at given times.

The segments follow from the dataset's scenario config (legs, scan period) and the trackers'
memory J (``segments``), so other legs give other segments; the default legs with J = 10
give the spec's 27-42 s, 45-90 s and 93-120 s.

Per run, ``track_lost`` (True or False, on each of its scans): the error exceeds the gate, or
is not finite (no estimate), at any scan from the window fill on, or the tracker flagged the
run (its ``status`` in its estimates, the tracker's own verdict, other than ``ok``). Track
loss is the share of runs ``track_lost``. A segment the scans do not reach (a shorter
scenario) gives NaN statistics.
"""

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tma.config_nodes import validate
from tma.families.radar2d.estimators.alphabeta import Config as AlphaBetaConfig
from tma.families.radar2d.scenario import Config, scan_times, vessel_path

GATE_M = 30.0
SEGMENT_NAMES = ("straight1", "turn", "straight2")
# The window of the spec's alpha-beta (J = 10): the segment rule's J for runs of trackers
# without a memory (the IMM alone), so their rows match those of a full table.
DEFAULT_MEMORY = AlphaBetaConfig().memory
EPS_S = 1e-9  # scan times and leg ends are sums of floats: compare with a tolerance


@dataclass(frozen=True)
class Segments:
    """Where one dataset's metrics look (all s). ``windows``: name -> (first scan, last scan)
    of each segment, inclusive, (NaN, NaN) when no scan falls in it; ``loss_from_s``: first
    scan gated for track loss (inf if the window never fills); ``turn_end_s``: end of the
    turn leg (recovery of m = J is timed from it); ``sigma_times_s``: sigma_hat is reported
    at the scans nearest these times."""

    windows: dict
    loss_from_s: float
    turn_end_s: float
    sigma_times_s: tuple


def segments(scenario: dict, memory: int = DEFAULT_MEMORY) -> Segments:
    """The segments of a ``radar2d`` scenario config (a dataset manifest's ``config``) for
    trackers of memory ``memory`` (J scans).

    Rule (``docs/families.md``): the turn is the first turn leg [a, b], scans
    a <= t <= b. The first straight runs from the scan where the J-scan window is first full,
    t = (J - 1) tau (before it the growing-memory fit is still settling), to the last scan
    before a; the second straight from the first scan after b to the last scan before the
    next turn leg (or the path's end). Track loss counts from the window fill. sigma_hat is
    read a third into the turn, at its end and at the path's end. Without a turn leg the
    first straight runs to the end and the turn, the second straight and the turn's sigma
    times are empty.
    """
    cfg = validate(Config, scenario, "radar2d dataset config")
    path = vessel_path(cfg)
    t = scan_times(cfg, path)
    fill = float(t[memory - 1]) if memory <= t.size else np.inf
    turns = [(s.t0_s, s.t0_s + s.duration_s) for s in path.segments if s.rate_rad_s != 0.0]
    a, b = turns[0] if turns else (np.inf, np.inf)
    following = turns[1][0] if len(turns) > 1 else np.inf

    def window(mask):
        return (float(t[mask][0]), float(t[mask][-1])) if mask.any() else (np.nan, np.nan)

    windows = {
        "straight1": window((t >= fill - EPS_S) & (t < a - EPS_S)),
        "turn": window((t >= a - EPS_S) & (t <= b + EPS_S)),
        "straight2": window((t > b + EPS_S) & (t < following - EPS_S)),
    }
    sigma_times = ((a + (b - a) / 3, b) if turns else ()) + (path.duration_s,)
    return Segments(windows, fill, b if turns else np.nan,
                    tuple(float(s) for s in sigma_times))


def _in(t, window):
    a, b = window
    return (t >= a - EPS_S) & (t <= b + EPS_S)  # NaN bounds: empty


def sigma_column(time_s: float) -> str:
    return f"sigma_hat_{time_s:g}s_m"


def per_scan_errors(estimates: pd.DataFrame, truth: pd.DataFrame, segs: Segments) -> pd.DataFrame:
    df = estimates.merge(truth[["track_id", "step", "x_m", "y_m"]], on=["track_id", "step"],
                         suffixes=("", "_true"), validate="one_to_one")
    df["error_m"] = np.hypot(df["x_m"] - df["x_m_true"], df["y_m"] - df["y_m_true"])
    late = df["t_s"] >= segs.loss_from_s - EPS_S
    lost = (~(df["error_m"] <= GATE_M) & late) | (df["status"] != "ok")  # NaN: no estimate
    df["track_lost"] = lost.groupby(df["track_id"]).transform("any").astype(bool)
    keep = ["track_id", "step", "t_s", "error_m"] + [c for c in ("m", "sigma_hat_m", "p_turn")
                                                     if c in df] + ["track_lost"]
    return df[keep].sort_values(["track_id", "step"], kind="stable").reset_index(drop=True)


def scan_matrix(per_scan: pd.DataFrame, column: str, dtype=None):
    """(n_runs, n_scans) array of a per-scan column (in ``dtype``) and the scan times."""
    wide = per_scan.pivot(index="track_id", columns="step", values=column)
    t = per_scan.groupby("step")["t_s"].first().to_numpy()
    return wide.to_numpy(dtype), t


def summary_row(per_scan: pd.DataFrame, estimator: str, speed: float, segs: Segments,
                memory=None) -> dict:
    """One table row; ``memory``: J of a tracker that selects its memory (else None)."""
    err, t = scan_matrix(per_scan, "error_m")
    row = {"estimator": estimator, "speed_m_s": speed, "n_runs": err.shape[0]}
    for name in SEGMENT_NAMES:
        seg = err[:, _in(t, segs.windows[name])]
        per_run_max = seg.max(axis=1) if seg.size else np.full(err.shape[0], np.nan)
        row[f"{name}_mean_m"] = seg.mean() if seg.size else np.nan
        row[f"{name}_max_median_m"] = np.median(per_run_max)
        row[f"{name}_max_p95_m"] = np.percentile(per_run_max, 95)
    row["track_loss"] = float(np.mean(per_scan.groupby("track_id")["track_lost"].first()))
    row.update(memory_stats(per_scan, memory, segs))
    if "p_turn" in per_scan:
        p, _ = scan_matrix(per_scan, "p_turn")
        turn = _in(t, segs.windows["turn"])
        row["p_turn_model_in_turn"] = np.nanmean(p[:, turn]) if turn.any() else np.nan
    else:
        row["p_turn_model_in_turn"] = np.nan
    return row


def memory_stats(per_scan: pd.DataFrame, memory, segs: Segments) -> dict:
    names = ["m_median", "m_min_turn_median", "p_m_max_straight", "recover_s_median",
             *map(sigma_column, segs.sigma_times_s)]
    if "m" not in per_scan or memory is None:
        return dict.fromkeys(names, np.nan)
    m, t = scan_matrix(per_scan, "m")
    sigma, _ = scan_matrix(per_scan, "sigma_hat_m")
    turn = _in(t, segs.windows["turn"])
    straight = _in(t, segs.windows["straight1"]) | _in(t, segs.windows["straight2"])
    after = t >= segs.turn_end_s - EPS_S  # NaN (no turn): nothing to recover from
    at_max = (m[:, after] == memory)
    first = np.where(at_max.any(axis=1), np.argmax(at_max, axis=1), -1)
    recover = (np.where(first >= 0, t[after][np.maximum(first, 0)] - segs.turn_end_s, np.nan)
               if after.any() else np.full(m.shape[0], np.nan))
    out = {
        "m_median": np.nanmedian(m),
        "m_min_turn_median": np.median(np.nanmin(m[:, turn], axis=1)) if turn.any() else np.nan,
        "p_m_max_straight": float(np.mean(m[:, straight] == memory)) if straight.any()
        else np.nan,
        "recover_s_median": np.nanmedian(recover) if np.isfinite(recover).any() else np.nan,
    }
    for s in segs.sigma_times_s:
        out[sigma_column(s)] = float(np.mean(sigma[:, np.argmin(np.abs(t - s))]))
    return out


def table_columns(sigma_times_s) -> list[str]:
    """The table's columns; the sigma_hat columns are named by their times (s), sorted."""
    return ["estimator", "speed_m_s", "n_runs",
            *[f"{s}_{k}" for s in SEGMENT_NAMES for k in ("mean_m", "max_median_m", "max_p95_m")],
            "track_loss", "m_median", "m_min_turn_median", "p_m_max_straight",
            "recover_s_median", *map(sigma_column, sorted(set(sigma_times_s))),
            "p_turn_model_in_turn"]
