"""Outputs of a log of several platforms (issue 39): a ship that turns once and a buoy that
stays put take one contact's bearings at their own times (some at the same time), the ship
alone another's. The map MCAP holds each platform's track and, per contact, each platform's
lines of sight from where it was; the contact plot draws both platforms and their lines of
sight; the report names the platforms per contact. The expected positions and bearings come
from the scenario's own formulas below, not from the code under test."""

import json

import numpy as np
import pandas as pd
import pymap3d
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from tests.families.bearings2d.test_bearings2d_map_outputs import (
    _estimate_and_aggregate,
    _ingested_dataset,
    _simulated,
)
from tma.families.bearings2d import contact_plots
from tma.families.bearings2d.log import BearingsLog
from tma.families.bearings2d.track_report import contact_report, write_track_report

ORIGIN = (59.9, 10.7)  # deg
EPOCH_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z
SHIP_T = np.arange(0.0, 1201.0, 10.0)  # s: the ship's bearing times
BUOY_T = np.arange(5.0, 1200.0, 15.0)  # s: the buoy's, 20, 50, .. at the ship's times too
BUOY_XY = np.array([8000.0, -3000.0])  # m
TARGETS = {"T1": ((6000.0, 8000.0), (-3.0, 1.0)),  # seen by both: (x0, y0) m, (vx, vy) m/s
           "T2": ((-4000.0, 9000.0), (4.0, -1.0))}  # by the ship alone
SIGMA_DEG = 0.5
# the targets are declared to hold their course and speed (as a simulation's are): a recording's
# manoeuvre search gives no answer where two platforms' bearings share a time (below)
ACCEL_PSD = 0.0


def ship_xy(t):
    """East at 5 m/s for 600 s from the origin, then north at 5 m/s."""
    t = np.asarray(t, float)
    return np.column_stack([5.0 * np.minimum(t, 600.0), 5.0 * np.maximum(t - 600.0, 0.0)])


def target_xy(label, t):
    (x0, y0), (vx, vy) = TARGETS[label]
    return np.column_stack([x0 + vx * np.asarray(t), y0 + vy * np.asarray(t)])


def two_platform_log(accel_psd_m2_s3=ACCEL_PSD) -> BearingsLog:
    t = np.concatenate([SHIP_T, BUOY_T])
    platform = np.concatenate([np.zeros(SHIP_T.size, np.int64), np.ones(BUOY_T.size, np.int64)])
    order = np.lexsort((platform, t))  # by time, then platform
    t, platform = t[order], platform[order]
    own = np.where(platform[:, None] == 0, ship_xy(t), BUOY_XY)
    rng = np.random.default_rng(11)
    bearings = []
    for label in TARGETS:
        d = target_xy(label, t) - own
        b = np.rad2deg(np.arctan2(d[:, 0], d[:, 1])) + rng.normal(0, SIGMA_DEG, t.size)
        bearings.append(np.where((platform == 1) & (label == "T2"), np.nan, b % 360.0))
    log = BearingsLog(t_s=t, own_x_m=own[:, 0].copy(), own_y_m=own[:, 1].copy(),
                      track_id=np.array([1, 2]), bearing_deg=np.array(bearings),
                      sigma_deg=SIGMA_DEG, epoch_utc_ns=EPOCH_NS, origin_deg=ORIGIN,
                      track_label=np.array(list(TARGETS), dtype=object), platform=platform,
                      platforms=("ship", "buoy"), accel_psd_m2_s3=accel_psd_m2_s3)
    log.validate("two platforms")
    return log


@pytest.fixture(scope="module")
def crossed(tmp_path_factory):
    """The log ingested as a dataset, estimated by lm and aggregated as `pipeline.table`
    does: the table, its estimates, the map MCAP and the run's kept trajectories."""
    tmp_path = tmp_path_factory.mktemp("platforms")
    log = two_platform_log()
    _ingested_dataset(tmp_path / "data", "cross", log)
    report, estimates = _estimate_and_aggregate(tmp_path, "cross")
    paths = list((tmp_path / "data" / "runs" / "cross").glob("lm-*/path.parquet"))
    return (tmp_path / "tables", log, report, estimates,
            pd.read_parquet(paths[0]) if paths else None)


def _decoded(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id].name
                   for c in summary.channels.values()}
        metadata = {c.topic: c.metadata for c in summary.channels.values()}
        messages = {}
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            messages.setdefault(channel.topic, []).append((message, decoded))
    return schemas, metadata, messages


