"""The ``bearings2d`` cross-fix table (experiment ``bearings2d_crossfix``, issue 39): one
platform against two on the same targets. The scenario declares its platforms once
(``scenario.observers``: own-ship on a straight course, own-ship on its usual legs, a buoy, a
second ship) and ``scenario.observing`` picks the ones that take bearings in each dataset, so
the datasets share their targets and each platform its noise (``scenario.py``).

One row per (estimator, platforms, target motion) over the simulated targets of one dataset:

- ``crossing_deg``: the median over the tracks of the angle at which the lines of sight from
  the reference platform and from the other(s) cross at the target's true position at its
  last bearing (0-90 deg; with several others the widest; blank for one platform);
- ``ok`` and ``consistent``: the share of ``ok`` tracks, and of those whose normalised error
  of theta against the truth lies below the chi-square(4) 95 % point (about 95 % when the
  one-sigma errors are honest);
- Ref1..Ref4 (``metrics.REGIONS``: bearing, range, course and speed errors at the last
  bearing all within bounds), over every track;
- the median |range error| / range (the tracks with an estimate), and the range RMSE of the
  ``ok`` tracks at the last bearing beside the root of their mean Cramer-Rao bound
  (``metrics.crlb_now``, from the reference platform) and their ratio, and the median bound
  over every track (inf where the geometry leaves range unobservable: one platform that does
  not manoeuvre);
- rates with 95 % Wilson intervals.
"""

from pathlib import Path

import numpy as np
import pandas as pd

from tma.families.bearings2d.benchmark import _num, _pct, dataset_bounds, estimator_label
from tma.families.bearings2d.log import read_bearings_log
from tma.families.bearings2d.manoeuvre_table import motion_label
from tma.families.bearings2d.metrics import (
    NEES_95,
    REGIONS,
    THETA,
    errors_now,
    track_metrics,
)
from tma.families.bearings2d.platforms import observer_now, position_at
from tma.maths.angles import bearing_from_north, crossing_angle_deg
from tma.maths.stats import rate_columns
from tma.tables.write import write_table

COLUMNS = [
    "estimator", "platforms", "motion", "sigma_deg", "n_tracks", "crossing_deg",
    "ok", "ok_lo", "ok_hi", "consistent", "consistent_lo", "consistent_hi",
    *[f"{r}{s}" for r in REGIONS for s in ("", "_lo", "_hi")],
    "median_range_error", "rmse_range_ok_m", "crlb_range_ok_m", "rmse_over_crlb",
    "crlb_range_median_m", "n_failed",
]

INTRO = """Bearings-only TMA from one platform against two (`docs/families.md`, several
platforms): the same simulated targets observed by own-ship alone (on a straight course, or
on its usual legs) and by own-ship with a second platform whose lines of sight cross its own
(the platforms, each reporting at its own times, below the table). Range and bearing now are
read from the first platform (the reference) at each track's last bearing. One row per
estimator, platforms and target motion over N simulated targets: crossing: median angle at
which the lines of sight of the platforms cross at the target at its last bearing; ok: share
with status `ok`; consistent: share of the ok tracks whose normalised error lies below the
chi-square(4) 95 % point (about 95 % when the one-sigma errors are honest); Ref1..Ref4, share
of targets inside each success region; the median |range error| / range (the tracks with an
estimate); the range RMSE of the ok tracks at the last bearing beside the root of their mean
Cramer-Rao bound (RMSE / CRLB: 1 for an efficient estimator; the bound is that of a
constant-velocity target, which wander raises) and the median bound over every track (inf:
range unobservable from that geometry). 95 % Wilson intervals. Every number is read from the
run and dataset files under `data/`."""


