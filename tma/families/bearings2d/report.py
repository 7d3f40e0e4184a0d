"""``bearings2d`` outputs: the comparison table (md, csv, png) and, for datasets without
truth (ingested logs), a per-track report of the estimated state and kinematics now (local
metres, latitude/longitude, UTC) with 1-sigma uncertainties from the Gauss-Newton covariance
(J^T J)^-1 sigma^2 and each track's status (computed by the estimators,
``tma.families.bearings2d.status``), with its maps (``map_outputs``): a PNG per contact and,
when the dataset has a geographic origin, the estimated tracks as an MCAP for Foxglove."""

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402

from tma.families.bearings2d import (  # noqa: E402
    benchmark,
    manoeuvre_table,
    paper,
    real_motion_table,
)
from tma.families.bearings2d.map_outputs import (  # noqa: E402
    MAX_PLOTS,
    contact_figure,
    position_covariance,
    read_logs,
    reference,
    theta_covariance,
    write_map_mcap,
    write_track_plots,
)
from tma.families.bearings2d.metrics import (  # noqa: E402
    REGIONS,
    TABLE_COLUMNS,
    THETA,
    summary_row,
    track_metrics,
)
from tma.families.bearings2d.status import (  # noqa: E402
    HEADING_UNDETERMINED,
    STATUSES,
    not_an_answer,
)
from tma.families.bearings2d.truth_report import (  # noqa: E402
    coverage_text,
    dataset_truth,
    shown_columns,
    with_truth,
)
from tma.io import arrow  # noqa: E402
from tma.io.atomic import write_parquet_atomic  # noqa: E402
from tma.maths.geo import local_to_geodetic  # noqa: E402
from tma.report.tables import fixed_layout, save_figure, table_subplots, write_table  # noqa: E402
from tma.sources.labels import shown_labels  # noqa: E402
from tma.utc import format_utc  # noqa: E402

INTRO = """Bearings-only TMA of a constant-velocity target from a manoeuvring observer
(`../shared/specs/bearings2d.md`). Each row: one estimator at one bearing noise sigma over
N simulated targets. Ref1..Ref4: share of targets whose estimate lies inside the success
region (bearing and distance at the end of the observation, course, speed; Ref1 is the
strictest), with the 95 % Wilson interval. sqrt(Ka) = sqrt(F(theta_hat)/n) in degrees: a
good maximum-likelihood fit gives sqrt(Ka) close to sigma. Nf: evaluations of F, Iter:
accepted LM steps (medians; direct estimators have none). Status: tracks per verdict
({statuses}, see the README).
Consistent: share of the ok tracks whose normalised error (theta_hat - theta)^T Sigma^-1
(theta_hat - theta), Sigma = (J^T J)^-1 sigma^2, lies below the chi-square(4) 95 % point;
about 95 % for honest one-sigma errors. Every number is read from the run files under
`data/runs/`."""

log = logging.getLogger(__name__)

REGION_NOTE = "\n".join(
    f"- {r.capitalize()}: bearing <= {b} deg, distance <= {d:.0%}, course <= {c} deg, "
    f"speed <= {s:.0%}" for r, (b, d, c, s) in REGIONS.items()
)


def _pct(rate, lo, hi):
    return f"{100 * rate:.1f} % ({100 * lo:.1f}-{100 * hi:.1f})"


def _num(x, fmt="{:.3g}"):
    return "-" if pd.isna(x) else fmt.format(x)


# the statuses' names in the table's status column
STATUS_ABBREVIATIONS = {"ok": "ok", "not_converged": "not_conv", "poor_fit": "poor_fit",
                        "unobservable": "unobs", "manoeuvring": "manoeuv",
                        "approximate": "approx", "position_only": "pos_only"}
# counted (a column of the CSV, a count in the status column) only where some row has one: a
# status only targets that may manoeuvre get, which a constant-velocity table never shows
COUNTED_WHERE_SEEN = ("position_only",)


