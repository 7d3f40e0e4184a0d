"""``radar2d`` outputs: one row per (estimator, speed), error-vs-time and m-vs-time plots, and
the section "Against the paper" (``tma.families.radar2d.paper``)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402

from tma.families import estimator_class  # noqa: E402
from tma.families.radar2d import paper, real_motion_table  # noqa: E402
from tma.families.radar2d.metrics import (  # noqa: E402
    DEFAULT_MEMORY,
    GATE_M,
    SEGMENT_NAMES,
    Segments,
    per_scan_errors,
    segments,
    sigma_column,
    summary_row,
    table_columns,
)
from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.maths.angles import course_from_velocity  # noqa: E402
from tma.tables.write import fixed_layout, save_figure, table_subplots, write_table  # noqa: E402

INTRO = """Tracking a small fast boat that turns sharply{radius} in front of a coastal
radar (`docs/families.md`); one row per tracker and boat speed over the Monte Carlo
runs. Segment columns: mean position error over runs and scans, and the median and 95th
percentile of each run's maximum error ({segments}). Track loss: share of runs
whose error exceeds {gate:g} m, or that have no estimate, at any scan from {loss} on (column
`track_lost` in each run's `metrics.parquet`). For `fuzzy_mm`: the selected memory
m (median; median over runs of the minimum in the turn; P(m = J) on the straight legs; median
time to recover m = J after the turn) and sigma_hat at {sigma}. For `imm`: the mean
probability of the turn model during the turn."""


def _f(x, fmt="{:.1f}"):
    return "-" if pd.isna(x) else fmt.format(x)


def _window(w):
    return "none" if np.isnan(w[0]) else str(w)


def _times(times_s):
    return "/".join(f"{s:g}" for s in times_s)


def _intro(by_dataset: dict) -> str:
    """INTRO with the segment times of the datasets (``name -> (Segments, scenario config)``):
    inline when they share them, else one line per dataset."""
    def describe(segs):  # the line break after "turn" keeps the default text as it was
        w = segs.windows
        loss = (f"{segs.loss_from_s:g} s" if np.isfinite(segs.loss_from_s)
                else "the window fill (never reached)")
        return (f"first straight {_window(w['straight1'])} s, turn\n{_window(w['turn'])} s, "
                f"second straight {_window(w['straight2'])} s", loss,
                f"{_times(segs.sigma_times_s)} s")

    radii = {next((leg.get("turn_radius_m") for leg in cfg["legs"] if leg.get("turn_radius_m")),
                  None)
             for _, cfg in by_dataset.values()}
    radius = f" (radius {radii.pop():g} m)" if len(radii) == 1 and None not in radii else ""
    texts = {name: describe(segs) for name, (segs, _) in by_dataset.items()}
    if len(set(texts.values())) == 1:
        segs_text, loss, sigma = next(iter(texts.values()))
        return INTRO.format(radius=radius, segments=segs_text, gate=GATE_M, loss=loss,
                            sigma=sigma)
    intro = INTRO.format(radius=radius, segments="per dataset below", gate=GATE_M,
                         loss="the window fill", sigma="the times below")
    lines = [f"- `{name}`: {a}; track loss from {b}; sigma_hat at {c}".replace("\n", " ")
             for name, (a, b, c) in texts.items()]
    return intro + "\n\n" + "\n".join(lines)


# the other kinds of table an experiment may ask for (``table_kind=``): vessels of an AIS
# recording
TABLE_KINDS = {"real_motion": real_motion_table.write_real_motion_table}


def aggregate_runs(entries, tables_dir, table_name, progress=None, table_kind=None
                   ) -> list[Path]:
    if table_kind is not None:
        return TABLE_KINDS[table_kind](entries, tables_dir, table_name)
    # one set of segments per dataset, so that its rows are measured on the same scans: the
    # rule's J is the longest memory among the dataset's trackers (the default if none has one)
    configs = {e.dataset.name: e.dataset.manifest["config"] for e in entries}
    by_dataset = {name: (segments(config, max(
        (e.manifest["config"]["memory"] for e in entries
         if e.dataset.name == name and "memory" in e.manifest["config"]),
        default=DEFAULT_MEMORY)), config) for name, config in configs.items()}
    rows, sigma_times, curves, runs = [], [], [], []
    for e in entries:
        segs = by_dataset[e.dataset.name][0]
        per_scan = per_scan_errors(e.estimates, e.dataset.read_truth(), segs)
        write_parquet_atomic(e.run_root / "metrics.parquet",
                             pa.Table.from_pandas(per_scan, preserve_index=False))
        speed = e.dataset.manifest["config"]["speed_m_s"]
        selects_memory = "m" in estimator_class(e.estimator).outputs
        rows.append(summary_row(per_scan, e.estimator, speed, segs,
                                e.manifest["config"]["memory"] if selects_memory else None))
        if e.estimator == paper.ESTIMATOR:
            runs.append(paper.Run(speed, per_scan, segs, e.dataset.manifest["config"],
                                  e.manifest["config"]))
        sigma_times.append(segs.sigma_times_s)
        g = per_scan.groupby("t_s")
        curve = pd.DataFrame({"t_s": g["error_m"].mean().index, "error_mean_m":
                              g["error_m"].mean().to_numpy()})
        if "m" in per_scan:
            curve["m_median"] = g["m"].median().to_numpy()
            curve["m_p10"] = g["m"].quantile(0.1).to_numpy()
            curve["m_p90"] = g["m"].quantile(0.9).to_numpy()
        curves.append((e.estimator, speed, curve, segs))
    columns = table_columns([s for times in sigma_times for s in times])
    table = pd.DataFrame(rows, columns=columns).assign(sigma_times=sigma_times).sort_values(
        ["speed_m_s", "estimator"], kind="stable").reset_index(drop=True)
    tables_dir = Path(tables_dir)
    plots = [tables_dir / f"{table_name}.png", tables_dir / f"{table_name}_memory.png"]
    shared_times = len(set(sigma_times)) == 1

    def sigma_cell(row):
        values = [row[sigma_column(s)] for s in row["sigma_times"]]
        if pd.isna(values[0]):
            return "-"
        text = " / ".join(f"{v:.1f}" for v in values)
        return text if shared_times else f"{text} (at {_times(row['sigma_times'])} s)"

    shown = pd.DataFrame({
        "estimator": table["estimator"], "speed (m/s)": table["speed_m_s"].map("{:g}".format),
        "runs": table["n_runs"],
        **{f"{s} mean / med max / p95 max (m)": [
            f"{a:.1f} / {b:.1f} / {c:.1f}" for a, b, c in
            table[[f"{s}_mean_m", f"{s}_max_median_m", f"{s}_max_p95_m"]].to_numpy()]
           for s in SEGMENT_NAMES},
        "track loss": table["track_loss"].map("{:.1%}".format),
        "m median": table["m_median"].map(lambda x: _f(x, "{:g}")),
        "m min in turn": table["m_min_turn_median"].map(lambda x: _f(x, "{:g}")),
        "P(m=J) straight": table["p_m_max_straight"].map(lambda x: _f(x, "{:.1%}")),
        "recover m=J (s)": table["recover_s_median"].map(lambda x: _f(x, "{:g}")),
        (f"sigma_hat {_times(sigma_times[0])} s (m)" if shared_times else "sigma_hat (m)"):
            [sigma_cell(row) for _, row in table.iterrows()],
        "P(turn model) in turn": table["p_turn_model_in_turn"].map(lambda x: _f(x, "{:.2f}")),
    })
    paths = write_table(tables_dir, table_name,
                        "Vessel tracking: fuzzy multi-model alpha-beta vs alpha-beta vs IMM",
                        _intro(by_dataset), table[columns], shown, float_format="%.6g",
                        paper=(paper.against_paper(runs), paper.INTRO))
    _plot(*plots, curves)
    return paths + plots


def _shade(ax, segs):
    a, b = segs.windows["turn"]
    if not np.isnan(a):
        ax.axvspan(a, b, color="0.9", zorder=0)


def _plot(error_path, memory_path, curves):
    speeds = sorted({s for _, s, _, _ in curves})
    fig, axes = table_subplots(1, len(speeds), figsize=(6 * len(speeds), 4.5), squeeze=False)
    for ax, speed in zip(axes[0], speeds, strict=True):
        _shade(ax, next(segs for _, s, _, segs in curves if s == speed))
        for name, s, curve, _ in sorted(curves, key=lambda c: c[0]):
            if s == speed:
                ax.plot(curve["t_s"], curve["error_mean_m"], marker=".", label=name)
        ax.axhline(GATE_M, color="r", lw=0.8, ls="--", label=f"gate {GATE_M:g} m")
        ax.set_title(f"{speed:g} m/s (turn shaded)")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("mean position error (m)")
        ax.grid(alpha=0.3)
        ax.legend()
    fixed_layout(fig, title=False)
    save_figure(fig, error_path)
    plt.close(fig)

    fig, axes = table_subplots(1, len(speeds), figsize=(6 * len(speeds), 4.5), squeeze=False)
    for ax, speed in zip(axes[0], speeds, strict=True):
        _shade(ax, next(segs for _, s, _, segs in curves if s == speed))
        for name, s, curve, _ in curves:
            if s == speed and "m_median" in curve:
                ax.fill_between(curve["t_s"], curve["m_p10"], curve["m_p90"], alpha=0.25,
                                label=f"{name} 10-90 %")
                ax.step(curve["t_s"], curve["m_median"], where="mid", label=f"{name} median")
        ax.set_title(f"selected memory m, {speed:g} m/s")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("m (scans)")
        ax.set_ylim(1.5, np.nanmax([c["m_p90"].max() for _, _, c, _ in curves if "m_p90" in c]
                               or [10]) + 0.5)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # a speed without a memory-selecting tracker
            ax.legend()
    fixed_layout(fig, title=False)
    save_figure(fig, memory_path)
    plt.close(fig)


# -- the Python API's hook (tma.api): what tma.estimate returns of radar2d estimates

def results(run) -> tuple[pd.DataFrame, dict]:
    """``tma.estimate``'s results of ``run`` (``tma.api.Estimated``): one row per run (a
    track), its state at its last scan (``t_now_s``, ``x_now_m``, ``y_now_m``, velocity
    ``vx_now_m_s``, ``vy_now_m_s``, ``speed_m_s``, ``course_deg`` clockwise from north) and
    its ``status``, the tracker's verdict (``ok`` or ``divergent``); against its truth, as the
    table measures it (``metrics.per_scan_errors``, the segments of the scenario and of the
    tracker's memory J), the position error now (``position_err_m``), its mean and maximum
    from the scan where the window fills (``position_err_mean_m``, ``position_err_max_m``)
    and ``track_lost``. Tables: ``estimates`` (per scan) and, with a truth, ``errors`` (per
    scan)."""
    est = run.estimates.sort_values(["track_id", "step"], kind="stable").reset_index(drop=True)
    last = est.groupby("track_id", sort=False).tail(1).reset_index(drop=True)
    frame = pd.DataFrame({
        "track_id": last["track_id"], "t_now_s": last["t_s"],
        "x_now_m": last["x_m"], "y_now_m": last["y_m"],
        "vx_now_m_s": last["vx_m_s"], "vy_now_m_s": last["vy_m_s"],
        "speed_m_s": np.hypot(last["vx_m_s"], last["vy_m_s"]),
        "course_deg": np.rad2deg(course_from_velocity(last["vx_m_s"], last["vy_m_s"])),
        "status": last["status"]})
    tables = {"estimates": est}
    if run.truth is None:
        return frame, tables
    memory = getattr(run.estimator.config, "memory", DEFAULT_MEMORY)
    if (run.scenario.get("real") or {}).get("file") is None:
        segs = segments(run.scenario, memory)
    else:  # real motion: no legs, track loss from the window fill (real_motion_table)
        segs = Segments({}, (memory - 1) * run.scenario["scan_period_s"], np.nan, ())
    per_scan = per_scan_errors(est, run.truth, segs)
    late = per_scan[per_scan["t_s"] >= segs.loss_from_s - 1e-9]
    by_run = late.groupby("track_id")["error_m"]
    gaps = late["error_m"].isna().groupby(late["track_id"]).any()  # a scan without estimate
    ids = frame["track_id"]
    frame["position_err_m"] = per_scan.groupby("track_id").tail(1).set_index("track_id")[
        "error_m"].reindex(ids).to_numpy()
    frame["position_err_mean_m"] = by_run.mean().mask(gaps).reindex(ids).to_numpy()
    frame["position_err_max_m"] = by_run.max().mask(gaps).reindex(ids).to_numpy()
    frame["track_lost"] = per_scan.groupby("track_id")["track_lost"].first().reindex(
        ids).to_numpy()
    return frame, {**tables, "errors": per_scan}
