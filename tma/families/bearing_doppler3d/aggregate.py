"""``bearing_doppler3d`` outputs: one row per (estimator, Doppler on/off), RMSE-vs-time
plots with each filter's own std dashed, and the section "Against the paper"
(``tma.families.bearing_doppler3d.paper``)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402

from tma.families import estimator_class  # noqa: E402
from tma.families.bearing_doppler3d import paper  # noqa: E402
from tma.families.bearing_doppler3d.metrics import (  # noqa: E402
    DIVERGENCE_AFTER_S,
    DIVERGENCE_M,
    errors,
    nees,
    nees_band,
    path_metrics,
    per_step,
)
from tma.families.bearing_doppler3d.model import STATE_NAMES  # noqa: E402
from tma.io import arrow  # noqa: E402
from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.maths.angles import wrap_to_180  # noqa: E402
from tma.tables.write import fixed_layout, save_figure, table_subplots, write_table  # noqa: E402

SHORT = {"X_m": "X", "Y_m": "Y", "Z_m": "Z", "v_m_s": "v", "phi_rad": "phi", "a_m_s2": "a"}
MID_S = 50.0


def _columns():
    cols = ["estimator", "doppler", "n_paths", "training_paths"]
    for when in ("50", "T"):
        cols += [f"rmse_{SHORT[c]}_{when}" for c in STATE_NAMES]
    cols += [f"rmse_{SHORT[c]}_T_all" for c in STATE_NAMES]
    return cols + ["divergence_share", "nees_mean", "nees_band_lo", "nees_band_hi",
                   "us_per_path_obs"]


def aggregate_runs(entries, tables_dir, table_name, progress=None, table_kind=None
                   ) -> list[Path]:
    rows, curves, runs = [], [], []
    for e in entries:
        err, est, t, ok = errors(e.estimates, e.dataset.read_truth())
        K = t.size
        paths = path_metrics(np.unique(est["track_id"]), err, t, ok)
        write_parquet_atomic(e.run_root / "path_metrics.parquet",
                             pa.Table.from_pandas(paths, preserve_index=False))
        divergent = paths["track_lost"].to_numpy()
        keep = ~divergent
        steps = per_step(err, est, t, keep, K)
        covariance = arrow.read_table(e.run_root / "covariance.parquet").to_pandas()
        path_nees, stored = nees(err, covariance, np.unique(est["track_id"]))
        nees_steps = pd.DataFrame({"step": stored, "t_s": t[stored],
                                   "nees_mean": np.nanmean(path_nees[keep], axis=0)})
        steps = steps.merge(nees_steps, on=["step", "t_s"], how="left")
        write_parquet_atomic(e.run_root / "metrics.parquet",
                             pa.Table.from_pandas(steps, preserve_index=False))
        doppler = not e.dataset.manifest["config"]["no_doppler"]
        size = estimator_class(e.estimator).training_size  # declared, not guessed from keys
        row = {"estimator": e.estimator, "doppler": doppler, "n_paths": len(keep),
               "training_paths": e.manifest["config"][size] if size else np.nan}
        for when, target in (("50", MID_S), ("T", t[-1])):
            k = int(np.argmin(np.abs(t - target)))
            at = steps[steps.step == k].set_index("component")
            for c in STATE_NAMES:
                row[f"rmse_{SHORT[c]}_{when}"] = at.loc[c, "rmse"]
                if when == "T":
                    row[f"rmse_{SHORT[c]}_T_all"] = at.loc[c, "rmse_all_paths"]
        lo, hi = nees_band(int(keep.sum()))
        row.update({"divergence_share": float(divergent.mean()),
                    "nees_mean": float(np.nanmean(nees_steps["nees_mean"])),
                    "nees_band_lo": lo, "nees_band_hi": hi,
                    "us_per_path_obs": 1e6 * e.seconds_per_track / K})
        rows.append(row)
        curves.append((e.estimator, doppler, steps))
        runs.append(paper.Run(e.estimator, doppler, steps, divergent,
                              e.dataset.manifest["config"], e.manifest["config"]))
    table = pd.DataFrame(rows, columns=_columns()).sort_values(
        ["doppler", "estimator"], ascending=[False, True], kind="stable").reset_index(drop=True)
    tables_dir = Path(tables_dir)
    plots = [tables_dir / f"{table_name}.png", tables_dir / f"{table_name}_bearings_only.png"]
    training = sorted({int(x) for x in table["training_paths"].dropna()})
    shown = pd.DataFrame({
        "estimator": table["estimator"], "Doppler": table["doppler"].map({True: "yes",
                                                                          False: "no"}),
        "paths": table["n_paths"],
        **{f"RMSE {SHORT[c]} @50 s / @T": [
            f"{a:.3g} / {b:.3g}" for a, b in
            table[[f"rmse_{SHORT[c]}_50", f"rmse_{SHORT[c]}_T"]].to_numpy()]
           for c in STATE_NAMES},
        "divergent": table["divergence_share"].map("{:.1%}".format),
        "mean NEES (95 % band)": [f"{m:.2f} ({lo:.2f}-{hi:.2f})" for m, lo, hi in
                                  table[["nees_mean", "nees_band_lo", "nees_band_hi"]].to_numpy()],
        "us / path / obs": table["us_per_path_obs"].map("{:.2f}".format),
    })
    intro = f"""Passive tracking of a manoeuvring AUV by 8 fixed hydrophones
