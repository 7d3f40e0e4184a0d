"""A recorded log scored against the AIS of its trial: the truth columns of its per-contact
report (``ingest truth=FILE``, ``tma.ais.truth``).

Per contact with a truth, at its last bearing ("now", where the report gives the estimate):
the ship (``truth_mmsi``, ``truth_match``: ``given`` or ``bearings``, ``truth_rms_deg``: how
well its AIS fits the contact's bearings), its true range, bearing, course and speed and
position (``true_*``), the errors of the estimate (estimate - truth: ``range_err_m``,
``bearing_err_deg``, ``course_err_deg`` wrapped to [-180, 180), ``speed_err_m_s``), their
z-scores (error / the estimate's one-sigma error: ``range_z``...), the same errors in units of
the answer's own intervals (``range_iz``, ``course_iz``, ``speed_iz``: ``calibration.interval_z``;
|z| <= 2: the truth inside the 95.4 % interval) and ``covered``: whether the
truth lies in the estimate's 95 % region, the normalised error (theta_hat - theta)^T Sigma^-1
(theta_hat - theta) of theta = (x0, y0, vx, vy) (``nees``) below the chi-square(4) 95 % point:
the test the simulated tables' ``consistent (ok)`` column counts, so an ``ok`` contact
covers its truth 95 % of the time when its errors are honest. ``coverage`` counts the covered
``ok`` contacts over the log, with a 95 % Wilson interval. Contacts without a truth (no ship
fits, ambiguous, an AIS gap: the manifest says why) have these columns blank.
"""

import numpy as np
import pandas as pd

from tma.families.bearings2d.calibration import SCALES, interval_zs
from tma.families.bearings2d.drawn_tracks import theta_covariance
from tma.families.bearings2d.metrics import NEES_95, THETA, normalised_error
from tma.families.bearings2d.status import kinematics_now
from tma.maths.angles import wrap_to_180
from tma.maths.geo import north_at_local
from tma.maths.stats import wilson_interval

# quantity: (the report's estimate, its one-sigma error, the unit of the columns' names)
QUANTITIES = {"range": ("range_now_m", "range_sd_m", "m"),
              "bearing": ("bearing_now_deg", "bearing_sd_deg", "deg"),
              "course": ("course_deg", "course_sd_deg", "deg"),
              "speed": ("speed_m_s", "speed_sd_m_s", "m_s")}
INTERVAL_QUANTITIES = tuple(SCALES)  # (those an answer states intervals of)
COLUMNS = ["truth_mmsi", "truth_match", "truth_rms_deg", "true_x_m", "true_y_m",
           *[f"true_{q}_{u}" for q, (_, _, u) in QUANTITIES.items()],
           *[f"{q}_err_{u}" for q, (_, _, u) in QUANTITIES.items()],
           *[f"{q}_z" for q in QUANTITIES], *[f"{q}_iz" for q in INTERVAL_QUANTITIES],
           "nees", "covered"]


def dataset_truth(dataset):
    """``(truth, truth track)`` DataFrames of an ingested dataset scored against AIS
    (verified), or ``(None, None)``."""
    from tma.ais.truth import TRUTH, TRUTH_TRACK
    from tma.io import arrow

    if TRUTH not in dataset.manifest["files"]:
        return None, None
    return tuple(arrow.read_table(dataset.verified_path(rel)).to_pandas()
                 for rel in (TRUTH, TRUTH_TRACK))