def write_success_table(rows: list[dict], tables_dir, name="bearings2d",
                        paper_section=None) -> list[Path]:
    """Write ``<name>.csv``, ``<name>.md`` (with ``paper_section``, ``tables.write_table``)
    and ``<name>.png``; returns their paths. A status of ``COUNTED_WHERE_SEEN`` is counted
    only where some row has one."""
    tables_dir = Path(tables_dir)
    table = pd.DataFrame(rows, columns=TABLE_COLUMNS).sort_values(
        ["estimator", "sigma_deg"], kind="stable").reset_index(drop=True)
    statuses = [s for s in STATUSES
                if s not in COUNTED_WHERE_SEEN or table[f"n_{s}"].fillna(0).any()]
    table = table.drop(columns=[f"n_{s}" for s in STATUSES if s not in statuses])

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
        "status " + " / ".join(STATUS_ABBREVIATIONS[s] for s in statuses): [
            " / ".join(str(v) for v in r) for r in table[[f"n_{s}" for s in statuses]].to_numpy()],
        "consistent (ok)": [_pct(*v) if pd.notna(v[0]) else "-" for v in
                            table[["consistent", "consistent_lo", "consistent_hi"]].to_numpy()],
    })
    paths = write_table(tables_dir, name, "Bearings-only TMA: success rates by estimator and "
                        "noise", INTRO.format(statuses=" / ".join(statuses)), table, shown,
                        float_format="%.6g",
                        notes="Success regions:\n" + REGION_NOTE, paper=paper_section)
    paths.append(tables_dir / f"{name}.png")

    fig, axes = table_subplots(2, 2, figsize=(10, 7), sharex=True, sharey=True)
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
    fixed_layout(fig)
    save_figure(fig, paths[-1])
    plt.close(fig)
    return paths


REPORT_COLUMNS = ["range_now_m", "range_sd_m", "bearing_now_deg", "bearing_sd_deg",
                  "course_deg", "course_sd_deg", "speed_m_s", "speed_sd_m_s", "sigma_used_deg",
                  "fit_p_value", "motion_p_value", "accel_psd_m2_s3", "leg_start_s", "status"]


def _poor_fit_note(row) -> str:
    """Why the residuals are not the declared noise, by which way the test failed."""
    ratio = row.sqrt_ka_deg / row.sigma_used_deg if row.sigma_used_deg > 0 else np.inf
    if ratio < 1:
        why = "far smaller than the declared noise: every bearing in radians, or sigma overstated?"
    else:
        why = ("larger than the declared noise: outliers, sigma_deg understated, or some "
               "bearings in radians?")
    return (f"residual RMS {row.sqrt_ka_deg:.3g} deg against sigma {row.sigma_used_deg:.3g} deg "
            f"(chi-square p = {row.fit_p_value:.1e}): {why}")


NOT_CONVERGED = {  # by stop_reason (estimates.parquet; marquardt.py's STOP_MAX_ITER and
    # STOP_LAMBDA_MAX, not imported: it loads the compiler, which aggregate never needs)
    1: "the estimator stopped at max_iter before converging",
    2: "the estimator stopped at lambda_max (its damping) before converging",
}
SINGULAR = ("no finite estimate: the solve was singular (too little change of bearing: no "
            "own-ship manoeuvre? a target far away?)")