def _enu(lat, lon):
    east, north, _ = pymap3d.geodetic2enu(np.asarray(lat), np.asarray(lon), 0.0, *ORIGIN, 0.0)
    return np.column_stack([east, north])


def _lonlat_enu(coordinates):
    """(k, 2) east/north m of GeoJSON's [lon, lat] points."""
    lon, lat = np.asarray(coordinates).T
    return _enu(lat, lon)


def test_the_report_names_the_platforms_that_saw_each_contact(crossed):
    tables, _, report, _, _ = crossed
    assert list(report.label) == ["T1", "T2"]
    assert list(report.platforms) == ["ship+buoy", "ship"]
    assert list(report.columns).index("platforms") == list(report.columns).index(
        "n_bearings") + 1
    assert list(report.n_bearings) == [SHIP_T.size + BUOY_T.size, SHIP_T.size]
    markdown = (tables / "cross-lm.md").read_text()
    header = next(line for line in markdown.splitlines() if line.startswith("| track"))
    assert "| platforms |" in header
    assert "| ship+buoy |" in markdown and "| ship |" in markdown
    assert "range and bearing now are from `ship`" in markdown
    # the answers hold: the two platforms' lines of sight cross where the contacts are
    assert (report.status == "ok").all(), report.note.tolist()
    t = report.t_now_s.to_numpy()
    for n, label in enumerate(TARGETS):
        err = report.loc[n, ["x_now_m", "y_now_m"]].to_numpy(float) - target_xy(label, t[n])[0]
        sd = report.loc[n, ["x_sd_m", "y_sd_m"]].to_numpy(float)
        assert np.all(np.abs(err) < 4 * sd), (label, err, sd)


def test_the_map_holds_each_platforms_track_and_no_own_ship(crossed):
    tables, log, _, _, _ = crossed
    schemas, metadata, messages = _decoded(tables / "cross-lm.mcap")
    assert "/ownship/location_fix" not in schemas
    assert {schemas[t] for t in ("/platforms/0/location_fix", "/platforms/1/location_fix")} == {
        "foxglove.LocationFix"}
    for k, (name, times, xy) in enumerate([("ship", SHIP_T, ship_xy(SHIP_T)),
                                           ("buoy", BUOY_T, np.tile(BUOY_XY, (BUOY_T.size, 1)))]):
        fixes = messages[f"/platforms/{k}/location_fix"]
        assert metadata[f"/platforms/{k}/location_fix"]["platform"] == name
        assert {f.frame_id for _, f in fixes} == {name}
        stamps = [f.timestamp.seconds * 10**9 + f.timestamp.nanos for _, f in fixes]
        np.testing.assert_array_equal(stamps, EPOCH_NS + np.round(times * 1e9).astype(np.int64))
        np.testing.assert_array_equal(stamps, [m.log_time for m, _ in fixes])
        np.testing.assert_allclose(_enu([f.latitude for _, f in fixes],
                                        [f.longitude for _, f in fixes]), xy, rtol=0, atol=1e-3)
    assert {schemas[f"/tma/estimate/{label}"] for label in TARGETS} == {"foxglove.LocationFix"}
    log_times = [m.log_time for m, _ in sorted((m for ms in messages.values() for m in ms),
                                               key=lambda m: m[0].sequence)]
    assert log_times == sorted(log_times)  # written in time order


def _platform_at(name, t):
    return ship_xy([t])[0] if name == "ship" else BUOY_XY


def _bearing_of(log, label, name, t):
    """The log's bearing of contact ``label`` taken by platform ``name`` at ``t``."""
    k = log.platforms.index(name)
    (epoch,) = np.flatnonzero((log.t_s == t) & (log.platform == k))
    return log.bearing_deg[list(TARGETS).index(label), epoch]


