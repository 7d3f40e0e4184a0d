"""tma's MCAP writer against the reference, ``mcap.writer.Writer`` fed message by message with
the same options (tma's former LogWriter): the files must be byte-identical, every CRC, index,
statistic and summary offset included, with zstd and lz4 chunks, JSON and protobuf messages
(each message as orjson or protobuf's own serializer writes it). And log times against
``epoch + round(t * 1e9)``."""

import io

import numpy as np
import orjson
import pytest
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import register_schema as register_protobuf_schema

from tests.conftest import proto_message_class
from tma import __version__
from tma.errors import InputError
from tma.families.bearings2d.log import (
    BEARINGS_TOPIC,
    CHANNELS,
    COMPRESSION,
    OWNSHIP_FIX_CHANNEL,
    OWNSHIP_FIX_TOPIC,
    OWNSHIP_FRAME,
    OWNSHIP_TOPIC,
    BearingsLog,
    _ownship_fixes,
    channels,
    read_bearings_log,
    write_bearings_log,
)
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.io.mcap_log import LogWriter, schema_bytes
from tma.io.mcap_read import check_integrity, read_log
from tma.io.mcap_values import json_record
from tma.io.mcap_writer import Encoded, McapWriter
from tma.io.proto_columns import proto_schema
from tma.maths.geo import local_to_geodetic, location_fix

EPOCH_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z
NUMPY = orjson.OPT_SERIALIZE_NUMPY


# -- the reference ----------------------------------------------------------------------------

COMPRESSION_TYPE = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}


def reference_bytes(channels, metadata, messages, chunk_size=1024 * 1024,
                    compression="zstd") -> bytes:
    """mcap's writer with LogWriter's options. ``messages``: (topic, log time ns, payload)."""
    out = io.BytesIO()
    w = Writer(out, chunk_size=chunk_size, compression=COMPRESSION_TYPE[compression],
               enable_crcs=True, enable_data_crcs=True)
    w.start(profile="", library=f"tma {__version__}")
    schema_ids, ids = {}, {}
    for ch in channels:
        if ch.schema not in schema_ids:
            schema_ids[ch.schema] = (
                register_protobuf_schema(w, ch.message_class) if ch.message_class is not None
                else w.register_schema(name=ch.schema, encoding="protobuf",
                                       data=proto_schema(ch.schema).descriptor_set)
                if ch.encoding == "protobuf"
                else w.register_schema(name=ch.schema, encoding="jsonschema",
                                       data=schema_bytes(ch.schema)))
        ids[ch.topic] = w.register_channel(
            topic=ch.topic, schema_id=schema_ids[ch.schema], message_encoding=ch.encoding,
            metadata={k: str(v) for k, v in ch.metadata.items()})
    for name, record in metadata.items():
        w.add_metadata(name, {k: str(v) for k, v in record.items()})
    for sequence, (topic, t_ns, data) in enumerate(messages):
        w.add_message(ids[topic], log_time=t_ns, publish_time=t_ns, data=data,
                      sequence=sequence)
    w.finish()
    return out.getvalue()


def _serializer(encoding: str):
    """One message's bytes, as orjson or as protobuf's own serializer writes it."""
    if encoding == "json":
        return lambda schema, message: orjson.dumps(message, option=NUMPY)
    return lambda schema, message: proto_message_class(schema)(**{
        k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in message.items()
    }).SerializeToString(deterministic=True)


