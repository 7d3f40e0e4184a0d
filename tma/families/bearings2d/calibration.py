"""Whether the one-sigma errors of ``ok`` answers are honest both ways (neither too narrow
nor too wide), per quantity a user reads and where it matters: the calibration table of the
manoeuvre experiment (``manoeuvre_table.write_calibration_table``; issue 36, item 2).

Over the ``ok`` tracks of one estimator on one dataset, in the cell ``all`` and in cells:

- per quantity at the last bearing (range, course, speed): z = (estimate - truth) / the
  stated sd (the course error wrapped to [-180, 180) deg), and the shares with |z| <= 1 and
  |z| <= 2: 68.3 and 95.4 % for honest Gaussian errors; the targets 60-76 % and 92-98 %
  (``WITHIN_TARGETS``);
- per quantity, the same shares of the truth within the answer's own central intervals
  that hold what 1 and 2 sd of a Gaussian hold (``status.INTERVAL_COLUMNS``: a single
  Gaussian's are its estimate +- 1 and 2 sd (range log-normal), a mixture's its own
  quantiles, asymmetric and mostly narrower than the sd's, which its tails widen), by the
  interval z of ``interval_z`` (|z| <= 1: inside the 1-sd interval); the same targets;
- the 4D consistency: the share whose NEES (theta_hat - theta)^T Sigma^-1 (theta_hat - theta)
  lies at or below the chi-square(4) 95 % point (target 88-98 %, ``CONSISTENT_TARGET``), and
  the mean NEES beside the central 95 % interval of the mean of N chi-square(4) draws
  (``tma.maths.stats.chi2_mean_interval``): below it the errors are too wide, above it too
  narrow.

The cells (``cells``): the target's true range at the last bearing (< 15, 15-30, > 30 km);
the manoeuvres it made over the observation (truth ``n_manoeuvres``: 0, 1, 2, 3+; simulated
targets that move); and the posterior probability of a manoeuvre the answer states
(``p_manoeuvre``: < 0.5, 0.5-0.99, > 0.99; ``lm`` with manoeuvres in its prior). A cell
without the column its split needs is absent, one without tracks left out. Cells with at
least ``GRADED_MIN_OK`` ``ok`` tracks are graded: their consistency and their per-quantity
shares against their targets (a cell is not honest by its pooled 4D figure); ``outside``
names the figures of a graded cell that miss their targets. Shares come with 95 % Wilson intervals.
"""

import numpy as np
import pandas as pd

from tma.families.bearings2d.metrics import NEES_95, THETA, errors_now, normalised_error
from tma.families.bearings2d.status import INTERVAL_COLUMNS
from tma.maths.stats import chi2_mean_interval, rate_columns

# quantity: (error column of ``errors_now``, the estimate's stated one-sigma error)
QUANTITIES = {"range": ("range_err_m", "range_sd_m"),
              "course": ("course_err_deg", "course_sd_deg"),
              "speed": ("speed_err_m_s", "speed_sd_m_s")}
# quantity: the estimate's column, and the scale its intervals are read on (``interval_z``)
ESTIMATES = {"range": "range_now_m", "course": "course_deg", "speed": "speed_m_s"}
SCALES = {"range": "log", "course": "circular", "speed": "linear"}
WITHIN_TARGETS = {1: (0.60, 0.76), 2: (0.92, 0.98)}  # |z| <= k sd: honest 68.3 %, 95.4 %
CONSISTENT_TARGET = (0.88, 0.98)  # NEES <= chi-square(4) 95 % point: honest 95 %
GRADED_MIN_OK = 100  # ok tracks a cell needs to be graded
RANGE_EDGES_KM = (15.0, 30.0)
P_MANOEUVRE_EDGES = (0.5, 0.99)
MANOEUVRES_MAX = 3  # the last cell of manoeuvres made is this many or more
NEES_DOF = 4

