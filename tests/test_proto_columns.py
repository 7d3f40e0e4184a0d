"""tma's schemas as protobuf (``tma.io.proto_columns``) against protobuf's own implementation:
``encode_columns`` writes the bytes protobuf's serializer writes, ``decode_message`` reads
what any protobuf writer may send (any field order, unpacked or split arrays, unknown
fields) as protobuf's parser does, and refuses what protobuf's parser refuses. And a log with
a protobuf channel whose schema is not tma's, or an encoding tma does not read, is one
clear error."""

import struct

import numpy as np
import pytest
from google.protobuf.message import DecodeError
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from mcap.writer import Writer

from tests.conftest import proto_message_class
from tma.errors import InputError
from tma.families.bearings2d.log import BEARINGS_TOPIC, OWNSHIP_TOPIC, SCHEMAS
from tma.io.mcap_read import read_log
from tma.io.mcap_writer import Ragged
from tma.io.proto_columns import decode_message, encode_columns, encode_message, proto_schema

SCHEMA_NAMES = ["tma.BearingBatch", "tma.OwnshipNavigation", "tma.HydrophoneBatch",
                "tma.PlotBatch", "tma.RangeBatch"]
floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
int64s = st.integers(-(2**63), 2**63 - 1)


def test_each_schema_has_its_json_fields_in_order():
    expected = {"tma.BearingBatch": [("t_s", "double", False), ("track_id", "sfixed64", True),
                                     ("bearing_deg", "double", True)],
                "tma.OwnshipNavigation": [("t_s", "double", False), ("x_m", "double", False),
                                          ("y_m", "double", False)]}
    for name, fields in expected.items():
        schema = proto_schema(name)
        assert schema.name == name
        assert [(f.name, f.kind, f.repeated) for f in schema.fields] == fields
        assert [f.number for f in schema.fields] == [1, 2, 3]
    for name in SCHEMA_NAMES:  # protobuf itself accepts every descriptor
        assert proto_message_class(name).DESCRIPTOR.full_name == name


def _values(draw, field, n):
    if field.kind == "double":
        return draw(hnp.arrays(np.float64, n, elements=floats))
    return np.array(draw(st.lists(int64s, min_size=n, max_size=n)), np.int64)


@st.composite
def messages(draw):
    """A schema, and n messages of it as columns: any float64 bit pattern (NaN, -0.0, 0),
    any int64, empty arrays, fields left out."""
    schema = proto_schema(draw(st.sampled_from(SCHEMA_NAMES)))
    n = draw(st.integers(1, 6))
    columns = {}
    for f in schema.fields:
        if draw(st.integers(0, 5)) == 0:
            continue  # not given: left out
        if f.repeated:
            counts = np.array(draw(st.lists(st.integers(0, 4), min_size=n, max_size=n)))
            columns[f.name] = Ragged(_values(draw, f, int(counts.sum())), counts)
        else:
            columns[f.name] = _values(draw, f, n)
    return schema, n, columns


def _message(columns, i):
    out = {}
    for key, c in columns.items():
        if isinstance(c, Ragged):
            end = np.cumsum(c.counts)
            out[key] = c.values[end[i] - c.counts[i]:end[i]]
        else:
            out[key] = c[i]
    return out


@settings(max_examples=150, deadline=None)
@given(messages())
def test_encoding_is_protobufs_and_decoding_gives_the_values_back(case):
    schema, n, columns = case
    if not columns:
        return
    cls = proto_message_class(schema.name)
    encoded = encode_columns(schema, columns)
    assert len(encoded) == n
    for i in range(n):
        values = _message(columns, i)
        reference = cls(**{k: v.tolist() if isinstance(v, np.ndarray) else v.item()
                           for k, v in values.items()}).SerializeToString(deterministic=True)
        assert encoded[i] == reference
        assert encode_message(schema, values) == reference  # one message at a time
        back = decode_message(schema, reference)
        for f in schema.fields:
            want = values.get(f.name, np.zeros(0) if f.repeated else 0)
            np.testing.assert_array_equal(back[f.name], want)  # NaN where NaN
            if not f.repeated:  # bit for bit: -0.0 stays -0.0
                assert struct.pack("<d" if f.kind == "double" else "<q", back[f.name]) == \
                    struct.pack("<d" if f.kind == "double" else "<q", want)


def _key(number, wire):
    return bytes([number << 3 | wire])


def test_any_valid_protobuf_encoding_reads_as_protobuf_reads_it():
    """Fields out of order, an array in two packed pieces, unpacked elements, a scalar sent
    twice (the last wins), unknown fields of every wire type: protobuf's parser and ours agree."""
    schema, cls = proto_schema("tma.BearingBatch"), proto_message_class("tma.BearingBatch")
    d = struct.Struct("<d").pack
    q = struct.Struct("<q").pack
    data = (_key(3, 2) + bytes([16]) + d(1.5) + d(-2.5)  # bearing_deg, packed
            + _key(1, 1) + d(7.0)  # t_s
            + _key(2, 1) + q(-4)  # track_id, one unpacked element
            + _key(9, 0) + b"\x96\x01"  # unknown varint
            + _key(10, 5) + b"abcd"  # unknown fixed32
            + _key(11, 2) + b"\x03xyz"  # unknown bytes
            + _key(12, 1) + d(1.0)  # unknown fixed64
            + _key(2, 2) + bytes([16]) + q(5) + q(2**62)  # track_id, packed, more
            + _key(3, 1) + d(np.inf)  # bearing_deg, unpacked
            + _key(1, 1) + d(8.0))  # t_s again: the last wins
    ours, theirs = decode_message(schema, data), cls.FromString(data)
    assert ours["t_s"] == theirs.t_s == 8.0
    assert ours["track_id"].tolist() == list(theirs.track_id) == [-4, 5, 2**62]
    assert ours["bearing_deg"].tolist() == list(theirs.bearing_deg) == [1.5, -2.5, np.inf]
    empty = decode_message(schema, b"")
    assert empty["t_s"] == 0.0 and empty["track_id"].size == empty["bearing_deg"].size == 0


