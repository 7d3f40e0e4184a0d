"""``ranges2d`` outputs: one row per estimator over repeated runs, errors against the
``quadrature`` reference, a plot of both samplers' draws over the posterior, and the section
"Against the paper" (``tma.families.ranges2d.paper``).

Each run's ``status`` is its estimator's verdict (``tma.families.ranges2d.estimators.base``: ok,
not_converged, box_too_small, failed); the table counts runs per status (``n_<status>``) and
computes its statistics over the runs with an estimate (errors: where the reference has one
too)."""

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402
from scipy.special import ndtri  # noqa: E402  (norm.ppf; scipy.stats takes 0.5 s to import)

from tma.errors import ConfigError  # noqa: E402
from tma.families import estimator_class  # noqa: E402
from tma.families.ranges2d import paper  # noqa: E402
from tma.families.ranges2d.estimators.base import STATUSES  # noqa: E402
from tma.families.ranges2d.log import read_ranges_log  # noqa: E402
from tma.families.ranges2d.model import RangeModel  # noqa: E402
from tma.io import arrow  # noqa: E402
from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.paper import write_against_paper  # noqa: E402
from tma.tables import markdown_table, save_figure, write_csv, write_markdown  # noqa: E402

COLUMNS = [
    "estimator", "n_runs", "x_mean_m", "y_mean_m", "err_x_rms_m", "err_y_rms_m",
    "err_abs_max_m", "within_stated_error", "re_x_mean", "re_x_sd", "re_y_mean", "re_y_sd",
    "corr_x_mean", "corr_y_mean", "samples_mean", "samples_sd", "samples_median",
    "evaluations_mean", "reached_accuracy", "truth_rms_m", "seconds_per_run",
    *[f"n_{s}" for s in STATUSES],
]


def track_metrics(estimates: pd.DataFrame, reference: pd.DataFrame, truth, confidence):
    """Per run: error against the quadrature reference and whether it lies within the
    estimator's own stated error (z x SE per coordinate)."""
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
        out["truth_err_m"] = np.hypot(estimates["x_m"].to_numpy() - t["x_m"].to_numpy(),
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
        "truth_rms_m": (np.sqrt((m["truth_err_m"] ** 2).mean())
                        if "truth_err_m" in m else np.nan),
        "seconds_per_run": seconds_per_run,
        **counts,
    }


def _seconds_per_run(run_root: Path) -> float:
    timing = json.loads((run_root / "timing.json").read_text())["shards"].values()
    return sum(s["seconds"] for s in timing) / max(sum(s["rows"] for s in timing), 1)


