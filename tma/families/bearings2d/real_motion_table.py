"""The ``bearings2d`` real-motion table (experiment ``bearings2d_real_motion``, ``report:
real_motion``): each estimator on own-ships and targets from an AIS recording
(``real_motion.py``), the rows of the manoeuvre table (``manoeuvre_table.manoeuvre_row``) per
target class over the window (``steady``, ``manoeuvring``, ``tma.ais.pairs.classify``) and
over all of them, so that it reads beside the simulated ``bearings2d_manoeuvre`` table:
flagged, ``ok`` and ``consistent`` (the ``ok`` tracks whose normalised error against the AIS
truth lies below the chi-square(4) 95 % point: about 95 % when their one-sigma errors are
honest), Ref1..Ref4, the median |range error| and the range RMSE of the ``ok`` tracks; and
per pair (``<name>_pairs.csv``) the share ``ok`` and consistent of each estimator.
"""

from pathlib import Path

import numpy as np
import pandas as pd

from tma.families.bearings2d.benchmark import estimator_label
from tma.families.bearings2d.manoeuvre_table import COLUMNS, manoeuvre_row, shown_table
from tma.families.bearings2d.metrics import NEES_95, track_metrics
from tma.tables.write import markdown_table, write_csv, write_table

INTRO = """Bearings-only TMA on real ship motion: own-ship and target from the AIS recording
`{file}` ({pairs} pairs found by `tma.ais.pairs`: own-ship turning {turn:g} deg or more over
{window:g} s, the target {rmin:g}-{rmax:g} m away, steady or manoeuvring), bearings every
{period:g} s with {sigma:g} deg noise, {draws} Monte Carlo draws of the noise per pair. The logs
declare no motion model (as a recording): the estimators test for manoeuvres and assume
real-ship wander. One row per estimator and target class (all: every pair): flagged: share
found manoeuvring; ok: share with status `ok`; consistent: share of the ok tracks whose
normalised error against the AIS truth (the target's state at the last bearing, its velocity
the mean over the last 120 s) lies below the chi-square(4) 95 % point (about 95 % when the
one-sigma errors are honest); Ref1..Ref4, the median |range error| / range and the range RMSE
of the ok tracks at the last bearing. 95 % Wilson intervals; the pairs repeat, so the
intervals understate the spread between vessels: the per-pair shares are in
`{name}_pairs.csv`. Read beside the simulated `bearings2d_manoeuvre` table."""


def _pairs_rows(label, estimates, truth) -> list[dict]:
    metrics = track_metrics(estimates, truth).merge(
        truth[["track_id", "pair", "own_mmsi", "target_mmsi", "manoeuvring"]], on="track_id")
    rows = []
    for (pair, own, target, moved), m in metrics.groupby(
            ["pair", "own_mmsi", "target_mmsi", "manoeuvring"], sort=True):
        ok = m["status"] == "ok"
        rows.append({"estimator": label, "pair": int(pair), "own_mmsi": int(own),
                     "target_mmsi": int(target),
                     "motion": "manoeuvring" if moved else "steady", "n_tracks": len(m),
                     "ok": float(ok.mean()),
                     "consistent": float((m.loc[ok, "nees"] <= NEES_95).mean())
                     if ok.any() else np.nan})
    return rows


def write_real_motion_table(entries, tables_dir, name: str) -> list[Path]:
    """``<name>.csv``, ``<name>.md`` and ``<name>_pairs.csv`` from the runs ``entries`` of
    real-motion datasets (``scenario.real.file``); none without one."""
    rows, pairs, config = [], [], None
    for entry in entries:
        truth = entry.dataset.read_truth()
        config = entry.dataset.manifest["config"]
        if truth is None or "pair" not in truth:
            continue
        label = estimator_label(entry.estimator, entry.manifest.get("config") or {})
        est = entry.estimates
        for motion, keep in (("all", np.ones(len(truth), dtype=bool)),
                             ("steady", ~truth["manoeuvring"].to_numpy(bool)),
                             ("manoeuvring", truth["manoeuvring"].to_numpy(bool))):
            ids = truth.loc[keep, "track_id"]
            if len(ids):
                rows.append(manoeuvre_row(label, motion, config["sigma_deg"],
                                          est[est["track_id"].isin(ids)], truth[keep]))
        pairs += _pairs_rows(label, est, truth)
    if not rows:
        return []
    table = pd.DataFrame(rows, columns=COLUMNS)
    pairs = pd.DataFrame(pairs)
    tables_dir = Path(tables_dir)
    real, n_pairs = config["real"], int(pairs["pair"].nunique())
    draws = int(pairs.groupby(["estimator", "pair"])["n_tracks"].sum().max())
    intro = INTRO.format(file=real["file"], pairs=n_pairs, turn=real["min_turn_deg"],
                         window=real["window_s"], rmin=real["min_range_m"],
                         rmax=real["max_range_m"], period=config["sample_period_s"],
                         sigma=config["sigma_deg"], draws=draws, name=name)
    per_pair = pairs.groupby("estimator").agg(
        pairs=("pair", "size"), pairs_mostly_ok=("ok", lambda s: int((s >= 0.5).sum())),
        consistent_median=("consistent", "median")).reset_index()
    notes = ("Per pair (`" + name + "_pairs.csv`): the pairs where the estimator is `ok` on "
             "half the draws or more, and the median over the pairs of the consistent share:\n\n"
             + markdown_table(per_pair.assign(consistent_median=per_pair[
                 "consistent_median"].map(lambda x: "-" if pd.isna(x) else f"{100 * x:.0f} %"))))
    paths = write_table(tables_dir, name, "Bearings-only TMA on real ship motion (AIS)", intro,
                        table, shown_table(table), float_format="%.6g", notes=notes)
    paths.append(tables_dir / f"{name}_pairs.csv")
    write_csv(pairs, paths[-1], float_format="%.6g")
    return paths
