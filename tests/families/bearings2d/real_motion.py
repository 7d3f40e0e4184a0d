"""Bearings-only TMA on real ship motion: the AIS cases of the Solent (``tests/data/ais``) and
New York Harbor (``tests/data/ais_nyharbor``) recordings (own-ship
a real vessel that turns, the target another vessel, bearings from the true geodesic
geometry with 0.5 deg noise), each written as the navigation export a user would ingest,
then ingested and estimated by the same code as ``python -m pipeline.ingest input=<case>``
and ``python -m pipeline.estimate dataset=<case> estimator=<name>
estimator.initial_bearing_deg=null``, and judged against the AIS truth at the last bearing.

Two sets of checks: issue 28's (``CRITERIA``: one noise draw per pair, one-sided) and issue
36's (item 5, ``TWO_SIDED``): several noise draws per pair (``run_cases(draws=)``), per
quantity and two-sided (``figures``, ``two_sided``; the median in units of the answers' own
intervals, ``two_sided_intervals`` the rest in those units), with intervals clustered by target
vessel, under the prior a recording gets (measured on both recordings, pooled) and under the
prior measured on the other recording alone (leave one recording out: ``measured_prior``,
``priors``). The Solent's prior is measured on its committed subset (the case vessels only).
Fishing traffic stays out of both recordings, for an independent check.

Used by ``test_bearings2d_real_motion.py`` (the assertions) and ``bench/bench.py`` (the
figures).
"""

import functools
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import norm
from scipy.stats import t as student_t

from tests.families.bearings2d.recorded_geometry import ingest
from tma.families import build_estimator
from tma.families.bearings2d import calibration
from tma.families.bearings2d.log import read_bearings_log
from tma.io.dataset import Dataset
from tma.maths.angles import wrap_to_180
from tma.maths.stats import wilson_interval

AIS = Path(__file__).resolve().parents[2] / "data" / "ais"
CRITERIA = {  # issue 28, item 3, on every recording
    "ok_within_3_sd": 0.90,  # of the ok tracks, truth within 3 sd on range, course and speed
    "max_ok_z": 5.0,  # no ok track beyond 5 sd on any of them
    "steady_ok": 0.5,  # at least half of the steady targets ok (own-ship turns in every case)
}


def _ais_module(name: str, file: str):
    """The script ``tests/data/ais/<file>`` as a module (the test data's own builders)."""
    spec = importlib.util.spec_from_file_location(name, AIS / file)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


def _cases_module():
    return _ais_module("ais_build_cases", "build_cases.py")


def run_cases(workdir, estimator: dict, sigma_deg=None, recording: str = "solent",
              draws: int = 1) -> pd.DataFrame:
    """Every case of the AIS ``recording`` (``build_cases.RECORDINGS``: ``solent``,
    ``nyharbor``) ingested (``sigma_deg``: as ``ingest sigma_deg=``) and estimated with
    ``estimator`` (an estimator config node, e.g. ``{"name": "lm"}``; each track starts from
    its first bearing), one row per case and noise draw: the estimate, its one-sigma errors,
    status, and the errors against the truth.

    ``draws``: noise draws per case (the same true bearings, 0.5 deg of noise drawn anew):
    draw 0 is the recording's own (``build_cases``' seed), draw d >= 1 the seed ``[seed,
    d]``. Per row, ``z_range``, ``z_course`` (the course error wrapped to +-180 deg),
    ``z_speed``: error / stated sd (signed; NaN where the sd is not finite), ``z`` the
    largest of their |z|; ``z_bearing`` likewise for the bearing now (the position of a
    ``position_only`` answer is its range and bearing). ``target_mmsi`` is the cluster of
    ``figures``' intervals."""
    workdir = Path(workdir)
    cases = _cases_module()
    seed = cases.get_recording(recording).seed
    rows = []
    for draw in range(draws):
        where = workdir if draw == 0 else workdir / f"draw{draw}"
        truth = cases.write_cases(where / "cases", recording=recording,
                                  seed=seed if draw == 0 else [seed, draw])
        for case in truth.itertuples(index=False):
            rows.append({"draw": draw, **_estimate_case(where, case, estimator, sigma_deg)})
    return pd.DataFrame(rows)