def status_note(report: pd.DataFrame, stop_reason=None, sigma_known=True) -> list[str]:
    """Why a track is not ok, in words (empty for ok tracks), naming the test that decided;
    ``stop_reason`` (per track) says why an estimator did not converge: LM's ``max_iter`` or
    ``lambda_max``, or a direct solver's (``iv``, ``nbearings``) singular system.
    ``sigma_known``: the log declares its noise (the chi-square test decides ``poor_fit``);
    else a robust fit's runs test on the residuals' signs does."""
    notes = []
    stops = [None] * len(report) if stop_reason is None else list(stop_reason)
    for row, stop in zip(report.itertuples(index=False), stops, strict=True):
        status = row.status
        if status == "poor_fit" and not sigma_known:
            note = (f"the residuals are not white noise (runs test on their signs, p = "
                    f"{row.fit_p_value:.1e}): a systematic error (a bias, a drift, outliers in "
                    "runs?); give sigma_deg= to test them against your sensor's noise")
        elif status == "poor_fit":
            note = (_poor_fit_note(row) if np.isfinite(row.fit_p_value) and
                    row.sigma_used_deg > 0 else
                    f"the residuals are not noise (p = {row.fit_p_value:.1e})")
        elif status == "manoeuvring":
            note = (f"the residuals drift (trend test p = {row.motion_p_value:.1e}): the "
                    "target did not move as assumed (a manoeuvre?); `estimator=last_leg` "
                    "solves its last leg")
        elif status == "not_converged":
            note = (NOT_CONVERGED.get(stop, SINGULAR) if stop is not None else
                    "the estimator stopped before converging")
        elif status == "position_only":
            note = (f"course sd {row.course_sd_deg:.0f} deg, speed sd {row.speed_sd_m_s:.3g} "
                    f"m/s at {row.speed_m_s:.3g} m/s: where it is heading is not determined (a "
                    "manoeuvre too recent for the bearings to show where it led?)")
        elif status == "unobservable":
            note = ((f"range sd {row.range_sd_m / row.range_now_m:.0%} of the range: "
                     if np.isfinite(row.range_sd_m) else "range ") +
                    "not determined from this geometry (no own-ship manoeuvre? target too "
                    "far? too much target motion?)")
        elif status == "approximate":
            note = ("the estimator's one-sigma errors are not honest here: it is biased "
                    "(nbearings) or assumes a constant-velocity target while this log's "
                    "targets are not known to move so; use lm")
        else:
            note = ""
        notes.append(note)
    return notes


# what a report shows of an estimate: blank, all of it, where it is no answer
# (``status.not_an_answer``); its heading (course, speed) blank where the status says that it
# is not determined (``status.HEADING_UNDETERMINED``: ``position_only``)
HEADING_COLUMNS = ["course_deg", "course_sd_deg", "speed_m_s", "speed_sd_m_s"]
ESTIMATE_COLUMNS = ["x_now_m", "x_sd_m", "y_now_m", "y_sd_m", "lat_now_deg", "lon_now_deg",
                    "range_now_m", "range_sd_m", "bearing_now_deg", "bearing_sd_deg",
                    *HEADING_COLUMNS]
END_BEARING_COLUMNS = ["end_bearing_deg", "end_bearing_sd_deg"]  # the estimate stage's
NOT_DETERMINED = "not determined"  # a heading cell of the Markdown where it is blank so


def blank_non_answers(report: pd.DataFrame, max_range_rel_sd=None, recorded=True,
                      end_bearing=None) -> np.ndarray:
    """Blank (NaN) every estimated number of the tracks whose estimate is no answer
    (``status.not_an_answer``: diverged, collapsed, without a one-sigma error, or off where
    its last bearings point: ``end_bearing``, the estimate stage's ``END_BEARING_COLUMNS``,
    None: not checked), in place, and add why to their note; their status stays (the
    cause). Returns the mask."""
    bearings = None if end_bearing is None else {
        "bearing_now_deg": report["bearing_now_deg"], "bearing_sd_deg": report["bearing_sd_deg"],
        **end_bearing}
    why = not_an_answer(report["range_now_m"], report["range_sd_m"], report["speed_m_s"],
                        *(() if max_range_rel_sd is None else (max_range_rel_sd,)),
                        recorded=recorded, bearings=bearings)
    blank = why != ""
    if blank.any():
        for column in ESTIMATE_COLUMNS:
            report[column] = report[column].astype(float).mask(blank)
        report["note"] = [
            "; ".join(filter(None, [note, f"the estimate is not shown: {reason}"]))
            if reason and not note.startswith("no finite estimate") else note
            for note, reason in zip(report["note"], why, strict=True)]
    return blank