def test_the_maps_lines_of_sight_start_at_the_platform_that_took_the_bearing(crossed):
    tables, log, report, _, _ = crossed
    schemas, _, messages = _decoded(tables / "cross-lm.mcap")
    for label, names in (("T1", {"ship", "buoy"}), ("T2", {"ship"})):
        topic = f"/tma/lines_of_sight/{label}"
        assert schemas[topic] == "foxglove.GeoJSON"
        collections = [(m.log_time, json.loads(g.geojson)) for m, g in messages[topic]]
        assert len(collections) >= 20 * len(names)  # every k-th of about 40 per platform
        latest = {}
        for log_time, collection in collections:
            assert collection["type"] == "FeatureCollection"
            by_platform = {f["properties"]["platform"]: f for f in collection["features"]}
            assert len(by_platform) == len(collection["features"])  # one line per platform
            for name, feature in by_platform.items():
                p = feature["properties"]
                assert p["t_s"] <= (log_time - EPOCH_NS) / 1e9 + 1e-9  # taken by then
                assert p["t_s"] >= latest.get(name, -np.inf)  # each platform's latest
                latest[name] = p["t_s"]
                start, end = _lonlat_enu(feature["geometry"]["coordinates"])
                np.testing.assert_allclose(start, _platform_at(name, p["t_s"]), rtol=0,
                                           atol=1e-3)
                assert p["bearing_deg"] == _bearing_of(log, label, name, p["t_s"])
                along = np.rad2deg(np.arctan2(*(end - start)))
                assert abs((along - p["bearing_deg"] + 180) % 360 - 180) < 0.01
        assert set(latest) == names
        # the last collection: the platforms' last lines cross where their bearings from
        # where they were say (the rays in local metres), and reach past the crossing
        final = {f["properties"]["platform"]: f for f in collections[-1][1]["features"]}
        assert set(final) == names
        if len(final) == 2:
            (a0, a1), (b0, b1) = (_lonlat_enu(final[n]["geometry"]["coordinates"])
                                  for n in ("ship", "buoy"))
            s = np.linalg.solve(np.column_stack([a1 - a0, b0 - b1]), b0 - a0)
            assert 0 < s[0] < 1 and 0 < s[1] < 1
            rays = []
            for name in ("ship", "buoy"):
                p = final[name]["properties"]
                b = np.deg2rad(p["bearing_deg"])
                rays.append((_platform_at(name, p["t_s"]), np.array([np.sin(b), np.cos(b)])))
            (p0, u), (q0, v) = rays
            r = np.linalg.solve(np.column_stack([u, -v]), q0 - p0)
            np.testing.assert_allclose(a0 + s[0] * (a1 - a0), p0 + r[0] * u, rtol=0, atol=1.0)
            # and near the contact (noise 0.5 deg at 6-13 km, the lines 20 deg apart)
            t_now = report.set_index("label").t_now_s[label]
            assert np.hypot(*(p0 + r[0] * u - target_xy(label, t_now)[0])) < 1000.0


def _lines(figure):
    """The plot's drawn lines by label (those with data)."""
    return {ln.get_label(): ln for ln in figure.axes[0].lines if len(ln.get_xdata())}


def _segments(line):
    xy = np.column_stack(line.get_data()) * 1e3  # km -> m
    return xy[0::3], xy[1::3]  # start, end (NaN between)


def test_the_plot_draws_both_platforms_and_their_lines_of_sight(crossed):
    _, log, report, estimates, paths = crossed
    figure = contact_plots.contact_figure(report, estimates, [log], "T1", paths=paths)
    lines = _lines(figure)
    legend = [t.get_text() for t in figure.axes[0].get_legend().get_texts()]
    assert "own-ship" not in lines and "own-ship" not in legend
    ship, buoy = lines["ship"], lines["buoy (fixed)"]
    np.testing.assert_allclose(np.column_stack(ship.get_data()) * 1e3, ship_xy(SHIP_T),
                               rtol=0, atol=1e-9)
    assert ship.get_linestyle() == "-"
    np.testing.assert_allclose(np.column_stack(buoy.get_data()) * 1e3,
                               np.tile(BUOY_XY, (BUOY_T.size, 1)), rtol=0, atol=1e-9)
    assert buoy.get_linestyle() == "None" and buoy.get_marker() == "^"  # a point
    assert ship.get_color() != buoy.get_color()
    sights = {name: next(v for k, v in lines.items() if k.startswith(f"{name}'s bearings"))
              for name in ("ship", "buoy")}
    assert {n: s.get_color() for n, s in sights.items()} == {
        "ship": ship.get_color(), "buoy": buoy.get_color()}
    assert set(legend) >= {"ship", "buoy (fixed)", "estimated track",
                           *(s.get_label() for s in sights.values())}
    for name, times in (("ship", SHIP_T), ("buoy", BUOY_T)):
        start, end = _segments(sights[name])
        assert 20 <= len(start) <= 41
        for a, b in zip(start, end, strict=True):  # each from where its platform was
            # when it took the bearing, along that bearing
            t = times[np.argmin([np.hypot(*(a - _platform_at(name, s))) for s in times])]
            np.testing.assert_allclose(a, _platform_at(name, t), rtol=0, atol=1e-6)
            along = np.rad2deg(np.arctan2(*(b - a)))
            bearings = [_bearing_of(log, "T1", name, s) for s in times
                        if np.hypot(*(a - _platform_at(name, s))) < 1e-6]
            assert min(abs((along - v + 180) % 360 - 180) for v in bearings) < 1e-6
    # T2, which the buoy did not see: the buoy drawn, no line of sight from it
    lines = _lines(contact_plots.contact_figure(report, estimates, [log], "T2", paths=paths))
    assert "buoy (fixed)" in lines and not any(k.startswith("buoy's") for k in lines)
    start, _ = _segments(next(v for k, v in lines.items() if k.startswith("ship's bearings")))
    assert np.isin(start[:, 0], ship_xy(SHIP_T)[:, 0]).all()


