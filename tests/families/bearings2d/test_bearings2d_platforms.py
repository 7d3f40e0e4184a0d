"""Bearings of one contact from several platforms (issue 39): the log format, the readers
(a platform column in a table or a DataFrame, a navigation file per platform, a platform
fixed at one fix), the estimators (each bearing from its own platform, range and bearing now
from the reference platform) and the refusals."""

import numpy as np
import pandas as pd
import pytest

import tma
from tests.families.bearings2d.recorded_geometry import source_options
from tma.errors import ConfigError, InputError
from tma.families import build_estimator
from tma.families.bearings2d.log import BearingsLog, read_bearings_log, write_bearings_log
from tma.families.bearings2d.platforms import observer_now, position_at
from tma.sources.mcap import read_mcap

START = pd.Timestamp("2026-05-01T10:00:00Z")
ORIGIN = (50.7, -1.2)
SHIP = ("ship A", 0.0, (0.0, 0.0, 4.0, 0.0))  # name, time offset (s), x, y (m), vx, vy (m/s)
BUOY = ("buoy 7", 5.0, (9000.0, -4000.0, 0.0, 0.0))
CONTACTS = {"C0": (3000.0, 9000.0, -3.0, 2.0), "C1": (12000.0, 7000.0, 2.0, -4.0)}


def two_platform_export(seed=2, platforms=(SHIP, BUOY), span_s=1800.0) -> pd.DataFrame:
    """A navigation export of bearings taken every 10 s by each platform (the second 5 s
    after the first: asynchronous), each row where its platform was: ``timestamp_utc,
    platform, latitude_deg, longitude_deg, contact, bearing_deg`` (0.5 deg noise); the
    contacts and the ship hold course (the ship alone cannot range them)."""
    from tma.maths.geo import local_to_geodetic

    rng = np.random.default_rng(seed)
    rows = []
    for name, offset, (px, py, vx, vy) in platforms:
        t = np.arange(0.0, span_s, 10.0) + offset
        ox, oy = px + vx * t, py + vy * t
        lat, lon = local_to_geodetic(ox, oy, ORIGIN)
        for label, (x0, y0, cvx, cvy) in CONTACTS.items():
            b = np.rad2deg(np.arctan2(x0 + cvx * t - ox, y0 + cvy * t - oy))
            b = (b + rng.normal(0.0, 0.5, t.size)) % 360.0
            rows += [(START + pd.Timedelta(seconds=float(s)), name, la, lo, label, v)
                     for s, la, lo, v in zip(t, lat, lon, b, strict=True)]
    frame = pd.DataFrame(rows, columns=["timestamp_utc", "platform", "latitude_deg",
                                        "longitude_deg", "contact", "bearing_deg"])
    frame = frame.sort_values("timestamp_utc", kind="stable").reset_index(drop=True)
    frame["timestamp_utc"] = frame["timestamp_utc"].dt.strftime("%Y-%m-%dT%H:%M:%SZ")
    return frame


def write_namespaced(path, lg, spaces, bearing_topic=None):
    """A log of several platforms as another tool may write it: each platform's own-ship
    (``tma.OwnshipNavigation``) on ``<space>/navigation`` and its bearings on
    ``bearing_topic(k)`` (default ``<space>/sonar/bearings``), JSON, with no record saying
    which platforms there are."""
    from tma.families.bearings2d.log import SCHEMAS
    from tma.io.mcap_log import Channel, LogWriter

    bearing_topic = bearing_topic or (lambda k: f"{spaces[k]}/sonar/bearings")
    chans = [Channel(f"{s}/navigation", SCHEMAS["/ownship/navigation"], {}, encoding="json")
             for s in spaces]
    chans += [Channel(bearing_topic(k), SCHEMAS["/sonar/bearings"], {}, encoding="json")
              for k in range(len(spaces))]
    with LogWriter(path, chans, epoch_utc_ns=lg.epoch_utc_ns) as w:
        for e in range(lg.t_s.size):
            k, t = int(lg.platform[e]), float(lg.t_s[e])
            w.write(f"{spaces[k]}/navigation", t, {"t_s": t, "x_m": float(lg.own_x_m[e]),
                                                   "y_m": float(lg.own_y_m[e])})
            has = np.isfinite(lg.bearing_deg[:, e])
            w.write(bearing_topic(k), t, {"t_s": t, "track_id": lg.track_id[has].tolist(),
                                          "bearing_deg": lg.bearing_deg[has, e].tolist()})