def _estimate_case(workdir: Path, case, estimator: dict, sigma_deg) -> dict:
    root = ingest(workdir / "cases" / f"{case.case}.csv", data_dir=workdir / "data",
                  name=case.case, sigma_deg=sigma_deg, force=True)
    dataset = Dataset.open(root)
    (shard,) = dataset.shard_paths
    node = {**({"initial_bearing_deg": None} if estimator["name"] in ("lm", "last_leg")
               else {}), **estimator}
    est = build_estimator(node).estimate(read_bearings_log(dataset.verified_path(shard)))
    get = {k: float(v[0]) if np.ndim(v) == 1 and k != "status" else v[0]
           for k, v in est.items() if np.ndim(v) == 1}
    range_err = get["range_now_m"] - case.range_m
    course_err = float(wrap_to_180(get["course_deg"] - case.course_deg))
    speed_err = get["speed_m_s"] - case.speed_m_s
    bearing_err = float(wrap_to_180(get["bearing_now_deg"] - case.bearing_deg))
    with np.errstate(divide="ignore", invalid="ignore"):
        zs = {"z_range": range_err / get["range_sd_m"],
              "z_course": course_err / get["course_sd_deg"],
              "z_speed": speed_err / get["speed_sd_m_s"],
              "z_bearing": bearing_err / get["bearing_sd_deg"]}
    zs |= interval_zs(get, {"range": range_err, "course": course_err, "speed": speed_err})
    zs = {k: v if np.isfinite(v) else np.nan for k, v in zs.items()}
    three = [abs(zs[k]) for k in ("z_range", "z_course", "z_speed")]
    return {
        "case": case.case, "kind": case.kind, "target_mmsi": int(case.target_mmsi),
        "own_mmsi": int(case.own_mmsi), "status": str(get["status"]),
        "range_m": case.range_m, "range_error": range_err / case.range_m,
        "range_sd": get["range_sd_m"] / get["range_now_m"],
        "range_half_1sd_interval": (get["range_hi1_m"] - get["range_lo1_m"]) / 2
        / get["range_now_m"], "course_error_deg": course_err,
        "course_sd_deg": get["course_sd_deg"], "speed_error_m_s": speed_err,
        "speed_sd_m_s": get["speed_sd_m_s"],
        "z": np.inf if any(np.isnan(three)) else max(three), **zs,
        "leg_start_s": get["leg_start_s"], "motion_p_value": get["motion_p_value"],
    }


def interval_zs(get: dict, errors: dict) -> dict:
    """``iz_range``, ``iz_course``, ``iz_speed``: one answer's errors (``errors``: quantity
    -> estimate - truth, deg for course) in units of its own intervals
    (``calibration.interval_zs``; ``get``: the answer's columns by name)."""
    return {f"iz_{q}": float(iz) for q, iz in calibration.interval_zs(get, errors).items()}


def criteria(results: pd.DataFrame) -> dict:
    """The figures issue 28 (item 3) asks for, from ``run_cases``: ``ok`` tracks, the share
    of them with the truth within 3 sd on range, course and speed, the largest of those z of
    an ok track, the share of steady targets ok; and of the manoeuvring targets, how many are
    ok and how many flagged (not ok) or within 3 sd."""
    ok = results[results.status == "ok"]
    steady = results[results.kind == "steady"]
    manoeuvring = results[results.kind == "manoeuvring"]
    return {
        "cases": len(results), "steady": len(steady), "manoeuvring": len(manoeuvring),
        "ok": len(ok),
        "ok_within_3_sd": float((ok.z <= 3).mean()) if len(ok) else np.nan,
        "max_ok_z": float(ok.z.max()) if len(ok) else 0.0,
        "max_ok_range_error": float(ok.range_error.abs().max()) if len(ok) else 0.0,
        "max_ok_course_error_deg": float(ok.course_error_deg.abs().max()) if len(ok) else 0.0,
        "steady_ok": float((steady.status == "ok").mean()),
        "manoeuvring_ok": int((manoeuvring.status == "ok").sum()),
        "manoeuvring_flagged_or_within_3_sd": float(
            ((manoeuvring.status != "ok") | (manoeuvring.z <= 3)).mean()),
    }


