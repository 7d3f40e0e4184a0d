"""The published ``bearing_doppler3d`` conclusions and our table held against them
(``tma.tables.paper``).

Transcribed from ``docs/families.md``, section "``bearing_doppler3d``", what it published: a
student's summary of Borisov, Bosov, Miller, Miller, "Passive Underwater Target Tracking:
Conditionally Minimax Nonlinear Filtering with Bearing-Doppler Observations" (Sensors, 2020).
The summary publishes no numbers, only three conclusions, each held here against named
statistics of ours on the bearing-Doppler runs (the paper's observations) and on the
bearings-only runs. Data only: no filter reads them.
"""

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from tma.families.bearing_doppler3d.metrics import DIVERGENCE_AFTER_S, DIVERGENCE_M
from tma.families.bearing_doppler3d.scenario import Config as ScenarioConfig
from tma.tables.paper import by_setting, claim, config_differences, differs_reason, share

FAMILY = "bearing_doppler3d"
FILTERS = ("ekf", "srekf", "cmnf")
BASELINE = "prior_mean"
MID_S = 50.0  # the table's middle epoch
SHORT = {"X_m": "X", "Y_m": "Y", "Z_m": "Z", "v_m_s": "v", "phi_rad": "phi", "a_m_s2": "a"}
# the summary's numbered conclusions (papers.md), split where one sentence claims two things
CLAIMS = {
    "1": "the EKF and its square-root form give practically identical results",
    "2a": "the filters beat the trivial estimate (the unconditional mean) for X, Y, phi and a",
    "2b": "... but not for Z and v (which do not change in the model)",
    "2c": "the advantage on X, Y, phi and a grows with time",
    "3a": "CMNF has a smaller share of divergent paths than the EKF",
    "3b": "CMNF has a better estimate of Z than the EKF",
    "3c": "CMNF's error in v grows markedly with time",
}
INFORMED = ("X_m", "Y_m", "phi_rad", "a_m_s2")
CONSTANT = ("Z_m", "v_m_s")
IDENTICAL_REL = 0.01  # "practically identical": RMSE within 1 % at every epoch and component
NO_GAIN = 0.9  # "does not beat": the filter's RMSE at least 90 % of the baseline's
MARKED = 1.5  # "grows markedly": RMSE of v at T at least 1.5 x its smallest from 10 s on
JOURNAL = ("CMNF's own standard deviations (sqrt of diag K-hat) plotted in the journal paper "
           "for a 17-state model with a random turn plane")

INTRO = f"""Published: three conclusions of a summary of Borisov et al. (Sensors, 2020), no
numbers (`docs/families.md`; transcribed in
`tma/families/bearing_doppler3d/paper.py`). Each is held against statistics of ours named in
the table, first on the runs with Doppler readings (the paper's bearing-Doppler observations),
then on the bearings-only runs (whether a conclusion depends on the Doppler readings). RMSE is
the table's, over each filter's non-divergent paths; the trivial estimate (`{BASELINE}`) is
measured over all paths (most of its paths count as divergent, so that is its meaningful
RMSE). The thresholds that turn words into tests are stated with each claim ("practically
identical": within {100 * IDENTICAL_REL:g} %; "does not beat": at least {100 * NO_GAIN:g} % of
the baseline; "markedly": a factor {MARKED:g})."""

IGNORE = ("family", "n_tracks", "seed", "shard_size", "epoch_utc", "no_doppler")


@dataclass
class Run:
    """One filter with or without Doppler: its per-epoch statistics (``metrics.per_step``),
    the per-path divergence flags, the dataset's scenario and the run's config."""

    estimator: str
    doppler: bool
    steps: pd.DataFrame
    divergent: np.ndarray
    scenario: dict
    config: dict


def _rmse(run: Run, component: str, t_s: float, all_paths=False) -> float:
    s = run.steps[run.steps.component == component]
    k = int(np.argmin(np.abs(s["t_s"].to_numpy() - t_s)))
    return float(s["rmse_all_paths" if all_paths else "rmse"].to_numpy()[k])


def _t_end(run: Run) -> float:
    return float(run.steps["t_s"].max())


def _ratios(run: Run, base: Run, components, t_s) -> dict:
    """filter RMSE / baseline RMSE (all paths) per component at ``t_s``."""
    return {c: _rmse(run, c, t_s) / _rmse(base, c, t_s, all_paths=True) for c in components}


def _fmt(ratios: dict) -> str:
    return ", ".join(f"{SHORT[c]} {r:.3g}" for c, r in ratios.items())


def _claim(key, setting, statistic, ours, holds, note=""):
    return claim(FAMILY, CLAIMS[key], setting, "conclusion " + key[0], statistic, ours, holds,
                 note)


def _identical(ekf: Run, srekf: Run, obs: str) -> dict:
    a = ekf.steps.sort_values(["component", "step"])["rmse"].to_numpy()
    b = srekf.steps.sort_values(["component", "step"])["rmse"].to_numpy()
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.abs(b - a) / np.abs(a)
    rel = np.where(a == b, 0.0, rel)
    worst = float(np.nanmax(rel))
    same = ekf.divergent.sum() == srekf.divergent.sum()
    return _claim("1", f"ekf, srekf; {obs}",
                  "largest relative difference |RMSE_srekf - RMSE_ekf| / RMSE_ekf over every "
                  f"epoch and component; holds at most {IDENTICAL_REL:g} with equal divergence "
                  "shares", worst, bool(worst <= IDENTICAL_REL and same),
                  f"divergent paths: ekf {int(ekf.divergent.sum())}, srekf "
                  f"{int(srekf.divergent.sum())}")