def reference_bearings_messages(log: BearingsLog, encoding: str = "protobuf"):
    """The messages of ``log`` as write_bearings_log wrote them one by one before."""
    epoch, serialize = log.epoch_utc_ns or 0, _serializer(encoding)
    if log.origin_deg is not None:
        lat, lon = local_to_geodetic(log.own_x_m, log.own_y_m, log.origin_deg)
    for k, t in enumerate(log.t_s.tolist()):
        t_ns = epoch + int(round(t * 1e9))
        yield OWNSHIP_TOPIC, t_ns, serialize("tma.OwnshipNavigation", {
            "t_s": t, "x_m": float(log.own_x_m[k]), "y_m": float(log.own_y_m[k])})
        if log.origin_deg is not None:
            yield OWNSHIP_FIX_TOPIC, t_ns, location_fix(
                t_ns, OWNSHIP_FRAME, lat[k], lon[k]).SerializeToString(deterministic=True)
        has = np.isfinite(log.bearing_deg[:, k])
        yield BEARINGS_TOPIC, t_ns, serialize("tma.BearingBatch", {
            "t_s": t, "track_id": log.track_id[has],
            "bearing_deg": np.ascontiguousarray(log.bearing_deg[has, k])})


def _written_metadata(path) -> dict:
    """The metadata records of a written log, in file order (checked against the summary)."""
    with open(path, "rb") as f:
        return {m.name: m.metadata for m in make_reader(f).iter_metadata()}


# -- the file writer --------------------------------------------------------------------------

def _random_messages(rng, n, n_channels=3):
    return [(int(rng.integers(1, n_channels + 1)), int(rng.integers(0, 2**63)),
             rng.bytes(int(rng.integers(0, 300)))) for _ in range(n)]


def _mcap_writer_bytes(messages, chunk_size, metadata, batches, compression="zstd") -> bytes:
    out = io.BytesIO()
    w = McapWriter(out, profile="p", library="lib", chunk_size=chunk_size,
                   compression=compression)
    json_schema = w.add_schema("tma.A", "jsonschema", b'{"type": "object"}')
    proto_schema = w.add_schema("pkg.B", "protobuf", bytes(range(256)))
    w.add_channel("/a", "json", json_schema, {"units": "m", "frame": "ü"})
    w.add_channel("/b", "protobuf", proto_schema, {})
    w.add_channel("/c", "json", json_schema, {})
    for name, record in metadata.items():
        w.add_metadata(name, record)
    for part in np.array_split(np.arange(len(messages)), batches):
        batch = [messages[i] for i in part]
        payloads = Encoded.of([data for _, _, data in batch])
        w.add_messages(np.array([c for c, _, _ in batch], np.uint16),
                       np.array([t for _, t, _ in batch], np.uint64), [payloads.data],
                       payloads.offsets[:-1], np.diff(payloads.offsets))
    w.finish()
    return out.getvalue()


def _mcap_reference_bytes(messages, chunk_size, metadata, compression="zstd") -> bytes:
    out = io.BytesIO()
    w = Writer(out, chunk_size=chunk_size, compression=COMPRESSION_TYPE[compression],
               enable_crcs=True, enable_data_crcs=True)
    w.start(profile="p", library="lib")
    json_schema = w.register_schema("tma.A", "jsonschema", b'{"type": "object"}')
    proto_schema = w.register_schema("pkg.B", "protobuf", bytes(range(256)))
    w.register_channel("/a", "json", json_schema, {"units": "m", "frame": "ü"})
    w.register_channel("/b", "protobuf", proto_schema, {})
    w.register_channel("/c", "json", json_schema, {})
    for name, record in metadata.items():
        w.add_metadata(name, record)
    for sequence, (channel, t, data) in enumerate(messages):
        w.add_message(channel, log_time=t, publish_time=t, data=data, sequence=sequence)
    w.finish()
    return out.getvalue()


@pytest.mark.parametrize("n, chunk_size, batches", [
    (0, 1024, 1),  # no message: schemas and channels only in the summary
    (1, 1024, 1),
    (40, 100_000, 1),  # one chunk
    (3000, 2000, 1),  # many chunks, each cut after the message that passes the size
    (3000, 2000, 17),  # the same messages handed over in batches: the same file
    (500, 10, 500),  # a chunk per message; one message per batch
    (2000, 1024 * 1024, 3),  # mcap's default chunk size
])
@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_the_file_is_byte_identical_to_mcaps_writer(n, chunk_size, batches, compression):
    messages = _random_messages(np.random.default_rng(n + batches), n)
    metadata = {"first": {"a": "1", "ü": "ß"}, "empty": {}}
    ours = _mcap_writer_bytes(messages, chunk_size, metadata, batches, compression)
    assert ours == _mcap_reference_bytes(messages, chunk_size, metadata, compression)
    assert check_integrity(ours) is None
    reader = make_reader(io.BytesIO(ours), validate_crcs=True)
    read = [(ch.id, m.log_time, m.data) for _, ch, m in reader.iter_messages(log_time_order=False)]
    assert read == messages


