"""No answer may put the target where the last bearings do not point (issue 36, item 1): the
bearing the log's own last bearings give at each track's end (``end_bearing``, computed in
the estimate stage), against the truth; and ``status.not_an_answer``'s rule on it, for every
estimator: silent on ordinary logs, blanking an answer moved to the mirror side of own-ship.
"""

import re

import numpy as np
import pandas as pd
import pytest

from tma.families import build_estimator, estimator_class, estimator_names
from tma.families.bearings2d.end_bearing import end_bearing
from tma.families.bearings2d.scenario import Config, OutlierConfig, simulate_shard
from tma.families.bearings2d.status import END_SIGMAS, kinematics_now, not_an_answer
from tma.families.bearings2d.target_motion import ManoeuvreConfig, TargetConfig
from tma.families.bearings2d.track_report import ESTIMATE_COLUMNS, track_report

THETA = ["x0_m", "y0_m", "vx_m_s", "vy_m_s"]
ESTIMATORS = [n for n in estimator_names() if estimator_class(n).family == "bearings2d"]
REASON = re.compile(r"its bearing now, ([\d.]+) deg, is ([\d.]+) deg off the ([\d.]+) deg its "
                    r"last bearings point to")


def _true_bearing_now(log, truth, last):
    theta = truth.set_index("track_id").loc[log.track_id, THETA].to_numpy(float)
    (_, bearing, _, _), _ = kinematics_now(theta, log.t_s[last], log.own_x_m[last],
                                           log.own_y_m[last], jacobian=False)
    return np.rad2deg(bearing)


@pytest.mark.parametrize("sigma, outliers", [(0.5, 0.0), (0.5, 0.05), (0.0, 0.0)],
                         ids=["0.5 deg", "0.5 deg, 5 % outliers", "noiseless"])
def test_the_last_bearings_give_the_true_bearing_now_within_their_error(sigma, outliers):
    """2,000 simulated targets: the end bearing against the true bearing at the last bearing
    time, in units of its stated one-sigma error: about N(0, 1) (wild bearings uniform on the
    circle do not move it; without noise the error is the straight line's misfit, which
    its error covers), never beyond 4.5."""
    cfg = Config(n_tracks=2000, shard_size=2000, sigma_deg=sigma, seed=21,
                 outliers=OutlierConfig(prob=outliers))
    log, truth = simulate_shard(cfg, 0)
    measured = np.deg2rad(log.bearing_deg)
    valid = np.isfinite(measured)
    last = valid.shape[1] - 1 - np.argmax(valid[:, ::-1], axis=1)
    end = end_bearing(log.t_s, np.where(valid, measured, 0.0), None if valid.all() else valid,
                      last, np.full(log.n_tracks, np.deg2rad(sigma)))
    err = (end["end_bearing_deg"] - _true_bearing_now(log, truth.to_pandas(), last)
           + 180.0) % 360.0 - 180.0
    z = err / end["end_bearing_sd_deg"]
    assert np.abs(z).max() < 4.5, np.abs(z).max()
    if sigma > 0:
        assert 0.85 <= np.std(z) <= 1.1, np.std(z)
        assert np.median(end["end_bearing_sd_deg"]) < 0.7 * sigma  # 10 bearings, not 1
    else:
        assert np.abs(err).max() < 0.1


def _estimates(log, name, **options):
    columns = build_estimator({"name": name, **options}).estimate(log)
    return pd.DataFrame({"track_id": log.track_id,
                         **{k: v for k, v in columns.items() if np.ndim(v) == 1}})


@pytest.fixture(scope="module")
def steady():
    """Constant-velocity targets, 0.5 deg, and every estimator's estimates of them."""
    log, truth = simulate_shard(Config(n_tracks=100, shard_size=100, sigma_deg=0.5, seed=4), 0)
    return log, {name: _estimates(log, name) for name in ESTIMATORS}


@pytest.fixture(scope="module")
def manoeuvring():
    """Targets that wander and manoeuvre (3 an hour), as the log declares, estimated by the
    estimators that follow them."""
    cfg = Config(n_tracks=40, shard_size=40, sigma_deg=0.5, seed=5, target=TargetConfig(
        accel_psd_m2_s3=1e-4, manoeuvres=ManoeuvreConfig(rate_per_h=3.0)))
    log, _ = simulate_shard(cfg, 0)
    return {name: _estimates(log, name) for name in ("lm", "last_leg")}