def holds(figures: dict) -> bool:
    """Whether ``criteria``'s figures meet ``CRITERIA``."""
    return (figures["ok_within_3_sd"] >= CRITERIA["ok_within_3_sd"]
            and figures["max_ok_z"] <= CRITERIA["max_ok_z"]
            and figures["steady_ok"] >= CRITERIA["steady_ok"])


# issue 36, item 5: two-sided, per quantity, on several noise draws per pair. The median is
# read in units of the answers' own intervals (calibration.interval_z), its band the issue's
# (1.0-1.6 about the 1.26 of three independent Gaussian |z|) scaled to what honest answers of
# this kind give: 1.02 on lm's own model (2,000 targets; test_bearings2d_intervals holds its
# 1,000 inside the band). In units of the sd, which a mixture's tails widen beyond its core,
# honest answers give 0.57, below any band about 1.26.
GAUSSIAN_MEDIAN_MAX_Z, OWN_MODEL_MEDIAN_MAX_IZ = 1.26, 1.02
TWO_SIDED = {
    "median_max_iz": tuple(round(v * OWN_MODEL_MEDIAN_MAX_IZ / GAUSSIAN_MEDIAN_MAX_Z, 2)
                           for v in (1.0, 1.6)),  # (0.81, 1.3): median over ok tracks
    "within_2_sd": 0.90,  # each of range, course and speed, of the ok tracks
    "beyond_5_sd": 0,  # ok tracks with any |z| above 5
}
QUANTITIES = ("range", "course", "speed")
BOOT = 2000  # cluster-bootstrap resamples of the median
BOOT_SEED = 20240536


Z95 = 1.959963984540054  # the standard normal's 97.5 % point


def wilson_clustered(success, cluster, z: float = Z95) -> tuple[float, float]:
    """95 % Wilson interval (Wilson, JASA 22(158), 1927) of the share of ``success`` (bool,
    n rows) from rows grouped in clusters (``cluster`` labels, k of them), on Korn and
    Graubard's effective sample size (Survey Methodology 24(2), 1998): n / deff, where deff =
    the cluster-robust variance of the share (k / (k - 1) times the sum over clusters of
    (successes - share x rows)^2, over n^2) over the binomial p (1 - p) / n, at least 1 (1
    at a share of 0 or 1, where no variance is seen), times (z / t)^2 with t the Student
    quantile of k - 1 degrees of freedom (few clusters know their variance poorly).
    (nan, nan) without rows."""
    success = np.asarray(success, dtype=bool)
    n = success.size
    if n == 0:
        return np.nan, np.nan
    p = success.mean()
    _, index = np.unique(np.asarray(cluster), return_inverse=True)
    rows = np.bincount(index).astype(float)
    hits = np.bincount(index, weights=success.astype(float))
    k = rows.size
    deff = 1.0
    if 0 < p < 1 and k > 1:
        robust = k / (k - 1) * np.sum((hits - p * rows) ** 2) / n**2
        deff = max(1.0, robust / (p * (1 - p) / n))
    m = n / deff * ((z / student_t.ppf(norm.cdf(z), k - 1)) ** 2 if k > 1 else 1.0)
    lo, hi = wilson_interval(p * m, m, confidence=2 * norm.cdf(z) - 1)
    return float(max(0.0, lo)), float(min(1.0, hi))


def median_boot(values, cluster, boot: int = BOOT, seed: int = BOOT_SEED
                ) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of the median of ``values``, clustered: the
    clusters (``cluster`` labels) are resampled with replacement, ``boot`` times, each with
    all its values (``seed`` fixed, so the interval is reproducible). (nan, nan) without
    values."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return np.nan, np.nan
    _, index = np.unique(np.asarray(cluster), return_inverse=True)
    groups = [values[index == g] for g in range(index.max() + 1)]
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    medians = np.array([np.median(np.concatenate([groups[i] for i in pick]))
                        for pick in rng.integers(0, len(groups), (boot, len(groups)))])
    lo, hi = np.percentile(medians, [2.5, 97.5])
    return float(lo), float(hi)


KINDS = ("steady", "manoeuvring")  # build_cases' kinds of pair: the target held course or not