(`docs/families.md`): elevation sine, bearing cosine and Doppler frequency
every second, with and without the Doppler readings. RMSE over the non-divergent test paths at
t = 50 s and t = T (units: m, m, m, m/s, rad, m/s^2); a path diverges (`track_lost` in
the run's `path_metrics.parquet`) when its horizontal error exceeds {DIVERGENCE_M:g} m, or is
not finite, at any t >= {DIVERGENCE_AFTER_S:g} s, or its filter flagged it (the CSV also gives the
RMSE over all paths at T, `rmse_*_T_all`: for `prior_mean`, whose paths mostly count as
divergent, that is the meaningful figure). Mean NEES over the stored
covariance epochs (6 degrees of freedom: a consistent filter stays inside the band). CMNF is
trained on {', '.join(map(str, training)) or 'n/a'} simulated paths (its gains and own
covariance are an artefact reused by later runs); `prior_mean` (the unconditional mean of the
same bundle) is the baseline. Microseconds per path per observation are wall time of the
vectorised filters (2 workers share the shards) and vary between machines."""
    paths = write_table(tables_dir, table_name,
                        "Underwater bearing-Doppler tracking: EKF, square-root EKF, CMNF",
                        intro, table, shown, float_format="%.6g",
                        paper=(paper.against_paper(runs), paper.INTRO))
    for path, doppler in ((plots[0], True), (plots[1], False)):
        _plot(path, [c for c in curves if c[1] == doppler], doppler)
    return paths + plots


def _plot(path, curves, doppler):
    fig, axes = table_subplots(2, 3, figsize=(15, 8))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, comp in zip(axes.flat, STATE_NAMES, strict=True):
        for i, (name, _, steps) in enumerate(sorted(curves, key=lambda c: c[0])):
            s = steps[steps.component == comp]
            colour = colours[i % len(colours)]
            ax.plot(s["t_s"], s["rmse"], color=colour, label=f"{name} RMSE")
            ax.plot(s["t_s"], s["own_sd"], color=colour, ls="--", lw=1, label=f"{name} own std")
        ax.set_title(comp)
        ax.set_xlabel("t (s)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("RMSE vs time (solid) and each filter's own std (dashed), "
                 + ("with Doppler" if doppler else "bearings only"))
    fixed_layout(fig)
    save_figure(fig, path)
    plt.close(fig)


# -- the Python API's hook (tma.api): what tma.estimate returns of bearing_doppler3d estimates

# each state as the results of every family name it (bearings2d's: the position now, its
# one-sigma error ``_sd``, its error against the truth ``_err``; angles in degrees)
RESULT_NAMES = {"X_m": "x", "Y_m": "y", "Z_m": "z", "v_m_s": "speed", "phi_rad": "course",
                "a_m_s2": "a"}


def _result_columns(state: str, values: np.ndarray, kind: str) -> tuple[str, np.ndarray]:
    """A state's ``values`` (the estimate, ``kind`` ``now``; its ``sd``; its ``err``) under its
    results name and unit: the heading phi (rad, counter-clockwise from +X) as the course
    (deg, clockwise from north, as ``radar2d``'s and ``bearings2d``'s)."""
    name, unit = RESULT_NAMES[state], state.partition("_")[2]
    if state == "phi_rad":
        unit, values = "deg", np.rad2deg(values)
        values = (90.0 - values) % 360.0 if kind == "now" else (
            values if kind == "sd" else wrap_to_180(-values))
    if kind == "now":
        return (f"{name}_now_{unit}" if name in ("x", "y", "z") else f"{name}_{unit}"), values
    return f"{name}_{kind}_{unit}", values


def results(run) -> tuple[pd.DataFrame, dict]:
    """``tma.estimate``'s results of ``run`` (``tma.api.Estimated``): one row per path, the
    filter's state at its last epoch (``t_now_s``; ``x_now_m``, ``y_now_m``, ``z_now_m``,
    ``speed_m_s``, ``course_deg`` clockwise from north, ``a_m_s2``) with its own standard
    deviations (``x_sd_m``..., ``course_sd_deg``), its flag (``filter_ok``) and ``status``,
    the filter's verdict (``ok``, or ``divergent`` where it flagged the path); against the
    truth, as the table measures it (``metrics``): the errors then (``x_err_m``...,
    ``course_err_deg`` wrapped), the largest horizontal error from ``DIVERGENCE_AFTER_S`` on,
    the NEES then (``nees``, 6 degrees of freedom) and ``track_lost`` (the path diverged).
    Tables: ``estimates`` (per epoch, the model's states) and ``covariance`` (every
    ``covariance_every`` epochs)."""
    est = run.estimates.sort_values(["track_id", "step"], kind="stable").reset_index(drop=True)
    last = est.groupby("track_id", sort=False).tail(1).reset_index(drop=True)
    ok = last["filter_ok"].astype(bool)
    frame = pd.DataFrame({"track_id": last["track_id"], "t_now_s": last["t_s"]})
    for c in STATE_NAMES:
        for kind, column in (("now", c), ("sd", f"sd_{c}")):
            name, values = _result_columns(c, last[column].to_numpy(), kind)
            frame[name] = values
    frame["filter_ok"] = ok
    frame["status"] = np.where(ok, "ok", "divergent")
    tables = {"estimates": est, **run.side_tables}
    if run.truth is None:
        return frame, tables
    err, _, t, flags = errors(est, run.truth)
    ids = frame["track_id"].to_numpy()
    paths = path_metrics(ids, err, t, flags)
    for k, c in enumerate(STATE_NAMES):
        name, values = _result_columns(c, err[:, -1, k], "err")
        frame[name] = values
    frame["horizontal_err_max_m"] = paths["horizontal_err_max_m"].to_numpy()
    covariance = run.side_tables.get("covariance")
    if covariance is not None:  # the last epoch's covariance is always kept
        path_nees, stored = nees(err, covariance, ids)
        frame["nees"] = path_nees[:, -1] if stored[-1] == t.size - 1 else np.nan
    frame["track_lost"] = paths["track_lost"].to_numpy()
    return frame, tables
