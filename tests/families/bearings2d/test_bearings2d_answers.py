"""Never a number that is not an answer (issue 28, item 4): an estimate that diverged,
collapsed onto own-ship or has no one-sigma error is blank in every output, with its status
and a note; one rule (``status.not_an_answer``) decides, and it never blanks an ``ok`` track.
Also the logs the output tests share: simulated encounters written as the navigation export a
user would bring (an own-ship that never manoeuvres: range unobservable, the estimates
diverge or collapse; targets that manoeuvre: ``last_leg`` solves a late leg)."""

import logging

import numpy as np
import pandas as pd
import pytest

import tma
from tests.families.bearings2d.real_motion import _cases_module
from tma.families.bearings2d import contact_plots, map_mcap
from tma.families.bearings2d.status import (
    HEADING_UNDETERMINED,
    MAX_RANGE_M,
    MAX_SPEED_M_S,
    MIN_RANGE_M,
    not_an_answer,
)
from tma.families.bearings2d.track_report import ESTIMATE_COLUMNS, track_report
from tma.maths.geo import local_to_geodetic
from tma.utc import format_utc

ORIGIN = {"lat": 59.9, "lon": 10.7}


def navigation_export(log, path, prefix="C"):
    """Write a simulated ``log`` (with an origin) as a navigation export: one row per bearing,
    ``timestamp_utc`` (ISO-8601), own-ship's ``latitude_deg``/``longitude_deg``,
    ``bearing_deg`` and ``contact`` (``<prefix><track id>``)."""
    lat, lon = local_to_geodetic(log.own_x_m, log.own_y_m, log.origin_deg)
    row, col = np.nonzero(np.isfinite(log.bearing_deg))
    order = np.lexsort((row, col))
    row, col = row[order], col[order]
    pd.DataFrame({
        "timestamp_utc": [format_utc(log.epoch_utc_ns + round(t * 1e9)) for t in log.t_s[col]],
        "latitude_deg": lat[col], "longitude_deg": lon[col],
        "bearing_deg": log.bearing_deg[row, col],
        "contact": [f"{prefix}{i}" for i in log.track_id[row]],
    }).to_csv(path, index=False)
    return path


def straight_log(path, n=3):
    """Own-ship on one straight leg (it never manoeuvres): no bearing can give the range, so
    every estimator's range diverges or collapses (a scaled copy of the encounter gives the
    same bearings)."""
    sim = tma.simulate("bearings2d", n_tracks=n, shard_size=n, sigma_deg=0.5, seed=3,
                       origin=ORIGIN, observer={"legs": [{"course_deg": 0.0,
                                                          "duration_s": 1200.0}]})
    return navigation_export(sim.logs[0], path, "S")


def late_leg_log(path, n=6):
    """Targets that each turn once, mid-way (20-120 deg), seen by the default manoeuvring
    own-ship: ``last_leg`` re-solves them on a leg that starts late."""
    sim = tma.simulate("bearings2d", n_tracks=n, shard_size=n, sigma_deg=0.3, seed=2,
                       origin=ORIGIN, target={"manoeuvres": {"prob": 1.0}, "declared": False})
    return navigation_export(sim.logs[0], path, "M")


def line_data(figure, label):
    """(x, y) in km of the plot's line labelled ``label`` (``contact_plots._TrackPlots``)."""
    (line,) = [ln for ln in figure.axes[0].lines if ln.get_label().startswith(label)]
    return np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)


# -- the rule --------------------------------------------------------------------------------

