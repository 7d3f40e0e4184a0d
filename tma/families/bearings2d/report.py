"""``bearings2d`` outputs: the comparison table (md, csv, png) and, for datasets without
truth (ingested logs), a per-track report of the estimated kinematics now with 1-sigma
uncertainties from the Gauss-Newton covariance (J^T J)^-1 sigma^2 and each track's status
(computed by the estimators, ``tma.families.bearings2d.status``)."""

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402

from tma.families.bearings2d.metrics import (  # noqa: E402
    REGIONS,
    TABLE_COLUMNS,
    summary_row,
    track_metrics,
)
from tma.families.bearings2d.status import STATUSES  # noqa: E402
from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.tables import markdown_table, save_figure, write_csv, write_markdown  # noqa: E402

INTRO = """Bearings-only TMA of a constant-velocity target from a manoeuvring observer
(`../shared/specs/bearings2d.md`). Each row: one estimator at one bearing noise sigma over
N simulated targets. Ref1..Ref4: share of targets whose estimate lies inside the success
region (bearing and distance at the end of the observation, course, speed; Ref1 is the
strictest), with the 95 % Wilson interval. sqrt(Ka) = sqrt(F(theta_hat)/n) in degrees: a
good maximum-likelihood fit gives sqrt(Ka) close to sigma. Nf: evaluations of F, Iter:
accepted LM steps (medians; direct estimators have none). Status: tracks per verdict
(ok / not_converged / poor_fit / unobservable, see the README). Consistent: share of the ok
tracks whose normalised error (theta_hat - theta)^T Sigma^-1 (theta_hat - theta), Sigma =
(J^T J)^-1 sigma^2, lies below the chi-square(4) 95 % point; about 95 % for honest one-sigma
errors. Every number is read from the run files under `data/runs/`."""

log = logging.getLogger(__name__)

REGION_NOTE = "\n".join(
    f"- {r.capitalize()}: bearing <= {b} deg, distance <= {d:.0%}, course <= {c} deg, "
    f"speed <= {s:.0%}" for r, (b, d, c, s) in REGIONS.items()
)


def _pct(rate, lo, hi):
    return f"{100 * rate:.1f} % ({100 * lo:.1f}-{100 * hi:.1f})"


def _num(x, fmt="{:.3g}"):
    return "-" if pd.isna(x) else fmt.format(x)


def write_table(rows: list[dict], tables_dir, name="bearings2d") -> list[Path]:
    """Write ``<name>.csv``, ``<name>.md`` and ``<name>.png``; returns their paths."""
    tables_dir = Path(tables_dir)
    table = pd.DataFrame(rows, columns=TABLE_COLUMNS).sort_values(
        ["estimator", "sigma_deg"], kind="stable").reset_index(drop=True)
    paths = [tables_dir / f"{name}.{ext}" for ext in ("csv", "md", "png")]
    write_csv(table, paths[0], float_format="%.6g")

    shown = pd.DataFrame({
        "estimator": table["estimator"],
        "sigma (deg)": table["sigma_deg"].map("{:g}".format),
        "N": table["n_tracks"],
        **{r.capitalize(): [_pct(*v) for v in table[[r, f"{r}_lo", f"{r}_hi"]].to_numpy()]
           for r in REGIONS},
        "sqrt(Ka) mean (deg)": table["sqrt_ka_mean"].map(_num),
        "sqrt(Ka) median (deg)": table["sqrt_ka_median"].map(_num),
        "Nf median": table["nf_median"].map(lambda x: _num(x, "{:g}")),
        "Iter median": table["iter_median"].map(lambda x: _num(x, "{:g}")),
        "status ok / not_conv / poor_fit / unobs": [
            " / ".join(str(v) for v in r) for r in table[[f"n_{s}" for s in STATUSES]].to_numpy()],
        "consistent (ok)": [_pct(*v) if pd.notna(v[0]) else "-" for v in
                            table[["consistent", "consistent_lo", "consistent_hi"]].to_numpy()],
    })
    write_markdown(paths[1], "Bearings-only TMA: success rates by estimator and noise", INTRO,
                   markdown_table(shown), "Success regions:\n" + REGION_NOTE)

    fig, axes = plt.subplots(2, 2, figsize=(10, 7), sharex=True, sharey=True)
    for ax, region in zip(axes.flat, REGIONS, strict=True):
        for estimator, rows_e in table.groupby("estimator", sort=True):
            x = rows_e["sigma_deg"].to_numpy()
            ax.plot(x, 100 * rows_e[region], marker="o", label=estimator)
            ax.fill_between(x, 100 * rows_e[f"{region}_lo"], 100 * rows_e[f"{region}_hi"],
                            alpha=0.2)
        ax.set_title(region.capitalize())
        ax.grid(True, alpha=0.3)
        ax.set_ylim(-2, 102)
    for ax in axes[1]:
        ax.set_xlabel("bearing noise sigma (deg)")
    for ax in axes[:, 0]:
        ax.set_ylabel("success rate (%)")
    axes[0, 0].legend()
    fig.suptitle("Bearings-only TMA: success rate vs noise (95 % Wilson bands)")
    fig.tight_layout()
    save_figure(fig, paths[2])
    plt.close(fig)
    return paths


