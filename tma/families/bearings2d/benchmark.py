"""The ``bearings2d`` benchmark table: each estimator against the Cramer-Rao bound, by bearing
noise sigma and outlier share (experiments ``bearings2d_benchmark``, ``bearings2d_outliers``).

One row per (estimator, sigma, outlier share) over the simulated targets of one dataset:
Ref1..Ref4 with 95 % Wilson intervals (as in the seed table), the RMSE of range (m), course
(deg) and speed (m/s) at each track's last bearing beside the root of the mean Cramer-Rao
bound and the efficiency = mean bound / MSE (``metrics.efficiency_row``), the share of ``ok``
tracks and of those whose normalised error lies below the chi-square(4) 95 % point
(``consistent``, about 95 % for honest one-sigma errors), both with Wilson intervals, and the
estimator's wall time per track (``RunEntry.seconds_per_track``: every shard's seconds over
its tracks; worker processes may share the machine, so it varies between runs and machines).
Runs of one estimator with a non-default config (e.g. ``mpekf`` with an innovation gate) are
told apart by those settings in the ``estimator`` column. The plot gives RMSE / root mean
bound (1 = the bound) per quantity and Ref1 against sigma, or against the outlier share when
only that varies. Every number is read from the run and dataset files.
"""

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from tma.config import to_plain  # noqa: E402
from tma.families import estimator_class  # noqa: E402
from tma.families.bearings2d.log import read_bearings_log  # noqa: E402
from tma.families.bearings2d.metrics import (  # noqa: E402
    EFFICIENCY,
    REGIONS,
    crlb_now,
    efficiency_row,
    errors_now,
    summary_row,
    track_metrics,
)
from tma.maths.stats import wilson_interval  # noqa: E402
from tma.tables.write import fixed_layout, save_figure, table_subplots, write_table  # noqa: E402

log = logging.getLogger(__name__)

UNITS = {"range": "m", "course": "deg", "speed": "m_s"}
COLUMNS = [
    "estimator", "sigma_deg", "outlier_prob", "n_tracks",
    *[f"{r}{s}" for r in REGIONS for s in ("", "_lo", "_hi")],
    *[f"{kind}_{q}_{UNITS[q]}" for q in EFFICIENCY for kind in ("rmse", "crlb")],
    *[f"efficiency_{q}" for q in EFFICIENCY],
    "n_failed", "ok", "ok_lo", "ok_hi", "consistent", "consistent_lo", "consistent_hi",
    "starts_changed", "starts_changed_lo", "starts_changed_hi", "ms_per_track",
]

INTRO = """Bearings-only TMA (`docs/families.md`): each estimator against the
Cramer-Rao lower bound (CRLB). One row per estimator, bearing noise sigma and outlier share
(bearings replaced by draws uniform on the circle) over N simulated targets. Ref1..Ref4:
share of targets inside each success region, 95 % Wilson interval. RMSE of range (m), course
(deg) and speed (m/s) at each track's last bearing, beside the root of the mean bound,
sqrt(mean of G (J^T J)^-1 G^T sigma^2) at the truth; efficiency = mean bound / mean squared
error (1: as good as any unbiased estimator can be; the CRLB counts the Gaussian noise only,
not the outliers); tracks without a finite estimate (`failed`) are left out of these. ok: share
of tracks with status `ok`; consistent: share of the ok tracks whose normalised error lies
below the chi-square(4) 95 % point (about 95 % when the one-sigma errors are honest). ms/track:
the estimator's wall time per track (worker processes; varies with the machine's load).
Every number is read from the run files under `data/runs/`."""


def estimator_label(name: str, config: dict) -> str:
    """``name``, followed by the settings in which ``config`` differs from its defaults."""
    try:
        defaults = to_plain(estimator_class(name).Config())
    except Exception:  # an estimator no longer registered: its name alone
        return name
    changed = [f"{k}={config[k]}" for k in sorted(config)
               if k != "name" and k in defaults and config[k] != defaults[k]]
    return " ".join([name, *changed])