def blank_headings(report: pd.DataFrame) -> np.ndarray:
    """Blank (NaN) course and speed and their errors of the tracks whose status says where
    they are heading is not determined (``status.HEADING_UNDETERMINED``), in place; their
    position now stays, and their note says why. Returns the mask."""
    headless = report["status"].isin(HEADING_UNDETERMINED).to_numpy()
    if headless.any():
        for column in HEADING_COLUMNS:
            report[column] = report[column].astype(float).mask(headless)
    return headless


def track_report(estimates: pd.DataFrame, epoch_utc_ns=None, origin_deg=None,
                 labels=None, sigma_known=True, max_range_rel_sd=None,
                 recorded=True) -> pd.DataFrame:
    """Per-track state and kinematics at each track's last bearing ("now") with 1-sigma
    errors and the status, as the estimator computed them; a note says why a track is not ok.
    An estimate that is no answer (``status.not_an_answer``: diverged, collapsed, without a
    one-sigma error, or off where its last bearings point) is blank, with its status and a
    note that says so (``max_range_rel_sd``: the estimator's, where above 1; ``recorded``: a
    recording, whose targets are real vessels); a ``position_only`` track's course and speed
    are blank (``blank_headings``), its position now shown.

    ``label``: the contact's name (``labels``: track id -> text; else the id);
    ``t_now_s``: the last bearing, in seconds from the log's start (its first bearing, the
    dataset's t = 0); ``time_now_utc``: its ISO-8601 UTC (``epoch_utc_ns``: UTC of t = 0;
    else blank); ``x_now_m``, ``y_now_m`` (local plane, m) with ``x_sd_m``, ``y_sd_m``;
    ``lat_now_deg``, ``lon_now_deg`` (WGS84, from ``origin_deg`` = (lat, lon) of the local
    plane's origin; NaN without one); ``leg_start_s`` (and ``leg_start_utc``): from when the
    solution holds (its first bearing, or the end of the last manoeuvre ``last_leg`` found),
    in seconds from the log's start. ``sigma_known``: the log declares its bearing noise
    (which test a ``poor_fit`` note names).
    """
    e = estimates

    def utc(seconds):
        return ([None] * len(seconds) if epoch_utc_ns is None else
                [format_utc(epoch_utc_ns + round(v * 1e9)) for v in seconds.tolist()])

    t = e["t_last_s"].to_numpy()
    x_now = (e["x0_m"] + e["vx_m_s"] * t).to_numpy()
    y_now = (e["y0_m"] + e["vy_m_s"] * t).to_numpy()
    cov = position_covariance(theta_covariance(e), t)
    lat, lon = ((np.full(t.size, np.nan),) * 2 if origin_deg is None
                else local_to_geodetic(x_now, y_now, origin_deg))
    ids = e["track_id"].tolist()
    report = pd.DataFrame({
        "track_id": e["track_id"],
        "label": [(labels or {}).get(i, str(i)) for i in ids],
        "n_bearings": e["n_bearings"],
        "t_now_s": t,
        "time_now_utc": utc(t),
        "x_now_m": x_now, "x_sd_m": np.sqrt(cov[:, 0, 0]),
        "y_now_m": y_now, "y_sd_m": np.sqrt(cov[:, 1, 1]),
        "lat_now_deg": lat, "lon_now_deg": lon,
        **{c: e[c] for c in REPORT_COLUMNS},
        "leg_start_utc": utc(e["leg_start_s"].to_numpy()),
        "sqrt_ka_deg": np.rad2deg(np.sqrt(e["cost_rad2"] / e["n_bearings"])),
        "converged": e["converged"].astype(bool),
    })
    report["note"] = status_note(report, e["stop_reason"].to_numpy(), sigma_known)
    blank_non_answers(report, max_range_rel_sd, recorded,
                      {c: e[c].to_numpy(float) for c in END_BEARING_COLUMNS}
                      if all(c in e for c in END_BEARING_COLUMNS) else None)
    blank_headings(report)
    return report