def figures(results: pd.DataFrame) -> dict:
    """Issue 36's figures (item 5; item 4's share answered) of ``run_cases``' rows (one
    recording, any number of draws), each with a 95 % interval clustered by target vessel
    (its MMSI: every pair and draw it is the target of), since pairs that share a vessel, and
    the draws of one pair, are not independent evidence: shares by ``wilson_clustered``, the
    median by ``median_boot``.

    Keys: ``ok`` and ``ok_or_position_only`` (shares of all rows); of the ok rows,
    ``median_max_z`` (the median of the largest |z| of range, course and speed: about 1.26
    where the errors are Gaussian, honest and the three independent; 0.57 for honest
    mixtures, whose sd is wider than their core), ``<q>_within_1_sd`` and
    ``<q>_within_2_sd`` for q in range, course, speed (honest: 68.3 and 95.4 %),
    ``within_3_sd`` (all three), ``beyond_5_sd`` (any |z| above 5: a count; its share's
    interval as ``beyond_5_sd_share_ci``); of the position_only rows,
    ``position_only_range_within_2_sd`` and ``position_only_bearing_within_2_sd`` (range and
    bearing now); the same in units of the answers' own intervals (``iz``: ``median_max_iz``,
    ``<q>_in_1_sd_interval``, ``<q>_in_2_sd_interval``, ``beyond_5_sd_intervals``); each
    share and median with ``<key>_ci`` (lo, hi). Also ``rows``, ``pairs``, ``draws``,
    ``vessels`` (clusters) and ``ok_rows``; and per kind of target (``KINDS``: suffix
    ``_<kind>``) the ok rows and their vessels, the median largest |z| in the intervals and
    each quantity's shares in its 1-sd and 2-sd interval (with ``_ci``)."""
    status = results.status.to_numpy()
    vessel = results.target_mmsi.to_numpy()
    ok = status == "ok"
    ok_vessel = vessel[ok]
    out = {"rows": len(results), "pairs": results.case.nunique(),
           "draws": results.draw.nunique(), "vessels": len(np.unique(vessel)),
           "ok_rows": int(ok.sum())}

    def share(key, success, clusters):
        out[key] = float(np.mean(success)) if len(success) else np.nan
        out[f"{key}_ci"] = wilson_clustered(success, clusters)

    def of_ok(prefix, median_key, within_key):
        """The ok rows' |z| (columns ``<prefix>_<q>``; an ok answer without a finite one is
        no honest one) and their largest: the median and the shares within 1 and 2; returns
        both."""
        z = np.abs(results.loc[ok, [f"{prefix}_{q}" for q in QUANTITIES]].to_numpy(float))
        z = np.where(np.isnan(z), np.inf, z)
        worst = z.max(axis=1, initial=0.0)
        out[median_key] = float(np.median(worst)) if len(worst) else np.nan
        out[f"{median_key}_ci"] = median_boot(worst, ok_vessel)
        for k in (1, 2):
            for j, q in enumerate(QUANTITIES):
                share(within_key.format(q=q, k=k), z[:, j] <= k, ok_vessel)
        return z, worst

    share("ok", ok, vessel)
    share("ok_or_position_only", ok | (status == "position_only"), vessel)
    _, worst = of_ok("z", "median_max_z", "{q}_within_{k}_sd")
    share("within_3_sd", worst <= 3, ok_vessel)
    po = status == "position_only"  # its answer is a position: range and bearing now
    for q in ("range", "bearing"):
        zq = np.abs(results.loc[po, f"z_{q}"].to_numpy(dtype=float))
        share(f"position_only_{q}_within_2_sd", np.nan_to_num(zq, nan=np.inf) <= 2,
              vessel[po])
    out["beyond_5_sd"] = int((worst > 5).sum())
    out["beyond_5_sd_share_ci"] = wilson_clustered(worst > 5, ok_vessel)
    # the same in units of the answers' own intervals (calibration.interval_z)
    iz, worst = of_ok("iz", "median_max_iz", "{q}_in_{k}_sd_interval")
    out["beyond_5_sd_intervals"] = int((worst > 5).sum())
    # by what the target did: the pooled figures mix the steady targets' answers, which the
    # manoeuvres they might have made widen, with the turning targets', which may be narrow
    kinds = results.kind.to_numpy()[ok]
    if not set(kinds) <= set(KINDS):
        raise ValueError(f"kinds of pair {sorted(set(kinds) - set(KINDS))} not in {KINDS}")
    for kind in KINDS:
        mine = kinds == kind
        out[f"ok_rows_{kind}"] = int(mine.sum())
        out[f"median_max_iz_{kind}"] = (float(np.median(worst[mine])) if mine.any()
                                        else np.nan)
        out[f"vessels_{kind}"] = len(np.unique(ok_vessel[mine]))
        for k in (1, 2):
            for j, q in enumerate(QUANTITIES):
                share(f"{q}_in_{k}_sd_interval_{kind}", iz[mine, j] <= k, ok_vessel[mine])
    return out