def crossing_angles(log, truth: pd.DataFrame) -> np.ndarray:
    """Per track of ``log`` the angle (deg, 0-90) at which the lines of sight from the
    reference platform (``platforms[0]``) and from each other platform cross at the target's
    true position at the track's last bearing, the widest over the others; NaN for a log of
    one platform."""
    n = log.n_tracks
    if log.platform is None:
        return np.full(n, np.nan)
    rows = truth.set_index("track_id").loc[log.track_id]
    theta = rows[list(THETA)].to_numpy(dtype=float)
    valid = np.isfinite(log.bearing_deg)
    last = valid.shape[1] - 1 - np.argmax(valid[:, ::-1], axis=1)
    t = log.t_s[last]
    x, y = theta[:, 0] + theta[:, 2] * t, theta[:, 1] + theta[:, 3] * t
    ref_x, ref_y = observer_now(log.t_s, log.own_x_m, log.own_y_m, log.platform, 0, last)
    ref = bearing_from_north(x - ref_x, y - ref_y)
    widest = np.zeros(n)
    for k in range(1, log.n_platforms):
        px, py = position_at(log.t_s, log.own_x_m, log.own_y_m, log.platform, k, t)
        widest = np.maximum(widest, crossing_angle_deg(bearing_from_north(x - px, y - py),
                                                       ref))
    return widest


def dataset_crossings(dataset, truth: pd.DataFrame) -> np.ndarray:
    """``crossing_angles`` of every track of a simulated dataset (its shards verified)."""
    return np.concatenate([crossing_angles(read_bearings_log(dataset.verified_path(rel)), truth)
                           for rel in dataset.shard_paths])


def platforms_text(scenario: dict) -> str:
    """The declared platforms of a dataset's scenario config, one line each: where they are,
    whether they move, when they take bearings."""
    lines = []
    for o in scenario.get("observers") or []:
        period = o.get("sample_period_s") or scenario["sample_period_s"]
        where = f"({o['start_x_m']:g}, {o['start_y_m']:g}) m"
        n = len(o.get("legs") or [])
        motion = (f"moving from {where} at {o['speed_m_s']:g} m/s on {n} leg{'s' * (n > 1)}"
                  if n else f"fixed at {where}")
        lines.append(f"- {o['name']}: {motion}, a bearing every {period:g} s from t = "
                     f"{o['time_offset_s']:g} s")
    return "\n".join(lines)


def platforms_label(scenario: dict) -> str:
    """The platforms of a dataset's scenario config that take bearings, joined by ``+``."""
    observers = scenario.get("observers") or []
    if not observers:
        return "ownship"
    return scenario.get("observing") or "+".join(o["name"] for o in observers)


def crossfix_row(label, platforms, motion, sigma, estimates, truth, bounds,
                 crossings) -> dict:
    """One table row (``COLUMNS``) from one run's estimates; ``bounds``: ``metrics.crlb_now``
    of the dataset's tracks; ``crossings``: their crossing angles (deg)."""
    metrics = track_metrics(estimates, truth)
    n = len(metrics)
    ok = (metrics["status"] == "ok").to_numpy()
    nees = metrics.loc[ok, "nees"]
    row = {"estimator": label, "platforms": platforms, "motion": motion, "sigma_deg": sigma,
           "n_tracks": n,
           "crossing_deg": float(np.nanmedian(crossings)) if np.isfinite(crossings).any()
           else np.nan,
           **rate_columns(int(ok.sum()), n, "ok"),
           **rate_columns(int((nees <= NEES_95).sum()), int(nees.notna().sum()), "consistent")}
    for region in REGIONS:
        row.update(rate_columns(int(metrics[region].sum()), n, region))
    err = errors_now(estimates, truth)
    bound = err[["track_id"]].merge(bounds, on="track_id", how="left",
                                    validate="one_to_one")["crlb_range_m"].to_numpy()
    e = err["range_err_m"].to_numpy()
    finite = np.isfinite(e)
    rel = np.abs(metrics["distance_rel_err"].to_numpy())
    row["median_range_error"] = float(np.median(rel[finite])) if finite.any() else np.nan
    use = ok & finite & np.isfinite(bound)
    row["rmse_range_ok_m"] = float(np.sqrt(np.mean(e[use] ** 2))) if use.any() else np.nan
    row["crlb_range_ok_m"] = float(np.sqrt(np.mean(bound[use] ** 2))) if use.any() else np.nan
    row["rmse_over_crlb"] = (row["rmse_range_ok_m"] / row["crlb_range_ok_m"]
                             if row["crlb_range_ok_m"] > 0 else np.nan)
    row["crlb_range_median_m"] = float(np.median(bounds["crlb_range_m"]))
    row["n_failed"] = int((~finite).sum())
    return row