REPORT_COLUMNS = ["range_now_m", "range_sd_m", "bearing_now_deg", "bearing_sd_deg",
                  "course_deg", "course_sd_deg", "speed_m_s", "speed_sd_m_s", "sigma_used_deg",
                  "fit_p_value", "status"]


def status_note(report: pd.DataFrame) -> list[str]:
    """Why a track is not ok, in words (empty for ok tracks)."""
    notes = []
    for row in report.itertuples(index=False):
        note = {
            "poor_fit": f"residual RMS {row.sqrt_ka_deg:.3g} deg vs sigma "
                        f"{row.sigma_used_deg:.3g} deg (p = {row.fit_p_value:.1e}): outliers, a "
                        "manoeuvring target, or bearings not in degrees?",
            "not_converged": "the estimator stopped before converging (max_iter or lambda_max)",
            "unobservable": f"range sd {row.range_sd_m / row.range_now_m:.0%} of the range: "
                            "not observable from this geometry (no own-ship manoeuvre? target "
                            "too far?)",
            "ok": "",
        }[row.status]
        if pd.isna(row.range_sd_m):
            note = "; ".join(filter(None, [note if row.status != "unobservable" else "",
                                           "J^T J is singular: no uncertainty can be given"]))
        notes.append(note)
    return notes


def track_report(estimates: pd.DataFrame, time_origin_s=0.0) -> pd.DataFrame:
    """Per-track kinematics at each track's last bearing ("now") with 1-sigma errors and
    the status, as the estimator computed them; a note says why a track is not ok."""
    e = estimates
    t = e["t_last_s"].to_numpy()
    report = pd.DataFrame({
        "track_id": e["track_id"],
        "n_bearings": e["n_bearings"],
        "t_now_s": t + time_origin_s,
        "x_now_m": e["x0_m"] + e["vx_m_s"] * t, "y_now_m": e["y0_m"] + e["vy_m_s"] * t,
        **{c: e[c] for c in REPORT_COLUMNS},
        "sqrt_ka_deg": np.rad2deg(np.sqrt(e["cost_rad2"] / e["n_bearings"])),
        "converged": e["converged"].astype(bool),
    })
    report["note"] = status_note(report)
    return report


def write_track_report(report: pd.DataFrame, tables_dir, name: str, source: str) -> list[Path]:
    tables_dir = Path(tables_dir)
    paths = [tables_dir / f"{name}.csv", tables_dir / f"{name}.md"]
    write_csv(report, paths[0])
    def pm(value, sd, fmt):
        return [f"{v:{fmt}} ± {e:{fmt}}" if np.isfinite(e) else f"{v:{fmt}} ± ? (unobservable)"
                for v, e in report[[value, sd]].to_numpy()]

    shown = pd.DataFrame({
        "track": report["track_id"], "n": report["n_bearings"],
        "t now (s)": report["t_now_s"].map("{:.1f}".format),
        "range now (m)": pm("range_now_m", "range_sd_m", ".0f"),
        "bearing now (deg)": pm("bearing_now_deg", "bearing_sd_deg", ".2f"),
        "course (deg)": pm("course_deg", "course_sd_deg", ".1f"),
        "speed (m/s)": pm("speed_m_s", "speed_sd_m_s", ".2f"),
        "sqrt(Ka) (deg)": report["sqrt_ka_deg"].map("{:.3g}".format),
        "status": report["status"],
        "why": report["note"],
    })
    intro = (f"Estimates per track of `{source}` (no ground truth). 'now' is each track's last "
             "bearing epoch; ± is one standard deviation from (J^T J)^-1 sigma^2, sigma as in "
             "column sigma_used_deg of the CSV (nominal, or estimated from the residuals). "
             "Trust only `ok` tracks; 'why' says what is wrong with the others.")
    write_markdown(paths[1], f"Bearings-only TMA estimates: {name}", intro, markdown_table(shown))
    return paths


def aggregate_runs(entries, tables_dir, table_name) -> list[Path]:
    """Metrics per track into each run dir; the comparison table for simulated datasets and
    a per-track report for each dataset without truth."""
    rows, written = [], []
    for entry in entries:
        truth = entry.dataset.read_truth()
        if truth is None:
            m = entry.dataset.manifest
            report = track_report(entry.estimates, time_origin_s=m.get("time_origin_s", 0.0))
            for row in report[report["status"] != "ok"].itertuples(index=False):
                log.warning("%s track %s: %s: %s", entry.dataset.name, row.track_id, row.status,
                            row.note)
            write_parquet_atomic(entry.run_root / "report.parquet",
                                 pa.Table.from_pandas(report, preserve_index=False))
            name = table_name if len(entries) == 1 else f"{entry.dataset.name}-{entry.estimator}"
            written += write_track_report(report, tables_dir, name,
                                          m.get("input", {}).get("path", entry.dataset.name))
            continue
        metrics = track_metrics(entry.estimates, truth)
        write_parquet_atomic(entry.run_root / "metrics.parquet",
                             pa.Table.from_pandas(metrics, preserve_index=False))
        sigma = entry.dataset.manifest["config"]["sigma_deg"]
        rows.append(summary_row(metrics, entry.estimator, sigma))
    if rows:
        written += write_table(rows, tables_dir, table_name)
    return written
