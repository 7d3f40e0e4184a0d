"""tma's own MCAP schema (``tma.OwnshipNavigation``, ``tma.BearingBatch``) through ``read_mcap``:
array and scalar fields, navigation starting after the first bearing, the metadata records
(``tma.time``, ``tma.geo``, ``tma.tracks``, ``tma.sensor``), and our topic names holding
Foxglove's schema."""

import time

import numpy as np
import pymap3d
import pytest
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix

from tests.families.bearings2d.recorded_geometry import (
    EPOCH_NS,
    ORIGIN,
    check_against_truth,
    estimate,
    ingest,
    recorded,
    source_options,
)
from tma.errors import ConfigError, InputError
from tma.families.bearings2d.log import (
    BEARINGS_TOPIC,
    CHANNELS,
    OWNSHIP_TOPIC,
    SENSOR,
    BearingsLog,
    channels,
    nominal_sigma,
    write_bearings_log,
)
from tma.io.dataset import Dataset
from tma.io.mcap_log import Channel, LogWriter
from tma.io.mcap_values import json_record
from tma.sources.mcap import read_mcap

NO_OPTIONS = source_options({})


def grid_log(rec, **kwargs) -> BearingsLog:
    """The recording as a BearingsLog (own-ship at the bearing epochs, one row per contact)."""
    b = rec.bearings
    t = np.unique(b.t_s)
    labels = np.unique(b.track)
    grid = np.full((labels.size, t.size), np.nan)
    grid[np.searchsorted(labels, b.track), np.searchsorted(t, b.t_s)] = b.bearing_deg
    own = b.drop_duplicates("t_s").set_index("t_s").loc[t]
    return BearingsLog(t_s=t, own_x_m=own.east_m.to_numpy(), own_y_m=own.north_m.to_numpy(),
                       track_id=np.arange(labels.size), bearing_deg=grid, **kwargs)


def write_scalar_log(path, rec, nav_from_s=0.0, epoch_ns=EPOCH_NS, channels=CHANNELS,
                     fix=None, extra=()):
    """One own-ship message per fix from ``nav_from_s`` on and one message per bearing with
    scalar ``track_id`` / ``bearing_deg`` (text labels as ids 1, 2, ...)."""
    nav = rec.navigation[rec.navigation.t_s >= nav_from_s]
    ids = {label: k + 1 for k, label in enumerate(sorted(set(rec.bearings.track)))}
    with LogWriter(path, channels, {SENSOR: json_record({"sigma_deg": 0.5})},
                   epoch_utc_ns=epoch_ns) as w:
        for row in nav.itertuples():
            message = ({"t_s": row.t_s, "x_m": row.east_m, "y_m": row.north_m} if fix is None
                       else fix(row))
            w.write(OWNSHIP_TOPIC, row.t_s, message)
        for row in rec.bearings.itertuples():
            w.write(BEARINGS_TOPIC, row.t_s, {"t_s": row.t_s, "track_id": ids[row.track],
                                              "bearing_deg": row.bearing_deg})
        for t_s, message in extra:
            w.write(BEARINGS_TOPIC, t_s, message)
    return path