def test_chunks_close_exactly_where_mcaps_do():
    """Every chunk size from 600 to 900 bytes over the same 60 messages: some chunk then fills
    to exactly the size, or one byte past it (mcap closes only past it)."""
    messages = _random_messages(np.random.default_rng(11), 60)
    messages = [(c, t, data[:40]) for c, t, data in messages]
    for chunk_size in range(600, 900):
        assert (_mcap_writer_bytes(messages, chunk_size, {}, 2)
                == _mcap_reference_bytes(messages, chunk_size, {})), chunk_size


def test_a_payload_past_the_chunk_size_and_channels_seen_late():
    rng = np.random.default_rng(5)
    messages = ([(3, 5, rng.bytes(5000))] + _random_messages(rng, 50, n_channels=1)
                + [(2, 1, b"")] + _random_messages(rng, 50))
    ours = _mcap_writer_bytes(messages, 1000, {}, 4)
    assert ours == _mcap_reference_bytes(messages, 1000, {})


# -- LogWriter and write_bearings_log ---------------------------------------------------------

def _log(n_tracks, n_epochs, seed=0, gaps=0.0, **extra) -> BearingsLog:
    rng = np.random.default_rng(seed)
    t = np.arange(n_epochs) * 2.0 + rng.uniform(0, 1e-3)  # times whose ns need rounding
    bearing = rng.uniform(-360.0, 360.0, (n_tracks, n_epochs))
    bearing[rng.random(bearing.shape) < gaps] = np.nan
    return BearingsLog(t_s=t, own_x_m=3.0 * t, own_y_m=500.0 * np.sin(t / 600.0),
                       track_id=rng.choice(10**6, n_tracks, replace=False),
                       bearing_deg=bearing, **extra)


def _simulated_geo_log() -> BearingsLog:
    cfg = Config(n_tracks=4, shard_size=4, sigma_deg=0.2)
    log, _ = simulate_shard(cfg, 0)
    log.t_s = log.t_s + 0.123456789  # fixes with nanoseconds
    log.origin_deg = (59.9, 10.7)
    log.epoch_utc_ns = EPOCH_NS
    log.track_label = np.array(["T1", "bravo 2", "ü", "T4"], dtype=object)
    return log


LOGS = {
    "tiny": lambda: _log(1, 3),
    "one track, multi-chunk": lambda: _log(1, 40_000, epoch_utc_ns=EPOCH_NS, sigma_deg=0.5),
    "gaps, empty epochs, no epoch": lambda: _log(5, 3000, seed=1, gaps=0.6),
    "wide": lambda: _log(104, 400, seed=2, gaps=0.1, epoch_utc_ns=EPOCH_NS),
    "geo: protobuf + JSON, labels, metadata": _simulated_geo_log,
}