def dataset_bounds(dataset, truth: pd.DataFrame) -> pd.DataFrame:
    """``metrics.crlb_now`` of every track of a simulated dataset (its shards verified)."""
    return pd.concat([crlb_now(read_bearings_log(dataset.verified_path(rel)), truth)
                      for rel in dataset.shard_paths], ignore_index=True)


def outlier_prob(dataset) -> float:
    return float((dataset.manifest["config"].get("outliers") or {}).get("prob", 0.0))


def benchmark_row(label, sigma, prob, estimates, truth, bounds, ms) -> dict:
    """One table row (``COLUMNS``) from one run's estimates."""
    metrics = track_metrics(estimates, truth)
    row = summary_row(metrics, label, sigma)
    n = row["n_tracks"]
    ok_lo, ok_hi = wilson_interval(row["n_ok"], n)
    row.update(efficiency_row(errors_now(estimates, truth), bounds))
    for q, unit in UNITS.items():
        row[f"rmse_{q}_{unit}"] = row.pop(f"rmse_{q}")
        row[f"crlb_{q}_{unit}"] = row.pop(f"crlb_{q}")
    row.update({"outlier_prob": prob, "ok": row["n_ok"] / n, "ok_lo": float(ok_lo),
                "ok_hi": float(ok_hi), "ms_per_track": ms})
    row.update(starts_changed(estimates))
    return {c: row[c] for c in COLUMNS}


def starts_changed(estimates: pd.DataFrame) -> dict:
    """The price of local minima: the share of tracks whose solution an extra start of
    ``lm starts=K`` changed (``start_won > 0``), with its Wilson interval; blank for an
    estimator with one start."""
    if "start_won" not in estimates:
        return {"starts_changed": np.nan, "starts_changed_lo": np.nan,
                "starts_changed_hi": np.nan}
    changed, n = int((estimates["start_won"] > 0).sum()), len(estimates)
    lo, hi = wilson_interval(changed, n)
    return {"starts_changed": changed / n, "starts_changed_lo": float(lo),
            "starts_changed_hi": float(hi)}


def benchmark_table(entries) -> pd.DataFrame:
    """The table of the runs ``entries`` (``tma.stages.aggregate.RunEntry``) of simulated
    datasets."""
    rows, bounds = [], {}
    for entry in entries:
        truth = entry.dataset.read_truth()
        if truth is None:
            continue
        if entry.dataset.name not in bounds:  # the bound depends on the dataset alone
            bounds[entry.dataset.name] = dataset_bounds(entry.dataset, truth)
        config = entry.manifest.get("config") or {}
        rows.append(benchmark_row(
            estimator_label(entry.estimator, config), entry.dataset.manifest["config"]["sigma_deg"],
            outlier_prob(entry.dataset), entry.estimates, truth, bounds[entry.dataset.name],
            1e3 * entry.seconds_per_track))
    return pd.DataFrame(rows, columns=COLUMNS).sort_values(
        ["estimator", "outlier_prob", "sigma_deg"], kind="stable").reset_index(drop=True)


def _pct(rate, lo, hi):
    return "-" if pd.isna(rate) else f"{100 * rate:.1f} ({100 * lo:.1f}-{100 * hi:.1f})"


def _num(x, fmt="{:.3g}"):
    return "-" if pd.isna(x) else fmt.format(x)


