"""The AIS cases of both recordings (``tests/data/ais/build_cases.py``): the New York Harbor
cases, reported once a minute, meet the same case rules as the Solent ones with the gap and
spike rules of their reporting, and are written in the same form."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pymap3d import enu2geodetic

AIS = Path(__file__).resolve().parents[2] / "data" / "ais"


def _load(name):
    spec = importlib.util.spec_from_file_location(f"ais_{name}", AIS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def bc():
    return _load("build_cases")


def test_nyharbor_cases_are_written_like_the_solent_ones(bc, tmp_path):
    truth = bc.write_cases(tmp_path / "ny", recording="nyharbor")
    solent = bc.write_cases(tmp_path / "solent")
    assert list(truth.columns) == list(solent.columns)
    assert len(truth) == len(bc.NY_CASES) >= 30
    kinds = truth["kind"].value_counts()
    assert kinds["steady"] >= 8 and kinds["manoeuvring"] >= 8, kinds
    assert (truth["min_range_m"] >= 1_000).all() and (truth["max_range_m"] <= 15_000).all()
    assert (truth["own_turn_deg"] >= 45).all()
    assert truth["start_utc"].str.startswith("2020-06-30T00:").all()
    assert set(truth["duration_s"]) <= {1200.0, 1500.0}
    for case in truth.itertuples():
        df = pd.read_csv(tmp_path / "ny" / f"{case.case}.csv")
        assert list(df.columns) == list(bc.EXPORT_COLUMNS)
        assert len(df) == case.n_bearings == case.duration_s / 5 + 1
        assert (df["track"] == case.target_mmsi).all()
    # the same vessels, in the positions of their own recording only
    ny = bc.load_positions(bc.NY_POSITIONS_PATH)
    used = set(truth["own_mmsi"]) | set(truth["target_mmsi"])
    assert used <= set(ny["mmsi"])
    assert not used & set(bc.load_positions(bc.POSITIONS_PATH)["mmsi"])


def test_a_case_that_breaks_the_recording_rules_is_refused(bc):
    """The New York gap rule (150 s) is what admits its cases: under the Solent's 60/90 s,
    the first New York case no longer meets the rules."""
    rec = bc.get_recording("nyharbor")
    tracks = bc.tracks_from(bc.load_positions(rec.positions_path), rec.rules)
    bc.make_case(1, rec.cases[0], tracks, 0.5, rec.seed, rec.rules)
    with pytest.raises(ValueError, match="no longer meets the case rules"):
        bc.make_case(1, rec.cases[0], tracks, 0.5, rec.seed, bc.SOLENT_RULES)
    with pytest.raises(ValueError, match="unknown AIS recording 'nowhere'"):
        bc.get_recording("nowhere")


def _ferry_turn(report_s: float):
    """A ferry at 13 m/s east that turns back (180 deg) in 60 s, reported every ``report_s``
    s: times (s), latitude, longitude (deg)."""
    t = np.arange(0.0, 600.0 + report_s, report_s)
    tf = np.arange(0.0, 601.0)
    psi = np.radians(90.0 + np.clip((tf - 300.0) * 3.0, 0.0, 180.0))  # 3 deg/s from 300 s
    e = np.r_[0.0, np.cumsum(13.0 * np.sin(psi[:-1]))]
    n = np.r_[0.0, np.cumsum(13.0 * np.cos(psi[:-1]))]
    lat, lon, _ = enu2geodetic(np.interp(t, tf, e), np.interp(t, tf, n), 0.0, 40.6, -74.0, 0.0)
    return t, np.asarray(lat), np.asarray(lon)


def test_one_minute_reports_of_a_turn_are_kept_and_a_gross_error_dropped(bc):
    """At one report a minute a genuine turn lies hundreds of metres off the line between
    its neighbours: the Solent's 300 m spike rule (made for 2-10 s) drops it, New York's
    2 km keeps it; a report 20 km off is dropped by both."""
    t, lat, lon = _ferry_turn(65.0)
    assert not bc.drop_spikes(t, lat, lon, bc.SOLENT_RULES.spike_m).all()  # genuine, lost
    assert bc.drop_spikes(t, lat, lon, bc.NYHARBOR_RULES.spike_m).all()
    t5, lat5, lon5 = _ferry_turn(5.0)  # reported every 5 s, the Solent's rule keeps it all
    assert bc.drop_spikes(t5, lat5, lon5, bc.SOLENT_RULES.spike_m).all()
    for (tt, la, lo), rules in (((t, lat, lon), bc.NYHARBOR_RULES),
                                ((t5, lat5, lon5), bc.SOLENT_RULES)):
        la = la.copy()
        la[3] += 0.18  # 20 km north
        keep = bc.drop_spikes(tt, la, lo, rules.spike_m)
        # (its neighbours lie off the lines through it, and go too)
        assert not keep[3] and keep[:2].all() and keep[5:].all()

def test_the_wander_fit_holds_at_one_report_a_minute():
    """``motion_stats``' ML fit of the NCV wander level on simulated legs reported every
    60-80 s (New York) recovers q: the pooled fit within 25 %."""
    ms = _load("motion_stats")
    rng = np.random.default_rng(np.random.SeedSequence(20200630))
    for q, r in ((1e-4, 3.0), (1e-3, 5.0)):
        legs = ms.simulate_legs(rng, q, r, (60.0, 80.0), 13)
        lq, _ = ms.fit_ncv(legs)
        assert abs(lq - np.log10(q)) < np.log10(1.25), (q, 10 ** lq)


def test_the_dispersion_of_manoeuvres_tells_poisson_from_clustered():
    """``motion_stats.dispersion`` on simulated underway runs of 2 hours: manoeuvres as a
    Poisson process at 9 an hour give a variance over mean near 1, no clustering found, and
    the same rate after a quiet spell; the same mean rate in runs that are busy (18 an hour)
    or quiet (none) is found clustered."""
    ms = _load("motion_stats")
    rng = np.random.default_rng(np.random.SeedSequence(20161112))

    def runs(rates_per_h):
        out = []
        for k, rate in enumerate(rates_per_h):
            n = rng.poisson(rate * 2.0)
            out.append((k, 0.0, 7200.0, np.sort(rng.uniform(0.0, 7200.0, n))))
        return out

    poisson = ms.dispersion(ms.Stats("poisson", runs=runs([9.0] * 200)))
    assert 0.85 < poisson["  variance / mean (Poisson 1)"] < 1.15, poisson
    assert poisson["  dispersion test p (clustered)"] > 1e-3, poisson
    assert poisson["20-min windows underway"] == 200 * 6
    assert 6.0 < poisson["  per h"] < 12.0, poisson  # memoryless: 9 an hour still
    clustered = ms.dispersion(ms.Stats("clustered", runs=runs([18.0, 0.0] * 100)))
    assert clustered["  variance / mean (Poisson 1)"] > 2.0, clustered
    assert clustered["  dispersion test p (clustered)"] < 1e-6, clustered
    assert clustered["  per h"] < 2.0, clustered  # a quiet spell: a quiet run, mostly