ROW_KEYS = ["estimator", "motion", "sigma_deg"]
COLUMNS = [
    *ROW_KEYS, "cell_group", "cell", "n_tracks", "n_ok", "graded",
    *[f"{q}_within_{k}sd{s}" for q in QUANTITIES for k in WITHIN_TARGETS
      for s in ("", "_lo", "_hi")],
    *[f"{q}_interval_within_{k}sd{s}" for q in QUANTITIES for k in WITHIN_TARGETS
      for s in ("", "_lo", "_hi")],
    "consistent", "consistent_lo", "consistent_hi", "mean_nees", "mean_nees_lo",
    "mean_nees_hi", "outside",
]


def _piecewise_z(truth, lo2, lo1, hi1, hi2):
    """``interval_z`` on a line: 0 at the middle of lo1-hi1, 1 and -1 at its ends, 2 and -2
    at lo2 and hi2, linear between them and on beyond with the outer pieces' slope."""
    mid = 0.5 * (lo1 + hi1)
    d = mid - truth  # (as the error: positive where the truth lies below)
    up1, up2, down1, down2 = hi1 - mid, hi2 - mid, mid - lo1, mid - lo2
    with np.errstate(divide="ignore", invalid="ignore"):
        below = np.where(d <= down1, d / down1, 1.0 + (d - down1) / (down2 - down1))
        above = np.where(-d <= up1, d / up1, -1.0 + (d + up1) / (up2 - up1))
    return np.where(d >= 0, below, above)


def interval_z(estimate, error, lo2, lo1, hi1, hi2, scale="linear") -> np.ndarray:
    """The error ``error`` = estimate - truth in units of the answer's central intervals
    (``lo1``-``hi1`` holding what 1 sd of a Gaussian holds, ``lo2``-``hi2`` what 2 sd hold):
    0 at the middle of the 1-sd interval, 1 and -1 at its lower and upper ends (the truth
    below it: the estimate too high), 2 and -2 at the 2-sd interval's, linear between them
    and on beyond with the outer pieces' slope; so |z| <= 1 and 2 say whether the truth lies
    inside each interval. ``scale``: ``linear``; ``log`` (range: read in its logarithm, as
    its intervals are stated); ``circular`` (course, deg: the ends read clockwise from
    ``lo2``, a truth outside the 2-sd arc beyond its nearer end; a 2-sd interval of a whole
    turn, blank, holds every course: a truth outside the 1-sd interval reads -+1.5). For a
    Gaussian answer (course or speed +- 1 and 2 sd) exactly the error over the sd; for a range
    r exp(+-k sd / r), log(estimate / truth) over sd / r; unless an end was clipped to what
    is plausible (a speed's at 0, a range's at ``status.MIN_RANGE_M``..``MAX_RANGE_M``): then
    z is read about the clipped interval's middle, and whether the truth lies inside each
    interval is still exact. NaN where an end is (but a whole turn's)."""
    est, err = np.asarray(estimate, dtype=float), np.asarray(error, dtype=float)
    truth = est - err
    ends = [np.asarray(a, dtype=float) for a in (lo2, lo1, hi1, hi2)]
    if scale == "log":
        with np.errstate(divide="ignore", invalid="ignore"):
            truth, *ends = (np.log(np.where(v > 0, v, np.nan)) for v in (truth, *ends))
        return _piecewise_z(truth, *ends)
    if scale != "circular":
        return _piecewise_z(truth, *ends)
    lo2, lo1, hi1, hi2 = ends
    whole = np.isnan(lo2) & np.isnan(hi2) & np.isfinite(lo1) & np.isfinite(hi1)
    start = np.where(whole, lo1, lo2)  # offsets clockwise from here
    a = (lo1 - start) % 360.0
    b = a + (hi1 - lo1) % 360.0
    c = np.where(whole, 360.0, b + (hi2 - hi1) % 360.0)
    t = (truth - start) % 360.0
    # outside the 2-sd arc: beyond its nearer end
    pos = np.where((t <= c) | (t - c <= 360.0 - t), t, t - 360.0)
    z = _piecewise_z(pos, np.zeros_like(a), a, b, c)
    outside_core = (t > b) & whole
    return np.where(outside_core, np.where(t - b <= 360.0 - t, -1.5, 1.5), z)