def write_track_report(report: pd.DataFrame, tables_dir, name: str, source: str,
                       geographic=None) -> list[Path]:
    """``<name>.csv`` (every column of ``report``) and ``<name>.md`` (its formatted cells; a
    blank estimate as ``-``); ``geographic``: the log has a geographic origin (a column of
    latitude and longitude; None: where the report has any)."""

    headless = (report["status"].isin(HEADING_UNDETERMINED)
                & report["range_now_m"].notna()).to_numpy()

    def pm(value, sd, fmt, heading=False):  # blank ("-") where the estimate is no answer
        # (its note says), "not determined" where its heading is not (position_only)
        return [f"{v:{fmt}} ± {e:{fmt}}" if np.isfinite(v) and np.isfinite(e) else
                NOT_DETERMINED if heading and h else "-"
                for (v, e), h in zip(report[[value, sd]].to_numpy(float), headless,
                                     strict=True)]

    def position():
        if not (report["lat_now_deg"].notna().any() if geographic is None else geographic):
            return {}
        return {"position now (lat, lon deg)": [
            f"{a:.5f}, {b:.5f}" if np.isfinite(a) else "-"
            for a, b in report[["lat_now_deg", "lon_now_deg"]].to_numpy()]}

    shown = pd.DataFrame({
        "track": shown_labels(report["label"]), "n": report["n_bearings"],
        "t now (s from start)": report["t_now_s"].map("{:.1f}".format),
        **({} if report["time_now_utc"].isna().all() else {"now (UTC)": report["time_now_utc"]}),
        **position(),
        "range now (m)": pm("range_now_m", "range_sd_m", ".0f"),
        "bearing now (deg)": pm("bearing_now_deg", "bearing_sd_deg", ".2f"),
        "course (deg)": pm("course_deg", "course_sd_deg", ".1f", heading=True),
        "speed (m/s)": pm("speed_m_s", "speed_sd_m_s", ".2f", heading=True),
        **shown_columns(report),  # against the AIS truth, when the log has one
        "sqrt(Ka) (deg)": report["sqrt_ka_deg"].map("{:.3g}".format),
        "holds from": (report["leg_start_s"].map("t = {:.1f} s".format)
                       if report["leg_start_utc"].isna().all() else report["leg_start_utc"]),
        "status": report["status"],
        "why": report["note"],
    })
    scored = "covered" in report  # against the AIS of its trial (truth_report)
    intro = (f"Estimates per track of `{source}` "
             f"({'against the AIS of its trial' if scored else 'no ground truth'}). 'now' is "
             "each track's last "
             "bearing epoch, in seconds from the log's start (its first bearing) and in UTC "
             "when the log is dated; ± is one standard deviation (sigma as in column "
             "sigma_used_deg of the CSV: nominal, or estimated from the residuals), which "
             "includes the "
             "target's own motion (accel_psd_m2_s3: a nearly-constant-velocity target) for "
             "`lm`; 'holds from' is the first bearing the solution rests on. "
             "Trust only `ok` tracks, and the position now of `position_only` ones (their course "
             f"and speed: '{NOT_DETERMINED}'); 'why' says what is wrong with the others, and "
             "why an estimate that is no answer (diverged, collapsed onto own-ship, without a "
             "one-sigma error, or off where its last bearings point) is not shown ('-'). The "
             "CSV also "
             "holds the position now in local metres (x east, y north) with its one-sigma "
             f"errors; `{name}-<track>.png` shows each contact on a plan (the first "
             f"{MAX_PLOTS}).")
    if scored:
        intro += (" AIS ship: the contact's ship and how well its AIS fits the bearings; z: "
                  "(estimate - truth) / one sigma; covered: the truth within the estimate's 95 % "
                  "region of position and velocity (the CSV has the errors and the truth).")
    return write_table(tables_dir, name, f"Bearings-only TMA estimates: {name}", intro, report,
                       shown, notes=coverage_text(report) if scored else "")


STATUS_WHY = {  # a verdict in a few words, for the one warning line of its tracks
    "not_converged": "the estimator did not converge",
    "manoeuvring": ("the residuals drift: the target did not move as assumed; "
                    "estimator=last_leg solves the last leg"),
    "poor_fit": "the residuals are not the declared noise",
    "unobservable": "the range is not determined from this geometry",
    "approximate": "the estimator's one-sigma errors are not honest here",
    "position_only": "where they are heading is not determined (their position now holds)",
}
LISTED = 10  # contacts named in a warning line