def _beats(run: Run, base: Run, obs: str) -> list[dict]:
    T = _t_end(run)
    setting = f"{run.estimator}; {obs}"
    mid, end = (_ratios(run, base, INFORMED, t) for t in (MID_S, T))
    worst = max(max(mid.values()), max(end.values()))
    rows = [_claim(
        "2a", setting, f"largest ratio RMSE {run.estimator} / RMSE {BASELINE} over X, Y, phi, "
        f"a at {MID_S:g} s and T = {T:g} s; holds below 1", worst, worst < 1.0,
        f"at T: {_fmt(end)}; at {MID_S:g} s: {_fmt(mid)}")]
    const = _ratios(run, base, CONSTANT, T)
    rows.append(_claim(
        "2b", setting, f"smallest ratio RMSE {run.estimator} / RMSE {BASELINE} of Z and v at T; "
        f"holds (no clear advantage) at least {NO_GAIN:g}", min(const.values()),
        min(const.values()) >= NO_GAIN,
        f"at T: {_fmt(const)}; Z and v are constant in the model but observed (elevation sine"
        + ("; Doppler" if run.doppler else "") + ", bearing rates), so a filter can learn them"))
    growth = {c: mid[c] / end[c] for c in INFORMED}  # advantage at T / advantage at 50 s
    rows.append(_claim(
        "2c", setting, f"smallest over X, Y, phi, a of the advantage ({BASELINE} RMSE / "
        f"{run.estimator} RMSE) at T divided by the advantage at {MID_S:g} s; holds above 1",
        min(growth.values()), min(growth.values()) > 1.0, f"per component: {_fmt(growth)}"))
    return rows


def _cmnf_vs_ekf(cmnf: Run, ekf: Run, obs: str) -> list[dict]:
    setting = f"cmnf, ekf; {obs}"
    a, b = (share(int(r.divergent.sum()), r.divergent.size) for r in (cmnf, ekf))
    pooled = (a.k + b.k) / (a.n + b.n)
    se = np.sqrt(pooled * (1 - pooled) * (1 / a.n + 1 / b.n))
    z = (a.value - b.value) / se if se > 0 else 0.0
    rows = [_claim("3a", setting, "divergence share of cmnf (Wilson interval) against the "
                   "ekf's: holds if smaller by more than 2 standard errors (pooled "
                   "two-proportion z < -2)", a, bool(z < -2.0),
                   f"ekf {b.value:.4f} ({b.lo:.4f} to {b.hi:.4f}); z = {z:+.1f}"
                   + ("; no path of either filter diverges here (horizontal error > "
                      f"{DIVERGENCE_M:g} m from {DIVERGENCE_AFTER_S:g} s on), so neither "
                      "share can be the smaller"
                      if a.k == b.k == 0 else ""))]
    T = _t_end(cmnf)
    z_ratio = _rmse(cmnf, "Z_m", T) / _rmse(ekf, "Z_m", T)
    rows.append(_claim("3b", setting, "RMSE of Z at T, cmnf / ekf; holds below 1", z_ratio,
                       z_ratio < 1.0, f"cmnf {_rmse(cmnf, 'Z_m', T):.3g} m, ekf "
                       f"{_rmse(ekf, 'Z_m', T):.3g} m at T = {T:g} s"))

    def growth(run):
        s = run.steps[(run.steps.component == "v_m_s") & (run.steps.t_s >= 10.0)]
        return _rmse(run, "v_m_s", T) / float(s["rmse"].min())

    g = growth(cmnf)
    rows.append(_claim("3c", f"cmnf; {obs}", "RMSE of v at T divided by its smallest value "
                       f"from 10 s on; holds at least {MARKED:g}", g, g >= MARKED,
                       f"the ekf's: {growth(ekf):.3g}"))
    return rows


def _mismatch(run: Run) -> str:
    return differs_reason(config_differences(run.scenario, asdict(ScenarioConfig()),
                                             ignore=IGNORE))


def _observations(doppler: bool) -> str:
    return "Doppler" if doppler else "bearings only"


def _conclusions(by: dict, obs: str) -> list[dict]:
    """Every conclusion on the runs of one observation model (``by``: estimator -> Run)."""
    reasons = {name: (f"not in this table ({obs})" if name not in by
                      else _mismatch(by[name])) for name in (*FILTERS, BASELINE)}

    def unavailable(keys, names, setting):
        why = "; ".join(f"{n}: {reasons[n]}" for n in names if reasons[n])
        return [_claim(k, setting, "-", None, None, why) for k in keys] if why else None

    rows = unavailable(["1"], ("ekf", "srekf"), f"ekf, srekf; {obs}") or [
        _identical(by["ekf"], by["srekf"], obs)]
    for name in FILTERS:
        rows += (unavailable(["2a", "2b", "2c"], (name, BASELINE), f"{name}; {obs}")
                 or _beats(by[name], by[BASELINE], obs))
    rows += (unavailable(["3a", "3b", "3c"], ("cmnf", "ekf"), f"cmnf, ekf; {obs}")
             or _cmnf_vs_ekf(by["cmnf"], by["ekf"], obs))
    return rows


def against_paper(runs: list[Run]) -> list[dict]:
    """Rows for ``tma.tables.paper``: every conclusion on the Doppler runs (the paper's
    observations), then on the bearings-only runs, not comparable where a filter is missing
    or the scenario is not the paper's; and the journal's curves."""
    rows = []
    for doppler in (True, False):
        rows += _conclusions(by_setting([r for r in runs if r.doppler == doppler],
                                        lambda r: r.estimator, _mismatch),
                             _observations(doppler))
    rows.append(claim(FAMILY, JOURNAL, "cmnf", "plotted curves", "-", None, None,
                      "a different model from ours (papers.md): not comparable and not "
                      "reproduced"))
    return rows
