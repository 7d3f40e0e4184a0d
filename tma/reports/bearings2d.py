"""``bearings2d`` outputs: the comparison table (md, csv, png) and, for datasets without
truth (ingested logs), a per-track report of the estimated kinematics now with 1-sigma
uncertainties from the Gauss-Newton covariance (J^T J)^-1 sigma^2."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402

from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.metrics.bearings2d import (  # noqa: E402
    REGIONS,
    TABLE_COLUMNS,
    kinematics_at,
    summary_row,
    track_metrics,
)
from tma.reports import markdown_table, save_figure, write_csv, write_markdown  # noqa: E402

INTRO = """Bearings-only TMA of a constant-velocity target from a manoeuvring observer
(`../shared/specs/bearings2d.md`). Each row: one estimator at one bearing noise sigma over
N simulated targets. Ref1..Ref4: share of targets whose estimate lies inside the success
region (bearing and distance at the end of the observation, course, speed; Ref1 is the
strictest), with the 95 % Wilson interval. sqrt(Ka) = sqrt(F(theta_hat)/n) in degrees: a
good maximum-likelihood fit gives sqrt(Ka) close to sigma. Nf: evaluations of F, Iter:
accepted LM steps (medians; direct estimators have none). Every number is read from the
run files under `data/runs/`."""

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
        "converged": table["n_converged"],
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


def track_report(estimates: pd.DataFrame, sigma_deg=None, time_origin_s=0.0) -> pd.DataFrame:
    """Per-track kinematics at each track's last bearing ("now") with 1-sigma errors.

    Covariance of theta: (J^T J)^-1 sigma^2 with sigma the nominal bearing noise, or, when
    ``sigma_deg`` is None, the residual estimate sigma^2 = F / (n - 4). Propagated to range,
    bearing, course and speed by their Jacobians (delta method).
    """
    e = estimates
    n = len(e)
    jtj = np.empty((n, 4, 4))
    for i in range(4):
        for j in range(i, 4):
            jtj[:, i, j] = jtj[:, j, i] = e[f"jtj_{i}{j}"].to_numpy()
    dof = np.maximum(e["n_bearings"].to_numpy() - 4, 1)
    sigma2 = (np.full(n, np.deg2rad(sigma_deg) ** 2) if sigma_deg is not None
              else e["cost_rad2"].to_numpy() / dof)
    cov_theta = np.full((n, 4, 4), np.nan)
    ok = np.linalg.cond(jtj) < 1e14
    cov_theta[ok] = np.linalg.inv(jtj[ok]) * sigma2[ok, None, None]

    t = e["t_last_s"].to_numpy()
    ox, oy = e["own_x_last_m"].to_numpy(), e["own_y_last_m"].to_numpy()
    x0, y0, vx, vy = (e[c].to_numpy() for c in ("x0_m", "y0_m", "vx_m_s", "vy_m_s"))
    bearing, rng, course, speed = kinematics_at(x0, y0, vx, vy, t, ox, oy)
    dx, dy = x0 + vx * t - ox, y0 + vy * t - oy
    # d(range, bearing, course, speed) / d(x0, y0, vx, vy); position now = p0 + v t
    G = np.zeros((n, 4, 4))
    G[:, 0, :2] = np.column_stack([dx, dy]) / rng[:, None]
    G[:, 1, :2] = np.column_stack([dy, -dx]) / (rng**2)[:, None]
    G[:, 0, 2:] = G[:, 0, :2] * t[:, None]
    G[:, 1, 2:] = G[:, 1, :2] * t[:, None]
    G[:, 2, 2:] = np.column_stack([vy, -vx]) / (speed**2)[:, None]
    G[:, 3, 2:] = np.column_stack([vx, vy]) / speed[:, None]
    sd = np.sqrt(np.einsum("nij,njk,nik->ni", G, cov_theta, G))
    return pd.DataFrame({
        "track_id": e["track_id"],
        "n_bearings": e["n_bearings"],
        "t_now_s": t + time_origin_s,
        "x_now_m": x0 + vx * t, "y_now_m": y0 + vy * t,
        "range_now_m": rng, "range_sd_m": sd[:, 0],
        "bearing_now_deg": np.rad2deg(bearing) % 360.0, "bearing_sd_deg": np.rad2deg(sd[:, 1]),
        "course_deg": np.rad2deg(course), "course_sd_deg": np.rad2deg(sd[:, 2]),
        "speed_m_s": speed, "speed_sd_m_s": sd[:, 3],
        "sqrt_ka_deg": np.rad2deg(np.sqrt(e["cost_rad2"] / e["n_bearings"])),
        "sigma_used_deg": np.rad2deg(np.sqrt(sigma2)),
        "converged": e["converged"].astype(bool),
    })


def write_track_report(report: pd.DataFrame, tables_dir, name: str, source: str) -> list[Path]:
    tables_dir = Path(tables_dir)
    paths = [tables_dir / f"{name}.csv", tables_dir / f"{name}.md"]
    write_csv(report, paths[0])
    def pm(value, sd, fmt):
        return [f"{v:{fmt}} ± {e:{fmt}}" for v, e in report[[value, sd]].to_numpy()]

    shown = pd.DataFrame({
        "track": report["track_id"], "n": report["n_bearings"],
        "t now (s)": report["t_now_s"].map("{:.1f}".format),
        "range now (m)": pm("range_now_m", "range_sd_m", ".0f"),
        "bearing now (deg)": pm("bearing_now_deg", "bearing_sd_deg", ".2f"),
        "course (deg)": pm("course_deg", "course_sd_deg", ".1f"),
        "speed (m/s)": pm("speed_m_s", "speed_sd_m_s", ".2f"),
        "sqrt(Ka) (deg)": report["sqrt_ka_deg"].map("{:.3g}".format),
        "converged": report["converged"],
    })
    intro = (f"Estimates per track of `{source}` (no ground truth). 'now' is each track's last "
             "bearing epoch; ± is one standard deviation from (J^T J)^-1 sigma^2, sigma as in "
             "column sigma_used_deg of the CSV (nominal, or estimated from the residuals).")
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
            report = track_report(entry.estimates, sigma_deg=m.get("sigma_deg"),
                                  time_origin_s=m.get("time_origin_s", 0.0))
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