def crossfix_table(entries) -> pd.DataFrame:
    """The table of the runs ``entries`` (``tma.stages.aggregate.RunEntry``) of simulated
    datasets, sorted by estimator, motion and platforms."""
    rows, per_dataset = [], {}
    for entry in entries:
        truth = entry.dataset.read_truth()
        if truth is None:
            continue
        name = entry.dataset.name
        if name not in per_dataset:  # bounds and crossings depend on the dataset alone
            per_dataset[name] = (dataset_bounds(entry.dataset, truth),
                                 dataset_crossings(entry.dataset, truth))
        config = entry.dataset.manifest["config"]
        rows.append(crossfix_row(
            estimator_label(entry.estimator, entry.manifest.get("config") or {}),
            platforms_label(config), motion_label(config), config["sigma_deg"],
            entry.estimates, truth, *per_dataset[name]))
    return pd.DataFrame(rows, columns=COLUMNS).sort_values(
        ["estimator", "motion", "platforms"], kind="stable").reset_index(drop=True)


def shown_table(table: pd.DataFrame) -> pd.DataFrame:
    """The Markdown form: rates in percent with their intervals, figures to 3 digits."""
    shown = {"estimator": table["estimator"], "platforms": table["platforms"],
             "motion": table["motion"], "sigma (deg)": table["sigma_deg"].map("{:g}".format),
             "N": table["n_tracks"],
             "crossing (deg)": table["crossing_deg"].map(lambda x: _num(x, "{:.0f}"))}
    for name, title in (("ok", "ok %"), ("consistent", "consistent (ok) %"),
                        *((r, f"{r.capitalize()} %") for r in REGIONS)):
        shown[title] = [_pct(*v) for v in table[[name, f"{name}_lo", f"{name}_hi"]].to_numpy()]
    shown["median range error %"] = table["median_range_error"].map(
        lambda x: "-" if pd.isna(x) else f"{100 * x:.1f}")
    shown["range RMSE / CRLB, ok (m)"] = [
        f"{_num(a)} / {_num(b)}" for a, b in
        table[["rmse_range_ok_m", "crlb_range_ok_m"]].to_numpy()]
    shown["RMSE / CRLB"] = table["rmse_over_crlb"].map(lambda x: _num(x, "{:.2f}"))
    shown["range CRLB, median (m)"] = table["crlb_range_median_m"].map(_num)
    return pd.DataFrame(shown)


def write_crossfix_table(entries, tables_dir, name: str) -> list[Path]:
    """Write ``<name>.csv`` and ``<name>.md`` from the runs ``entries`` (those of datasets
    without truth are skipped); returns their paths (none without a simulated dataset)."""
    table = crossfix_table(entries)
    if table.empty:
        return []
    declared = next((platforms_text(e.dataset.manifest["config"]) for e in entries
                     if e.dataset.manifest["config"].get("observers")), "")
    regions = "\n".join(f"- {r.capitalize()}: bearing <= {b} deg, distance <= {d:.0%}, course "
                        f"<= {c} deg, speed <= {s:.0%}" for r, (b, d, c, s) in REGIONS.items())
    return write_table(tables_dir, name, "Bearings-only TMA: one platform against two "
                       "(cross fixes)", INTRO, table, shown_table(table), float_format="%.6g",
                       notes=(f"Platforms (x east, y north of the origin):\n{declared}\n\n"
                              if declared else "") + "Success regions:\n" + regions)