def warn_not_ok(report: pd.DataFrame, where: str):
    """One warning per verdict other than ``ok``: a track's note, or for several tracks their
    count, the verdict in words and the first ``LISTED`` contacts (the table's ``why`` column
    holds each one's note)."""
    shown = np.array(shown_labels(report["label"]), dtype=object)
    for status in [s for s in STATUSES if s != "ok"]:
        rows = np.flatnonzero((report["status"] == status).to_numpy())
        if rows.size == 1:
            log.warning("%s track %s: %s: %s", where, shown[rows[0]], status,
                        report["note"].iloc[rows[0]])
        elif rows.size:
            names = ", ".join(shown[rows[:LISTED]]) + (", ..." if rows.size > LISTED else "")
            log.warning("%s: %d tracks %s (%s): %s; the table's 'why' column says more for "
                        "each", where, rows.size, status, STATUS_WHY[status], names)


def contact_report(estimates: pd.DataFrame, logs, where: str, max_range_rel_sd=None,
                   recorded=True) -> pd.DataFrame:
    """``track_report`` of the estimates of ``logs`` (a recorded log's, one per own-ship, or
    a simulated one's: not ``recorded``): their UTC epoch, origin and labels. What aggregate
    writes, and ``tma.estimate`` returns (``max_range_rel_sd``: the estimator's)."""
    epoch, origin, labels = reference(logs, where)
    return track_report(estimates, epoch, origin, labels,
                        sigma_known=any(lg.sigma_deg is not None for lg in logs),
                        max_range_rel_sd=max_range_rel_sd, recorded=recorded)


def _report_without_truth(entry, tables_dir, name: str, progress=None) -> list[Path]:
    """The per-track report of a dataset without truth: ``<name>.{csv,md}``, a PNG per
    contact and, with a geographic origin, the map MCAP ``<name>.mcap``."""
    m, dataset = entry.dataset.manifest, entry.dataset
    logs = read_logs(dataset)
    epoch, origin, _ = reference(logs, str(dataset.root))
    report = contact_report(entry.estimates, logs, str(dataset.root),
                            entry.manifest["config"].get("max_range_rel_sd"))
    truth, truth_track = dataset_truth(dataset)
    if truth is not None:  # scored against the AIS of its trial (ingest truth=FILE)
        report = with_truth(report, entry.estimates, truth)
        log.info("%s: %s", dataset.name, coverage_text(report))
    warn_not_ok(report, dataset.name)
    write_parquet_atomic(entry.run_root / "report.parquet",
                         pa.Table.from_pandas(report, preserve_index=False))
    own = {}
    if m.get("navigation"):  # own-ship's source, when not the log (issue 38)
        from tma.ais.ownship import ownship_of

        own = ownship_of(m)
    written = write_track_report(report, tables_dir, name,
                                 m.get("input", {}).get("path", dataset.name)
                                 + (f"; own-ship: {own['ownship']}" if own else ""),
                                 geographic=origin is not None)
    paths = run_path(entry.run_root)
    written += write_track_plots(report, entry.estimates, logs, tables_dir, name, progress,
                                 paths)
    if origin is None:
        log.info("%s: no map MCAP (%s.mcap): the dataset has no geographic origin (its "
                 "own-ship is in local metres; ingest latitude/longitude navigation or give "
                 "origin.lat/origin.lon)", dataset.name, name)
    elif epoch is None:
        log.info("%s: no map MCAP (%s.mcap): the dataset's times are relative (no UTC), so the "
                 "map would be dated 1970; ingest it again with time.start_utc=<ISO-8601 UTC of "
                 "the log's time 0>", dataset.name, name)
    else:
        written.append(write_map_mcap(Path(tables_dir) / f"{name}.mcap", report,
                                      entry.estimates, logs, epoch, origin,
                                      {"dataset": dataset.name, "estimator": entry.estimator,
                                       **own},
                                      truth_track=truth_track, paths=paths))
    return written


