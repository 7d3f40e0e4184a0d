"""``bearings2d``'s report of a dataset without truth (an ingested log): per track the
estimated state and kinematics now (local metres, latitude/longitude, UTC) with one-sigma
errors from the Gauss-Newton covariance (J^T J)^-1 sigma^2 and each track's status (computed
by the estimators, ``tma.families.bearings2d.status``) with a note that says why a track is
not ok (``<name>.csv``, ``<name>.md``, ``report.parquet`` in the run), with its drawings: a
PNG per contact (``contact_plots``) and, when the dataset has a geographic origin, the
estimated tracks as an MCAP for Foxglove (``map_mcap``). A log of several platforms (ships,
buoys, shore stations) adds per track the ``platforms`` that took its bearings."""

import logging
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from tma.families.bearings2d.contact_plots import MAX_PLOTS, write_track_plots
from tma.families.bearings2d.drawn_tracks import (
    position_covariance,
    read_logs,
    reference,
    theta_covariance,
)
from tma.families.bearings2d.map_mcap import write_map_mcap
from tma.families.bearings2d.platforms import platforms_seen
from tma.families.bearings2d.status import (
    INTERVAL_COLUMNS,
    STATUSES,
    heading_undetermined,
    not_an_answer,
)
from tma.families.bearings2d.truth_report import (
    coverage_text,
    dataset_truth,
    shown_columns,
    with_truth,
)
from tma.io import arrow
from tma.io.atomic import write_parquet_atomic
from tma.maths.geo import local_to_geodetic, north_at_local
from tma.sources.labels import shown_labels
from tma.tables.write import write_table
from tma.utc import format_utc

log = logging.getLogger(__name__)


INTERVALS = tuple(c for ends in INTERVAL_COLUMNS.values() for c in ends)
REPORT_COLUMNS = ["range_now_m", "range_sd_m", "bearing_now_deg", "bearing_sd_deg",
                  "course_deg", "course_sd_deg", "speed_m_s", "speed_sd_m_s",
                  *INTERVALS, "sigma_used_deg",
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
                    "solves its last leg (its range only if own-ship manoeuvred since)")
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
                    "far? too much target motion?)" + _resting_on(row))
        elif status == "approximate":
            note = ("the estimator's one-sigma errors are not honest here: it is biased "
                    "(nbearings) or assumes a constant-velocity target while this log's "
                    "targets are not known to move so; use lm")
        else:
            note = ""
        notes.append(note)
    return notes


def _resting_on(row) -> str:
    """Where an answer rests on the recent part of its bearings (``leg_start_s`` after the
    log's start: a target that may manoeuvre, or a last leg), that only own-ship's motion
    within it can determine the range: a longer log cannot."""
    span = row.t_now_s - row.leg_start_s
    if not (row.leg_start_s > 0 and np.isfinite(span)):
        return ""
    return (f"; the answer rests on the last {span / 60:.0f} min of bearings (leg_start_s): "
            "an own-ship manoeuvre within them can give the range, earlier bearings cannot")


# what a report shows of an estimate: blank, all of it, where it is no answer
# (``status.not_an_answer``); its heading (course, speed) blank where the status says that it
# is not determined (``status.HEADING_UNDETERMINED``: ``position_only``, ``unobservable``)
HEADING_COLUMNS = ["course_deg", "course_sd_deg", "speed_m_s", "speed_sd_m_s",
                   *INTERVAL_COLUMNS["course"], *INTERVAL_COLUMNS["speed"]]
ESTIMATE_COLUMNS = ["x_now_m", "x_sd_m", "y_now_m", "y_sd_m", "lat_now_deg", "lon_now_deg",
                    "range_now_m", "range_sd_m", *INTERVAL_COLUMNS["range"], "bearing_now_deg",
                    "bearing_sd_deg", *HEADING_COLUMNS]
END_BEARING_COLUMNS = ["end_bearing_deg", "end_bearing_sd_deg"]  # the estimate stage's
NOT_DETERMINED = "not determined"  # a heading cell of the Markdown where it is blank so