def widened_intervals(lo2, lo1, hi1, hi2, extra_sd, scale="linear") -> list:
    """The intervals (lower and upper ends of the 2- and 1-sd ones) of an answer compared
    with a truth of its own one-sigma error ``extra_sd`` (a sparse AIS's; 0: exact): each
    end's distance from the 1-sd interval's middle d_k grown to sqrt(d_k^2 + (k extra)^2),
    on the ``scale`` ``interval_z`` reads them on (``log``: ``extra_sd`` in metres over the
    middle's range; ``circular``: degrees, the ends clockwise from ``lo2``). A Gaussian
    answer's +- k sd become +- k hypot(sd, extra_sd), as its z divides by. Returns
    [lo2, lo1, hi1, hi2]."""
    ends = [np.asarray(a, dtype=float) for a in (lo2, lo1, hi1, hi2)]
    extra = np.asarray(extra_sd, dtype=float)
    if scale == "circular":
        lo2, lo1, hi1, hi2 = ends
        mid = lo1 + ((hi1 - lo1) % 360.0) / 2
        dist = [(mid - lo2) % 360.0, (mid - lo1) % 360.0, (hi1 - mid) % 360.0,
                (hi2 - mid) % 360.0]
        grown = [np.hypot(d, k * extra) for d, k in zip(dist, (2.0, 1.0, 1.0, 2.0),
                                                        strict=True)]
        with np.errstate(invalid="ignore"):  # an arc of a whole turn or more: none (blank)
            whole2 = grown[0] + grown[3] >= 360.0
            whole1 = grown[1] + grown[2] >= 360.0
        out = [(mid + s * g) % 360.0 for s, g in zip((-1.0, -1.0, 1.0, 1.0), grown, strict=True)]
        return [np.where(whole2 | whole1, np.nan, out[0]), np.where(whole1, np.nan, out[1]),
                np.where(whole1, np.nan, out[2]), np.where(whole2 | whole1, np.nan, out[3])]
    if scale == "log":
        with np.errstate(divide="ignore", invalid="ignore"):
            logs = [np.log(e) for e in ends]
            mid = 0.5 * (logs[1] + logs[2])
            extra = extra / np.exp(mid)
        return [np.exp(mid + np.sign(v - mid) * np.hypot(v - mid, k * extra))
                for v, k in zip(logs, (2.0, 1.0, 1.0, 2.0), strict=True)]
    mid = 0.5 * (ends[1] + ends[2])
    return [mid + np.sign(v - mid) * np.hypot(v - mid, k * extra)
            for v, k in zip(ends, (2.0, 1.0, 1.0, 2.0), strict=True)]


def interval_zs(answers, errors, truth_sd=None) -> dict:
    """Per quantity (range, course, speed) the errors ``errors`` (quantity -> estimate -
    truth; deg for course) of ``answers`` (a DataFrame, or a dict of one answer's columns)
    in units of their own intervals (``interval_z``, each on its ``SCALES``); with
    ``truth_sd`` (quantity -> the truth's own one-sigma error), the intervals widened by it
    (``widened_intervals``). NaN where the answers state no intervals."""
    out = {}
    for q, scale in SCALES.items():
        names = INTERVAL_COLUMNS[q]
        if not all(c in answers for c in names):
            out[q] = np.full(np.shape(errors[q]), np.nan)
            continue
        ends = [np.asarray(answers[c], dtype=float) for c in names]
        if truth_sd is not None:
            ends = widened_intervals(*ends, truth_sd[q], scale)
        out[q] = interval_z(np.asarray(answers[ESTIMATES[q]], dtype=float), errors[q], *ends,
                            scale=scale)
    return out