def two_sided(f: dict) -> dict:
    """Each check of ``TWO_SIDED`` on ``figures``' ``f``: name -> whether it holds (the
    median in units of the intervals, the shares and the 5-sd count in units of the sd)."""
    lo, hi = TWO_SIDED["median_max_iz"]
    out = {"median_max_iz": lo <= f["median_max_iz"] <= hi}
    out |= {f"{q}_within_2_sd": f[f"{q}_within_2_sd"] >= TWO_SIDED["within_2_sd"]
            for q in QUANTITIES}
    out["beyond_5_sd"] = f["beyond_5_sd"] <= TWO_SIDED["beyond_5_sd"]
    return out


def two_sided_intervals(f: dict) -> dict:
    """``TWO_SIDED``'s per-quantity checks read on the answers' own intervals (``figures``'
    ``<q>_in_2_sd_interval``, ``beyond_5_sd_intervals``): name -> whether it holds. (Not the
    1-sd shares against 60-76 %: clustered over a recording's 12-14 target vessels their
    intervals span 35-45 points, and no answers, however wide or narrow, were found to miss
    it; ``figures`` reports them.)"""
    out = {f"{q}_in_2_sd_interval": f[f"{q}_in_2_sd_interval"] >= TWO_SIDED["within_2_sd"]
            for q in QUANTITIES}
    out["beyond_5_sd_intervals"] = f["beyond_5_sd_intervals"] <= TWO_SIDED["beyond_5_sd"]
    return out


def _stats_module():
    return _ais_module("ais_motion_stats", "motion_stats.py")


def measured_prior(recordings) -> dict:
    return dict(_measured_prior(tuple(recordings)))  # (a copy: callers may change it)


@functools.cache
def _measured_prior(recordings: tuple) -> dict:
    """The targets' motion prior measured by ``tests/data/ais/motion_stats.py`` on the
    positions of ``recordings`` (names of ``build_cases.RECORDINGS``, pooled where several;
    the Solent's committed subset, as ``motion_stats.py`` measures it by default), as
    estimator options: ``accel_psd_m2_s3`` the median over legs of each leg's ML q;
    ``manoeuvre_rate_per_h`` the sized manoeuvres (short trips at rest apart) per underway
    hour; ``manoeuvre_dv_m_s`` their velocity change's RMS per axis; ``manoeuvre_durations_s``
    the means of the thirds of their durations (as ``target_motion.declared_prior``
    summarises a simulation's). ``manoeuvre_prior.RECORDED_*`` and ``ncv.RECORDED_ACCEL_PSD`` are
    figures of this kind for both whole recordings pooled, rounded (``priors``' ``pooled``)."""
    ms = _stats_module()
    parts = []
    for name in recordings:
        rec = ms.bc.get_recording(name)
        parts.append(ms.analyse(name, ms.load_tracks(rec.positions_path, None, name),
                                rec.rules.max_gap_own_s))
    stats = ms.pool(parts) if len(parts) > 1 else parts[0]
    q = np.median([10.0 ** leg["log10_q"] for leg in stats.legs])
    m = pd.DataFrame(stats.manoeuvres)
    m = m[m[["speed_before_m_s", "speed_after_m_s"]].max(axis=1) >= ms.MIN_SPEED_M_S]
    durations = np.sort(m.duration_s.dropna().to_numpy())
    return {"accel_psd_m2_s3": float(f"{q:.3g}"),
            "manoeuvre_rate_per_h": round(float(len(m) / stats.underway_h), 2),
            "manoeuvre_dv_m_s": round(float(np.sqrt(np.mean(m.dv_m_s ** 2) / 2.0)), 2),
            "manoeuvre_durations_s": [round(float(p.mean()), 1)
                                      for p in np.array_split(durations, 3)]}


