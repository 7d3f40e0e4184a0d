"""The ``bearings2d`` manoeuvre table: how each estimator fares on targets that move like
ships (experiment ``bearings2d_manoeuvre``): constant velocity, nearly-constant velocity
(``target.accel_psd_m2_s3``) and manoeuvres (``target.manoeuvres``), from logs that declare
the motion they were made with (or, ``target.declared`` false, none, as recordings).

One row per (estimator, motion) over the simulated targets of one dataset:

- ``flagged``: share of tracks found manoeuvring: status ``manoeuvring``, a last leg found
  (``last_leg``: ``n_rounds`` > 0), or a manoeuvre more probable than not after the bearings
  (``lm`` with manoeuvres in its prior: ``p_manoeuvre`` > 0.5). On constant-velocity targets
  it is the false-alarm rate, on manoeuvring ones the detection rate;
- ``ok`` and ``consistent``: the share of ``ok`` tracks, and of those whose normalised error
  against the truth lies below the chi-square(4) 95 % point (about 95 % when honest);
- ``steady ok``: the share ``ok`` of the targets that made no manoeuvre;
- Ref1..Ref4, the median |range error| over range (the tracks with an estimate) and the
  range RMSE of the ok tracks, at the last bearing, against the target's state then (on its
  last leg);
- rates with 95 % Wilson intervals.

The plot gives the detection rate against the size of the manoeuvre (|course change|,
binned), per estimator, and the share ok with its consistency per motion. A second table,
``<name>-calibration``, says whether the ok tracks' errors are honest both ways, per
quantity (range, course, speed) and by cell (range now, manoeuvres made, ``p_manoeuvre``):
``calibration.py``.
"""

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from tma.families.bearings2d import calibration  # noqa: E402
from tma.families.bearings2d.benchmark import _pct, estimator_label  # noqa: E402
from tma.families.bearings2d.metrics import (  # noqa: E402
    NEES_95,
    REGIONS,
    errors_now,
    track_metrics,
)
from tma.maths.stats import rate_columns  # noqa: E402
from tma.tables.write import (  # noqa: E402
    fixed_layout,
    markdown_table,
    save_figure,
    table_subplots,
    write_csv,
    write_table,
)

log = logging.getLogger(__name__)

SIZE_BINS_DEG = (0, 30, 45, 60, 75, 90, 120)
COLUMNS = [
    "estimator", "motion", "sigma_deg", "n_tracks",
    "flagged", "flagged_lo", "flagged_hi", "ok", "ok_lo", "ok_hi",
    "consistent", "consistent_lo", "consistent_hi", "steady_ok", "steady_ok_lo", "steady_ok_hi",
    *[f"{r}{s}" for r in REGIONS for s in ("", "_lo", "_hi")],
    "median_range_error", "rmse_range_ok_m", "n_failed",
]

INTRO = """Bearings-only TMA of targets that move like ships: wander (random acceleration of
spectral density q per axis) and manoeuvres (turns and speed changes at the times of a
Poisson process), from logs that declare the motion they were made with. `lm` assumes the
declared motion: its answer averages over the manoeuvres the target may have made
(docs/manoeuvres.md); `motion_prior_scale` 10 and 0.1 assume ten times more and less wander
and manoeuvres than there are. One row per estimator and target motion over N simulated
targets: flagged: share found manoeuvring (status `manoeuvring`, a last leg found, or
p_manoeuvre > 0.5; the false-alarm rate on constant-velocity targets); ok: share with status
`ok`; consistent: share of the ok tracks whose normalised error lies below the chi-square(4)
95 % point (about 95 % when the one-sigma errors are honest); steady ok: share `ok` of the
targets that did not manoeuvre; Ref1..Ref4, the median |range error| / range (the tracks
with an estimate) and the range RMSE of the ok tracks, at the last bearing against the
target's state then. 95 % Wilson intervals. Every number is read from the run and dataset
files under `data/`."""


def motion_label(scenario: dict) -> str:
    """The target motion of a dataset's scenario config, in words."""
    target = scenario.get("target") or {}
    q = float(target.get("accel_psd_m2_s3", 0.0))
    manoeuvres = target.get("manoeuvres") or {}
    prob, rate = float(manoeuvres.get("prob", 0.0)), float(manoeuvres.get("rate_per_h", 0.0))
    parts = [f"wander q={q:g}" if q > 0 else "", f"manoeuvres {prob:g}" if prob > 0 else "",
             f"manoeuvres {rate:g}/h" if rate > 0 else ""]
    return " + ".join(p for p in parts if p) or "constant velocity"


def flagged(estimates: pd.DataFrame) -> np.ndarray:
    """Tracks an estimator found manoeuvring."""
    found = (estimates["status"] == "manoeuvring").to_numpy()
    if "n_rounds" in estimates:
        found = found | (estimates["n_rounds"].to_numpy() > 0)
    if "p_manoeuvre" in estimates:
        found = found | (estimates["p_manoeuvre"].to_numpy() > 0.5)
    return found