def with_truth(report: pd.DataFrame, estimates: pd.DataFrame, truth: pd.DataFrame,
               origin_deg=None) -> pd.DataFrame:
    """``report`` (``report.track_report``, one row per track of ``estimates``) with the truth
    columns (module docstring); blank for tracks the truth lacks. ``origin_deg``: the local
    plane's, whose report reads bearing and course from true north (``north_at_local``):
    the truth's are read alike."""
    own = [c for c in TRUTH_SD if c in truth]  # the truth's own uncertainty (sparse AIS)
    df = estimates.merge(truth[["track_id", "mmsi", "match", "rms_deg", *THETA, *own]],
                         on="track_id", how="left", suffixes=("", "_true"), validate="one_to_one")
    has = df["mmsi"].notna().to_numpy()
    at = (df["t_last_s"].to_numpy(float), df["own_x_last_m"].to_numpy(float),
          df["own_y_last_m"].to_numpy(float))
    (rng, brg, crs, spd), _ = kinematics_now(df[[f"{c}_true" for c in THETA]].to_numpy(float),
                                             *at, jacobian=False)
    true = {"range": rng, "bearing": np.rad2deg(brg) % 360.0, "course": np.rad2deg(crs) % 360.0,
            "speed": spd}
    t = at[0]
    if origin_deg is not None:  # read from true north, as the report reads the estimates
        true["bearing"] = (true["bearing"] - north_at_local(at[1], at[2], origin_deg)) % 360.0
        true["course"] = (true["course"] - north_at_local(
            (df["x0_m_true"] + df["vx_m_s_true"] * t).to_numpy(float),
            (df["y0_m_true"] + df["vy_m_s_true"] * t).to_numpy(float), origin_deg)) % 360.0
    out = report.copy()
    out["truth_mmsi"] = pd.array([int(m) if h else pd.NA for m, h in zip(
        df["mmsi"].to_numpy(), has, strict=True)], dtype="Int64")
    out["truth_match"] = df["match"].where(has, None)
    out["truth_rms_deg"] = df["rms_deg"].to_numpy(float)
    out["true_x_m"] = (df["x0_m_true"] + df["vx_m_s_true"] * t).to_numpy(float)
    out["true_y_m"] = (df["y0_m_true"] + df["vy_m_s_true"] * t).to_numpy(float)
    for q, (_, _, unit) in QUANTITIES.items():
        out[f"true_{q}_{unit}"] = true[q]
    truth_sd = _truth_sd(df, true, own)
    for q, (column, sd, unit) in QUANTITIES.items():
        err = report[column].to_numpy(float) - true[q]
        if unit == "deg":
            err = wrap_to_180(err)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[f"{q}_err_{unit}"] = err
            out[f"{q}_z"] = err / np.hypot(report[sd].to_numpy(float), truth_sd[q])
    # the same errors in units of the answer's own intervals, the truth's sd folded in
    errors = {q: out[f"{q}_err_{QUANTITIES[q][2]}"].to_numpy(float) for q in INTERVAL_QUANTITIES}
    for q, iz in interval_zs(report, errors, truth_sd).items():
        out[f"{q}_iz"] = iz
    filled = df.assign(**{f"{c}_true": df[f"{c}_true"].fillna(0.0) for c in THETA})
    nees = np.where(has, normalised_error(filled), np.nan)
    if own:  # where the truth is uncertain: e^T (Sigma + Sigma_truth)^-1 e
        out["truth_pos_sd_m"] = df["truth_pos_sd_m"].to_numpy(float)
        out["truth_vel_sd_m_s"] = df["truth_vel_sd_m_s"].to_numpy(float)
        nees = np.where(has & (truth_sd["range"] > 0), _nees_with_truth(filled), nees)
    out["nees"] = nees
    out["covered"] = pd.array([bool(v <= NEES_95) if np.isfinite(v) else pd.NA for v in nees],
                              dtype="boolean")
    return out


TRUTH_SD = ("truth_pos_sd_m", "truth_vel_sd_m_s", "truth_var_x0_m2", "truth_cov_x0_v_m2_s",
            "truth_var_v_m2_s2")