def track_calibration(estimates: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Per track of ``estimates``: ``status``, ``range_z``, ``course_z``, ``speed_z``
    (estimate - truth at the last bearing over the stated sd), ``range_iz``, ``course_iz``,
    ``speed_iz`` (the same error in units of the stated intervals, ``interval_z``; NaN
    where the estimates have none), ``nees`` (NaN where the
    estimate has none), ``range_true_m``, and ``n_manoeuvres`` (where the truth has it) and
    ``p_manoeuvre`` (where the estimates have it)."""
    errors = errors_now(estimates, truth)  # (checks that the truth holds every track)
    out = pd.DataFrame({"track_id": errors["track_id"],
                        "status": estimates["status"].to_numpy()})
    for q, (err, sd) in QUANTITIES.items():
        with np.errstate(divide="ignore", invalid="ignore"):
            out[f"{q}_z"] = errors[err].to_numpy() / estimates[sd].to_numpy(dtype=float)
    in_intervals = interval_zs(estimates, {q: errors[err].to_numpy()
                                           for q, (err, _) in QUANTITIES.items()})
    for q, iz in in_intervals.items():
        out[f"{q}_iz"] = iz
    merged = estimates.merge(truth[["track_id", *THETA]], on="track_id", how="left",
                             suffixes=("", "_true"))
    out["nees"] = normalised_error(merged)
    out["range_true_m"] = errors["range_true_m"].to_numpy()
    if "n_manoeuvres" in truth:
        out["n_manoeuvres"] = merged["track_id"].map(
            truth.set_index("track_id")["n_manoeuvres"]).to_numpy()
    if "p_manoeuvre" in estimates:
        out["p_manoeuvre"] = estimates["p_manoeuvre"].to_numpy(dtype=float)
    return out


def within_shares(z, name: str) -> dict:
    """``<name>_within_1sd`` and ``_2sd`` (each with ``_lo``, ``_hi``): the shares of the
    finite ``z`` with |z| <= 1 and <= 2, with 95 % Wilson intervals."""
    z = np.abs(np.asarray(z, dtype=float))
    z = z[np.isfinite(z)]
    row = {}
    for k in WITHIN_TARGETS:
        row.update(rate_columns(int(np.sum(z <= k)), z.size, f"{name}_within_{k}sd"))
    return row


def nees_figures(nees) -> dict:
    """Over the finite ``nees``: ``consistent`` (the share at or below the chi-square(4)
    95 % point, with its Wilson interval) and ``mean_nees`` with ``mean_nees_lo``,
    ``mean_nees_hi``, where the mean of that many chi-square(4) draws lies 95 % of the
    time."""
    nees = np.asarray(nees, dtype=float)
    nees = nees[np.isfinite(nees)]
    lo, hi = chi2_mean_interval(nees.size, NEES_DOF)
    return {**rate_columns(int(np.sum(nees <= NEES_95)), nees.size, "consistent"),
            "mean_nees": float(nees.mean()) if nees.size else np.nan,
            "mean_nees_lo": float(lo), "mean_nees_hi": float(hi)}


def _three_bins(values, edges, labels):
    """(label, mask) of ``values`` below ``edges[0]``, between the two edges (both
    included) and above ``edges[1]``; a NaN in none."""
    values = np.asarray(values, dtype=float)
    (a, b), (below, between, above) = edges, labels
    return [(below, values < a), (between, (values >= a) & (values <= b)), (above, values > b)]


def cells(tracks: pd.DataFrame) -> list[tuple[str, str, np.ndarray]]:
    """(group, cell, mask over ``tracks``) of every cell (module docstring): ``all``, then
    by the true range now, the manoeuvres made and ``p_manoeuvre`` where those columns are
    there."""
    a, b = RANGE_EDGES_KM
    out = [("all", "all", np.ones(len(tracks), dtype=bool))]
    out += [("range_km", label, mask) for label, mask in _three_bins(
        tracks["range_true_m"] / 1e3, RANGE_EDGES_KM, [f"<{a:g}", f"{a:g}-{b:g}", f">{b:g}"])]
    if "n_manoeuvres" in tracks:
        made = tracks["n_manoeuvres"].to_numpy()
        out += [("manoeuvres", str(m), made == m) for m in range(MANOEUVRES_MAX)]
        out.append(("manoeuvres", f"{MANOEUVRES_MAX}+", made >= MANOEUVRES_MAX))
    if "p_manoeuvre" in tracks:
        a, b = P_MANOEUVRE_EDGES
        out += [("p_manoeuvre", label, mask) for label, mask in _three_bins(
            tracks["p_manoeuvre"], P_MANOEUVRE_EDGES, [f"<{a:g}", f"{a:g}-{b:g}", f">{b:g}"])]
    return out


def cell_row(tracks: pd.DataFrame, mask) -> dict:
    """The figures of one cell (``COLUMNS`` from ``n_tracks`` on, ``outside`` for the cell
    ``all``) over the tracks ``mask`` selects, of which the ``ok`` ones count."""
    mask = np.asarray(mask, dtype=bool)
    ok = mask & (tracks["status"] == "ok").to_numpy()
    row = {"n_tracks": int(mask.sum()), "n_ok": int(ok.sum()),
           "graded": bool(ok.sum() >= GRADED_MIN_OK)}
    for q in QUANTITIES:
        row.update(within_shares(tracks[f"{q}_z"].to_numpy()[ok], q))
        row.update(within_shares(tracks[f"{q}_iz"].to_numpy()[ok], f"{q}_interval"))
    row.update(nees_figures(tracks["nees"].to_numpy()[ok]))
    return row


def shares_text(row: dict) -> str:
    """A cell ``row``'s (``cell_row``) shares per quantity as text: in the answers' 1-sd / 2-sd
    intervals, and in brackets within 1 / 2 sd, in %."""
    return "; ".join(
        f"{q} " + " / ".join(_pct(row[f"{q}_interval_within_{k}sd"]) for k in (1, 2))
        + " (" + " / ".join(_pct(row[f"{q}_within_{k}sd"]) for k in (1, 2)) + ") %"
        for q in QUANTITIES)


def outside_targets(row: dict) -> list[str]:
    """The figures of a graded cell ``row`` (``cell_row``) outside their targets, e.g.
    ``"consistent 67.1 % < 88 %"``: the shares within 1 and 2 sd per quantity and the 4D
    consistency. None for a cell not graded."""
    if not row["graded"]:
        return []
    checks = [(f"{q}_within_{k}sd", f"{q} within {k} sd", WITHIN_TARGETS[k])
              for q in QUANTITIES for k in WITHIN_TARGETS]
    checks += [(f"{q}_interval_within_{k}sd", f"{q} in its {k}-sd interval", WITHIN_TARGETS[k])
               for q in QUANTITIES for k in WITHIN_TARGETS]
    checks.append(("consistent", "consistent", CONSISTENT_TARGET))
    out = []
    for key, name, (lo, hi) in checks:
        share = row[key]
        if share < lo or share > hi:  # (a NaN share, no intervals stated, is neither)
            side, bound = ("<", lo) if share < lo else (">", hi)
            out.append(f"{name} {_beside(100 * share, 100 * bound)} % {side} {100 * bound:g} %")
    return out


def _beside(value, bound) -> str:
    """``value`` with one decimal, or as many more as tell it from ``bound`` (87.96 against
    88, not 88.0)."""
    for decimals in range(1, 6):
        text = f"{value:.{decimals}f}"
        if float(text) != bound:
            return text
    return f"{value:g}"


def calibration_rows(label: str, motion: str, sigma_deg: float, estimates: pd.DataFrame,
                     truth: pd.DataFrame) -> list[dict]:
    """The table's rows (``COLUMNS``) of one run: one per cell with tracks."""
    tracks = track_calibration(estimates, truth)
    rows = []
    for group, cell, mask in cells(tracks):
        if not mask.any():
            continue
        row = {"estimator": label, "motion": motion, "sigma_deg": sigma_deg,
               "cell_group": group, "cell": cell, **cell_row(tracks, mask)}
        row["outside"] = "; ".join(outside_targets(row))
        rows.append(row)
    return rows


# -- the Markdown ------------------------------------------------------------------------------

INTRO = """Whether the one-sigma errors of `ok` answers are honest both ways (neither too narrow
nor too wide), per quantity a user reads and where it matters
(`tma/families/bearings2d/calibration.py`). Over the `ok` tracks of each estimator and target
motion: per quantity at the last bearing (range, course, speed), z = (estimate - truth) /
stated sd (course error wrapped), the share within 1 sd and within 2 sd (honest Gaussian
errors: 68.3 and 95.4 %; targets 60-76 % and 92-98 %); the 4D consistency, the share whose
NEES lies at or below the chi-square(4) 95 % point (honest: 95 %; target 88-98 %); and the
mean NEES beside the interval where the mean of that many chi-square(4) draws lies 95 % of
the time (low: errors too wide; high: too narrow). Cells: the true range at the last bearing,
the manoeuvres the target made over the observation, and the probability of a manoeuvre the
answer states (`p_manoeuvre`, `lm` with manoeuvres in its prior). A cell with at least 100
`ok` tracks is graded (consistency and the per-quantity shares, against their targets);
"outside" names what misses. N: tracks in the cell, ok: the `ok` ones (cells
without `ok` tracks are in the CSV only, which has every number with 95 % Wilson
intervals)."""

GROUP_TITLES = {"all": "all", "range_km": "range {} km", "manoeuvres": "manoeuvres made: {}",
                "p_manoeuvre": "p_manoeuvre {}"}


def _pct(x) -> str:
    return "-" if pd.isna(x) else f"{100 * x:.1f}"


def _mean_nees(row) -> str:
    mean, lo, hi = row["mean_nees"], row["mean_nees_lo"], row["mean_nees_hi"]
    if pd.isna(mean):
        return "-"
    side = " low" if mean < lo else " high" if mean > hi else ""
    return f"{mean:.3g} ({lo:.3g}-{hi:.3g}){side}"


def _within(table, k) -> list[str]:
    return [" / ".join(_pct(v) for v in row) for row in
            table[[f"{q}_within_{k}sd" for q in QUANTITIES]].to_numpy()]


def _in_intervals(table) -> list[str]:
    return ["; ".join(f"{_pct(row[f'{q}_interval_within_1sd'])} / "
                      f"{_pct(row[f'{q}_interval_within_2sd'])}" for q in QUANTITIES)
            for _, row in table.iterrows()]


def shown_rows(table: pd.DataFrame) -> pd.DataFrame:
    """The Markdown's first table: the cell ``all`` of each estimator and motion."""
    rows = table[table["cell_group"] == "all"]
    return pd.DataFrame({
        "estimator": rows["estimator"], "motion": rows["motion"], "N": rows["n_tracks"],
        "ok": rows["n_ok"],
        "within 1 sd %: range / course / speed": _within(rows, 1),
        "within 2 sd %: range / course / speed": _within(rows, 2),
        "in the 1-sd / 2-sd intervals %: range; course; speed": _in_intervals(rows),
        "consistent (ok) %": [f"{_pct(a)} ({_pct(b)}-{_pct(c)})" if pd.notna(a) else "-"
                              for a, b, c in rows[["consistent", "consistent_lo",
                                                   "consistent_hi"]].to_numpy()],
        "mean NEES (95 % if honest)": [_mean_nees(r) for _, r in rows.iterrows()],
        "outside the targets": [v or ("-" if not g else "none") for v, g in
                                rows[["outside", "graded"]].to_numpy()],
    })


def shown_cells(table: pd.DataFrame) -> pd.DataFrame:
    """The Markdown's second table: every other cell with ``ok`` tracks (the CSV has those
    without too)."""
    rows = table[(table["cell_group"] != "all") & (table["n_ok"] > 0)]
    return pd.DataFrame({
        "estimator": rows["estimator"], "motion": rows["motion"],
        "cell": [GROUP_TITLES[g].format(c) for g, c in rows[["cell_group", "cell"]].to_numpy()],
        "N": rows["n_tracks"], "ok": rows["n_ok"],
        "graded (>= 100 ok)": rows["graded"].map({True: "yes", False: "no"}),
        "consistent (ok) %": [f"{_pct(a)} ({_pct(b)}-{_pct(c)})" if pd.notna(a) else "-"
                              for a, b, c in rows[["consistent", "consistent_lo",
                                                   "consistent_hi"]].to_numpy()],
        "mean NEES (95 % if honest)": [_mean_nees(r) for _, r in rows.iterrows()],
        "within 1 / 2 sd %: range, course, speed": [
            f"{a}; {b}" for a, b in zip(_within(rows, 1), _within(rows, 2), strict=True)],
        "in the 1-sd / 2-sd intervals %: range; course; speed": _in_intervals(rows),
        "outside": [v or ("-" if not g else "none") for v, g in
                    rows[["outside", "graded"]].to_numpy()],
    })
