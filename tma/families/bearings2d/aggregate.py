"""``bearings2d``'s side of the aggregate stage and of the Python API
(``tma.families.Family.aggregate``): ``aggregate_runs`` (the metrics of simulated runs and
their table, ``success_table``, or another kind an experiment names, ``TABLE_KINDS``; the
report of a recorded log's, ``track_report``) and the hooks of ``tma.estimate``,
``tma.plot_contact`` and ``tma.write_map``."""

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from tma.families.bearings2d import (
    benchmark,
    crossfix_table,
    manoeuvre_table,
    paper,
    real_motion_table,
)
from tma.families.bearings2d.contact_plots import contact_figure
from tma.families.bearings2d.drawn_tracks import platform_now
from tma.families.bearings2d.map_mcap import write_map_mcap
from tma.families.bearings2d.metrics import THETA, summary_row, track_metrics
from tma.families.bearings2d.status import heading_undetermined
from tma.families.bearings2d.success_table import write_success_table
from tma.families.bearings2d.track_report import contact_report, write_report_without_truth
from tma.families.bearings2d.truth_report import with_truth
from tma.io.atomic import write_parquet_atomic
from tma.utc import format_utc

# the other kinds of table of simulated runs an experiment may ask for (``table_kind=``): each
# estimator against the Cramer-Rao bound, targets that manoeuvre, one platform against two
TABLE_KINDS = {"benchmark": benchmark.write_benchmark,
           "manoeuvre": manoeuvre_table.write_manoeuvre_table,
           "real_motion": real_motion_table.write_real_motion_table,  # AIS own-ship, targets
           "crossfix": crossfix_table.write_crossfix_table}


def aggregate_runs(entries, tables_dir, table_name, progress=None, table_kind=None
                   ) -> list[Path]:
    """Metrics per track into each run dir; for simulated datasets the comparison table with
    its section against the paper, or the kind of table ``table_kind`` names (``TABLE_KINDS``), and
    a per-track report for each dataset without truth (``progress``: a progress bar over its
    per-contact plots; None: on a terminal only)."""
    rows, written, runs, truths = [], [], [], {}
    for entry in entries:
        if id(entry.dataset) not in truths:  # read (and checked) once per dataset
            truths[id(entry.dataset)] = entry.dataset.read_truth()
        truth = truths[id(entry.dataset)]
        if truth is None or entry.dataset.manifest["source"] != "simulate":  # a recorded log
            name = table_name if len(entries) == 1 else f"{entry.dataset.name}-{entry.estimator}"
            written += write_report_without_truth(entry, tables_dir, name, progress)
            continue
        metrics = track_metrics(entry.estimates, truth)
        write_parquet_atomic(entry.run_root / "metrics.parquet",
                             pa.Table.from_pandas(metrics, preserve_index=False))
        sigma = entry.dataset.manifest["config"]["sigma_deg"]
        rows.append(summary_row(metrics, entry.estimator, sigma))
        runs.append(paper.Run(entry.estimator, sigma, metrics,
                              entry.estimates["n_bearings"].to_numpy(),
                              entry.dataset.manifest["config"], entry.manifest["config"]))
    if rows and table_kind is not None:  # another kind of table, declared by the experiment
        written += TABLE_KINDS[table_kind](entries, tables_dir, table_name)
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
        report = with_truth(report, est, run.truth, run.logs[0].origin_deg)
    elif run.truth is not None:  # a simulation
        metrics = track_metrics(est, run.truth)
        metrics.loc[blank, SIMULATED_ERRORS] = np.nan
        metrics.loc[heading_undetermined(report["status"]), HEADING_ERRORS] = np.nan
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
    position (with several platforms: one of theirs then), and its UTC the same where both
    are dated."""
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
                    and _observed_from(lg, last, e.own_x_last_m, e.own_y_last_m)):
                why = "its last bearing is at another time or own-ship position here"
            elif isinstance(r.time_now_utc, str) and epoch is not None and (
                    r.time_now_utc != format_utc(epoch + round(r.t_now_s * 1e9))):
                why = f"its last bearing is at {r.time_now_utc} there, at another UTC here"
        if why:
            raise ValueError(f"these results were not estimated from this recording (contact "
                             f"{r.label!r}: {why}); pass the recording given to tma.estimate")


def _observed_from(lg, last: int, x_m: float, y_m: float) -> bool:
    """Whether the results' observer at a contact's last bearing (epoch ``last``), ``x_m``,
    ``y_m``, is the log's: own-ship there, or in a log of several platforms one of them
    then (the reference platform range and bearing now are read from, the estimator's
    ``reference_platform``, which the results do not name)."""
    if lg.platform is None:
        return abs(lg.own_x_m[last] - x_m) <= SAME_PLACE_M and abs(
            lg.own_y_m[last] - y_m) <= SAME_PLACE_M
    return any(np.hypot(*(platform_now(lg, k, lg.t_s[last]) - (x_m, y_m))) <= SAME_PLACE_M
               for k in range(lg.n_platforms))


def plot_contact(report: pd.DataFrame, estimates: pd.DataFrame, logs, label,
                 side_tables=None):
    """``tma.plot_contact``: the Figure of contact ``label`` (``contact_plots.contact_figure``)
    of the contacts of ``report`` and their ``estimates``, drawn over ``logs``, along the
    trajectory its answer rests on where ``side_tables`` hold it (``path``)."""
    check_logs(report, estimates, logs)
    return contact_figure(report, estimates, logs, label,
                          paths=(side_tables or {}).get("path"))


def write_map(path, report: pd.DataFrame, estimates: pd.DataFrame, logs, truth_track=None,
              side_tables=None) -> Path:
    """``tma.write_map``: the map MCAP of the contacts of ``report`` (``map_mcap.
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