def priors(recording: str, pooled_measured: bool = False) -> dict:
    """The priors ``recording`` is tested under, as estimator options by name: ``pooled`` (a
    recording's default: ``RECORDED_*``, both recordings pooled), ``left out`` (measured on
    the other recording alone, ``measured_prior``), with ``pooled_measured`` also ``pooled,
    measured`` (both recordings by ``measured_prior``, unrounded: the committed Solent
    subset instead of the whole recording), and ``pooled x0.1`` (ten times too poor: q and
    the rate times 0.1)."""
    others = [r for r in _cases_module().RECORDINGS if r != recording]
    out = {"pooled": {}, "left out": measured_prior(others)}
    if pooled_measured:
        out["pooled, measured"] = measured_prior([recording, *others])
    out["pooled x0.1"] = {"motion_prior_scale": 0.1}
    return out


def describe(f: dict) -> list[str]:
    """``figures``' ``f`` as lines of text (percentages; 95 % intervals in brackets), and
    which of ``TWO_SIDED``'s checks fail."""
    def pc(key):
        lo, hi = f[f"{key}_ci"]
        return f"{f[key]:.1%} ({lo:.0%}-{hi:.0%})" if np.isfinite(f[key]) else "-"

    lo, hi = f["median_max_z_ci"]
    ilo, ihi = f["median_max_iz_ci"]
    failed = [k for k, ok in (two_sided(f) | two_sided_intervals(f)).items() if not ok]
    return [
        f"{f['rows']} answers ({f['pairs']} pairs x {f['draws']} draws, {f['vessels']} target "
        f"vessels): ok {pc('ok')}, ok or position_only {pc('ok_or_position_only')}",
        f"ok ({f['ok_rows']}): median largest |z| {f['median_max_z']:.2f} ({lo:.2f}-{hi:.2f});"
        f" beyond 5 sd {f['beyond_5_sd']}; all three within 3 sd {pc('within_3_sd')}",
        *(f"  {q:6} within 1 sd {pc(f'{q}_within_1_sd'):19} within 2 sd "
          f"{pc(f'{q}_within_2_sd')}" for q in QUANTITIES),
        f"in the answers' own intervals: median largest |z| {f['median_max_iz']:.2f} "
        f"({ilo:.2f}-{ihi:.2f}); beyond 5 {f['beyond_5_sd_intervals']}",
        *(f"  {q:6} in the 1-sd interval {pc(f'{q}_in_1_sd_interval'):19} in the 2-sd "
          f"{pc(f'{q}_in_2_sd_interval')}" for q in QUANTITIES),
        *(f"{kind} targets' ok ({f[f'ok_rows_{kind}']}, {f[f'vessels_{kind}']} vessels): median "
          f"largest |z| in the intervals {f[f'median_max_iz_{kind}']:.2f}; in the 1-sd / 2-sd "
          "interval " + ", ".join(
              f"{q} {f[f'{q}_in_1_sd_interval_{kind}']:.0%} / "
              f"{pc(f'{q}_in_2_sd_interval_{kind}')}" for q in QUANTITIES)
          for kind in KINDS),
        f"position_only: range within 2 sd {pc('position_only_range_within_2_sd')}, bearing "
        f"{pc('position_only_bearing_within_2_sd')}",
        "checks: " + ("all hold" if not failed else "FAIL " + ", ".join(failed)),
    ]


def prior_text(options: dict) -> str:
    """The prior an estimator ``options`` node sets (the recorded one where it sets none)."""
    from tma.families.bearings2d.manoeuvre_prior import RECORDED_MANOEUVRES as m
    from tma.families.bearings2d.ncv import RECORDED_ACCEL_PSD

    scale = options.get("motion_prior_scale", 1.0)
    durations = options.get("manoeuvre_durations_s", m.durations_s)
    return (f"q {options.get('accel_psd_m2_s3', RECORDED_ACCEL_PSD) * scale:.2g} m^2/s^3, "
            f"{options.get('manoeuvre_rate_per_h', m.rate_per_h) * scale:.3g}/h, dv "
            f"{options.get('manoeuvre_dv_m_s', m.dv_m_s):.2f} m/s, durations "
            + "/".join(f"{d:.0f}" for d in durations) + " s")
