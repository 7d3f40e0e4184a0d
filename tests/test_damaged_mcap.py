"""Damaged or malformed MCAP input gives one InputError naming the file, never a traceback
and never data that differ from what was written (issue 8)."""

import numpy as np
import orjson
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from tests.families.bearings2d.recorded_geometry import ingest
from tma.errors import InputError
from tma.families.bearing_doppler3d import scenario as bearing_doppler3d
from tma.families.bearing_doppler3d.log import read_hydrophone_log, write_hydrophone_log
from tma.families.bearings2d import scenario as bearings2d
from tma.families.bearings2d.log import (
    BEARINGS_TOPIC,
    CHANNELS,
    OWNSHIP_TOPIC,
    read_bearings_log,
    write_bearings_log,
)
from tma.families.radar2d import scenario as radar2d
from tma.families.radar2d.log import read_radar_log, write_radar_log
from tma.families.ranges2d import scenario as ranges2d
from tma.families.ranges2d.log import read_ranges_log, write_ranges_log
from tma.io.mcap_log import LogWriter
from tma.io.mcap_writer import Ragged
from tma.io.proto_columns import decode_message, encode_columns, proto_schema

FIELDS = ("t_s", "own_x_m", "own_y_m", "track_id", "bearing_deg")
N_DAMAGES = 300


def _shard():
    log, _ = bearings2d.simulate_shard(bearings2d.Config(n_tracks=5, shard_size=5, seed=3), 0)
    return log


def _same(a, b) -> bool:
    return all(getattr(a, f).shape == getattr(b, f).shape
               and np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True) for f in FIELDS)