def test_the_rule_names_each_kind_of_number_that_is_no_answer():
    rows = {  # range (m), range sd (m), speed (m/s), recorded, max_range_rel_sd -> reason
        "an answer": (5000.0, 500.0, 5.0, True, 0.2, ""),
        "unobservable but an answer": (5000.0, 4000.0, 5.0, True, 0.2, ""),
        "no estimate": (np.nan, np.nan, np.nan, True, 0.2, "no finite estimate"),
        "singular": (3.6e10, np.nan, 3e9, True, 0.2, "singular"),
        "infinite sd": (5000.0, np.inf, 5.0, True, 0.2, "singular"),
        "own-ship within one sigma": (11.3, 12.7, 6.0, True, 0.2, "exceeds the range"),
        "run away": (4.9e5, 2.3e7, 1162.0, False, 0.2, "exceeds the range"),
        "nanometres": (1.8e-9, 8e-11, 10.0, True, 0.2, "collapsed onto own-ship"),
        "beyond a bearing's reach": (3e6, 1e5, 5.0, True, 0.2, "beyond 2000 km"),
        "faster than a vessel": (1.03e6, 6e5, 504.0, True, 0.2, "speed beyond 343 m/s"),
        "a simulation declares its scale": (3e6, 1e5, 504.0, False, 0.2, ""),
        "a simulated contact close by": (1.8e-9, 8e-11, 10.0, False, 0.2, ""),
        # a user who calls ok a range sd up to twice the range: such a track is not blanked
        "within the user's ok threshold": (5000.0, 7500.0, 5.0, True, 2.0, ""),
        "beyond it": (5000.0, 10500.0, 5.0, True, 2.0, "exceeds the range"),
    }
    for name, (rng, sd, speed, recorded, rel, expected) in rows.items():
        (why,) = not_an_answer([rng], [sd], [speed], rel, recorded=recorded)
        assert (expected in why) if expected else why == "", (name, why)
    assert MIN_RANGE_M < 100 and MAX_RANGE_M >= 1e6 and MAX_SPEED_M_S > 250  # real targets
    # vectorised, in order
    why = not_an_answer([5000.0, 5000.0], [np.nan, 100.0], [5.0, 5.0])
    assert "singular" in why[0] and why[1] == ""


def test_no_ok_track_is_blanked_in_simulation():
    """Simulated targets at 5-50 km, steady or turning, at three noise levels (noiseless
    included, whose errors are 0): every ok track is shown, as a recording's would be."""
    for sigma, target in [(0.0, {}), (0.5, {}), (1.0, {"manoeuvres": {"prob": 1.0}})]:
        sim = tma.simulate("bearings2d", n_tracks=200, shard_size=200, sigma_deg=sigma,
                           seed=11, target=target)
        found = tma.estimate(sim)
        ok = found[found["status"] == "ok"]
        assert len(ok) >= 20, found["status"].value_counts()
        shown = [c for c in ESTIMATE_COLUMNS if not c.startswith(("lat", "lon"))]
        assert ok[shown].notna().all().all()
        # nor would the bounds on a recording's targets
        assert (not_an_answer(ok["range_now_m"], ok["range_sd_m"], ok["speed_m_s"]) == "").all()


def test_real_ship_motion_shows_no_number_that_is_not_an_answer(tmp_path):
    """The 30 Solent AIS cases (real own-ship and target motion, 0.5 deg noise) through
    ``tma.estimate`` as a user runs them, with ``lm`` and ``last_leg``: no ok track is
    blanked, every blanked one keeps its status and says why, and no number shown is a
    diverged or collapsed one (before: ranges of 11-21 m and 8e8-3e13 m, speeds to 2e10 m/s,
    for targets 1.4-3.8 km away)."""
    truth = _cases_module().write_cases(tmp_path)
    for estimator in ("lm", "last_leg"):
        for case in truth.itertuples(index=False):
            rec = tma.read_log(tmp_path / f"{case.case}.csv", sigma_deg=0.5)
            found = tma.estimate(rec, estimator=estimator)
            (row,) = found.itertuples(index=False)
            (theta,) = found.tma.estimates.itertuples(index=False)
            where = (estimator, case.case, row.status, row.range_now_m, row.speed_m_s)
            if np.isnan(row.range_now_m):  # blanked: all of it, with its status and why
                assert row.status != "ok", where
                assert "the estimate is not shown" in row.note or (
                    row.note.startswith("no finite estimate")), where
                assert all(np.isnan(getattr(row, c)) for c in ESTIMATE_COLUMNS), where
                assert np.isnan(theta.x0_m) and np.isnan(theta.vy_m_s), where
            else:  # shown: an answer of the right order, whatever its status
                assert case.range_m / 10 < row.range_now_m < case.range_m * 10, where
                if row.status in HEADING_UNDETERMINED:  # where it is heading: not
                    # determined (position_only), nor its range (unobservable)
                    assert np.isnan(row.speed_m_s) and np.isnan(row.course_sd_deg), where
                    assert (("where it is heading is not determined" in row.note)
                            if row.status == "position_only" else
                            ("not determined from this geometry" in row.note)), where
                else:
                    assert row.speed_m_s < 10 * case.speed_m_s + 5, where
                assert row.range_sd_m <= row.range_now_m, where