@pytest.mark.parametrize("encoding", ["protobuf", "json"])
@pytest.mark.parametrize("name", LOGS)
def test_bearings_logs_are_byte_identical_to_the_reference(tmp_path, name, encoding):
    log = LOGS[name]()
    metadata = {"tma.dataset": json_record({"family": "bearings2d", "shard": 3})}
    path = tmp_path / "log.mcap"
    n = write_bearings_log(path, log, metadata, encoding=encoding)
    messages = list(reference_bearings_messages(log, encoding))
    chosen = channels(encoding) + ([] if log.origin_deg is None else [OWNSHIP_FIX_CHANNEL])
    expected = reference_bytes(chosen, _written_metadata(path), messages,
                               compression=COMPRESSION[encoding])
    assert n == len(messages)
    assert path.read_bytes() == expected
    back = read_bearings_log(path)
    row = {track: i for i, track in enumerate(log.track_id.tolist())}
    rows = [row[track] for track in back.track_id.tolist()]  # the reader may sort the tracks
    assert sorted(rows) == list(range(log.n_tracks))
    np.testing.assert_array_equal(back.t_s, log.t_s)
    np.testing.assert_array_equal(back.bearing_deg, log.bearing_deg[rows])


def test_the_metadata_compared_is_the_one_asked_for(tmp_path):
    """The byte comparison above takes the reference's metadata from the written file; here
    the records themselves are checked."""
    log = _simulated_geo_log()
    write_bearings_log(tmp_path / "log.mcap", log, {"tma.dataset": {"shard": "3"}})
    records = _written_metadata(tmp_path / "log.mcap")
    assert list(records) == ["tma.dataset", "tma.sensor", "tma.target", "tma.tracks", "tma.geo",
                             "tma.time"]
    assert records["tma.target"] == {"accel_psd_m2_s3": "0.0"}  # a simulation's targets
    assert records["tma.dataset"] == {"shard": "3"}
    assert orjson.loads(records["tma.time"]["epoch_utc_ns"]) == EPOCH_NS


@pytest.mark.parametrize("encoding, compression", [("json", "zstd"), ("protobuf", "lz4"),
                                                   ("protobuf", "zstd")])
def test_write_and_write_epochs_mixed_in_any_order(tmp_path, encoding, compression):
    """Single messages, batches of several topics (dicts, protobuf objects, ``Encoded``) and
    times out of order: the file is the reference's for the same sequence of messages."""
    chosen = [*channels(encoding), OWNSHIP_FIX_CHANNEL]
    serialize = _serializer(encoding)
    rng = np.random.default_rng(9)
    expected = []
    with LogWriter(tmp_path / "mixed.mcap", chosen, {"m": {"k": "v"}},
                   epoch_utc_ns=EPOCH_NS, compression=compression) as w:
        for step in range(40):
            t = rng.uniform(-100.0, 1e5, int(rng.integers(0, 30)))
            own = {"t_s": t, "x_m": rng.normal(size=t.size), "y_m": rng.normal(size=t.size)}
            fixes = [LocationFix(latitude=v, frame_id="f") for v in rng.normal(size=t.size)]
            bearings = [{"t_s": v, "track_id": [1, 2], "bearing_deg": [v, np.nan]}
                        for v in t.tolist()]
            if step % 3 == 0:
                w.write(OWNSHIP_TOPIC, t[0] if t.size else 1.5, {"t_s": 1.0})
                expected.append((OWNSHIP_TOPIC, w.time_ns(t[0] if t.size else 1.5),
                                 serialize("tma.OwnshipNavigation", {"t_s": 1.0})))
            w.write_epochs(t, {OWNSHIP_TOPIC: w.columns(OWNSHIP_TOPIC, own),
                               OWNSHIP_FIX_TOPIC: fixes, BEARINGS_TOPIC: bearings})
            for i, v in enumerate(t.tolist()):
                t_ns = EPOCH_NS + round(v * 1e9)
                expected += [
                    (OWNSHIP_TOPIC, t_ns, serialize("tma.OwnshipNavigation",
                                                    {k: float(c[i]) for k, c in own.items()})),
                    (OWNSHIP_FIX_TOPIC, t_ns, fixes[i].SerializeToString(deterministic=True)),
                    (BEARINGS_TOPIC, t_ns, serialize("tma.BearingBatch", bearings[i]))]
        w.write_many(BEARINGS_TOPIC, [3.0], [{"t_s": 3.0}])
        expected.append((BEARINGS_TOPIC, EPOCH_NS + 3 * 10**9,
                         serialize("tma.BearingBatch", {"t_s": 3.0})))
    assert w.n_messages == len(expected)
    assert list(w.metadata) == ["m", "tma.time"]
    assert (tmp_path / "mixed.mcap").read_bytes() == reference_bytes(
        chosen, w.metadata, expected, compression=compression)
    messages, _ = read_log(tmp_path / "mixed.mcap", {BEARINGS_TOPIC: "tma.BearingBatch"})
    assert len(messages[BEARINGS_TOPIC]) == sum(t == BEARINGS_TOPIC for t, _, _ in expected)
    t_s = [m["t_s"] for m in messages[BEARINGS_TOPIC]]  # written out of order, read in order
    assert t_s == sorted(t_s) and t_s != [m for m in t_s[:1]] * len(t_s)