def test_arrays_with_epoch_origin_labels_and_sigma(tmp_path):
    rec = recorded(("T1", "T2"))
    log = grid_log(rec, sigma_deg=0.5, epoch_utc_ns=EPOCH_NS, origin_deg=ORIGIN,
                   track_label=np.array(["T1", "T2"], dtype=object))
    path = tmp_path / "dataset.mcap"
    write_bearings_log(path, log)  # with an origin: also /ownship/location_fix (LocationFix)
    got = read_mcap(path, NO_OPTIONS)
    nav, obs = got.navigation, got.contacts
    assert nominal_sigma(got.metadata, "test") == 0.5
    assert nav.epoch_utc_ns == obs.epoch_utc_ns == EPOCH_NS + 500_000_000  # t = 0.5 s
    np.testing.assert_allclose(nav.t_s, log.t_s - 0.5, rtol=0, atol=1e-9)
    # lat/lon at the log's origin: back through pymap3d's forward map to the metres written
    east, north, _ = pymap3d.geodetic2enu(nav.lat_deg, nav.lon_deg, 0.0, *ORIGIN, 0.0)
    np.testing.assert_allclose(east, log.own_x_m, rtol=0, atol=1e-6)
    np.testing.assert_allclose(north, log.own_y_m, rtol=0, atol=1e-6)
    assert any("(not used: /ownship/location_fix (foxglove.LocationFix" in n for n in got.notes)
    expected = rec.bearings.sort_values(["t_s", "track"], kind="stable")
    np.testing.assert_allclose(obs.t_s, expected.t_s - 0.5, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(obs.track, expected.track)  # labels from tma.tracks
    np.testing.assert_array_equal(obs.values, expected.bearing_deg)
    assert not obs.units_stated  # bearing_deg: degrees assumed, the radians guard applies


def test_scalar_messages_with_gps_starting_after_the_first_bearing(tmp_path):
    rec = recorded()
    path = write_scalar_log(tmp_path / "late_gps.mcap", rec, nav_from_s=1.0)  # bearings: 0.5 s
    got = read_mcap(path, NO_OPTIONS)
    assert got.navigation.epoch_utc_ns == EPOCH_NS + 500_000_000  # the first bearing
    assert got.contacts.t_s[0] == 0.0 and got.navigation.t_s[0] == 0.5  # raw, not refused
    np.testing.assert_allclose(got.navigation.x_m, rec.navigation.east_m[1:])
    np.testing.assert_allclose(got.contacts.t_s, rec.bearings.t_s - 0.5, rtol=0, atol=1e-9)
    assert nominal_sigma(got.metadata, "test") == 0.5
    np.testing.assert_array_equal(got.contacts.values, rec.bearings.bearing_deg)
    assert set(got.contacts.track) == {1}
    root = ingest(path, data_dir=tmp_path / "data", name="late_gps")
    manifest = Dataset.open(root).manifest
    assert manifest["dropped_bearings"]["count"] == 0  # 0.5 s before the fixes: extrapolated
    check_against_truth(estimate(root), (manifest["epoch_utc_ns"] - EPOCH_NS) / 1e9,
                        labels={"1": "T1"})


def test_json_and_protobuf_logs_read_the_same(tmp_path):
    """A hand-written log in tma's JSON schema (one bearing per message, as a user's script
    writes it) and the same log as protobuf: the same raw fixes and bearings."""
    rec = recorded(("T1", "T2"))
    got = [read_mcap(write_scalar_log(tmp_path / f"{encoding}.mcap", rec,
                                      channels=channels(encoding)), NO_OPTIONS)
           for encoding in ("json", "protobuf")]
    for part, keys in [("navigation", ("t_s", "x_m", "y_m", "epoch_utc_ns")),
                       ("contacts", ("t_s", "track", "values", "epoch_utc_ns"))]:
        for key in keys:
            np.testing.assert_array_equal(getattr(getattr(got[0], part), key),
                                          getattr(getattr(got[1], part), key))
    assert got[0].contacts.values.size == len(rec.bearings)


def test_relative_times_of_older_logs(tmp_path):
    rec = recorded()
    log = grid_log(rec)
    path = tmp_path / "relative.mcap"
    write_bearings_log(path, log)  # no epoch, no origin: log_time = t_s
    got = read_mcap(path, NO_OPTIONS)
    assert got.navigation.epoch_utc_ns is None and got.contacts.epoch_utc_ns is None
    np.testing.assert_allclose(got.navigation.t_s, log.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(got.navigation.x_m, log.own_x_m)
    np.testing.assert_allclose(got.contacts.t_s, log.t_s, rtol=0, atol=1e-9)
    assert nominal_sigma(got.metadata, "test") is None and set(got.contacts.track) == {0}
    rad = read_mcap(path, source_options({"bearing": {"units": "rad"}}))
    np.testing.assert_allclose(rad.contacts.values, np.rad2deg(log.bearing_deg[0]))
    with pytest.raises(ConfigError, match="bearing.field=data: /sonar/bearings has tma's schema "
                                          "tma.BearingBatch, whose bearings are 'bearing_deg'"):
        read_mcap(path, source_options({"bearing": {"field": "data"}}))


def test_duplicate_time_of_one_contact_is_refused(tmp_path):
    rec = recorded()
    again = (42.5, {"t_s": 42.5, "track_id": 1, "bearing_deg": 10.0})  # a bearing's time
    path = write_scalar_log(tmp_path / "twice.mcap", rec, extra=[again])
    with pytest.raises(InputError, match="/sonar/bearings: two bearings of contact 1 at "
                                         "2025-06-01T08:00:42.5Z"):
        read_mcap(path, NO_OPTIONS)
    other = (42.5, {"t_s": 42.5, "track_id": 2, "bearing_deg": 10.0})  # another contact: fine
    got = read_mcap(write_scalar_log(tmp_path / "other.mcap", rec, extra=[other]), NO_OPTIONS)
    assert sorted(set(got.contacts.track)) == [1, 2]


def test_location_fix_on_our_ownship_topic_is_read_by_its_schema(tmp_path):
    rec = recorded()
    channels = [Channel.protobuf(OWNSHIP_TOPIC, LocationFix), CHANNELS[1]]

    def fix(row):
        message = LocationFix(latitude=row.lat, longitude=row.lon)
        message.timestamp.FromNanoseconds(EPOCH_NS + round(row.t_s * 1e9))
        return message

    path = write_scalar_log(tmp_path / "mixed.mcap", rec, channels=channels, fix=fix)
    got = read_mcap(path, NO_OPTIONS)
    n = len(rec.navigation)
    assert f"own-ship: /ownship/navigation (foxglove.LocationFix, {n}) found by its schema" in (
        got.notes)
    np.testing.assert_array_equal(got.navigation.lat_deg, rec.navigation.lat)
    np.testing.assert_allclose(got.navigation.t_s, rec.navigation.t_s, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.contacts.t_s, rec.bearings.t_s, rtol=0, atol=1e-9)


def test_times_that_are_not_seconds_are_refused(tmp_path):
    rec = recorded()
    rec.bearings.loc[3, "t_s"] = 1e10  # 317 years: nanoseconds of it overflow int64
    with pytest.raises(InputError, match="/sonar/bearings has log times beyond the year 2262 "):
        read_mcap(write_scalar_log(tmp_path / "far.mcap", rec, epoch_ns=None), NO_OPTIONS)
    far = (3.0, {"t_s": 1e10, "track_id": 1, "bearing_deg": 1.0})  # t_s alone: not seconds
    with pytest.raises(InputError, match="t_s 10000000000.0 on /sonar/bearings is not a time "
                                         "in seconds within"):
        read_mcap(write_scalar_log(tmp_path / "t_s.mcap", recorded(), extra=[far]), NO_OPTIONS)


def test_damaged_own_log_is_one_line(tmp_path):
    path = write_scalar_log(tmp_path / "log.mcap", recorded())
    data = path.read_bytes()
    path.write_bytes(data[:200] + bytes([data[200] ^ 1]) + data[201:])
    with pytest.raises(InputError, match=f"^{path}: not a valid MCAP log \\(data section fails "
                                         "its CRC check"):
        read_mcap(path, NO_OPTIONS)


def test_scalar_decoding_speed(tmp_path):
    """Not a limit: prints the cost per 10,000 one-bearing messages of tma's schema."""
    rec = recorded()
    n = 10_000
    t = np.arange(n) * 0.5
    many = rec.bearings.iloc[[0] * n].assign(t_s=t, bearing_deg=np.linspace(0, 359, n))
    path = write_scalar_log(tmp_path / "speed.mcap",
                            type(rec)(bearings=many, navigation=rec.navigation))
    start = time.perf_counter()
    got = read_mcap(path, NO_OPTIONS)
    seconds = time.perf_counter() - start
    assert got.contacts.t_s.size == n
    print(f"\ntma schema, scalar fields: {seconds * 1e3:.0f} ms per 10k bearing messages "
          f"(+ {len(rec.navigation)} fixes)")
