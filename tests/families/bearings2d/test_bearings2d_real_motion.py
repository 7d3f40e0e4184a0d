"""Honest answers on real ship motion: own-ship/target pairs from two public AIS recordings of
different traffic, the Solent (harbour approaches: ferries, tugs, hovercraft, 2-10 s
reports) and New York Harbor (ferries, tugs, service craft, one report a minute)
(``tests/data/ais*``, ``real_motion.py``), ingested and estimated as the README says, judged
against the AIS truth at the last bearing.

Issue 28, item 3 (one noise draw per pair): at least 90 % of the ``ok`` tracks within 3 sd on
range, course and speed, none beyond 5 sd, at least half of the steady targets ok.

Issue 36, item 5 (``DRAWS`` noise draws per pair, sigma estimated as the README's command
does): two-sided and per quantity, under the pooled prior and under the prior measured on the
other recording alone (leave one recording out): the median over ``ok`` tracks of the largest
|z| of range, course and speed read in units of the answers' own central intervals (the
mixture's own, which its heavy tails do not widen at the core) in the issue's band (1.0-1.6
about the 1.26 of Gaussian answers) scaled to the 1.02 honest answers of this kind give on
lm's own model, 0.81-1.3 (in units of the sd they give 0.57; below, errors wider than the
bearings allow), each quantity within 2 sd on at least 90 % of them, none beyond 5 sd; and a
prior ten times too poor fails them on the side of overconfidence. The intervals also hold
the truth as the sd's one-sided checks ask, and are sharper than the sd."""

import numpy as np
import pytest

from tests.conftest import once_per_run
from tests.families.bearings2d.real_motion import (
    KINDS,
    QUANTITIES,
    TWO_SIDED,
    criteria,
    figures,
    holds,
    median_boot,
    priors,
    run_cases,
    two_sided,
    two_sided_intervals,
    wilson_clustered,
)

DRAWS = 5

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


def _figures(tmp_path_factory, recording: str, prior: str) -> dict:
    """``figures`` of ``recording``'s pairs, ``DRAWS`` noise draws each, under ``prior`` (a
    name of ``priors``); computed once per test run (``once_per_run``)."""
    def compute():
        workdir = tmp_path_factory.mktemp(f"ais-{recording}-draws")
        results = run_cases(workdir, {"name": "lm", **priors(recording)[prior]}, None,
                            recording=recording, draws=DRAWS)
        if results.case.nunique() < 30 or results.draw.nunique() != DRAWS:  # (no assert: an
            # xfail that expects an AssertionError must not take this for its failure)
            raise RuntimeError(f"{recording}: {results.case.nunique()} cases, "
                               f"{results.draw.nunique()} draws")
        return figures(results)

    return once_per_run(tmp_path_factory, f"real-{recording}-{prior.replace(' ', '-')}",
                        compute)


def _shown(f: dict) -> dict:
    return {k: round(v, 3) if isinstance(v, float) else v for k, v in f.items()
            if not k.endswith("_ci")}


# Issue 36's two-sided checks do not all hold on New York (docs/manoeuvres.md): the median
# largest |z| in units of the answers' own intervals is 0.53 and 0.47 there, below the band
# honest answers' 1.02 sets (TWO_SIDED: 0.81-1.3); the Solent's 0.86 and 1.01 lie inside it.
# Strict: the day they hold, these fail until the marks go.
TOO_WIDE = ("median largest |z| in units of the answers' intervals below the band: wider than "
            "the targets needed (the prior's wander and manoeuvres, more than these pairs made)")
KNOWN = {("nyharbor", "pooled"): TOO_WIDE, ("nyharbor", "left out"): TOO_WIDE}


def _pairs(known: dict) -> list:
    """Every recording under the pooled and the left-out prior, those of ``known`` ((recording,
    prior) -> why) marked as failing, strictly."""
    return [pytest.param(r, p, marks=[pytest.mark.xfail(strict=True, raises=AssertionError,
                                                        reason=known[r, p])]
                         if (r, p) in known else [])
            for r in RECORDINGS for p in ("pooled", "left out")]


@pytest.mark.parametrize("recording, prior", _pairs(KNOWN))
def test_lm_is_honest_both_ways_on_real_ship_motion(tmp_path_factory, recording, prior):
    """Issue 36, item 5: every check of ``TWO_SIDED`` (the message names those that fail)."""
    f = _figures(tmp_path_factory, recording, prior)
    failed = [name for name, held in two_sided(f).items() if not held]
    assert not failed, f"{failed} fail {TWO_SIDED}: {_shown(f)}"


@pytest.mark.parametrize("recording, prior", [(r, p) for r in RECORDINGS
                                              for p in ("pooled", "left out")])
