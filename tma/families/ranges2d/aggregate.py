"""``ranges2d`` outputs: one row per estimator over repeated runs (``metrics``), errors against
the ``quadrature`` reference, a plot of both samplers' draws over the posterior, and the
section "Against the paper" (``tma.families.ranges2d.paper``)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402

from tma.errors import ConfigError  # noqa: E402
from tma.families import estimator_class  # noqa: E402
from tma.families.ranges2d import paper  # noqa: E402
from tma.families.ranges2d.estimators.base import STATUSES  # noqa: E402
from tma.families.ranges2d.log import read_ranges_log  # noqa: E402
from tma.families.ranges2d.metrics import COLUMNS, summary_row, track_metrics  # noqa: E402
from tma.families.ranges2d.model import RangeModel  # noqa: E402
from tma.io import arrow  # noqa: E402
from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.tables.write import fixed_layout, save_figure, table_subplots, write_table  # noqa: E402


def aggregate_runs(entries, tables_dir, table_name, progress=None, table_kind=None
                   ) -> list[Path]:
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
        rows.append(summary_row(e.estimator, metrics, e.seconds_per_track))
        if e.estimator in paper.ESTIMATORS:
            runs.append(paper.Run(e.estimator, metrics, e.dataset.manifest["config"],
                                  e.manifest["config"]))
        if (e.run_root / "samples.parquet").exists():
            samples[e.estimator] = arrow.read_table(e.run_root / "samples.parquet").to_pandas()
    table = pd.DataFrame(rows, columns=COLUMNS)
    plot = Path(tables_dir) / f"{table_name}.png"

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
             f"(`docs/families.md`), dataset `{ds.name}`. Each Monte Carlo "
             "estimator runs until both coordinates are within its accuracy target at its "
             "confidence by the delta-method error of a ratio (or a fixed count); errors are "
             "against `quadrature` (tensor Gauss-Legendre). RE is per single draw; samples "
             "include the bisection evaluations of the adaptive density. Seconds per run are "
             "wall time and vary between machines and runs. Statistics are over the runs "
             "with an estimate; runs by status: ok, not_converged (stopped at max_samples "
             "short of the target), box_too_small (posterior mass outside the estimator's "
             "box: no estimate), failed (degenerate weights).\n\n" + headline)
    paths = write_table(tables_dir, table_name,
                        "Range-only navigation: Bayesian mean by importance sampling", intro,
                        table, shown, float_format="%.6g",
                        paper=(paper.against_paper(runs, reference.estimates), paper.INTRO))
    _plot(plot, ds, reference.estimates, samples)
    return [*paths, plot]


def _pm(a, b):
    return "-" if not np.isfinite(a) else f"{a:.2f} ± {b:.2f}"


def _plot(path, dataset, reference, samples):
    log = read_ranges_log(dataset.verified_path(dataset.shard_paths[0]))
    model = RangeModel.from_ranges(
        log.landmarks_m, log.ranges_m[0], log.model["sigma_m"], log.model["prior_mean_m"],
        log.model["prior_sd_m"])
    centre = reference.set_index("track_id").loc[log.track_id[0], ["x_m", "y_m"]].to_numpy()
    names = sorted(samples) or ["(no samplers)"]
    fig, axes = table_subplots(1, len(names), figsize=(5.5 * len(names), 5), squeeze=False)
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
    fixed_layout(fig)
    save_figure(fig, path)
    plt.close(fig)


# -- the Python API's hook (tma.api): what tma.estimate returns of ranges2d estimates

# the estimates' columns the results show, by the results' names of every family (bearings2d's:
# the position now)
SHOWN = {"track_id": "track_id", "x_m": "x_now_m", "y_m": "y_now_m", "se_x_m": "se_x_m",
         "se_y_m": "se_y_m", "samples_used": "samples_used", "status": "status"}


def results(run) -> tuple[pd.DataFrame, dict]:
    """``tma.estimate``'s results of ``run`` (``tma.api.Estimated``): one row per track, its
    position, the posterior mean ``x_now_m``, ``y_now_m``, with the estimator's own standard
    errors ``se_x_m``, ``se_y_m`` (Monte Carlo; 0 for ``quadrature``), the samples it used
    (bisection evaluations included) and ``status``; against the truth of a ``population``
    scenario (``concrete`` has none) the error of each coordinate (``x_err_m``, ``y_err_m``)
    and the distance (``position_err_m``, as ``metrics.track_metrics``). Tables:
    ``estimates`` (every column: relative errors, correlations, counts) and the sampler's
    first draws (``samples``) where it keeps them."""
    est = run.estimates
    frame = est[list(SHOWN)].rename(columns=SHOWN)
    if run.truth is not None:
        truth = run.truth.set_index("track_id").loc[est["track_id"]]
        frame["x_err_m"] = est["x_m"].to_numpy() - truth["x_m"].to_numpy()
        frame["y_err_m"] = est["y_m"].to_numpy() - truth["y_m"].to_numpy()
        frame["position_err_m"] = np.hypot(frame["x_err_m"], frame["y_err_m"])
    return frame, {"estimates": est, **run.side_tables}