# -- plots and map of a dataset without truth, from the run's raw estimates ----------------

@pytest.fixture(scope="module")
def diverged(tmp_path_factory):
    """A recording whose own-ship never manoeuvres, its lm estimates as the run stores them
    (raw) and as the report shows them."""
    tmp = tmp_path_factory.mktemp("diverged")
    rec = tma.read_log(straight_log(tmp / "straight.csv"))
    from tma.families import build_estimator

    (log,) = rec.logs
    est = build_estimator({"name": "lm", "initial_bearing_deg": None}).estimate(log)
    raw = pd.DataFrame({"track_id": log.track_id, **est})
    labels = dict(zip(log.track_id.tolist(), map(str, log.track_label), strict=True))
    report = track_report(raw, log.epoch_utc_ns, log.origin_deg, labels, sigma_known=False)
    return rec, raw, report


def test_the_raw_estimates_diverged_and_the_report_shows_none(diverged):
    _, raw, report = diverged
    assert np.isfinite(raw["range_now_m"]).all()  # the estimator's numbers, kept in the run
    assert (~np.isfinite(raw["range_sd_m"]) | (raw["range_sd_m"] > raw["range_now_m"])).all()
    assert report[ESTIMATE_COLUMNS].isna().all().all()
    assert list(report["status"]) == list(raw["status"]) and "ok" not in set(raw["status"])
    assert report["note"].str.contains("the estimate is not shown").all()


def test_plots_draw_no_estimate_where_the_table_shows_none(diverged, tmp_path, monkeypatch):
    rec, raw, report = diverged
    drawn = {}

    def keep(figure, path):  # what write_track_plots would save
        drawn[path.name] = (figure.axes[0].get_title(), line_data(figure, "estimated"),
                            line_data(figure, "95 %"), line_data(figure, "own-ship"))

    monkeypatch.setattr(contact_plots, "save_figure", keep)
    contact_plots.write_track_plots(report, raw, rec.logs, tmp_path, "s", progress=False)
    assert sorted(drawn) == ["s-S0.png", "s-S1.png", "s-S2.png"]
    for title, track, ring, own in drawn.values():
        assert "no estimate shown (the table's note says why)" in title and " km" not in title
        assert track[0].size == 0 and ring[0].size == 0
        assert own[0].size == rec.logs[0].t_s.size


def test_the_map_leaves_out_estimates_the_table_does_not_show(diverged, tmp_path, caplog):
    from tests.conftest import plain_messages

    rec, raw, report = diverged
    (log,) = rec.logs
    with caplog.at_level(logging.WARNING):
        path = map_mcap.write_map_mcap(tmp_path / "m.mcap", report, raw, rec.logs,
                                       log.epoch_utc_ns, log.origin_deg, {})
    assert {ch.topic for ch, _, _ in plain_messages(path)} == {"/ownship/location_fix"}
    assert "no estimate shown (the table's note says why)" in caplog.text
    assert "for S0, S1, S2: not in the map" in caplog.text
