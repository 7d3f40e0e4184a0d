"""Honest answers on real ship motion (issue 28, item 3): own-ship/target pairs from two public
AIS recordings of different traffic, the Solent (harbour approaches: ferries, tugs,
hovercraft, 2-10 s reports) and New York Harbor (ferries, tugs, service craft, one report a
minute) (``tests/data/ais*``, ``real_motion.py``), ingested and estimated as the README says,
judged against the AIS truth at the last bearing: at least 90 % of the ``ok`` tracks within 3
sd on range, course and speed, none beyond 5 sd, at least half of the steady targets ok."""

import pytest

from tests.families.bearings2d.real_motion import criteria, holds, run_cases

RECORDINGS = ("solent", "nyharbor")


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("ais")


@pytest.mark.parametrize("sigma_deg", [None, 0.5], ids=["sigma estimated", "sigma declared"])
@pytest.mark.parametrize("recording", RECORDINGS)
def test_lm_is_honest_on_real_ship_motion(workdir, recording, sigma_deg):
    figures = criteria(run_cases(workdir / f"{recording}-{sigma_deg}", {"name": "lm"},
                                 sigma_deg, recording=recording))
    assert figures["cases"] >= 30 and figures["steady"] >= 10, figures
    assert figures["manoeuvring"] >= 15, figures
    assert holds(figures), figures


def test_without_manoeuvres_in_the_prior_it_was_not(workdir):
    """The same Solent cases with the targets assumed at constant velocity and no trend test
    (the behaviour before issue 20): most ok answers miss the truth by more than 3 sd."""
    figures = criteria(run_cases(workdir / "cv", {"name": "lm", "accel_psd_m2_s3": 0.0,
                                                  "manoeuvre_rate_per_h": 0.0,
                                                  "motion_test": "off"}, 0.5))
    assert figures["ok_within_3_sd"] < 0.6, figures


@pytest.mark.parametrize("recording", RECORDINGS)
def test_last_leg_on_real_ship_motion(workdir, recording):
    """``last_leg`` re-solves the tracks the trend test flags on their last legs, under the
    same motion model: as honest."""
    figures = criteria(run_cases(workdir / f"last_leg-{recording}", {"name": "last_leg"}, 0.5,
                                 recording=recording))
    assert holds(figures), figures