def _truth_now(label, t_now, observer=(4.0, 0.0)):
    """True range (m) and bearing (deg) of a contact at ``t_now`` (s) from the ship."""
    x0, y0, vx, vy = CONTACTS[label]
    dx = x0 + vx * t_now - observer[0] * t_now
    dy = y0 + vy * t_now - observer[1] * t_now
    return np.hypot(dx, dy), np.rad2deg(np.arctan2(dx, dy)) % 360.0


def test_a_log_of_several_platforms_round_trips_through_mcap(tmp_path):
    """Platforms at their own times (two at one time allowed), a contact missing at some
    epochs: read back exactly; a log of one platform keeps today's topics."""
    t = np.array([0.0, 0.0, 10.0, 20.0, 20.0, 30.0])
    lg = BearingsLog(t_s=t, own_x_m=np.array([0.0, 5e3, 10.0, 20.0, 5e3, 5e3]),
                     own_y_m=np.zeros(6), track_id=np.array([3, 7]),
                     bearing_deg=np.random.default_rng(0).uniform(0, 360, (2, 6)),
                     sigma_deg=0.5, platform=np.array([0, 1, 0, 0, 1, 1]),
                     platforms=("ship", "buoy"), origin_deg=(50.0, -1.0), epoch_utc_ns=10**18)
    lg.bearing_deg[1, 2] = np.nan
    write_bearings_log(tmp_path / "a.mcap", lg)
    back = read_bearings_log(tmp_path / "a.mcap")
    for name in ("t_s", "own_x_m", "own_y_m", "track_id", "bearing_deg", "platform"):
        np.testing.assert_array_equal(getattr(back, name), getattr(lg, name))
    assert back.platforms == ("ship", "buoy")
    from mcap.reader import make_reader

    with open(tmp_path / "a.mcap", "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert "/platforms/1/location_fix" in topics and "/ownship/navigation" not in topics
    # one epoch per platform and time: the same platform twice at one time is refused
    bad = BearingsLog(**{**lg.__dict__, "platform": np.array([0, 0, 0, 0, 1, 1])})
    with pytest.raises(InputError, match="duplicate time stamps at t = 0.0 s"):
        bad.validate("x")


def test_the_reference_platform_is_placed_between_and_beyond_its_epochs():
    """``position_at`` interpolates a platform's own epochs and extends its end segments; a
    platform of one place stays there (checked against the straight line it was on)."""
    t = np.array([0.0, 5.0, 10.0, 15.0, 20.0])
    platform = np.array([0, 1, 0, 1, 0])
    x = np.where(platform == 0, 3.0 * t, 700.0)
    y = np.where(platform == 0, -2.0 * t, 50.0)
    px, py = position_at(t, x, y, platform, 0, np.array([5.0, 25.0, -5.0]))
    np.testing.assert_allclose(px, 3.0 * np.array([5.0, 25.0, -5.0]))
    np.testing.assert_allclose(py, -2.0 * np.array([5.0, 25.0, -5.0]))
    bx, by = position_at(t, x, y, platform, 1, np.array([0.0, 99.0]))
    np.testing.assert_array_equal(bx, [700.0, 700.0])
    np.testing.assert_array_equal(by, [50.0, 50.0])
    nx, _ = observer_now(t, x, y, None, 0, np.array([4, 1]))  # one own-ship: as it is
    np.testing.assert_array_equal(nx, x[[4, 1]])


def test_a_platform_column_makes_one_track_per_contact_and_ranges_it(tmp_path):
    """The export of a steady ship and a buoy: one dataset log of both platforms, each
    contact one track; lm ranges both (the ship alone cannot) and its answers hold the truth
    within a few stated sd, from the ship (the first platform) at the last bearing."""
    two_platform_export().to_csv(tmp_path / "two.csv", index=False)
    rec = tma.read_log(tmp_path / "two.csv")
    (lg,) = rec.logs
    assert lg.platforms == ("ship A", "buoy 7")
    assert set(rec.bearings["platform"]) == {"ship A", "buoy 7"}
    assert lg.n_tracks == 2 and np.isfinite(lg.bearing_deg).sum() == 4 * 180
    res = tma.estimate(rec).set_index("label")
    t_now = 1795.0
    for label in CONTACTS:
        row = res.loc[label]
        assert row["status"] in ("ok", "position_only")
        true_range, true_bearing = _truth_now(label, t_now)
        assert abs(row["range_now_m"] - true_range) < 4 * row["range_sd_m"]
        assert row["range_sd_m"] < 0.1 * true_range
        off = (row["bearing_now_deg"] - true_bearing + 180) % 360 - 180
        assert abs(off) < 4 * row["bearing_sd_deg"]
    # the same ship alone: no range (it holds course): unobservable, not a fit collapsed onto
    # own-ship (a target riding with it) whose trend test said it manoeuvred
    alone = two_platform_export(platforms=(SHIP,))
    alone.to_csv(tmp_path / "one.csv", index=False)
    assert set(tma.estimate(tma.read_log(tmp_path / "one.csv"))["status"]) == {"unobservable"}


def test_a_navigation_file_per_platform_and_a_buoy_of_one_fix(tmp_path):
    """Bearings with a platform column and no positions, the positions in a navigation file
    with a platform column where the buoy is one row: the same answers as the export that
    gives every row's position."""
    frame = two_platform_export()
    frame.to_csv(tmp_path / "two.csv", index=False)
    frame[["timestamp_utc", "platform", "contact", "bearing_deg"]].to_csv(
        tmp_path / "bearings.csv", index=False)
    fixes = frame[["timestamp_utc", "platform", "latitude_deg", "longitude_deg"]]
    ship = fixes[fixes["platform"] == "ship A"].drop_duplicates("timestamp_utc")
    pd.concat([ship, fixes[fixes["platform"] == "buoy 7"].iloc[:1]]).to_csv(
        tmp_path / "nav.csv", index=False)
    both = tma.estimate(tma.read_log(tmp_path / "two.csv"))
    rec = tma.read_log(tmp_path / "bearings.csv", navigation=tmp_path / "nav.csv")
    assert any("'buoy 7' has one fix: taken as fixed there" in n for n in rec.notes)
    split = tma.estimate(rec)
    for col in ("range_now_m", "range_sd_m", "bearing_now_deg", "course_deg", "status"):
        if split[col].dtype.kind == "f":
            np.testing.assert_allclose(split[col], both[col], rtol=1e-6)
        else:
            assert list(split[col]) == list(both[col])
    # a navigation file naming no platform, for bearings of several: refused in one line
    ship.drop(columns="platform").to_csv(tmp_path / "nav1.csv", index=False)
    with pytest.raises(InputError, match=r"nav1\.csv: .*several platforms.*columns\.platform"):
        tma.read_log(tmp_path / "bearings.csv", navigation=tmp_path / "nav1.csv")
    # a platform whose fixes the navigation file lacks: named
    ship.to_csv(tmp_path / "nav2.csv", index=False)
    with pytest.raises(InputError, match=r"no own-ship fixes of platform\(s\) 'buoy 7'"):
        tma.read_log(tmp_path / "bearings.csv", navigation=tmp_path / "nav2.csv")


def test_frames_take_a_platform_column_and_the_reference_is_named(tmp_path):
    """``Recording.from_frames`` reads the same export; ``reference_platform`` gives range
    and bearing now from the buoy instead (its own geometry, the truth within a few sd); an
    unknown name, or mpekf on a log of two platforms, is one line."""
    frame = two_platform_export()
    frame["timestamp_utc"] = pd.to_datetime(frame["timestamp_utc"], utc=True)
    rec = tma.Recording.from_frames(frame)
    res = tma.estimate(rec, reference_platform="buoy 7").set_index("label")
    buoy = np.array(BUOY[2][:2])
    for label, (x0, y0, vx, vy) in CONTACTS.items():
        t_now = 1795.0
        true_range = np.hypot(x0 + vx * t_now - buoy[0], y0 + vy * t_now - buoy[1])
        row = res.loc[label]
        assert abs(row["range_now_m"] - true_range) < 4 * row["range_sd_m"]
    with pytest.raises(ConfigError, match="reference_platform=tug is no platform of the log; "
                       "its platforms are ship A, buoy 7"):
        tma.estimate(rec, reference_platform="tug")
    with pytest.raises(InputError, match="mpekf: the log's bearings come from 2 platforms"):
        tma.estimate(rec, estimator="mpekf", sigma_deg=0.5)


@pytest.mark.parametrize("name", ["lm", "last_leg", "iv", "nbearings"])
def test_every_estimator_takes_each_bearing_from_its_own_platform(name):
    """On 40 steady targets seen from a steady ship and a buoy (the ship alone could not
    range them), each estimator's answers lie near the truth: the median range error under
    5 % (nbearings, from three bearings, under 25 %); lm's ``ok`` ones within 2 sd on 80 %
    or more."""
    rng = np.random.default_rng(5)
    t1, t2 = np.arange(0.0, 1200.0, 10.0), np.arange(5.0, 1200.0, 10.0)
    t = np.r_[t1, t2]
    p = np.r_[np.zeros(t1.size, np.int64), np.ones(t2.size, np.int64)]
    order = np.lexsort((p, t))
    t, p = t[order], p[order]
    ox, oy = np.where(p == 0, 5.0 * t, 8000.0), np.where(p == 0, 0.0, -3000.0)
    n = 40
    x0, y0 = rng.uniform(-5e3, 15e3, n), rng.uniform(8e3, 15e3, n)
    vx, vy = rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
    b = np.rad2deg(np.arctan2(x0[:, None] + vx[:, None] * t - ox,
                              y0[:, None] + vy[:, None] * t - oy))
    b = (b + rng.normal(0.0, 0.5, b.shape)) % 360.0
    lg = BearingsLog(t_s=t, own_x_m=ox, own_y_m=oy, track_id=np.arange(n), bearing_deg=b,
                     sigma_deg=0.5, platform=p, platforms=("ship", "buoy"),
                     accel_psd_m2_s3=0.0)
    cols = build_estimator({"name": name}).estimate(lg).columns
    true = np.hypot(x0 + vx * t[-1] - 5.0 * t[-1], y0 + vy * t[-1])
    np.testing.assert_allclose(cols["own_x_last_m"], 5.0 * t[-1])
    err = np.abs(cols["range_now_m"] - true) / true
    assert np.median(err) < (0.25 if name == "nbearings" else 0.05)
    if name == "lm":
        ok = cols["status"] == "ok"
        assert ok.mean() > 0.9
        z = (cols["range_now_m"] - true)[ok] / cols["range_sd_m"][ok]
        assert np.mean(np.abs(z) < 2) >= 0.8


def test_mcap_logs_of_several_platforms(tmp_path):
    """tma's own log of several platforms is read back as such (``tma.platforms``: the same
    answers); another tool's log with each platform's topics under its own namespace is read
    with ``ownship.topic`` a pattern, each platform named by its namespace; a value topic
    under no platform's namespace is refused in one line."""
    two_platform_export().to_csv(tmp_path / "two.csv", index=False)
    rec = tma.read_log(tmp_path / "two.csv")
    write_bearings_log(tmp_path / "two.mcap", rec.logs[0])
    back = tma.read_log(tmp_path / "two.mcap")
    assert back.logs[0].platforms == ("ship A", "buoy 7")
    np.testing.assert_allclose(tma.estimate(back)["range_now_m"],
                               tma.estimate(rec)["range_now_m"], rtol=1e-9)

    lg = rec.logs[0]
    spaces = ("/ship_a", "/buoy")

    def write(path, bearing_topic=lambda k: f"{spaces[k]}/sonar/bearings"):
        write_namespaced(path, lg, spaces, bearing_topic)

    write(tmp_path / "ns.mcap")
    other = tma.read_log(tmp_path / "ns.mcap", ownship={"topic": "/*/navigation"},
                         origin={"lat": ORIGIN[0], "lon": ORIGIN[1]})
    assert other.logs[0].platforms == ("/buoy", "/ship_a")  # in topic order
    res = tma.estimate(other, reference_platform="/ship_a")
    np.testing.assert_allclose(res["range_now_m"], tma.estimate(rec)["range_now_m"],
                               rtol=1e-6)
    write(tmp_path / "bad.mcap", lambda k: f"/sonar{k}/bearings")
    with pytest.raises(InputError, match=r"bearings on /sonar0/bearings: no one own-ship "
                       r"topic shares its namespace"):
        tma.read_log(tmp_path / "bad.mcap", ownship={"topic": "/*/navigation"})


def test_one_navigation_file_per_platform(tmp_path):
    """``navigation=[ship_a.nmea, buoy_7.csv]``: each file the platform its stem names (the
    ship's NMEA 0183 fixes, the buoy one CSV row), matched to the bearings' platform column:
    the answers of the export that gives every row's position; bearings that name no
    platform are refused in one line."""
    from tests.families.bearings2d.test_bearings2d_sources_nmea import write_nmea

    frame = two_platform_export()
    frame["platform"] = frame["platform"].map({"ship A": "ship_a", "buoy 7": "buoy_7"})
    frame.to_csv(tmp_path / "two.csv", index=False)
    frame[["timestamp_utc", "platform", "contact", "bearing_deg"]].to_csv(
        tmp_path / "bearings.csv", index=False)
    ship = frame[frame["platform"] == "ship_a"].drop_duplicates("timestamp_utc")
    t_s = (pd.to_datetime(ship["timestamp_utc"]) - START).dt.total_seconds().to_numpy()
    write_nmea(tmp_path / "ship_a.nmea", pd.DataFrame(
        {"t_s": t_s, "lat": ship["latitude_deg"], "lon": ship["longitude_deg"]}),
        start=START.value, garbage=False)
    frame[frame["platform"] == "buoy_7"][["timestamp_utc", "latitude_deg", "longitude_deg"]
                                         ].iloc[:1].to_csv(tmp_path / "buoy_7.csv", index=False)
    files = [tmp_path / "ship_a.nmea", tmp_path / "buoy_7.csv"]
    rec = tma.read_log(tmp_path / "bearings.csv", navigation=files)
    assert rec.logs[0].platforms == ("ship_a", "buoy_7")
    both = tma.estimate(tma.read_log(tmp_path / "two.csv"))
    split = tma.estimate(rec)
    # NMEA positions are written to 1e-4 minute (about 0.2 m): the answers agree to that
    np.testing.assert_allclose(split["range_now_m"], both["range_now_m"], rtol=1e-3)
    assert list(split["status"]) == list(both["status"])
    frame.drop(columns="platform").to_csv(tmp_path / "unnamed.csv", index=False)
    with pytest.raises(InputError, match=r"one own-ship file per platform .* names no "
                       r"platform per row"):
        tma.read_log(tmp_path / "unnamed.csv", navigation=files)


@pytest.mark.parametrize("lat, apart_km", [(50.0, 10.0), (60.0, 80.0)])
def test_shore_stations_far_apart_read_bearings_from_true_north(lat, apart_km):
    """Two stations ``apart_km`` east-west, their bearings true azimuths where they stand
    (pymap3d's geodesic ``geodetic2aer``, 0.5 deg noise), a contact 15 km north of their
    middle: the bearings are turned onto the plane's north at each station (1.2 deg between
    stations 80 km apart at 60 deg N, which read as plane bearings put the answer 8 sd off),
    so range and bearing now from either station hold the geodesic truth within 3 sd."""
    import pymap3d

    rng = np.random.default_rng(3)
    dlon = np.rad2deg(apart_km * 1e3 / (6378137.0 * np.cos(np.deg2rad(lat))))
    stations = {"west": (lat, 0.0), "east": (lat, dlon)}
    t = np.arange(0.0, 1800.01, 6.0)
    east, north = 5.0 * np.sin(np.deg2rad(120.0)) * t, 15e3 + 5.0 * np.cos(np.deg2rad(120.0)) * t
    tlat, tlon, _ = pymap3d.enu2geodetic(east, north, 0 * t, lat, dlon / 2, 0.0)
    rows = []
    for name, (la, lo) in stations.items():
        az, _, _ = pymap3d.geodetic2aer(tlat, tlon, 0 * t, la, lo, 0.0)
        rows += [(START + pd.Timedelta(seconds=float(s)), name, la, lo, "C1", b % 360.0)
                 for s, b in zip(t, az + rng.normal(0.0, 0.5, t.size), strict=True)]
    frame = pd.DataFrame(rows, columns=["timestamp_utc", "platform", "latitude_deg",
                                        "longitude_deg", "contact", "bearing_deg"])
    frame = frame.sort_values(["timestamp_utc", "platform"], kind="stable")
    for name, (la, lo) in stations.items():
        row = tma.estimate(frame, reference_platform=name, sigma_deg=0.5).iloc[0]
        az, _, true_range = pymap3d.geodetic2aer(tlat[-1], tlon[-1], 0.0, la, lo, 0.0)
        assert row["status"] == "ok"
        assert abs(row["range_now_m"] - true_range) < 3 * row["range_sd_m"]
        off = (row["bearing_now_deg"] - az + 180.0) % 360.0 - 180.0
        assert abs(off) < 3 * row["bearing_sd_deg"], (name, off, row["bearing_sd_deg"])


def test_refusals_of_several_platforms_name_the_platform_column(tmp_path):
    """A two-platform export without a platform column whose reports coincide, or its
    navigation without one: the refusal says rows of several platforms and names
    ``columns.platform``; one bad fix of a platform among several: named with its line; a
    track whose estimate is no answer is never ``ok``."""
    frame = two_platform_export(platforms=(SHIP, ("buoy 7", 0.0, BUOY[2])))  # same times
    frame.drop(columns="platform").to_csv(tmp_path / "noplat.csv", index=False)
    with pytest.raises(InputError, match=r"duplicate timestamp_utc .*several platforms.*"
                       r"columns\.platform=<column>"):
        tma.read_log(tmp_path / "noplat.csv")
    frame[["timestamp_utc", "platform", "contact", "bearing_deg"]].to_csv(
        tmp_path / "bearings.csv", index=False)
    frame[["timestamp_utc", "latitude_deg", "longitude_deg"]].drop_duplicates().to_csv(
        tmp_path / "nav.csv", index=False)
    with pytest.raises(InputError, match=r"nav\.csv: two different own-ship positions .*"
                       r"several platforms.*columns\.platform"):
        tma.read_log(tmp_path / "bearings.csv", navigation=tmp_path / "nav.csv")
    bad = frame.copy()
    k = int(np.flatnonzero(bad["platform"] == "ship A")[7])
    bad.loc[k, "latitude_deg"] += 0.3
    bad.to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(InputError, match=rf"platform 'ship A' has two different positions at "
                       rf"the time of line ({k + 1}|{k + 2}) "):
        tma.read_log(tmp_path / "bad.csv")


def test_named_platforms_are_matched_by_name_and_named_once(tmp_path):
    """Where the input and the navigation both name platforms they are matched by name, even
    one each (a buoy's file never gives a ship its fixes); a platform named by two files is
    refused naming both; navigation=[] names no file; a platform named NA is a name."""
    frame = two_platform_export()
    ship = frame[frame["platform"] == frame["platform"].iloc[0]]
    ship[["timestamp_utc", "platform", "contact", "bearing_deg"]].to_csv(
        tmp_path / "bearings.csv", index=False)
    fixes = ship[["timestamp_utc", "latitude_deg", "longitude_deg"]].drop_duplicates()
    fixes.to_csv(tmp_path / "buoy_7.csv", index=False)
    with pytest.raises(InputError, match=r"no own-ship fixes of platform\(s\) .* \(its "
                       r"platforms: 'buoy_7'\): name each platform's file after it"):
        tma.read_log(tmp_path / "bearings.csv", navigation=[tmp_path / "buoy_7.csv"])
    name = ship["platform"].iloc[0]
    fixes.assign(platform=name).to_csv(tmp_path / "b.csv", index=False)
    fixes.to_csv(tmp_path / f"{name}.csv", index=False)
    with pytest.raises(InputError, match=rf"platform '{name}' is named by two navigation "
                       r"sources"):
        tma.read_log(tmp_path / "bearings.csv",
                     navigation=[tmp_path / f"{name}.csv", tmp_path / "b.csv"])
    with pytest.raises(ValueError, match=r"navigation=\[\] names no file"):
        tma.read_log(tmp_path / "bearings.csv", navigation=[])
    na = frame.assign(platform=np.where(frame["platform"] == name, "NA", "buoy"))
    na.to_csv(tmp_path / "na.csv", index=False)
    rec = tma.read_log(tmp_path / "na.csv")
    assert set(rec.bearings["platform"]) == {"NA", "buoy"}
    assert len(rec.bearings) == len(frame)


@pytest.mark.parametrize("topic", [["/ship_a/navigation", "/buoy/navigation"],
                                   "/*/navigation"])
def test_several_own_ship_topics_and_a_navigation_file_are_refused_in_one_line(tmp_path,
                                                                                topic):
    """``ownship.topic`` naming several platforms' topics (a list or a pattern) and a
    navigation file: two sources of own-ship, refused naming both (was a TypeError or a
    misleading "no such topic")."""
    two_platform_export().to_csv(tmp_path / "two.csv", index=False)
    rec = tma.read_log(tmp_path / "two.csv")
    write_namespaced(tmp_path / "ns.mcap", rec.logs[0], ("/ship_a", "/buoy"))
    pd.DataFrame({"time_s": [0.0, 1.0], "own_x_m": [0.0, 1.0], "own_y_m": 0.0}).to_csv(
        tmp_path / "nav.csv", index=False)
    with pytest.raises(InputError, match=r"ownship\.topic=.* names the own-ship topics of "
                       r"several platforms, but own-ship comes from navigation=: drop one"):
        tma.read_log(tmp_path / "ns.mcap", navigation=tmp_path / "nav.csv",
                     ownship={"topic": topic})
    # the reader of one recording (read_mcap): refused in one line too (was a TypeError)
    with pytest.raises(InputError, match=r"ownship\.topic=.* names the own-ship topics of "
                       r"several platforms, where one recording is read: .*tma\.read_log"):
        read_mcap(tmp_path / "ns.mcap", source_options({"ownship": {"topic": topic}}))