def _damage(clean: bytes, seed: int):
    """Seeded damage: alternately one flipped bit and 16 overwritten bytes, anywhere."""
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    for i in range(N_DAMAGES):
        data = bytearray(clean)
        if i % 2 == 0:
            bit = int(rng.integers(8 * len(data)))
            data[bit // 8] ^= 1 << (bit % 8)
            where = f"bit {bit}"
        else:
            at = int(rng.integers(len(data) - 16))
            data[at:at + 16] = rng.bytes(16)
            where = f"bytes {at}..{at + 15}"
        yield where, bytes(data)


def _fuzz(clean: bytes, path, seed, read, reference, allow_different=False):
    """Count outcomes; an exception other than InputError propagates (a traceback)."""
    rejected, identical, different = 0, 0, []
    for i, (where, data) in enumerate(_damage(clean, seed)):
        path.write_bytes(data)
        try:
            got = read(path, i)
        except InputError as exc:
            assert path.name in str(exc) and "\n" not in str(exc), str(exc)
            rejected += 1
            continue
        if _same(got, reference):
            identical += 1
        else:
            different.append(where)
    assert allow_different or not different, f"damage read as different data: {different}"
    return rejected, identical


def _tma_file(path, log):
    write_bearings_log(path, log, {"tma.dataset": {"family": "bearings2d", "shard": 0}})


def _other_tool_file(path, log):
    """As other tools write: chunk and summary CRCs, no data-section CRC (0 = not computed)."""
    _tma_file(path.with_suffix(".tmp"), log)
    _rewrite(path.with_suffix(".tmp"), path)


def test_damaged_dataset_shard_is_rejected(tmp_path):
    path = tmp_path / "shard-00000.mcap"
    _tma_file(path, _shard())
    clean, reference = path.read_bytes(), read_bearings_log(path)
    rejected, identical = _fuzz(clean, tmp_path / "damaged.mcap", 8_2026,
                                lambda p, i: read_bearings_log(p), reference)
    # every byte of a file tma writes is under a CRC (chunks, data section, summary + footer)
    assert (rejected, identical) == (N_DAMAGES, 0)


def test_damaged_log_of_another_tool_is_rejected_or_read_unchanged(tmp_path):
    path = tmp_path / "other.mcap"
    _other_tool_file(path, _shard())
    clean, reference = path.read_bytes(), read_bearings_log(path)
    rejected, identical = _fuzz(clean, tmp_path / "damaged.mcap", 2_8026,
                                lambda p, i: read_bearings_log(p), reference)
    assert rejected > 0.6 * N_DAMAGES and identical > 0  # unused bytes (indexes, metadata)


def test_damaged_log_without_crcs_is_never_a_traceback(tmp_path):
    # Without any CRC, damage inside a chunk may decode to other numbers: undetectable (the
    # reason tma writes every CRC), but the reader must still never crash.
    path = tmp_path / "no-crc.mcap"
    _tma_file(path.with_suffix(".tmp"), _shard())
    _rewrite(path.with_suffix(".tmp"), path, crcs=False)
    _fuzz(path.read_bytes(), tmp_path / "damaged.mcap", 6_2028,
          lambda p, i: read_bearings_log(p), read_bearings_log(path), allow_different=True)


@pytest.mark.parametrize("write", [_tma_file, _other_tool_file])
def test_damaged_ingest_input_is_rejected(tmp_path, write):
    log = _shard()
    log.t_s = log.t_s + 1.7e9  # a recording with clock time stamps and gaps
    log.bearing_deg[1, 100:130] = np.nan
    log.bearing_deg[3, ::7] = np.nan
    src = tmp_path / "rec.mcap"
    write(src, log)
    data_dir = tmp_path / "data"

    def ingested(path, i):
        root = ingest(path, data_dir=data_dir, name=f"d{i}")
        return read_bearings_log(root / "log" / "shard-00000.mcap")

    reference = ingested(src, "clean")
    _fuzz(src.read_bytes(), tmp_path / "damaged.mcap", 2026_8, ingested, reference)


def test_truncated_files_are_rejected(tmp_path):
    path = tmp_path / "log.mcap"
    write_bearings_log(path, _shard())
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    for n in [0, 1, 7, 8, 9, 100, len(data) // 2, len(data) - 38, len(data) - 37,
              len(data) - 9, len(data) - 8, len(data) - 1]:
        cut.write_bytes(data[:n])
        with pytest.raises(InputError, match="cut.mcap"):
            read_bearings_log(cut)
    cut.write_bytes(data + b"\0")  # trailing garbage: the footer is not where it must be
    with pytest.raises(InputError, match="cut.mcap"):
        read_bearings_log(cut)


def test_one_bearing_per_message_with_scalar_fields(tmp_path):
    log = _shard()
    log.bearing_deg[2, 10:20] = np.nan
    write_bearings_log(tmp_path / "arrays.mcap", log)
    with LogWriter(tmp_path / "scalars.mcap", CHANNELS) as w:
        for k, t in enumerate(log.t_s.tolist()):
            w.write(OWNSHIP_TOPIC, t, {"t_s": t, "x_m": float(log.own_x_m[k]),
                                       "y_m": float(log.own_y_m[k])})
            for i in np.flatnonzero(np.isfinite(log.bearing_deg[:, k]))[::-1]:  # any order
                w.write(BEARINGS_TOPIC, t, {"t_s": t, "track_id": int(log.track_id[i]),
                                            "bearing_deg": float(log.bearing_deg[i, k])})
    assert _same(read_bearings_log(tmp_path / "scalars.mcap"),
                 read_bearings_log(tmp_path / "arrays.mcap"))
    # a single contact, one message per epoch with scalars: the plain one-track case
    with LogWriter(tmp_path / "one.mcap", CHANNELS) as w:
        for k, t in enumerate(log.t_s.tolist()):
            w.write(OWNSHIP_TOPIC, t, {"t_s": t, "x_m": float(log.own_x_m[k]),
                                       "y_m": float(log.own_y_m[k])})
            w.write(BEARINGS_TOPIC, t, {"t_s": t, "track_id": 7,
                                        "bearing_deg": float(log.bearing_deg[0, k])})
    one = read_bearings_log(tmp_path / "one.mcap")
    np.testing.assert_array_equal(one.track_id, [7])
    np.testing.assert_array_equal(one.bearing_deg, log.bearing_deg[:1])


def _rewrite(src, dst, edit=lambda topic, n, msg: msg, meta=lambda name, record: record,
             crcs=True):
    """Copy an MCAP log the way another tool might write it (mcap's default Writer: chunk
    and summary CRCs, no data-section CRC; no CRC at all if not ``crcs``). Message n
    (decoded JSON on a JSON channel, its bytes on others) passes through
    ``edit(topic, n, message)``, which returns a replacement (a JSON value, or raw bytes),
    each metadata record through ``meta(name, record)``."""
    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [(c.topic, m.log_time, orjson.loads(m.data) if c.message_encoding == "json"
                     else m.data) for _, c, m in reader.iter_messages()]
        metadata = [(r.name, r.metadata) for r in reader.iter_metadata()]
    with open(dst, "wb") as f:
        w = Writer(f, enable_crcs=crcs)
        w.start()
        ids = {}
        for c in summary.channels.values():
            s = summary.schemas[c.schema_id]
            ids[c.topic] = w.register_channel(c.topic, c.message_encoding,
                                              w.register_schema(s.name, s.encoding, s.data),
                                              c.metadata)
        for name, record in metadata:
            w.add_metadata(name, meta(name, record))
        for n, (topic, t, data) in enumerate(messages):
            new = edit(topic, n, data)
            w.add_message(ids[topic], t, new if isinstance(new, bytes) else orjson.dumps(new), t)
        w.finish()


def _at(topic, n_msg, change):
    """An edit that applies ``change(message)`` to the n-th message of ``topic``."""
    seen = {}

    def edit(t, n, msg):
        seen[t] = seen.get(t, -1) + 1
        return change(msg) if t == topic and seen[t] == n_msg else msg
    return edit


def _set(**fields):
    return lambda msg: {**msg, **fields}


BAD_BEARING_MESSAGES = {
    "not JSON": lambda m: b'{"t_s": 1.0, "track_id": [0, 1',
    "not UTF-8": lambda m: b'{"t_s": \xff}',
    "JSON array": lambda m: [1, 2, 3],
    "JSON number": lambda m: 5,
    "missing t_s": lambda m: {k: v for k, v in m.items() if k != "t_s"},
    "t_s string": _set(t_s="12"),
    "t_s null": _set(t_s=None),
    "track_id string": _set(track_id="0,1,2,3,4"),
    "track_id fractional": _set(track_id=[0, 1.5, 2, 3, 4]),
    "track_id bool": _set(track_id=[True, 1, 2, 3, 4]),
    "track_id beyond int64": _set(track_id=[0, 1, 2, 3, 2**63]),
    "bearing string": _set(bearing_deg=["1", "2", "3", "4", "5"]),
    "bearing object": _set(bearing_deg={"a": 1}),
    "nested arrays": _set(bearing_deg=[[1.0, 2.0], [3.0, 4.0]], track_id=[[0, 1], [2, 3]]),
    "length mismatch": _set(bearing_deg=[1.0, 2.0]),
    "duplicate track": _set(track_id=[0, 0, 2, 3, 4]),
}


@pytest.mark.parametrize("case", BAD_BEARING_MESSAGES)
def test_malformed_bearing_message_is_a_clean_error(tmp_path, case):
    write_bearings_log(tmp_path / "ok.mcap", _shard(), encoding="json")
    _rewrite(tmp_path / "ok.mcap", tmp_path / "bad.mcap",
             _at(BEARINGS_TOPIC, 30, BAD_BEARING_MESSAGES[case]))
    with pytest.raises(InputError, match="bad.mcap"):
        read_bearings_log(tmp_path / "bad.mcap")


def _proto(change):
    """An edit of a protobuf BearingBatch: decoded, changed (a dict), encoded again."""
    schema = proto_schema("tma.BearingBatch")

    def edit(data):
        message = change(decode_message(schema, data))
        columns = {k: Ragged(np.asarray(v), [np.size(v)]) if np.ndim(v) else np.array([v])
                   for k, v in message.items()}
        return encode_columns(schema, columns)[0]
    return edit


BAD_PROTOBUF_BEARING_MESSAGES = {
    "truncated": lambda m: m[:-3],
    "cut inside a key": lambda m: m + b"\x80",
    "a length past the end": lambda m: m + b"\x1a\x10",
    "length mismatch": _proto(lambda m: {**m, "bearing_deg": m["bearing_deg"][:2]}),
    "duplicate track": _proto(lambda m: {**m, "track_id": np.zeros_like(m["track_id"])}),
    "NaN time": _proto(lambda m: {**m, "t_s": np.nan}),
    "time going back": _proto(lambda m: {**m, "t_s": -1.0}),
    "no ids": _proto(lambda m: {k: v for k, v in m.items() if k != "track_id"}),
    "bearing in radians' place": _proto(lambda m: {**m, "bearing_deg": m["bearing_deg"] * 1e3}),
}


@pytest.mark.parametrize("case", BAD_PROTOBUF_BEARING_MESSAGES)
def test_malformed_protobuf_bearing_message_is_a_clean_error(tmp_path, case):
    write_bearings_log(tmp_path / "ok.mcap", _shard())
    _rewrite(tmp_path / "ok.mcap", tmp_path / "bad.mcap",
             _at(BEARINGS_TOPIC, 30, BAD_PROTOBUF_BEARING_MESSAGES[case]))
    with pytest.raises(InputError, match="bad.mcap"):
        read_bearings_log(tmp_path / "bad.mcap")


def test_rewritten_log_without_data_crc_reads_the_same(tmp_path):
    # files from other tools have no data-section CRC (0 = not computed): still accepted
    write_bearings_log(tmp_path / "ok.mcap", _shard())
    _rewrite(tmp_path / "ok.mcap", tmp_path / "copy.mcap")
    assert _same(read_bearings_log(tmp_path / "copy.mcap"), read_bearings_log(tmp_path / "ok.mcap"))


def _radar(path, encoding="json"):
    write_radar_log(path, radar2d.simulate_shard(radar2d.Config(n_tracks=3, shard_size=3), 0)[0],
                    encoding=encoding)
    return read_radar_log, "/radar/plots"


def _ranges(path, encoding="json"):
    cfg = ranges2d.Config(n_tracks=3, shard_size=3, mode="population")
    write_ranges_log(path, ranges2d.simulate_shard(cfg, 0)[0], encoding=encoding)
    return read_ranges_log, "/ranging/ranges"


def _hydrophones(path, encoding="json"):
    cfg = bearing_doppler3d.Config(n_tracks=3, shard_size=3, duration_s=10.0)
    write_hydrophone_log(path, bearing_doppler3d.simulate_shard(cfg, 0)[0], encoding=encoding)
    return read_hydrophone_log, "/hydrophones/2"


@pytest.mark.parametrize("family", [_radar, _ranges, _hydrophones])
@pytest.mark.parametrize("change", [
    lambda m: [m], _set(t_s="0"), _set(track_id=[[0]]), _set(track_id=[0, 1]),
    _set(track_id=["a", "b", "c"]), lambda m: {k: v for k, v in m.items() if k != "track_id"},
    lambda m: {**m, **{k: {"x": 1} for k in m if k.endswith(("_m", "_hz", "_sin", "_cos"))}},
], ids=["array", "t_s string", "nested ids", "short ids", "string ids", "no ids",
        "object values"])
def test_malformed_messages_of_other_families(tmp_path, family, change):
    read, topic = family(tmp_path / "ok.mcap")
    read(tmp_path / "ok.mcap")
    _rewrite(tmp_path / "ok.mcap", tmp_path / "bad.mcap", _at(topic, 2, change))
    with pytest.raises(InputError, match="bad.mcap"):
        read(tmp_path / "bad.mcap")


@pytest.mark.parametrize("family", [_radar, _ranges, _hydrophones])
@pytest.mark.parametrize("change", [lambda m: m[:-3], lambda m: m + b"\x80"],
                         ids=["truncated", "cut inside a key"])
def test_malformed_protobuf_messages_of_other_families(tmp_path, family, change):
    read, topic = family(tmp_path / "ok.mcap", "protobuf")
    good = read(tmp_path / "ok.mcap")
    _rewrite(tmp_path / "ok.mcap", tmp_path / "copy.mcap")  # the same log, rewritten
    np.testing.assert_array_equal(read(tmp_path / "copy.mcap").t_s, good.t_s)
    _rewrite(tmp_path / "ok.mcap", tmp_path / "bad.mcap", _at(topic, 2, change))
    with pytest.raises(InputError, match="bad.mcap"):
        read(tmp_path / "bad.mcap")


@pytest.mark.parametrize("family,record,key", [(_radar, "tma.sensor", "sigma_m"),
                                               (_ranges, "tma.model", "sigma_m"),
                                               (_hydrophones, "tma.model", "sensors_m")])
@pytest.mark.parametrize("bad", ["{not json", "[1, 2]", '"text"', '{"a": 1}'])
def test_malformed_metadata_is_a_clean_error(tmp_path, family, record, key, bad):
    read, _ = family(tmp_path / "ok.mcap")
    _rewrite(tmp_path / "ok.mcap", tmp_path / "bad.mcap",
             meta=lambda name, rec: {**rec, key: bad} if name == record else rec)
    with pytest.raises(InputError, match="bad.mcap"):
        read(tmp_path / "bad.mcap")
