"""Honest answers on real ship motion (issue 20, item 6): 30 own-ship/target pairs from a
public AIS recording (``tests/data/ais``, ``real_motion.py``), ingested and estimated as the
README says, judged against the AIS truth at the last bearing."""

import pytest

from tests.families.bearings2d.real_motion import CRITERIA, criteria, run_cases


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("ais")


# ok tracks beyond the 25 % range bound, by name: a tug 2.5 km from a hovercraft (+27 % with
# a one-sigma error of 17 %, 1.3 sd) and, re-solved on its last leg, case 4 (+34 % with 17 %,
# 1.5 sd): imprecise but honest, so they stay ok; any other is a failure
WIDE_BUT_HONEST = {"lm": {"case_27"}, "last_leg": {"case_04", "case_27"}}


def _range_bound_holds(results, estimator):
    """The 25 % range bound on every ok track but the named ones, and those within 3 sd."""
    ok = results[results.status == "ok"]
    beyond = ok[ok.range_error.abs() > CRITERIA["max_ok_range_error"]]
    assert set(beyond.case) <= WIDE_BUT_HONEST[estimator], beyond
    assert (beyond.z <= 3).all(), beyond


@pytest.mark.parametrize("sigma_deg", [None, 0.5], ids=["sigma estimated", "sigma declared"])
def test_lm_is_honest_on_real_ship_motion(workdir, sigma_deg):
    results = run_cases(workdir / str(sigma_deg), {"name": "lm"}, sigma_deg)
    figures = criteria(results)
    assert figures["cases"] >= 20 and figures["steady"] >= 10 and figures["manoeuvring"] >= 8
    assert figures["ok_within_3_sd"] >= CRITERIA["ok_within_3_sd"], figures
    assert figures["steady_ok"] >= CRITERIA["steady_ok"], figures
    assert figures["max_ok_course_error_deg"] <= CRITERIA["max_ok_course_error_deg"], figures
    # every manoeuvring target is flagged (not ok), or ok with its truth within 3 sd
    assert figures["manoeuvring_flagged_or_within_3_sd"] == 1.0, figures
    _range_bound_holds(results, "lm")


def test_the_constant_velocity_fit_of_the_old_default_was_not_honest(workdir):
    """The same cases with the targets assumed at constant velocity and no trend test (the
    behaviour before issue 20): many ok answers miss the truth by more than 3 sd."""
    figures = criteria(run_cases(workdir / "cv", {"name": "lm", "accel_psd_m2_s3": 0.0,
                                                  "motion_test": "off"}, 0.5))
    assert figures["ok_within_3_sd"] < 0.6, figures


def test_last_leg_on_real_ship_motion(workdir):
    """``last_leg`` re-solves manoeuvring targets on their last legs: more of them ok than
    ``lm`` gives, the ok ones still honest at the criterion's rate."""
    results = run_cases(workdir / "last_leg", {"name": "last_leg"})
    figures = criteria(results)
    lm = criteria(run_cases(workdir / "lm", {"name": "lm"}))
    assert figures["manoeuvring_ok"] > lm["manoeuvring_ok"], (figures, lm)
    assert figures["ok_within_3_sd"] >= CRITERIA["ok_within_3_sd"], figures
    assert figures["steady_ok"] >= CRITERIA["steady_ok"], figures
    assert figures["max_ok_course_error_deg"] <= CRITERIA["max_ok_course_error_deg"], figures
    _range_bound_holds(results, "last_leg")