def manoeuvre_row(label, motion, sigma, estimates, truth) -> dict:
    """One table row (``COLUMNS``) from one run's estimates."""
    metrics = track_metrics(estimates, truth)
    n = len(metrics)
    ok = (metrics["status"] == "ok").to_numpy()
    consistent = int((metrics.loc[ok, "nees"] <= NEES_95).sum())
    moved = (metrics["track_id"].map(truth.set_index("track_id")["manoeuvring"])
             .to_numpy(dtype=bool) if "manoeuvring" in truth else np.zeros(n, dtype=bool))
    row = {"estimator": label, "motion": motion, "sigma_deg": sigma, "n_tracks": n,
           **rate_columns(int(flagged(estimates).sum()), n, "flagged"),
           **rate_columns(int(ok.sum()), n, "ok"),
           **rate_columns(consistent, int(metrics.loc[ok, "nees"].notna().sum()), "consistent"),
           **rate_columns(int((ok & ~moved).sum()), int((~moved).sum()), "steady_ok")}
    for region in REGIONS:
        row.update(rate_columns(int(metrics[region].sum()), n, region))
    err = errors_now(estimates, truth)["range_err_m"].to_numpy()
    finite = np.isfinite(err)
    rel = np.abs(metrics["distance_rel_err"].to_numpy())
    row["median_range_error"] = float(np.median(rel[finite])) if finite.any() else np.nan
    row["rmse_range_ok_m"] = (float(np.sqrt(np.mean(err[ok & finite] ** 2)))
                              if (ok & finite).any() else np.nan)
    row["n_failed"] = int((~finite).sum())
    return row


def _entries_with_truth(entries):
    for entry in entries:
        truth = entry.dataset.read_truth()
        if truth is not None:
            yield entry, truth