@pytest.mark.parametrize("data", [
    _key(1, 1) + b"\0" * 7,  # truncated double
    _key(3, 2) + bytes([16]) + b"\0" * 15,  # truncated packed array
    _key(3, 2) + bytes([12]) + b"\0" * 12,  # 12 bytes are no whole float64s
    b"\x80",  # a key cut short
    _key(9, 0) + b"\xff" * 11,  # a varint longer than 10 bytes
    _key(9, 3),  # groups
    _key(9, 7),  # no such wire type
    b"\x00" + b"\0" * 8,  # field number 0
    _key(9, 2) + b"\x05ab",  # an unknown field cut short
])
def test_what_protobuf_refuses_is_refused(data):
    schema, cls = proto_schema("tma.BearingBatch"), proto_message_class("tma.BearingBatch")
    with pytest.raises(DecodeError):
        cls.FromString(data)  # the reference agrees that these are not messages
    with pytest.raises(DecodeError):
        decode_message(schema, data)


@pytest.mark.parametrize("fields", [
    {"track_id": Ragged(np.array([1.5]), np.array([1]))},  # a float for an integer
    {"track_id": Ragged(np.array([2**63], np.uint64), np.array([1]))},
    {"t_s": np.array(["1"])},
    {"t_s": np.ones((1, 1))},
    {"t_s": np.ones(2), "bearing_deg": Ragged(np.ones(2), np.array([2]))},  # 2 vs 1 messages
    {"bearing_deg": Ragged(np.ones(3), np.array([2]))},  # counts do not add up
    {"speed": np.ones(1)},  # no such field
])
def test_encoding_refuses_what_it_cannot_write_exactly(fields):
    with pytest.raises(ValueError):
        encode_columns(proto_schema("tma.BearingBatch"), fields)


@pytest.mark.parametrize("message", [
    {"track_id": [1.5]}, {"track_id": [2**63]}, {"track_id": ["a"]}, {"t_s": [[1.0]]},
    {"speed": 1.0}, {"bearing_deg": ["x"]},
])
def test_one_message_refuses_what_it_cannot_write_exactly(message):
    with pytest.raises((ValueError, OverflowError)):
        encode_message(proto_schema("tma.BearingBatch"), message)


def _log_with(path, schema_data, message, encoding="protobuf", schema_encoding="protobuf"):
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        nav = w.register_schema("tma.OwnshipNavigation", "protobuf",
                                proto_schema("tma.OwnshipNavigation").descriptor_set)
        bearings = w.register_schema("tma.BearingBatch", schema_encoding, schema_data)
        ids = {OWNSHIP_TOPIC: w.register_channel(OWNSHIP_TOPIC, "protobuf", nav),
               BEARINGS_TOPIC: w.register_channel(BEARINGS_TOPIC, encoding, bearings)}
        w.add_message(ids[OWNSHIP_TOPIC], 0, encode_columns(
            proto_schema("tma.OwnshipNavigation"), {"t_s": np.ones(1)})[0], 0)
        w.add_message(ids[BEARINGS_TOPIC], 0, message, 0)
        w.finish()


def test_a_protobuf_schema_that_is_not_tmas_is_refused(tmp_path):
    from google.protobuf import descriptor_pb2

    message = encode_columns(proto_schema("tma.BearingBatch"), {"t_s": np.ones(1)})[0]
    _log_with(tmp_path / "ok.mcap", proto_schema("tma.BearingBatch").descriptor_set, message)
    assert read_log(tmp_path / "ok.mcap", SCHEMAS)[0][BEARINGS_TOPIC][0]["t_s"] == 1.0
    other = descriptor_pb2.FileDescriptorSet.FromString(
        proto_schema("tma.BearingBatch").descriptor_set)
    other.file[0].message_type[0].field[1].type = descriptor_pb2.FieldDescriptorProto.TYPE_INT64
    for data, kind in [(other.SerializeToString(), "protobuf"), (b"junk", "protobuf"),
                       (b"{}", "jsonschema")]:
        _log_with(tmp_path / "bad.mcap", data, message, schema_encoding=kind)
        with pytest.raises(InputError, match=r"bad.mcap: topic /sonar/bearings: the protobuf "
                                             "schema 'tma.BearingBatch' does not declare"):
            read_log(tmp_path / "bad.mcap", SCHEMAS)


def test_an_encoding_tma_does_not_read_is_one_line(tmp_path):
    _log_with(tmp_path / "cbor.mcap", b"", b"\xa0", encoding="cbor", schema_encoding="")
    with pytest.raises(InputError, match="message encoding 'cbor'; tma reads json or protobuf"):
        read_log(tmp_path / "cbor.mcap", SCHEMAS)