def run_path(run_root) -> pd.DataFrame | None:
    """The run's side table ``path`` (``estimated_path``: the trajectory each answer rests
    on, which the plots and the map draw), None where it kept none (an estimator that
    assumes constant velocity, a simulation, a run from before it)."""
    path = Path(run_root) / "path.parquet"
    return arrow.read_table(path).to_pandas() if path.exists() else None


# the other kinds of table of simulated runs an experiment may ask for (``report=``): each
# estimator against the Cramer-Rao bound, and targets that manoeuvre
REPORTS = {"benchmark": benchmark.write_benchmark,
           "manoeuvre": manoeuvre_table.write_manoeuvre_table,
           "real_motion": real_motion_table.write_real_motion_table}  # AIS own-ship, targets


def aggregate_runs(entries, tables_dir, table_name, progress=None, report=None) -> list[Path]:
    """Metrics per track into each run dir; for simulated datasets the comparison table with
    its section against the paper, or the kind of table ``report`` names (``REPORTS``), and
    a per-track report for each dataset without truth (``progress``: a progress bar over its
    per-contact plots; None: on a terminal only)."""
    rows, written, runs, truths = [], [], [], {}
    for entry in entries:
        if id(entry.dataset) not in truths:  # read (and checked) once per dataset
            truths[id(entry.dataset)] = entry.dataset.read_truth()
        truth = truths[id(entry.dataset)]
        if truth is None or entry.dataset.manifest["source"] != "simulate":  # a recorded log
            name = table_name if len(entries) == 1 else f"{entry.dataset.name}-{entry.estimator}"
            written += _report_without_truth(entry, tables_dir, name, progress)
            continue
        metrics = track_metrics(entry.estimates, truth)
        write_parquet_atomic(entry.run_root / "metrics.parquet",
                             pa.Table.from_pandas(metrics, preserve_index=False))
        sigma = entry.dataset.manifest["config"]["sigma_deg"]
        rows.append(summary_row(metrics, entry.estimator, sigma))
        runs.append(paper.Run(entry.estimator, sigma, metrics,
                              entry.estimates["n_bearings"].to_numpy(),
                              entry.dataset.manifest["config"], entry.manifest["config"]))
    if rows and report is not None:  # another kind of table, declared by the experiment
        written += REPORTS[report](entries, tables_dir, table_name)
    elif rows:
        written += write_success_table(rows, tables_dir, table_name,
                                       (paper.against_paper(runs), paper.INTRO))
    return written


# -- the Python API's hooks (tma.api): what tma.estimate returns, tma.plot_contact draws and
# tma.write_map writes of bearings2d estimates

# the metrics of a simulated track that are numbers of its estimate: blank where it is blank
SIMULATED_ERRORS = ["bearing_err_deg", "distance_rel_err", "course_err_deg", "speed_rel_err",
                    "nees"]
HEADING_ERRORS = ["course_err_deg", "speed_rel_err"]  # blank where the heading is


def results(run) -> tuple[pd.DataFrame, dict]:
    """``tma.estimate``'s results of ``run`` (``tma.api.Estimated``): the per-contact report
    aggregate writes (``contact_report``), then against the AIS of a recording its truth
    columns (``truth_report.with_truth``), against a simulation's truth its metrics
    (``metrics.track_metrics``, as ``tma.runs`` gives them; the errors and ``nees`` blank
    where the estimate is, the course and speed errors where its heading is). Tables:
    ``estimates``, the estimator's own columns (``x0_m``.., ``jtj_ij``, ``t_last_s``: what the
    plot and the map draw from), ``x0_m``.. blank where the report's estimate is, and the
    side table ``path`` where the estimator kept one (``estimated_path``: the trajectory
    each answer rests on, which the plot and the map draw)."""
    est = run.estimates
    report = contact_report(est, run.logs, "estimate",
                            getattr(run.estimator.config, "max_range_rel_sd", None),
                            run.recorded)
    blank = ~np.isfinite(report["range_now_m"].to_numpy(float))
    if run.truth is not None and run.recorded:  # the AIS of its trial
        report = with_truth(report, est, run.truth)
    elif run.truth is not None:  # a simulation
        metrics = track_metrics(est, run.truth)
        metrics.loc[blank, SIMULATED_ERRORS] = np.nan
        metrics.loc[report["status"].isin(HEADING_UNDETERMINED).to_numpy(),
                    HEADING_ERRORS] = np.nan
        report = pd.concat([report, metrics.drop(columns=[c for c in metrics
                                                          if c in report])], axis=1)
    estimates = est.copy()
    estimates.loc[blank, list(THETA)] = np.nan
    return report, {"estimates": estimates, **run.side_tables}