def manoeuvre_tables(entries) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The table of the runs ``entries`` and, per estimator and manoeuvre size bin, the
    detection rate on the manoeuvring targets."""
    rows, detections = [], []
    for entry, truth in _entries_with_truth(entries):
        config = entry.dataset.manifest["config"]
        label = estimator_label(entry.estimator, entry.manifest.get("config") or {})
        motion = motion_label(config)
        rows.append(manoeuvre_row(label, motion, config["sigma_deg"], entry.estimates, truth))
        if "manoeuvring" in truth:
            merged = entry.estimates.merge(truth, on="track_id", suffixes=("", "_true"))
            size = merged["course_change_deg"].abs().to_numpy()
            moved = merged["manoeuvring"].to_numpy(dtype=bool)
            found = flagged(merged)
            bins = np.digitize(size, SIZE_BINS_DEG[1:-1])
            for b in range(len(SIZE_BINS_DEG) - 1):
                sel = moved & (bins == b)
                detections.append({"estimator": label, "motion": motion,
                                   "size_lo_deg": SIZE_BINS_DEG[b],
                                   "size_hi_deg": SIZE_BINS_DEG[b + 1], "n": int(sel.sum()),
                                   **rate_columns(int(found[sel].sum()), int(sel.sum()),
                                                  "detected")})
    table = pd.DataFrame(rows, columns=COLUMNS).sort_values(
        ["estimator", "motion"], kind="stable").reset_index(drop=True)
    return table, pd.DataFrame(detections)


def calibration_table(entries) -> pd.DataFrame:
    """The calibration table (``calibration.COLUMNS``) of the runs ``entries``: per
    estimator and motion, its cells (``calibration.calibration_rows``)."""
    rows = []
    for entry, truth in _entries_with_truth(entries):
        config = entry.dataset.manifest["config"]
        label = estimator_label(entry.estimator, entry.manifest.get("config") or {})
        rows += calibration.calibration_rows(label, motion_label(config), config["sigma_deg"],
                                             entry.estimates, truth)
    return pd.DataFrame(rows, columns=calibration.COLUMNS).sort_values(
        ["estimator", "motion"], kind="stable").reset_index(drop=True)


def write_calibration_table(entries, tables_dir, name: str) -> list[Path]:
    """Write ``<name>.csv`` and ``<name>.md``: the calibration table of the runs ``entries``
    (none without a simulated dataset)."""
    table = calibration_table(entries)
    if table.empty:
        return []
    cells = calibration.shown_cells(table)
    notes = ("By cell (true range at the last bearing; manoeuvres made over the observation; "
             "`p_manoeuvre`):\n\n" + markdown_table(cells)) if len(cells) else ""
    return write_table(tables_dir, name, "Bearings-only TMA of targets that move like ships: "
                       "are the ok answers' errors honest?", calibration.INTRO, table,
                       calibration.shown_rows(table), float_format="%.6g", notes=notes)


def shown_table(table: pd.DataFrame) -> pd.DataFrame:
    shown = {"estimator": table["estimator"], "motion": table["motion"],
             "sigma (deg)": table["sigma_deg"].map("{:g}".format), "N": table["n_tracks"]}
    for name, title in (("flagged", "flagged %"), ("ok", "ok %"),
                        ("consistent", "consistent (ok) %"), ("steady_ok", "steady ok %")):
        shown[title] = [_pct(*v) for v in table[[name, f"{name}_lo", f"{name}_hi"]].to_numpy()]
    for r in REGIONS:
        shown[f"{r.capitalize()} %"] = [_pct(*v) for v in
                                        table[[r, f"{r}_lo", f"{r}_hi"]].to_numpy()]
    shown["median range error %"] = table["median_range_error"].map(
        lambda x: "-" if pd.isna(x) else f"{100 * x:.1f}")
    shown["range RMSE, ok (m)"] = table["rmse_range_ok_m"].map(
        lambda x: "-" if pd.isna(x) else f"{x:.3g}")
    return pd.DataFrame(shown)


def _plot(table: pd.DataFrame, detections: pd.DataFrame, path: Path):
    fig, axes = table_subplots(1, 2, figsize=(12, 4.5))
    ax = axes[0]
    if not detections.empty:
        for (estimator, motion), rows in detections.groupby(["estimator", "motion"], sort=True):
            rows = rows[rows["n"] > 0]
            mid = (rows["size_lo_deg"] + rows["size_hi_deg"]) / 2
            ax.plot(mid, 100 * rows["detected"], marker="o", label=f"{estimator}, {motion}")
            ax.fill_between(mid, 100 * rows["detected_lo"], 100 * rows["detected_hi"],
                            alpha=0.2)
    ax.set_xlabel("manoeuvre size: |course change| (deg)")
    ax.set_ylabel("detected (%)")
    ax.set_ylim(-2, 102)
    ax.set_title("Detection rate against manoeuvre size (95 % Wilson band)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[1]
    motions = sorted(table["motion"].unique())
    estimators = sorted(table["estimator"].unique())
    width = 0.8 / max(len(estimators), 1)
    for i, estimator in enumerate(estimators):
        rows = table[table["estimator"] == estimator].set_index("motion").reindex(motions)
        x = np.arange(len(motions)) + i * width
        ax.bar(x, 100 * rows["ok"], width, alpha=0.35, label=f"{estimator}: ok")
        ax.plot(x, 100 * rows["consistent"], "k_", markersize=14)
    ax.plot([], [], "k_", label="consistent (ok)")
    ax.axhline(95, color="k", lw=0.6, ls="--")
    ax.set_xticks(np.arange(len(motions)) + width * (len(estimators) - 1) / 2)
    ax.set_xticklabels(motions, fontsize=7)
    ax.set_ylabel("%")
    ax.set_ylim(0, 102)
    ax.set_title("Share ok, and consistent among them")
    ax.legend(fontsize=7)
    fig.suptitle("Bearings-only TMA of targets that move like ships")
    fixed_layout(fig, right=0.7)  # the last bar label reaches past the axes
    save_figure(fig, path)
    plt.close(fig)


def write_manoeuvre_table(entries, tables_dir, name: str) -> list[Path]:
    """Write ``<name>.csv``, ``<name>.md`` and ``<name>.png`` (and the detection rates as
    ``<name>_detection.csv``, the calibration table as ``<name>-calibration.csv`` and
    ``.md``) from the runs ``entries`` of simulated datasets; none without one."""
    table, detections = manoeuvre_tables(entries)
    if table.empty:
        return []
    tables_dir = Path(tables_dir)
    detection_md, extra = "", []
    if not detections.empty:
        extra.append(tables_dir / f"{name}_detection.csv")
        write_csv(detections, extra[0], float_format="%.6g")
        shown = detections[detections["n"] > 0].assign(**{
            "|course change| (deg)": lambda d: [f"{a:g}-{b:g}" for a, b in
                                                d[["size_lo_deg", "size_hi_deg"]].to_numpy()],
            "detected %": lambda d: [_pct(*v) for v in
                                     d[["detected", "detected_lo", "detected_hi"]].to_numpy()]})
        detection_md = ("Detection rate on the manoeuvring targets by manoeuvre size:\n\n"
                        + markdown_table(shown[["estimator", "motion", "|course change| (deg)",
                                                "n", "detected %"]]))
    calibrated = write_calibration_table(entries, tables_dir, f"{name}-calibration")
    if calibrated:
        detection_md += (f"\nWhether the ok tracks' errors are honest, per quantity and by cell "
                         f"(range now, manoeuvres made, p_manoeuvre): `{calibrated[1].name}`.\n")
    paths = write_table(tables_dir, name, "Bearings-only TMA of targets that move like ships",
                        INTRO, table, shown_table(table), float_format="%.6g",
                        notes=detection_md)
    paths.append(tables_dir / f"{name}.png")
    _plot(table, detections, paths[-1])
    return paths + extra + calibrated
