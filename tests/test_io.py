"""MCAP and Parquet round trips, atomic writes and MCAP error handling; absolute (UTC) log
times in every family; the geographic reference and Foxglove's own-ship fixes."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pymap3d
import pytest
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_protobuf.decoder import DecoderFactory

from tests.conftest import plain_messages
from tma.errors import ConfigError, InputError
from tma.families import NAMES, load_scenario
from tma.families.bearings2d.log import (
    CHANNELS,
    GEO,
    TRACKS,
    read_bearings_log,
    write_bearings_log,
)
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.io.atomic import atomic_path, write_parquet_atomic
from tma.io.mcap_log import LogWriter
from tma.io.mcap_values import json_record
from tma.utc import format_utc, parse_utc

EPOCH = "2026-01-01T00:00:00Z"
EPOCH_NS = 1_767_225_600 * 10**9  # the same instant, counted by hand
ORIGIN = (59.9, 10.7)  # deg: Oslofjord


def _small_log():
    log, truth = simulate_shard(Config(n_tracks=7, shard_size=7, sigma_deg=0.3), 0)
    return log, truth


def test_mcap_round_trip_is_exact(tmp_path):
    log, _ = _small_log()
    log.bearing_deg[2, 5:9] = np.nan  # gaps: a contact missing at some epochs
    path = tmp_path / "log.mcap"
    n = write_bearings_log(path, log, {"tma.dataset": {"family": "bearings2d"}})
    assert n == 2 * log.t_s.size
    back = read_bearings_log(path)
    np.testing.assert_array_equal(back.t_s, log.t_s)
    np.testing.assert_array_equal(back.own_x_m, log.own_x_m)
    np.testing.assert_array_equal(back.track_id, log.track_id)
    np.testing.assert_array_equal(back.bearing_deg, log.bearing_deg)  # NaN in the same places


def test_mcap_is_a_genuine_log_for_plain_readers(tmp_path):
    log, _ = _small_log()
    path = tmp_path / "log.mcap"
    write_bearings_log(path, log)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {"/ownship/navigation", "/sonar/bearings"}
        schema = summary.schemas[topics["/sonar/bearings"].schema_id]
        assert schema.encoding == "protobuf" and schema.name == "tma.BearingBatch"
        assert topics["/sonar/bearings"].message_encoding == "protobuf"
        assert "clockwise from north" in topics["/sonar/bearings"].metadata["convention"]
        assert summary.chunk_indexes[0].compression == "lz4"
    msgs = plain_messages(path, ["/sonar/bearings"])  # mcap-protobuf-support, not tma
    assert len(msgs) == log.t_s.size
    first = msgs[0][2]
    assert first["track_id"] == log.track_id.tolist()
    assert first["bearing_deg"] == log.bearing_deg[:, 0].tolist()  # float64, exactly
    assert msgs[3][1].log_time == EPOCH_NS + int(log.t_s[3] * 1e9)  # UTC: epoch_utc + t_s
    assert msgs[3][1].publish_time == msgs[3][1].log_time
    assert msgs[3][2]["t_s"] == log.t_s[3]  # payloads keep relative seconds


def test_a_json_log_is_read_as_the_protobuf_one(tmp_path):
    log, _ = _small_log()
    log.bearing_deg[1, 3:7] = np.nan
    write_bearings_log(tmp_path / "p.mcap", log)
    write_bearings_log(tmp_path / "j.mcap", log, encoding="json")
    with open(tmp_path / "j.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    schema = next(s for s in summary.schemas.values() if s.name == "tma.BearingBatch")
    assert schema.encoding == "jsonschema"
    assert "clockwise from north" in json.loads(schema.data)["description"]
    p, j = read_bearings_log(tmp_path / "p.mcap"), read_bearings_log(tmp_path / "j.mcap")
    for key in ("t_s", "own_x_m", "own_y_m", "track_id", "bearing_deg"):
        np.testing.assert_array_equal(getattr(p, key), getattr(j, key))
    assert ([m[2] for m in plain_messages(tmp_path / "p.mcap")]
            == [m[2] for m in plain_messages(tmp_path / "j.mcap")])


def test_mcap_bytes_are_reproducible(tmp_path):
    log, _ = _small_log()
    write_bearings_log(tmp_path / "a.mcap", log)
    write_bearings_log(tmp_path / "b.mcap", log)
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_parquet_round_trip(tmp_path):
    _, truth = _small_log()
    write_parquet_atomic(tmp_path / "truth.parquet", truth)
    assert pq.read_table(tmp_path / "truth.parquet").equals(truth)


def test_verified_bytes_are_read_as_the_file_is(tmp_path):
    """A dataset file whose sha256 was checked is parsed from the bytes checked (no second
    read) and without its own CRCs, which that sha256 already covers; the log is the same."""
    from tma.io.atomic import VerifiedPath, sha256_file
    from tma.io.dataset import Dataset, write_manifest
    from tma.io.mcap_read import check_integrity

    log, _ = _small_log()
    shard = tmp_path / "log" / "shard-00000.mcap"
    shard.parent.mkdir()
    write_bearings_log(shard, log)
    write_manifest(tmp_path, family="bearings2d", source="simulate", config={},
                   shards={"log/shard-00000.mcap": {"sha256": sha256_file(shard),
                                                    "bytes": shard.stat().st_size}}, files={})
    verified = Dataset.open(tmp_path).verified_path("log/shard-00000.mcap")
    assert isinstance(verified, VerifiedPath) and verified.data == shard.read_bytes()
    ours, plain = read_bearings_log(verified), read_bearings_log(shard)
    for f in dataclasses.fields(ours):
        a, b = getattr(ours, f.name), getattr(plain, f.name)
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, f.name
    derived = verified.parent / verified.name  # no bytes of its own: read as any path
    assert derived.data is None and read_bearings_log(derived).track_id.size == log.n_tracks
    damaged = bytearray(verified.data)
    damaged[20] ^= 0xFF  # inside the data section: its CRC no longer holds
    assert "CRC" in check_integrity(bytes(damaged))
    assert check_integrity(bytes(damaged), crcs=False) is None  # what the sha256 refuses


def test_truncated_and_non_mcap_files_are_rejected(tmp_path):
    log, _ = _small_log()
    path = tmp_path / "log.mcap"
    write_bearings_log(path, log)
    data = path.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="cut.mcap"):
        read_bearings_log(tmp_path / "cut.mcap")
    (tmp_path / "text.mcap").write_text("time_s,bearing_deg\n0,1\n")
    with pytest.raises(InputError, match="not a valid MCAP"):
        read_bearings_log(tmp_path / "text.mcap")
    with pytest.raises(InputError, match="no such file"):
        read_bearings_log(tmp_path / "absent.mcap")


def test_mcap_without_expected_topics(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/imu", "json", sid)
        w.add_message(cid, 0, b"{}", 0)
        w.finish()
    with pytest.raises(InputError, match=r"missing topic\(s\) /ownship/navigation, "
                                         r"/sonar/bearings; the log has: /imu"):
        read_bearings_log(path)


def test_ownship_is_interpolated_to_bearing_epochs(tmp_path):
    # Navigation at 1 Hz, bearings every 4 s offset by 0.5 s, as another tool might log them.
    path = tmp_path / "nav.mcap"
    with LogWriter(path, CHANNELS) as w:
        for t in np.arange(0.0, 41.0):
            w.write("/ownship/navigation", t, {"t_s": t, "x_m": 3.0 * t, "y_m": -2.0 * t})
        for t in np.arange(0.5, 40.0, 4.0):
            w.write("/sonar/bearings", t, {"t_s": t, "track_id": [4, 9],
                                            "bearing_deg": [10.0, 350.0]})
    back = read_bearings_log(path)
    np.testing.assert_allclose(back.t_s, np.arange(0.5, 40.0, 4.0))
    np.testing.assert_allclose(back.own_x_m, 3.0 * back.t_s, rtol=1e-14)
    np.testing.assert_allclose(back.own_y_m, -2.0 * back.t_s, rtol=1e-14)
    np.testing.assert_array_equal(back.track_id, [4, 9])


def test_atomic_path_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.bin"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("killed")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


# -- absolute time ------------------------------------------------------------------------------

@pytest.mark.parametrize("text", [EPOCH, "2026-01-01T02:00:00+02:00", "2026-06-30 23:59:59.5Z",
                                  "1970-01-01T00:00:00Z", "2031-03-04T05:06:07.123456789-01:30"])
def test_utc_times_are_exact_to_the_nanosecond(text):
    ns = parse_utc(text)
    assert ns == pd.Timestamp(text).value  # pandas: an independent ISO-8601 parser
    assert parse_utc(format_utc(ns)) == ns
    assert format_utc(ns).endswith("Z")


@pytest.mark.parametrize("bad", ["2026-01-01T00:00:00", "2026-01-01", "yesterday", "",
                                 "2026-02-30T00:00:00Z", "1969-12-31T23:59:59Z",
                                 "2300-01-01T00:00:00Z"])
@pytest.mark.parametrize("family", NAMES)
def test_a_bad_epoch_is_one_line_naming_the_key(family, bad):
    with pytest.raises(ConfigError, match=rf"scenario '{family}': epoch_utc: '{bad}' "):
        load_scenario({"family": family, "epoch_utc": bad})


def _first_message(path):
    _, message, fields = plain_messages(path)[0]
    with open(path, "rb") as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    return message, fields, records


@pytest.mark.parametrize("family", NAMES)
def test_every_family_logs_utc_times_from_its_epoch(family, tmp_path):
    small = {"bearing_doppler3d": {"duration_s": 3.0}, "ranges2d": {}, "radar2d": {},
             "bearings2d": {}}[family]
    module, cfg = load_scenario({"family": family, "n_tracks": 2, "shard_size": 2,
                                 "epoch_utc": "2026-05-17T12:00:00.25+02:00", **small})
    log, _ = module.simulate_shard(cfg, 0)
    module.write_log(tmp_path / "log.mcap", log)
    epoch = 1_779_012_000 * 10**9 + 250_000_000  # 10:00:00.25 UTC, counted by hand
    message, fields, records = _first_message(tmp_path / "log.mcap")
    t0 = fields["t_s"]
    assert message.log_time == message.publish_time == epoch + round(t0 * 1e9)
    assert json.loads(records["tma.time"]["epoch_utc_ns"]) == epoch
    back = module.read_log(tmp_path / "log.mcap")
    assert back.epoch_utc_ns == epoch
    np.testing.assert_array_equal(back.t_s, log.t_s)  # t from t_s, not from log times


def test_without_an_epoch_log_times_stay_relative(tmp_path):
    log, _ = _small_log()
    write_bearings_log(tmp_path / "rel.mcap", dataclasses.replace(log, epoch_utc_ns=None))
    message, _, records = _first_message(tmp_path / "rel.mcap")
    assert message.log_time == 0 and "tma.time" not in records
    assert read_bearings_log(tmp_path / "rel.mcap").epoch_utc_ns is None


def test_a_log_time_beyond_mcap_range_is_one_clear_error(tmp_path):
    log, _ = _small_log()
    log.t_s = log.t_s - 2e9  # 63 years before a 2026 epoch: before 1970
    with pytest.raises(InputError, match="outside MCAP's log time range"):
        write_bearings_log(tmp_path / "neg.mcap", log)
    assert list(tmp_path.iterdir()) == []


# -- geographic reference -------------------------------------------------------------------

def _geo_log():
    cfg = load_scenario({"family": "bearings2d", "n_tracks": 3, "shard_size": 3,
                         "origin": {"lat": ORIGIN[0], "lon": ORIGIN[1]}})[1]
    log, _ = simulate_shard(cfg, 0)
    log.track_label = np.array(["T1", "bravo 2", "ü"], dtype=object)
    return log


def _fixes(path, topic):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        schema = next(s for s in reader.get_summary().schemas.values()
                      if s.name == "foxglove.LocationFix")
        fixes = [(m, d) for _, _, m, d in reader.iter_decoded_messages(topics=[topic])]
    return schema, fixes


def test_ownship_location_fix_in_foxglove_schema(tmp_path):
    log = _geo_log()
    path = tmp_path / "geo.mcap"
    n = write_bearings_log(path, log)
    assert n == 3 * log.t_s.size
    schema, fixes = _fixes(path, "/ownship/location_fix")
    assert schema.encoding == "protobuf"
    assert len(fixes) == log.t_s.size
    lat = np.array([d.latitude for _, d in fixes])
    lon = np.array([d.longitude for _, d in fixes])
    # own-ship stays within 6 km of the origin: the tangent-plane point (up = 0) and the
    # sea-level point differ by < 3 mm there
    ref_lat, ref_lon, _ = pymap3d.enu2geodetic(log.own_x_m, log.own_y_m, 0.0, *ORIGIN, 0.0)
    np.testing.assert_allclose(lat, ref_lat, rtol=0, atol=1e-7)
    np.testing.assert_allclose(lon, ref_lon, rtol=0, atol=1e-7)
    east, north, _ = pymap3d.geodetic2enu(lat, lon, 0.0, *ORIGIN, 0.0)  # exact inverse
    np.testing.assert_allclose(east, log.own_x_m, rtol=0, atol=1e-3)
    np.testing.assert_allclose(north, log.own_y_m, rtol=0, atol=1e-3)
    for k, (message, fix) in enumerate(fixes):
        assert type(fix).DESCRIPTOR.full_name == LocationFix.DESCRIPTOR.full_name
        stamp = fix.timestamp.seconds * 10**9 + fix.timestamp.nanos
        assert stamp == message.log_time == EPOCH_NS + round(log.t_s[k] * 1e9)
        assert fix.frame_id == "ownship" and fix.position_covariance_type == 0
        assert fix.altitude == 0.0


def test_geo_references_round_trip_and_the_extra_channel_is_ignored(tmp_path):
    log = _geo_log()
    write_bearings_log(tmp_path / "geo.mcap", log)
    back = read_bearings_log(tmp_path / "geo.mcap")
    assert back.origin_deg == ORIGIN and back.epoch_utc_ns == EPOCH_NS
    assert list(back.track_label) == ["T1", "bravo 2", "ü"]
    np.testing.assert_array_equal(back.bearing_deg, log.bearing_deg)
    np.testing.assert_array_equal(back.own_x_m, log.own_x_m)
    _, _, records = _first_message(tmp_path / "geo.mcap")
    assert {k: json.loads(v) for k, v in records[GEO].items()} == {
        "origin_lat_deg": ORIGIN[0], "origin_lon_deg": ORIGIN[1], "epoch_utc_ns": EPOCH_NS}
    write_bearings_log(tmp_path / "again.mcap", log)
    assert (tmp_path / "again.mcap").read_bytes() == (tmp_path / "geo.mcap").read_bytes()


def test_an_ownship_beyond_the_local_plane_is_refused(tmp_path):
    log = _geo_log()
    log.own_x_m = log.own_x_m + 2.5e6  # 2500 km east of the origin
    with pytest.raises(InputError, match="own-ship goes farther than 2000 km from the origin"):
        write_bearings_log(tmp_path / "far.mcap", log)
    assert list(tmp_path.iterdir()) == []


def test_a_scenario_origin_is_validated():
    with pytest.raises(ConfigError, match="origin.lat and origin.lon must be given together"):
        load_scenario({"family": "bearings2d", "origin": {"lat": 59.9}})
    with pytest.raises(ConfigError, match=r"origin.lat must be in \(-90, 90\), got 95"):
        load_scenario({"family": "bearings2d", "origin": {"lat": 95.0, "lon": 10.0}})
    assert load_scenario({"family": "bearings2d"})[1].origin.lat is None  # none by default


@pytest.mark.parametrize("record, message", [
    ({TRACKS: {"track_id": [0, 1], "label": ["a", "b"]}}, r"no label for track\(s\) 2"),
    ({TRACKS: {"track_id": [0, 1, 2], "label": ["a", "b", 3]}}, "one text label per track"),
    ({TRACKS: {"track_id": [0, 1, 2], "label": ["a", "a", "b"]}}, "share one label"),
    ({GEO: {"origin_lat_deg": "59.9", "origin_lon_deg": 10.7}}, "tma.geo does not follow"),
    ({GEO: {"origin_lat_deg": 91.0, "origin_lon_deg": 10.7}}, "is not a latitude"),
    ({"tma.time": {"epoch_utc_ns": 1.5}}, "tma.time does not follow"),
])
def test_bad_reference_records_are_one_clear_error(tmp_path, record, message):
    log, _ = simulate_shard(Config(n_tracks=3, shard_size=3), 0)
    path = tmp_path / "bad.mcap"
    with LogWriter(path, CHANNELS, {k: json_record(v) for k, v in record.items()}) as w:
        for k, t in enumerate(log.t_s.tolist()):
            w.write("/ownship/navigation", t, {"t_s": t, "x_m": 0.0, "y_m": 0.0})
            w.write("/sonar/bearings", t, {"t_s": t, "track_id": log.track_id,
                                            "bearing_deg": log.bearing_deg[:, k]})
    with pytest.raises(InputError, match=message):
        read_bearings_log(path)