def aggregate_runs(entries, tables_dir, table_name) -> list[Path]:
    reference = next((e for e in entries if estimator_class(e.estimator).reference), None)
    if reference is None:
        raise ConfigError("the ranges2d table measures errors against 'quadrature': "
                          "include estimator=quadrature")
    rows, samples, runs = [], {}, []
    for e in entries:
        confidence = e.manifest["config"].get("confidence", 0.95)
        metrics = track_metrics(e.estimates, reference.estimates, e.dataset.read_truth(),
                                confidence)
        write_parquet_atomic(e.run_root / "metrics.parquet",
                             pa.Table.from_pandas(metrics, preserve_index=False))
        rows.append(summary_row(e.estimator, metrics, _seconds_per_run(e.run_root)))
        if e.estimator in paper.ESTIMATORS:
            runs.append(paper.Run(e.estimator, metrics, e.dataset.manifest["config"],
                                  e.manifest["config"]))
        if (e.run_root / "samples.parquet").exists():
            samples[e.estimator] = arrow.read_table(e.run_root / "samples.parquet").to_pandas()
    table = pd.DataFrame(rows, columns=COLUMNS)
    tables_dir = Path(tables_dir)
    paths = [tables_dir / f"{table_name}.{ext}" for ext in ("csv", "md", "png")]
    write_csv(table, paths[0], float_format="%.6g")

    by = table.set_index("estimator")
    headline = ""
    if {"prior_is", "adaptive_is"} <= set(by.index):
        ratio = by.loc["prior_is", "samples_mean"] / by.loc["adaptive_is", "samples_mean"]
        headline = (f"**Samples needed, prior / adaptive: {ratio:.1f}x** (mean over runs, "
                    "bisection evaluations included) for the same accuracy target.")
    shown = pd.DataFrame({
        "estimator": table["estimator"], "runs": table["n_runs"],
        "x (m)": table["x_mean_m"].map("{:.3f}".format),
        "y (m)": table["y_mean_m"].map("{:.3f}".format),
        "RMS error x / y vs quadrature (m)": [f"{a:.3f} / {b:.3f}" for a, b in
                                              table[["err_x_rms_m", "err_y_rms_m"]].to_numpy()],
        "within own 95 % error": table["within_stated_error"].map("{:.1%}".format),
        "RE x (mean ± sd)": [_pm(a, b) for a, b in table[["re_x_mean", "re_x_sd"]].to_numpy()],
        "RE y (mean ± sd)": [_pm(a, b) for a, b in table[["re_y_mean", "re_y_sd"]].to_numpy()],
        "corr num/den x, y": [f"{a:.2f}, {b:.2f}" if np.isfinite(a) else "-"
                              for a, b in table[["corr_x_mean", "corr_y_mean"]].to_numpy()],
        "samples used (mean ± sd)": [f"{a:,.0f} ± {b:,.0f}" for a, b in
                                     table[["samples_mean", "samples_sd"]].to_numpy()],
        "s per run": table["seconds_per_run"].map("{:.3f}".format),
        "runs by status": [", ".join(f"{row[f'n_{s}']} {s}" for s in STATUSES
                                     if row[f"n_{s}"]) for _, row in table.iterrows()],
    })
    ds = entries[0].dataset
    intro = (f"Posterior mean of a ship's position from ranges to landmarks "
             f"(`../shared/specs/ranges2d.md`), dataset `{ds.name}`. Each Monte Carlo "
             "estimator runs until both coordinates are within its accuracy target at its "
             "confidence by the delta-method error of a ratio (or a fixed count); errors are "
             "against `quadrature` (tensor Gauss-Legendre). RE is per single draw; samples "
             "include the bisection evaluations of the adaptive density. Seconds per run are "
             "wall time and vary between machines and runs. Statistics are over the runs "
             "with an estimate; runs by status: ok, not_converged (stopped at max_samples "
             "short of the target), box_too_small (posterior mass outside the estimator's "
             "box: no estimate), failed (degenerate weights).\n\n" + headline)
    write_markdown(paths[1], "Range-only navigation: Bayesian mean by importance sampling",
                   intro, markdown_table(shown))
    _plot(paths[2], ds, reference.estimates, samples)
    return paths + write_paper_section(runs, reference.estimates, paths[1])


def write_paper_section(runs: list, reference: pd.DataFrame, markdown_path: Path) -> list[Path]:
    """"Against the paper" (``tma.families.ranges2d.paper``): appended to the table's
    Markdown, and ``<table>_paper.csv`` beside it."""
    return write_against_paper(paper.against_paper(runs, reference), markdown_path,
                               paper.INTRO)


def _pm(a, b):
    return "-" if not np.isfinite(a) else f"{a:.2f} ± {b:.2f}"


def _plot(path, dataset, reference, samples):
    log = read_ranges_log(dataset.verified_path(dataset.shard_paths[0]))
    model = RangeModel.from_ranges(
        log.landmarks_m, log.ranges_m[0], log.model["sigma_m"], log.model["prior_mean_m"],
        log.model["prior_sd_m"])
    centre = reference.set_index("track_id").loc[log.track_id[0], ["x_m", "y_m"]].to_numpy()
    names = sorted(samples) or ["(no samplers)"]
    fig, axes = plt.subplots(1, len(names), figsize=(5.5 * len(names), 5), squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        pts = samples.get(name)
        span = 400.0
        grid = np.linspace(-span, span, 401)
        gx, gy = np.meshgrid(grid, grid)
        logf = model.log_kernel(gx, gy)
        ax.contour(gx, gy, np.exp(logf - logf.max()), levels=[1e-4, 1e-2, 0.1, 0.5],
                   colors="k", linewidths=0.8)
        if pts is not None:
            ax.plot(pts["x_m"], pts["y_m"], ".", ms=1.5, alpha=0.4, label=f"{name} draws")
        ax.plot(*centre, "r+", ms=12, label="quadrature mean")
        ax.set_xlim(-span, span)
        ax.set_ylim(-span, span)
        ax.set_aspect("equal")
        ax.set_title(name)
        ax.set_xlabel("x east (m)")
        ax.set_ylabel("y north (m)")
        ax.legend(loc="lower left", fontsize=8)
    fig.suptitle("First draws of each sampler over the posterior (contours of f2/max)")
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