def _truth_sd(df, true, own) -> dict:
    """Per quantity the truth's own one-sigma error (``tma.ais.truth``: sparse AIS); 0 for a
    truth without one (a simulation's, or one from before issue 38)."""
    if not own:
        return {q: 0.0 for q in QUANTITIES}
    pos = df["truth_pos_sd_m"].fillna(0.0).to_numpy(float)
    vel = df["truth_vel_sd_m_s"].fillna(0.0).to_numpy(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return {"range": pos, "bearing": np.rad2deg(pos / true["range"]), "speed": vel,
                "course": np.rad2deg(np.where(vel > 0, vel / true["speed"], 0.0))}


def _nees_with_truth(df) -> np.ndarray:
    """The normalised error with the truth's covariance of (x0, y0, vx, vy) added to the
    estimate's (x and y alike, independent)."""
    e = df[list(THETA)].to_numpy() - df[[f"{c}_true" for c in THETA]].to_numpy()
    cov = theta_covariance(df)  # (NaN where the estimate states no error)
    for a, b in ((0, 2), (1, 3)):  # (x0, vx) and (y0, vy)
        cov[:, a, a] += df["truth_var_x0_m2"].fillna(0.0).to_numpy()
        cov[:, b, b] += df["truth_var_v_m2_s2"].fillna(0.0).to_numpy()
        cov[:, a, b] += df["truth_cov_x0_v_m2_s"].fillna(0.0).to_numpy()
        cov[:, b, a] = cov[:, a, b]
    out = np.full(len(df), np.nan)
    stated = np.isfinite(cov).all(axis=(1, 2)) & np.isfinite(e).all(axis=1)
    out[stated] = np.einsum("ni,ni->n", e[stated],
                            np.linalg.solve(cov[stated], e[stated][..., None])[..., 0])
    return out


def coverage(report: pd.DataFrame) -> dict:
    """Over the ``ok`` contacts with a truth: how many, how many covered, the share and its
    95 % Wilson interval; and the contacts with a truth."""
    scored = report["covered"].notna()
    ok = scored & (report["status"] == "ok")
    k, n = int(report.loc[ok, "covered"].sum()), int(ok.sum())
    lo, hi = wilson_interval(k, n)
    return {"contacts": len(report), "with_truth": int(scored.sum()), "ok": n, "covered": k,
            "share": k / n if n else np.nan, "share_lo": float(lo), "share_hi": float(hi)}


VAGUE_VELOCITY = 0.5  # the truth's velocity sd (per axis) over its speed beyond which its
# course and speed say little: a course/speed z-score against it is no test


def vague_velocity(report: pd.DataFrame) -> np.ndarray:
    """Per contact whether its truth's velocity is uncertain by about its size (sparse AIS:
    velocity sd per axis at least ``VAGUE_VELOCITY`` times the true speed), so that its
    course and speed comparisons are not informative."""
    if "truth_vel_sd_m_s" not in report or "true_speed_m_s" not in report:
        return np.zeros(len(report), dtype=bool)
    sd = report["truth_vel_sd_m_s"].to_numpy(float)
    speed = report["true_speed_m_s"].to_numpy(float)
    with np.errstate(invalid="ignore"):
        return np.isfinite(sd) & (sd >= VAGUE_VELOCITY * np.nan_to_num(speed))


def _truth_own_text(report: pd.DataFrame) -> str:
    """What the table says of the truth's own uncertainty, whenever a contact's truth has one
    (whatever the contacts' status)."""
    sd = report.get("truth_pos_sd_m", pd.Series(dtype=float)).max()
    if not (np.isfinite(sd) and sd >= 1.0):
        return ""
    text = (f" The z-scores and covered include the truth's own uncertainty where its AIS is "
            f"sparse (position sd up to {sd:.0f} m: truth.accel_sd_m_s2).")
    vague = vague_velocity(report)
    if vague.any():
        rows = report[vague]
        shown = ", ".join(f"{r.label} ({r.truth_vel_sd_m_s:.1f} m/s at {r.true_speed_m_s:.1f} "
                          "m/s)" for r in rows.itertuples())
        text += (f" The truth's velocity is uncertain by about its size (sd per axis at "
                 f"least {VAGUE_VELOCITY:g} of the speed) for {shown}: their course and speed "
                 "comparisons are not informative, and a campaign leaves their course and "
                 "speed z-scores out.")
    return text


def coverage_text(report: pd.DataFrame) -> str:
    """The log's line of coverage, for the table and the log."""
    c = coverage(report)
    own = _truth_own_text(report)
    if not c["ok"]:
        return (f"Against the AIS truth: {c['with_truth']} of {c['contacts']} contacts have a "
                f"truth, none of them `ok`.{own}")
    return (f"Against the AIS truth: {c['with_truth']} of {c['contacts']} contacts have a truth; "
            f"{c['covered']} of the {c['ok']} `ok` ones are covered by their errors "
            f"({100 * c['share']:.0f} %, 95 % interval {100 * c['share_lo']:.0f}-"
            f"{100 * c['share_hi']:.0f} %; honest errors cover 95 %). 'z in [a, b]': the "
            f"error in units of the answer's own intervals, ±1 and ±2 at the ends of its "
            f"68.3 and 95.4 % ones (|z| <= 2: the truth inside [a, b]).{own}")


def shown_columns(report: pd.DataFrame) -> dict:
    """The Markdown table's truth columns (none without a truth)."""
    if "covered" not in report:
        return {}

    def zs(columns):  # one z per quantity, range / course / speed
        return ["-" if pd.isna(row[0]) else
                " / ".join("-" if pd.isna(v) else format(v, "+.1f") for v in row)
                for row in report[columns].to_numpy()]

    return {
        "AIS ship (RMS deg)": [
            "-" if pd.isna(m) else f"{m} ({r:.2f})"
            for m, r in report[["truth_mmsi", "truth_rms_deg"]].itertuples(index=False)],
        "true range / course / speed": [
            "-" if pd.isna(a) else f"{a:.0f} m / {b:.1f} deg / {c:.2f} m/s" for a, b, c in
            report[["true_range_m", "true_course_deg", "true_speed_m_s"]].to_numpy()],
        "z range / course / speed": zs(["range_z", "course_z", "speed_z"]),
        "z in [a, b] range / course / speed": zs([f"{q}_iz" for q in INTERVAL_QUANTITIES]),
        "covered": ["-" if pd.isna(v) else ("yes" if v else "no") for v in report["covered"]],
    }
