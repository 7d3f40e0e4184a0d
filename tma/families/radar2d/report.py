"""``radar2d`` outputs: one row per (estimator, speed), error-vs-time and m-vs-time plots."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402

from tma.families import estimator_class  # noqa: E402
from tma.families.radar2d.metrics import (  # noqa: E402
    GATE_M,
    SEGMENTS,
    TABLE_COLUMNS,
    per_scan_errors,
    summary_row,
)
from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.tables import markdown_table, save_figure, write_csv, write_markdown  # noqa: E402

INTRO = f"""Tracking a small fast boat that turns sharply (radius 300 m) in front of a coastal
radar (`../shared/specs/radar2d.md`); one row per tracker and boat speed over the Monte Carlo
runs. Segment columns: mean position error over runs and scans, and the median and 95th
percentile of each run's maximum error (first straight {SEGMENTS['straight1']} s, turn
{SEGMENTS['turn']} s, second straight {SEGMENTS['straight2']} s). Track loss: share of runs
whose error exceeds {GATE_M:g} m, or that have no estimate, at any scan from 27 s on (status
`track_lost` in each run's `metrics.parquet`). For `fuzzy_mm`: the selected memory
m (median; median over runs of the minimum in the turn; P(m = J) on the straight legs; median
time to recover m = J after the turn) and sigma_hat at 60/90/120 s. For `imm`: the mean
probability of the turn model during the turn."""


def _f(x, fmt="{:.1f}"):
    return "-" if pd.isna(x) else fmt.format(x)


def aggregate_runs(entries, tables_dir, table_name) -> list[Path]:
    rows, curves = [], []
    for e in entries:
        per_scan = per_scan_errors(e.estimates, e.dataset.read_truth())
        write_parquet_atomic(e.run_root / "metrics.parquet",
                             pa.Table.from_pandas(per_scan, preserve_index=False))
        speed = e.dataset.manifest["config"]["speed_m_s"]
        selects_memory = "m" in estimator_class(e.estimator).outputs
        rows.append(summary_row(per_scan, e.estimator, speed,
                                e.manifest["config"]["memory"] if selects_memory else None))
        g = per_scan.groupby("t_s")
        curve = pd.DataFrame({"t_s": g["error_m"].mean().index, "error_mean_m":
                              g["error_m"].mean().to_numpy()})
        if "m" in per_scan:
            curve["m_median"] = g["m"].median().to_numpy()
            curve["m_p10"] = g["m"].quantile(0.1).to_numpy()
            curve["m_p90"] = g["m"].quantile(0.9).to_numpy()
        curves.append((e.estimator, speed, curve))
    table = pd.DataFrame(rows, columns=TABLE_COLUMNS).sort_values(
        ["speed_m_s", "estimator"], kind="stable").reset_index(drop=True)
    tables_dir = Path(tables_dir)
    paths = [tables_dir / f"{table_name}.{ext}" for ext in ("csv", "md", "png")]
    paths.append(tables_dir / f"{table_name}_memory.png")
    write_csv(table, paths[0], float_format="%.6g")
    shown = pd.DataFrame({
        "estimator": table["estimator"], "speed (m/s)": table["speed_m_s"].map("{:g}".format),
        "runs": table["n_runs"],
        **{f"{s} mean / med max / p95 max (m)": [
            f"{a:.1f} / {b:.1f} / {c:.1f}" for a, b, c in
            table[[f"{s}_mean_m", f"{s}_max_median_m", f"{s}_max_p95_m"]].to_numpy()]
           for s in SEGMENTS},
        "track loss": table["track_loss"].map("{:.1%}".format),
        "m median": table["m_median"].map(lambda x: _f(x, "{:g}")),
        "m min in turn": table["m_min_turn_median"].map(lambda x: _f(x, "{:g}")),
        "P(m=J) straight": table["p_m_max_straight"].map(lambda x: _f(x, "{:.1%}")),
        "recover m=J (s)": table["recover_s_median"].map(lambda x: _f(x, "{:g}")),
        "sigma_hat 60/90/120 s (m)": [
            "-" if pd.isna(a) else f"{a:.1f} / {b:.1f} / {c:.1f}" for a, b, c in
            table[["sigma_hat_60s_m", "sigma_hat_90s_m", "sigma_hat_120s_m"]].to_numpy()],
        "P(turn model) in turn": table["p_turn_model_in_turn"].map(lambda x: _f(x, "{:.2f}")),
    })
    write_markdown(paths[1], "Vessel tracking: fuzzy multi-model alpha-beta vs alpha-beta vs IMM",
                   INTRO, markdown_table(shown))
    _plot(paths[2], paths[3], curves)
    return paths


def _shade(ax):
    a, b = SEGMENTS["turn"]
    ax.axvspan(a, b, color="0.9", zorder=0)


def _plot(error_path, memory_path, curves):
    speeds = sorted({s for _, s, _ in curves})
    fig, axes = plt.subplots(1, len(speeds), figsize=(6 * len(speeds), 4.5), squeeze=False)
    for ax, speed in zip(axes[0], speeds, strict=True):
        _shade(ax)
        for name, s, curve in sorted(curves, key=lambda c: c[0]):
            if s == speed:
                ax.plot(curve["t_s"], curve["error_mean_m"], marker=".", label=name)
        ax.axhline(GATE_M, color="r", lw=0.8, ls="--", label=f"gate {GATE_M:g} m")
        ax.set_title(f"{speed:g} m/s (turn shaded)")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("mean position error (m)")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    save_figure(fig, error_path)
    plt.close(fig)

    fig, axes = plt.subplots(1, len(speeds), figsize=(6 * len(speeds), 4.5), squeeze=False)
    for ax, speed in zip(axes[0], speeds, strict=True):
        _shade(ax)
        for name, s, curve in curves:
            if s == speed and "m_median" in curve:
                ax.fill_between(curve["t_s"], curve["m_p10"], curve["m_p90"], alpha=0.25,
                                label=f"{name} 10-90 %")
                ax.step(curve["t_s"], curve["m_median"], where="mid", label=f"{name} median")
        ax.set_title(f"selected memory m, {speed:g} m/s")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("m (scans)")
        ax.set_ylim(1.5, np.nanmax([c["m_p90"].max() for _, _, c in curves if "m_p90" in c]
                               or [10]) + 0.5)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    save_figure(fig, memory_path)
    plt.close(fig)