def test_lm_states_intervals_that_hold_real_ships_and_are_sharper(tmp_path_factory,
                                                                  recording, prior):
    """The same answers' central intervals (``status.INTERVAL_COLUMNS``, read by
    ``calibration.interval_z``): each quantity's 2-sd interval holds the truth on at least
    90 % of the ``ok`` tracks and none lies beyond 5 of their units, as the sd's checks ask;
    and they are sharper than the sd: the median largest |z| in their units is
    above the sd's (the sd carries the mixture's heavy tails; the intervals its core)."""
    f = _figures(tmp_path_factory, recording, prior)
    failed = [name for name, held in two_sided_intervals(f).items() if not held]
    assert not failed, f"{failed} fail: {_shown(f)}"
    assert f["median_max_iz"] > f["median_max_z"], _shown(f)


@pytest.mark.parametrize("recording", RECORDINGS)
def test_a_prior_ten_times_too_poor_fails_the_checks(tmp_path_factory, recording):
    """The checks see the prior: with ten times less wander and ten times fewer manoeuvres
    than measured, the ``ok`` answers are too sure of themselves and a check says so (a
    quantity within 2 sd on under 90 %, a track beyond 5 sd, or a median largest |z| in
    units of the intervals above 1.6)."""
    f = _figures(tmp_path_factory, recording, "pooled x0.1")
    overconfident = [name for name, held in two_sided(f).items()
                     if not held and name != "median_max_iz"]
    if f["median_max_iz"] > TWO_SIDED["median_max_iz"][1]:
        overconfident.append("median_max_iz")
    assert overconfident, f"no check fails: {_shown(f)}"


# New York's turning targets' ok answers put them too near (docs/manoeuvres.md, "By what the
# target did"): under the pooled prior their range is in the 2-sd interval on 65 % (clustered
# over 7 vessels, 29-89 %); left out, on 76 % (45-93 %: not clearly short). Strict: the day it
# holds, this fails until the mark goes.
TOO_NEAR = ("New York's turning targets' ok answers too near: range in the 2-sd interval "
            "clearly under 90 %")
KIND_KNOWN = {("nyharbor", "pooled"): TOO_NEAR}


@pytest.mark.parametrize("recording, prior", _pairs(KIND_KNOWN))
def test_the_answers_hold_steady_and_turning_targets_alike(tmp_path_factory, recording,
                                                           prior):
    """The pooled check, per kind of target (``real_motion.KINDS``: a turning target's answer
    narrow where a steady one's is wide would pass it pooled): each kind's 2-sd intervals
    hold the truth on a share whose interval, clustered by vessel, reaches 90 % per quantity
    (few answers of few vessels per kind: only a share clearly short fails); each kind has
    ok answers."""
    f = _figures(tmp_path_factory, recording, prior)
    assert all(f[f"ok_rows_{kind}"] for kind in KINDS), _shown(f)
    failed = [f"{q}, {kind}: {f[f'{q}_in_2_sd_interval_{kind}']:.0%} of "
              f"{f[f'ok_rows_{kind}']} (clustered {f[f'{q}_in_2_sd_interval_{kind}_ci']})"
              for kind in KINDS for q in QUANTITIES
              if f[f"{q}_in_2_sd_interval_{kind}_ci"][1] < TWO_SIDED["within_2_sd"]]
    assert not failed, failed


def test_the_clustered_intervals_cover():
    """``wilson_clustered`` and ``median_boot`` against shares and medians known by
    construction: clusters of 1-10 rows (a vessel's pairs and draws), each cluster's own
    success probability (Beta about the share) or level (normal about the median); over
    many samples the intervals hold the truth near 95 % of the time, where a Wilson interval
    that takes the rows as independent does not."""
    rng = np.random.default_rng(np.random.SeedSequence(36))
    runs, share, a = 600, 0.7, 1.0
    covered, naive = 0, 0
    for _ in range(runs):
        sizes = rng.integers(1, 11, 12)
        p = rng.beta(a * share / (1 - share), a, sizes.size)
        success = rng.random(sizes.sum()) < np.repeat(p, sizes)
        vessel = np.repeat(np.arange(sizes.size), sizes)
        lo, hi = wilson_clustered(success, vessel)
        covered += lo <= share <= hi
        lo, hi = wilson_clustered(success, np.arange(success.size))
        naive += lo <= share <= hi
    assert 0.92 <= covered / runs <= 0.99, covered / runs
    assert naive / runs < 0.88, naive / runs
    covered = 0
    for i in range(150):
        sizes = rng.integers(1, 11, 30)
        values = np.repeat(rng.normal(0.0, 1.0, sizes.size), sizes) + rng.normal(
            0.0, 0.5, sizes.sum())
        lo, hi = median_boot(values, np.repeat(np.arange(sizes.size), sizes), boot=500, seed=i)
        covered += lo <= 0.0 <= hi
    assert 0.88 <= covered / 150 <= 0.995, covered / 150