def blank_non_answers(report: pd.DataFrame, max_range_rel_sd=None, recorded=True,
                      end_bearing=None) -> np.ndarray:
    """Blank (NaN) every estimated number of the tracks whose estimate is no answer
    (``status.not_an_answer``: diverged, collapsed, without a one-sigma error, or off where
    its last bearings point: ``end_bearing``, the estimate stage's ``END_BEARING_COLUMNS``,
    None: not checked), in place, and add why to their note; their status stays (the
    cause), but an ``ok`` or ``position_only`` one, which promises an answer, becomes
    ``not_converged`` (the fit ran to no answer). Returns the mask."""
    bearings = None if end_bearing is None else {
        "bearing_now_deg": report["bearing_now_deg"], "bearing_sd_deg": report["bearing_sd_deg"],
        **end_bearing}
    why = not_an_answer(report["range_now_m"], report["range_sd_m"], report["speed_m_s"],
                        *(() if max_range_rel_sd is None else (max_range_rel_sd,)),
                        recorded=recorded, bearings=bearings)
    blank = why != ""
    if blank.any():
        promised = blank & report["status"].isin(["ok", "position_only"]).to_numpy()
        report.loc[promised, "status"] = "not_converged"
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
    headless = heading_undetermined(report["status"])
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
        # (the intervals NaN in the estimates of a run written before they were)
        **{c: e[c] if c in e or c not in INTERVALS else np.nan for c in REPORT_COLUMNS},
        "leg_start_utc": utc(e["leg_start_s"].to_numpy()),
        "sqrt_ka_deg": np.rad2deg(np.sqrt(e["cost_rad2"] / e["n_bearings"])),
        "converged": e["converged"].astype(bool),
    })
    report["note"] = status_note(report, e["stop_reason"].to_numpy(), sigma_known)
    blank_non_answers(report, max_range_rel_sd, recorded,
                      {c: e[c].to_numpy(float) for c in END_BEARING_COLUMNS}
                      if all(c in e for c in END_BEARING_COLUMNS) else None)
    blank_headings(report)
    if origin_deg is not None:  # directions from true north where they are read
        # the estimates stay on the plane (0.0156 deg per km east-west of the origin at 60 N)
        report["bearing_now_deg"] = (report["bearing_now_deg"] - north_at_local(
            e["own_x_last_m"], e["own_y_last_m"], origin_deg)) % 360.0
        north = north_at_local(x_now, y_now, origin_deg)
        for column in ("course_deg", *INTERVAL_COLUMNS["course"]):
            report[column] = (report[column] - north) % 360.0
    return report


