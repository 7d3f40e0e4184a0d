"""The published ``radar2d`` study and our table held against it (``tma.tables.paper``).

Transcribed from ``docs/families.md``, section "``radar2d``", what it published: Grinyak and
Devyatisilny (Vestnik MGTU, 2012). No table: the text's claims for the fuzzy tracker, read from
plots of single runs, each held here against one named statistic of ours over the Monte Carlo
runs. Data only: no tracker reads them.
"""

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from tma.families.radar2d.estimators.fuzzy_mm import Config as FuzzyConfig
from tma.families.radar2d.metrics import EPS_S, Segments, scan_matrix
from tma.families.radar2d.scenario import Config as ScenarioConfig
from tma.tables.paper import (
    by_setting,
    claim,
    config_differences,
    differs_reason,
    mean,
    median,
    quantile,
)

FAMILY = "radar2d"
ESTIMATOR = "fuzzy_mm"
SPEEDS = (10.0, 20.0)
# papers.md row -> (10 m/s, 20 m/s) as printed
TABLE = {
    "position error on the straight legs": ("10-12 m", "10-12 m"),
    "position error in the turn": ("at most 22 m", "at most 27 m"),
    "selected memory m on the straight legs": ("10 (the maximum)", "10"),
    "smallest m in the turn": ("5-6", "3-4"),
    "time for m to go from maximum to minimum and back": (
        "at most 10 s", "at most 10 s (interval [65, 75] s)"),
    "sigma_hat after about 60 s (20 scans)": ("stable, about 10 m", "stable, about 10 m"),
}
# the numbers in those claims: ranges [lo, hi] and bounds (None: no bound that side)
STRAIGHT_ERROR_M = (10.0, 12.0)
TURN_ERROR_MAX_M = {10.0: 22.0, 20.0: 27.0}
SMALLEST_M = {10.0: (5, 6), 20.0: (3, 4)}
DIP_MAX_S = 10.0
DIP_WINDOW_S = {20.0: (65.0, 75.0)}
SIGMA_TIMES_S = (60.0, 90.0, 120.0)
ABOUT_SIGMA_M = (9.0, 11.0)  # "about 10 m": within 10 %

INTRO = """Published: no table, only claims read from plots of single runs of the fuzzy
tracker (`docs/families.md`; transcribed in `tma/families/radar2d/paper.py`). Each is
held against one statistic of ours over the Monte Carlo runs of `fuzzy_mm`, named in the
table: a typical run (the median over runs of a per-run figure, with the order-statistic
interval) where the paper read a single run's curve, the mean over runs and scans where it read
a level. Ranges ("10-12 m", "5-6") hold when our statistic lies inside them, bounds ("at most")
when it does not exceed them."""

IGNORE = ("family", "n_tracks", "seed", "shard_size", "epoch_utc", "speed_m_s", "radar_xy_m",
          "range_sd_m", "bearing_sd_deg")  # the last three matter for polar noise only
ESTIMATOR_KEYS = ("memory", "bad_slope", "bad_centre", "residual_clip", "sigma_prior_m",
                  "sigma_hat_m")


@dataclass
class Run:
    """The fuzzy tracker at one speed: per-scan errors, m and sigma_hat
    (``metrics.per_scan_errors``), the dataset's segments, scenario and the run's config."""

    speed_m_s: float
    per_scan: pd.DataFrame
    segments: Segments
    scenario: dict
    config: dict


def _in(t, window):
    return (t >= window[0] - EPS_S) & (t <= window[1] + EPS_S)


def dip_times(m: np.ndarray, t: np.ndarray, turn: np.ndarray, memory: int) -> np.ndarray:
    """Per run (rows of ``m``, scans at ``t``): the last scan at m = J before the run's first
    minimum of m in the turn (mask ``turn``) and the first scan at m = J after it, as
    (n, 2) times (s). A run whose m stays at J in the turn dips for 0 s (both the minimum's
    time); a run that never returns to J ends at +inf, one never at J before starts at NaN."""
    at_max = m == memory
    scans = np.arange(t.size)
    turn_m = np.where(turn, m, np.inf)
    i_min = np.argmin(turn_m, axis=1)  # the first minimum in the turn
    before = at_max & (scans <= i_min[:, None])
    after = at_max & (scans >= i_min[:, None])
    start = np.where(before.any(axis=1),
                     t[np.where(before, scans, -1).max(axis=1).clip(0)], np.nan)
    end = np.where(after.any(axis=1),
                   t[np.where(after, scans, t.size).min(axis=1).clip(max=t.size - 1)], np.inf)
    return np.stack([start, end], axis=1)


def _text(lo, hi, unit=""):
    return f"[{lo:g}, {hi:g}]{unit}"