SAME_TIME_S = 1e-6  # a contact's last bearing time in the results and in its recording
SAME_PLACE_M = 1e-3  # own-ship there


def check_logs(report: pd.DataFrame, estimates: pd.DataFrame, logs):
    """ValueError, naming the first contact that differs, unless ``logs`` are those the
    contacts of ``report`` (and their ``estimates``, row for row) were estimated from: each
    contact's track id in them, its last bearing at the same time from the same own-ship
    position, and its UTC the same where both are dated."""
    where = {int(i): (lg, row) for lg in logs for row, i in enumerate(lg.track_id)}
    epoch = logs[0].epoch_utc_ns
    for r, e in zip(report.itertuples(index=False), estimates.itertuples(index=False),
                    strict=True):
        place = where.get(int(r.track_id))
        if place is None:
            why = f"track id {r.track_id} is not in this recording"
        else:
            lg, row = place
            last = np.flatnonzero(np.isfinite(lg.bearing_deg[row]))[-1]
            why = ""
            if not (abs(lg.t_s[last] - e.t_last_s) <= SAME_TIME_S
                    and abs(lg.own_x_m[last] - e.own_x_last_m) <= SAME_PLACE_M
                    and abs(lg.own_y_m[last] - e.own_y_last_m) <= SAME_PLACE_M):
                why = "its last bearing is at another time or own-ship position here"
            elif isinstance(r.time_now_utc, str) and epoch is not None and (
                    r.time_now_utc != format_utc(epoch + round(r.t_now_s * 1e9))):
                why = f"its last bearing is at {r.time_now_utc} there, at another UTC here"
        if why:
            raise ValueError(f"these results were not estimated from this recording (contact "
                             f"{r.label!r}: {why}); pass the recording given to tma.estimate")


def plot_contact(report: pd.DataFrame, estimates: pd.DataFrame, logs, label,
                 side_tables=None):
    """``tma.plot_contact``: the Figure of contact ``label`` (``map_outputs.contact_figure``)
    of the contacts of ``report`` and their ``estimates``, drawn over ``logs``, along the
    trajectory its answer rests on where ``side_tables`` hold it (``path``)."""
    check_logs(report, estimates, logs)
    return contact_figure(report, estimates, logs, label,
                          paths=(side_tables or {}).get("path"))


def write_map(path, report: pd.DataFrame, estimates: pd.DataFrame, logs, truth_track=None,
              side_tables=None) -> Path:
    """``tma.write_map``: the map MCAP of the contacts of ``report`` (``map_outputs.
    write_map_mcap``; along the trajectory each answer rests on where ``side_tables`` hold
    it, ``path``), which needs own-ship in latitude/longitude and UTC times."""
    check_logs(report, estimates, logs)
    epoch, origin = logs[0].epoch_utc_ns, logs[0].origin_deg
    if origin is None:
        raise ValueError("a map needs own-ship in latitude/longitude; this log's is in local "
                         "x/y metres (a simulation, or a log read without them): read a log "
                         "with its origin, origin={'lat': ..., 'lon': ...}")
    if epoch is None:
        raise ValueError("a map needs UTC times; this log's are relative: read it with "
                         "time={'start_utc': ...}")
    return write_map_mcap(path, report, estimates, logs, epoch, origin,
                          {"estimator": "tma.estimate"}, truth_track=truth_track,
                          paths=(side_tables or {}).get("path"))