def write_track_report(report: pd.DataFrame, tables_dir, name: str, source: str,
                       geographic=None, reference_platform: str | None = None) -> list[Path]:
    """``<name>.csv`` (every column of ``report``) and ``<name>.md`` (its formatted cells; a
    blank estimate as ``-``); ``geographic``: the log has a geographic origin (a column of
    latitude and longitude; None: where the report has any). A report of a log of several
    platforms (its column ``platforms``) shows them, and the intro says range and bearing
    now are from ``reference_platform``."""

    headless = heading_undetermined(report["status"]) & report["range_now_m"].notna().to_numpy()

    def pm(value, sd, fmt, heading=False, quantity=None):  # blank ("-") where the
        # estimate is no answer (its note says), "not determined" where its heading is not
        # (position_only); [the 2-sd interval] where the answer states one
        lo, hi = ((report[INTERVAL_COLUMNS[quantity][0]], report[INTERVAL_COLUMNS[quantity][3]])
                  if quantity else (np.full(len(report), np.nan),) * 2)
        return [(f"{v:{fmt}} ± {e:{fmt}}" + (f" [{a:{fmt}}, {b:{fmt}}]" if np.isfinite(a)
                                              and np.isfinite(b) else "")) if np.isfinite(v)
                and np.isfinite(e) else NOT_DETERMINED if heading and h else "-"
                for (v, e), a, b, h in zip(report[[value, sd]].to_numpy(float),
                                           np.asarray(lo, float), np.asarray(hi, float),
                                           headless, strict=True)]

    def position():
        if not (report["lat_now_deg"].notna().any() if geographic is None else geographic):
            return {}
        return {"position now (lat, lon deg)": [
            f"{a:.5f}, {b:.5f}" if np.isfinite(a) else "-"
            for a, b in report[["lat_now_deg", "lon_now_deg"]].to_numpy()]}

    shown = pd.DataFrame({
        "track": shown_labels(report["label"]), "n": report["n_bearings"],
        **({"platforms": ["+".join(shown_labels(seen.split("+")))
                          for seen in report["platforms"]]} if "platforms" in report else {}),
        "t now (s from start)": report["t_now_s"].map("{:.1f}".format),
        **({} if report["time_now_utc"].isna().all() else {"now (UTC)": report["time_now_utc"]}),
        **position(),
        "range now (m)": pm("range_now_m", "range_sd_m", ".0f", quantity="range"),
        "bearing now (deg)": pm("bearing_now_deg", "bearing_sd_deg", ".2f"),
        "course (deg)": pm("course_deg", "course_sd_deg", ".1f", heading=True,
                           quantity="course"),
        "speed (m/s)": pm("speed_m_s", "speed_sd_m_s", ".2f", heading=True, quantity="speed"),
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
             "sigma_used_deg of the CSV: nominal, or estimated from the bearings), which "
             "includes the "
             "target's own motion (accel_psd_m2_s3: a nearly-constant-velocity target) for "
             "`lm`; [a, b] is where the truth lies 95 % of the time by the answer's own "
             "account (95.4 %, what ±2 sd hold of a Gaussian; the CSV also has the 68.3 % "
             "one): ± is often wider, as it carries the tails of manoeuvres the bearings "
             "cannot rule out, and [a, b] reaches farther on the side one could have taken "
             "the target (a course's runs clockwise from a to b, across north where b < a); "
             "the estimate, an average over those, may lie outside it (simulated "
             "targets: [a, b] holds the truth at its rate where a manoeuvre is unlikely, "
             "less often where one was surely made); "
             "'holds from' is the first bearing the solution rests on. "
             "Trust only `ok` tracks, and the position now of `position_only` ones (their course "
             f"and speed: '{NOT_DETERMINED}'); 'why' says what is wrong with the others, and "
             "why an estimate that is no answer (diverged, collapsed onto own-ship, without a "
             "one-sigma error, or off where its last bearings point) is not shown ('-'). The "
             "CSV also "
             "holds the position now in local metres (x east, y north) with its one-sigma "
             f"errors; `{name}-<track>.png` shows each contact on a plan (the first "
             f"{MAX_PLOTS}).")
    if "platforms" in report:
        intro += (" 'platforms': those that took the track's bearings (the plan draws each "
                  "one's lines of sight from it, in its colour); range and bearing now are "
                  "from " + (f"`{shown_labels([reference_platform])[0]}`" if reference_platform
                             else "the first")
                  + ".")
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
    a simulated one's: not ``recorded``): their UTC epoch, origin and labels; where a log
    holds several platforms, per track the ``platforms`` that took its bearings
    (``platforms.platforms_seen``, names joined by ``+``) after ``n_bearings``. What
    aggregate writes, and ``tma.estimate`` returns (``max_range_rel_sd``: the
    estimator's)."""
    epoch, origin, labels = reference(logs, where)
    report = track_report(estimates, epoch, origin, labels,
                          sigma_known=any(lg.sigma_deg is not None for lg in logs),
                          max_range_rel_sd=max_range_rel_sd, recorded=recorded)
    if any(lg.platforms is not None for lg in logs):  # which platforms saw each contact
        seen = {}
        for lg in logs:
            seen.update(zip(lg.track_id.tolist(), platforms_seen(
                lg.platform, np.isfinite(lg.bearing_deg), lg.platforms or ("own-ship",)),
                strict=True))
        report.insert(report.columns.get_loc("n_bearings") + 1, "platforms",
                      [seen[int(i)] for i in report["track_id"]])
    return report


def write_report_without_truth(entry, tables_dir, name: str, progress=None) -> list[Path]:
    """The per-track report of a dataset without truth: ``<name>.{csv,md}``, a PNG per
    contact and, with a geographic origin, the map MCAP ``<name>.mcap``."""
    m, dataset = entry.dataset.manifest, entry.dataset
    logs = read_logs(dataset)
    epoch, origin, _ = reference(logs, str(dataset.root))
    report = contact_report(entry.estimates, logs, str(dataset.root),
                            entry.manifest["config"].get("max_range_rel_sd"))
    truth, truth_track = dataset_truth(dataset)
    if truth is not None:  # scored against the AIS of its trial (ingest truth=FILE)
        report = with_truth(report, entry.estimates, truth, origin)
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
                                 geographic=origin is not None,
                                 reference_platform=_reference_name(entry, logs))
    paths = kept_path_table(entry.run_root)
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


def _reference_name(entry, logs) -> str | None:
    """The platform range and bearing now are from (the estimator's ``reference_platform``,
    else the first) in a log of several; None for one own-ship."""
    names = next((lg.platforms for lg in logs if lg.platforms is not None), None)
    if names is None:
        return None
    return entry.manifest["config"].get("reference_platform") or names[0]


def kept_path_table(run_root) -> pd.DataFrame | None:
    """The run's side table ``path`` (``estimated_path``: the trajectory each answer rests
    on, which the plots and the map draw), None where it kept none (an estimator that
    assumes constant velocity, a simulation, a run from before it)."""
    path = Path(run_root) / "path.parquet"
    return arrow.read_table(path).to_pandas() if path.exists() else None