@pytest.mark.parametrize("name", ESTIMATORS)
def test_no_honest_answer_is_off_its_last_bearings(name, steady, manoeuvring):
    """On ordinary logs nothing is blanked by the rule: no answer of lm, last_leg, iv, mpekf
    at all; of nbearings (biased by its first bearing's noise: an answer degrees off, with an
    error of a tenth of one, fails it as it fails the noise test) none that passed its
    tests (approximate). Their |z| stays within 4, far inside ``END_SIGMAS``."""
    runs = [steady[1][name]] + ([manoeuvring[name]] if name in manoeuvring else [])
    for est in runs:
        report = track_report(est, recorded=False)
        fired = report["note"].str.contains("its last bearings point to").to_numpy()
        honest = est["status"].isin(["ok", "approximate", "position_only"]).to_numpy()
        assert not (fired & honest).any(), report.loc[fired, ["status", "note"]]
        if name != "nbearings":
            assert not fired.any(), report.loc[fired, ["status", "note"]]
        z = (np.abs((est["bearing_now_deg"] - est["end_bearing_deg"] + 180.0) % 360.0 - 180.0)
             / np.hypot(est["bearing_sd_deg"], est["end_bearing_sd_deg"]))
        assert np.nanmax(z[honest]) < 4.0


def _mirrored(est):
    """The estimates with each answer moved to its mirror through own-ship at the last
    bearing (the ghost of a fit run to the wrong side): the position now p becomes
    2 own - p, the velocity kept; range, bearing and their errors as the estimator gave them
    but for the bearing, turned by 180 deg."""
    t = est["t_last_s"].to_numpy(float)
    own = est[["own_x_last_m", "own_y_last_m"]].to_numpy(float)
    v = est[["vx_m_s", "vy_m_s"]].to_numpy(float)
    now = est[["x0_m", "y0_m"]].to_numpy(float) + v * t[:, None]
    ghost = 2 * own - now
    out = est.copy()
    out["x0_m"], out["y0_m"] = (ghost - v * t[:, None]).T
    (_, bearing, _, _), _ = kinematics_now(out[THETA].to_numpy(float), t, *own.T,
                                           jacobian=False)
    out["bearing_now_deg"] = np.rad2deg(bearing) % 360.0
    return out


@pytest.mark.parametrize("name", ESTIMATORS)
def test_an_answer_on_the_mirror_side_of_own_ship_is_no_answer(name, steady):
    """Every estimator's real answers, half of them moved to the mirror side of own-ship:
    those are blanked in the report (every number of the estimate; its status kept, but an
    ``ok`` or ``position_only`` one, which promised an answer, ``not_converged``) with the
    reason and its numbers (the answer's bearing now, 180 deg off the bearing its log's last
    bearings give, which the estimate stage stored), the others are not."""
    est = steady[1][name]
    moved = np.arange(len(est)) % 2 == 0
    ghosts = est.copy()
    ghosts[moved] = _mirrored(est[moved])
    shown = track_report(est, recorded=False)["range_now_m"].notna().to_numpy()
    assert shown[moved].sum() >= 40
    report = track_report(ghosts, recorded=False)
    fired = report["note"].str.contains("its last bearings point to").to_numpy()
    assert fired[moved & shown].all() and not fired[~moved & shown].any()
    assert report.loc[fired, ESTIMATE_COLUMNS].isna().all().all()
    promised = fired & est["status"].isin(["ok", "position_only"]).to_numpy()
    assert (report.loc[promised, "status"] == "not_converged").all()
    assert (report.loc[~promised, "status"] == est.loc[~promised, "status"]).all()
    ghost = moved & shown  # answers that agreed with their last bearings, now turned 180 deg
    for note, row in zip(report.loc[ghost, "note"], ghosts[ghost].itertuples(), strict=True):
        now, off, end = map(float, REASON.search(note).groups())
        assert now == pytest.approx(row.bearing_now_deg, abs=0.06)
        assert end == pytest.approx(row.end_bearing_deg, abs=0.06)
        assert off == pytest.approx(180.0, abs=5.0)
    # the rule itself: off by more than END_SIGMAS combined sd, not less
    row = ghosts[moved & shown].iloc[:1]
    sd = float(np.hypot(row["bearing_sd_deg"], row["end_bearing_sd_deg"]).iloc[0])
    for factor, fires in ((0.9, False), (1.1, True)):
        near = {"bearing_now_deg": row["end_bearing_deg"] + factor * END_SIGMAS * sd,
                "bearing_sd_deg": row["bearing_sd_deg"],
                "end_bearing_deg": row["end_bearing_deg"],
                "end_bearing_sd_deg": row["end_bearing_sd_deg"]}
        (why,) = not_an_answer(row["range_now_m"], row["range_sd_m"], row["speed_m_s"],
                               recorded=False, bearings=near)
        assert bool(REASON.search(why)) == fires, (factor, why)