def test_ownship_fixes_are_location_fixs_bytes():
    """One message reused, fields set anew: zeros (which proto3 leaves out) after non-zeros
    and back, whole and fractional seconds."""
    t_ns = np.array([EPOCH_NS, EPOCH_NS + 1, 0, 10**9, 2**63 + 12345, 7], np.uint64)
    lat = np.array([59.9, 0.0, -0.0, -89.5, 0.0, 1e-300])
    lon = np.array([0.0, 10.7, -0.0, 180.0, -180.0, 0.0])
    expected = [location_fix(int(ns), OWNSHIP_FRAME, a, b).SerializeToString(deterministic=True)
                for ns, a, b in zip(t_ns, lat, lon, strict=True)]
    got = _ownship_fixes(t_ns, lat, lon)
    assert [got[i] for i in range(len(got))] == expected


def test_write_epochs_needs_a_message_per_topic_and_time(tmp_path):
    with LogWriter(tmp_path / "x.mcap", CHANNELS) as w, pytest.raises(ValueError):
        w.write_epochs([1.0, 2.0], {OWNSHIP_TOPIC: [{"t_s": 1.0}]})


# -- log times --------------------------------------------------------------------------------

def test_log_times_are_epoch_plus_rounded_ns(tmp_path):
    rng = np.random.default_rng(3)
    t = np.concatenate([rng.uniform(-1e3, 1e9, 2000), np.arange(-5, 6) * 0.5e-9,  # ties
                        [0.0, -0.0, 1e10, 1.5e-9, 2.5e-9, 1e-10]])
    w = LogWriter(tmp_path / "unused.mcap", CHANNELS, epoch_utc_ns=EPOCH_NS)
    expected = [EPOCH_NS + int(round(v * 1e9)) for v in t.tolist()]
    assert w.log_times(t).tolist() == expected
    assert [w.time_ns(v) for v in t.tolist()] == expected


@pytest.mark.parametrize("epoch, t_s, ok", [
    (EPOCH_NS, -EPOCH_NS / 1e9, True),  # exactly 1970
    (EPOCH_NS, -EPOCH_NS / 1e9 - 1.0, False),  # before 1970
    (0, 1.8e10, True),  # 570 years: beyond int64 ns, still an MCAP time
    (0, 1.9e10, False),  # beyond 2^64 ns
    (EPOCH_NS, 1.6e10, True),
    (EPOCH_NS, 1.84e10, False),  # the epoch takes it past 2^64
    (0, float("nan"), False),
    (0, float("inf"), False),
    (0, 1e300, False),  # its ns overflow a float
    (0, -1e-10, True),  # rounds to 0
])
def test_times_outside_mcap_range_are_one_clear_error(tmp_path, epoch, t_s, ok):
    w = LogWriter(tmp_path / "unused.mcap", CHANNELS, epoch_utc_ns=epoch)
    if ok:
        assert w.log_times([t_s]).tolist() == [w.time_ns(t_s)] == [epoch + round(t_s * 1e9)]
        return
    for convert in (w.time_ns, lambda v: w.log_times([0.0, v])):
        with pytest.raises(InputError, match="outside MCAP's log time range"):
            convert(t_s)
