"""The ``radar2d`` real-motion table (experiment ``radar2d_real_motion``, ``report:
real_motion``): alpha-beta, the fuzzy multi-model tracker and the IMM on vessels of an AIS
recording (``real_motion.py``), one row per tracker and kind of window (``all``, ``turn``:
the course changes by more than ``real.turn_deg``, ``straight``: the others).

Per run, from the scan where the trackers' memory window is full, (J - 1) scan periods, on
(J: the longest memory among the dataset's trackers, as in the simulated table): the
position error at each scan, its mean and maximum; ``track_lost`` as in the simulated table
(an error over the 30 m gate, none, or the tracker's own flag, at any of those scans). The
row: the mean error over runs and scans, the median and 95th percentile over the runs of
each run's maximum, the track-loss share (95 % Wilson interval) and, for ``fuzzy_mm``, the
median selected memory m. Each run's ``metrics.parquet`` holds its per-scan errors and status
(``metrics.per_scan_errors``).
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from tma.families.radar2d.metrics import DEFAULT_MEMORY, GATE_M, Segments, per_scan_errors
from tma.io.atomic import write_parquet_atomic
from tma.maths.stats import wilson_interval
from tma.tables.write import write_table

COLUMNS = ["estimator", "windows", "n_runs", "n_windows", "error_mean_m", "error_max_median_m",
           "error_max_p95_m", "track_loss", "track_loss_lo", "track_loss_hi", "m_median"]
INTRO = """Tracking real vessels: each run is a vessel of the AIS recording `{file}` over
{window:g} s in which it is underway within {reach:g} m of the radar ({windows} windows, {turns}
of them turning more than {turn:g} deg), scanned every {period:g} s with the scenario's plot
noise ({noise}), the windows repeated with new noise over the runs. From the scan where the
J-scan window is full ({fill:g} s) on: the mean position error over runs and scans, the median
and 95th percentile of each run's maximum error, the track-loss share (an error over
{gate:g} m, or no estimate, at any scan; 95 % Wilson interval) and the fuzzy tracker's median
memory m. Read beside the simulated `radar2d` table (a boat turning on a 300 m radius)."""


def _row(name, kind, per_scan, runs, fill_s) -> dict:
    late = per_scan[per_scan["t_s"] >= fill_s - 1e-9]
    per_run = late.groupby("track_id")["error_m"].agg(["mean", "max"])
    lost = per_scan.groupby("track_id")["track_lost"].first()
    k, n = int(lost.sum()), len(lost)
    lo, hi = wilson_interval(k, n)
    finite = per_run["max"].to_numpy(float)
    finite = np.where(np.isfinite(finite), finite, np.inf)
    return {"estimator": name, "windows": kind, "n_runs": n,
            "n_windows": int(runs.loc[lost.index, "window"].nunique()),
            "error_mean_m": float(np.nanmean(late["error_m"])),
            "error_max_median_m": float(np.median(finite)),
            "error_max_p95_m": float(np.percentile(finite, 95)),
            "track_loss": k / n if n else np.nan, "track_loss_lo": float(lo),
            "track_loss_hi": float(hi),
            "m_median": float(np.nanmedian(late["m"])) if "m" in late else np.nan}


def write_real_motion_table(entries, tables_dir, name: str) -> list[Path]:
    """``<name>.csv`` and ``<name>.md`` from the runs ``entries`` of real-motion datasets
    (``scenario.real.file``); none without one."""
    rows, config = [], None
    for entry in entries:
        truth = entry.dataset.read_truth()
        config = entry.dataset.manifest["config"]
        if truth is None or "window" not in truth:
            continue
        memory = max((e.manifest["config"].get("memory", DEFAULT_MEMORY) for e in entries
                      if e.dataset.name == entry.dataset.name), default=DEFAULT_MEMORY)
        fill = (memory - 1) * config["scan_period_s"]
        per_scan = per_scan_errors(entry.estimates, truth,
                                   Segments({}, fill, np.nan, ()))
        write_parquet_atomic(entry.run_root / "metrics.parquet",
                             pa.Table.from_pandas(per_scan, preserve_index=False))
        runs = truth.groupby("track_id")[["window", "turning"]].first()
        for kind, keep in (("all", runs.index), ("turn", runs.index[runs["turning"]]),
                           ("straight", runs.index[~runs["turning"]])):
            if len(keep):
                rows.append(_row(entry.estimator, kind,
                                 per_scan[per_scan["track_id"].isin(keep)], runs, fill))
        windows = runs.drop_duplicates("window")
    if not rows:
        return []
    table = pd.DataFrame(rows, columns=COLUMNS)
    real = config["real"]
    intro = INTRO.format(file=real["file"], window=real["window_s"], reach=real["max_range_m"],
                         windows=len(windows), turns=int(windows["turning"].sum()),
                         turn=real["turn_deg"], period=config["scan_period_s"],
                         noise=(f"isotropic, {config['sigma_m']:g} m" if config["noise"] ==
                                "cartesian" else "polar"), fill=fill, gate=GATE_M)
    shown = pd.DataFrame({
        "tracker": table["estimator"], "windows": table["windows"], "runs": table["n_runs"],
        "error mean / med max / p95 max (m)": [
            f"{a:.1f} / {b:.1f} / {c:.1f}" for a, b, c in
            table[["error_mean_m", "error_max_median_m", "error_max_p95_m"]].to_numpy()],
        "track loss": [f"{100 * a:.1f} % ({100 * b:.1f}-{100 * c:.1f})" for a, b, c in
                       table[["track_loss", "track_loss_lo", "track_loss_hi"]].to_numpy()],
        "m median": table["m_median"].map(lambda x: "-" if pd.isna(x) else f"{x:g}"),
    })
    return write_table(Path(tables_dir), name, "Vessel tracking on real motion (AIS): fuzzy "
                       "multi-model alpha-beta vs alpha-beta vs IMM", intro, table, shown,
                       float_format="%.6g")