def run_claims(run: Run) -> list[dict]:
    """The six claims at one speed, from the fuzzy tracker's per-scan output."""
    v, segs = run.speed_m_s, run.segments
    memory = int(run.config.get("memory", FuzzyConfig().memory))
    setting = f"{ESTIMATOR}, {v:g} m/s"
    texts = {row: printed[SPEEDS.index(v)] for row, printed in TABLE.items()}
    err, t = scan_matrix(run.per_scan, "error_m", float)
    m, _ = scan_matrix(run.per_scan, "m", float)
    sigma, _ = scan_matrix(run.per_scan, "sigma_hat_m", float)
    straight = _in(t, segs.windows["straight1"]) | _in(t, segs.windows["straight2"])
    turn = _in(t, segs.windows["turn"])
    rows = []

    def add(row, statistic, ours, holds, note=""):
        rows.append(claim(FAMILY, row, setting, texts[row], statistic, ours, holds, note))

    row = "position error on the straight legs"
    level = mean(err[:, straight].mean(axis=1))
    add(row, "mean position error over runs and the scans of both straight legs (m); holds "
        f"inside {_text(*STRAIGHT_ERROR_M, ' m')}", level,
        STRAIGHT_ERROR_M[0] <= level.value <= STRAIGHT_ERROR_M[1])

    row = "position error in the turn"
    peak = err[:, turn].max(axis=1)
    typical = median(peak)
    add(row, "median over runs of each run's largest position error in the turn (m); holds "
        f"at most {TURN_ERROR_MAX_M[v]:g} m", typical, typical.value <= TURN_ERROR_MAX_M[v],
        f"95th percentile of the per-run maxima: {quantile(peak, 0.95).value:.1f} m")

    row = "selected memory m on the straight legs"
    per_run = np.median(m[:, straight], axis=1)
    level = median(per_run)
    add(row, f"median over runs of each run's median m on the straight legs; holds if J = "
        f"{memory}", level, level.value == memory,
        f"P(m = J) over runs and straight scans: {np.mean(m[:, straight] == memory):.3f}")

    row = "smallest m in the turn"
    lo, hi = SMALLEST_M[v]
    lowest = median(m[:, turn].min(axis=1))
    add(row, f"median over runs of each run's smallest m in the turn; holds inside "
        f"{_text(lo, hi)}", lowest, lo <= lowest.value <= hi)

    row = "time for m to go from maximum to minimum and back"
    dips = dip_times(m, t, turn, memory)
    duration = median(dips[:, 1] - dips[:, 0])
    window = DIP_WINDOW_S.get(v)
    start, end = median(dips[:, 0]).value, median(dips[:, 1]).value
    holds = duration.value <= DIP_MAX_S + EPS_S
    statistic = ("median over runs of the time from the last scan at m = J before the run's "
                 "first minimum of m in the turn to the first scan back at J (s); holds at most "
                 f"{DIP_MAX_S:g} s")
    if window:
        statistic += f" and if the median start and end lie in {_text(*window, ' s')}"
        holds &= window[0] - EPS_S <= start and end <= window[1] + EPS_S
    add(row, statistic, duration, holds,
        f"median start {start:g} s, end {end:g} s; scans every "
        f"{float(np.median(np.diff(t))):g} s")

    row = "sigma_hat after about 60 s (20 scans)"
    at = [mean(sigma[:, int(np.argmin(np.abs(t - s)))]) for s in SIGMA_TIMES_S]
    values = [a.value for a in at]
    holds = all(ABOUT_SIGMA_M[0] <= x <= ABOUT_SIGMA_M[1] for x in values)
    add(row, "mean over runs of sigma_hat at the scans nearest "
        f"{', '.join(f'{s:g}' for s in SIGMA_TIMES_S)} s (m); holds if every one lies in "
        f"{_text(*ABOUT_SIGMA_M, ' m')} (10 m within 10 %: about 10 and stable)", at[0], holds,
        f"at {', '.join(f'{s:g}' for s in SIGMA_TIMES_S)} s: "
        f"{', '.join(f'{x:.2f}' for x in values)} m; ours is, as the spec defines it, the "
        "running RMS since the track start of the 2-D innovation norm (the turn's innovations "
        f"enter it; per axis it is {values[0] / np.sqrt(2):.2f} m at {SIGMA_TIMES_S[0]:g} s)")
    return rows


def _mismatch(run: Run) -> str:
    return differs_reason(
        config_differences(run.scenario, asdict(ScenarioConfig()), ignore=IGNORE),
        config_differences(run.config, asdict(FuzzyConfig()), keys=ESTIMATOR_KEYS))


def against_paper(runs: list[Run]) -> list[dict]:
    """Rows for ``tma.tables.paper``: every claim at both speeds (not comparable where the speed
    is not in the table or the settings are not the paper's)."""
    by = by_setting(runs, lambda r: float(r.speed_m_s), _mismatch)
    rows = []
    for v in SPEEDS:
        run = by.get(v)
        reason = ("fuzzy_mm at this speed is not in this table" if run is None
                  else _mismatch(run))
        if reason:
            rows += [claim(FAMILY, row, f"{ESTIMATOR}, {v:g} m/s", printed[SPEEDS.index(v)],
                           "-", None, None, reason) for row, printed in TABLE.items()]
        else:
            rows += run_claims(run)
    return rows