def shown_table(table: pd.DataFrame) -> pd.DataFrame:
    """The Markdown form: rates in percent with their intervals, figures to 3 digits."""
    shown = {"estimator": table["estimator"], "sigma (deg)": table["sigma_deg"].map("{:g}".format)}
    if (table["outlier_prob"] > 0).any():
        shown["outliers"] = table["outlier_prob"].map("{:g}".format)
    shown["N"] = table["n_tracks"]
    for r in REGIONS:
        shown[f"{r.capitalize()} %"] = [_pct(*v) for v in table[[r, f"{r}_lo", f"{r}_hi"]]
                                        .to_numpy()]
    for q, unit in UNITS.items():
        u = unit.replace("_", "/")
        shown[f"{q} RMSE / CRLB ({u})"] = [
            f"{_num(a)} / {_num(b)}" for a, b in
            table[[f"rmse_{q}_{unit}", f"crlb_{q}_{unit}"]].to_numpy()]
        shown[f"eff. {q}"] = table[f"efficiency_{q}"].map(lambda x: _num(x, "{:.2f}"))
    shown["failed"] = table["n_failed"]
    shown["ok %"] = [_pct(*v) for v in table[["ok", "ok_lo", "ok_hi"]].to_numpy()]
    shown["consistent (ok) %"] = [
        _pct(*v) for v in table[["consistent", "consistent_lo", "consistent_hi"]].to_numpy()]
    if table["starts_changed"].notna().any():  # lm starts=K: the price of local minima
        shown["changed by extra starts %"] = [
            "" if np.isnan(v[0]) else _pct(*v)
            for v in table[["starts_changed", "starts_changed_lo", "starts_changed_hi"]]
            .to_numpy()]
    shown["ms/track"] = table["ms_per_track"].map(lambda x: _num(x, "{:.2f}"))
    return pd.DataFrame(shown)


def _plot(table: pd.DataFrame, path: Path):
    by_prob = table["sigma_deg"].nunique() == 1 and table["outlier_prob"].nunique() > 1
    x_col, x_label = (("outlier_prob", "outlier share") if by_prob
                      else ("sigma_deg", "bearing noise sigma (deg)"))
    lines = ["estimator"] if by_prob or table["outlier_prob"].nunique() == 1 \
        else ["estimator", "outlier_prob"]
    fig, axes = table_subplots(2, 2, figsize=(11, 8), sharex=True)
    for (ax, (q, unit)) in zip(axes.flat, UNITS.items(), strict=False):
        for key, rows in table.groupby(lines, sort=True):
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = rows[f"rmse_{q}_{unit}"] / rows[f"crlb_{q}_{unit}"]
            keep = np.isfinite(ratio) & (ratio > 0)
            ax.plot(rows[x_col][keep], ratio[keep], marker="o", label=_line_label(key))
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_yscale("log")
        ax.set_title(f"{q}: RMSE / root mean CRLB")
        ax.grid(True, which="both", alpha=0.3)
    ax = axes[1, 1]
    for key, rows in table.groupby(lines, sort=True):
        ax.plot(rows[x_col], 100 * rows["ref1"], marker="o", label=_line_label(key))
        ax.fill_between(rows[x_col], 100 * rows["ref1_lo"], 100 * rows["ref1_hi"], alpha=0.2)
    ax.set_title("Ref1 success rate (%), 95 % Wilson band")
    ax.set_ylim(-2, 102)
    ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel(x_label)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Bearings-only TMA: estimators against the Cramer-Rao bound")
    fixed_layout(fig)
    save_figure(fig, path)
    plt.close(fig)


def _line_label(key) -> str:
    key = key if isinstance(key, tuple) else (key,)
    return key[0] if len(key) == 1 else f"{key[0]}, outliers {key[1]:g}"


def write_benchmark(entries, tables_dir, name: str) -> list[Path]:
    """Write ``<name>.csv``, ``<name>.md`` and ``<name>.png`` from the runs ``entries``
    (those of datasets without truth are skipped); returns their paths (none without a
    simulated dataset)."""
    table = benchmark_table(entries)
    if table.empty:
        return []
    regions = "\n".join(f"- {r.capitalize()}: bearing <= {b} deg, distance <= {d:.0%}, course "
                        f"<= {c} deg, speed <= {s:.0%}" for r, (b, d, c, s) in REGIONS.items())
    paths = write_table(tables_dir, name,
                        "Bearings-only TMA: estimators against the Cramer-Rao bound", INTRO,
                        table, shown_table(table), float_format="%.6g",
                        notes="Success regions:\n" + regions)
    paths.append(Path(tables_dir) / f"{name}.png")
    _plot(table, paths[-1])
    return paths