def test_one_platform_outputs_name_no_platforms(tmp_path):
    """A log of one own-ship: no platforms column, no platform topics or lines of sight, the
    plot's own-ship and bearings as before (the byte-identical outputs: tests of
    test_bearings2d_map_outputs and `make table`)."""
    from tma.families import build_estimator

    log, _ = _simulated(n=2, labels=["A", "B"])
    estimates = pd.DataFrame({"track_id": log.track_id,
                              **build_estimator({"name": "lm"}).estimate(log).columns})
    report = contact_report(estimates, [log], "one")
    assert "platforms" not in report
    write_track_report(report, tmp_path, "one", "one")
    assert "platforms" not in (tmp_path / "one.md").read_text()
    lines = _lines(contact_plots.contact_figure(report, estimates, [log], "A"))
    assert {"own-ship", "estimated track"} <= set(lines)
    assert not any("'s bearings" in k for k in lines)


def test_a_recording_with_bearings_at_the_same_time_has_an_answer():
    """On a recording (the manoeuvre search runs), bearings of two platforms at one time are
    a step of no time: every track has an estimate (it was NaN, 0 / 0, before)."""
    from tma.families import build_estimator

    out = build_estimator({"name": "lm"}).estimate(two_platform_log(accel_psd_m2_s3=None))
    assert np.isfinite(out["x0_m"]).all()


def test_the_api_draws_a_log_of_several_platforms_whichever_the_reference(tmp_path):
    """``tma.plot_contact`` and ``tma.write_map``'s hooks take the results of a log of several
    platforms, range and bearing now from the buoy (``reference_platform``) while the ship
    took the last bearings; a log whose buoy lay elsewhere is refused."""
    import dataclasses

    from tma.families import build_estimator
    from tma.families.bearings2d.aggregate import plot_contact, write_map

    log = two_platform_log()
    # T1 alone: the buoy took none of T2's (end_bearing warns of an all-NaN median there)
    log = dataclasses.replace(log, track_id=log.track_id[:1], bearing_deg=log.bearing_deg[:1],
                              track_label=log.track_label[:1])
    out = build_estimator({"name": "lm", "reference_platform": "buoy"}).estimate(log)
    estimates = pd.DataFrame({"track_id": log.track_id, **out.columns})
    np.testing.assert_allclose(estimates[["own_x_last_m", "own_y_last_m"]].to_numpy(),
                               [BUOY_XY], rtol=0, atol=1e-9)
    assert log.platform[np.flatnonzero(np.isfinite(log.bearing_deg[0]))[-1]] == 0  # the ship
    report = contact_report(estimates, [log], "api")
    assert "buoy (fixed)" in _lines(plot_contact(report, estimates, [log], "T1"))
    schemas, _, _ = _decoded(write_map(tmp_path / "api.mcap", report, estimates, [log]))
    assert {"/platforms/0/location_fix", "/platforms/1/location_fix"} <= set(schemas)
    moved = dataclasses.replace(log, own_x_m=np.where(log.platform == 1, log.own_x_m + 10.0,
                                                      log.own_x_m))
    with pytest.raises(ValueError, match="not estimated from this recording"):
        plot_contact(report, estimates, [moved], "T1")
