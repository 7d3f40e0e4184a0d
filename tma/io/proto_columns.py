"""tma's message schemas as protobuf: whole columns encoded at once, messages decoded by
protobuf itself.

Each JSON schema in ``tma/io/schemas/<name>.json`` has a protobuf twin, built here from it,
so there is one definition of every message: the same fields in the same order, numbered
from 1, in a proto3 message whose full name is the schema's title (``tma.BearingBatch``):

- a ``number`` -> ``double``; an ``integer`` -> ``sfixed64``;
- an array (or "an array or one value") of numbers -> ``repeated double``; of integers ->
  ``repeated sfixed64`` (packed, as proto3 writes repeated numbers).

``encode_columns`` writes exactly what protobuf's own serializer writes for each message
(proto3: fields in number order, a scalar equal to 0 and an empty array left out, -0.0 and
NaN kept), which the tests check against protobuf's serializer. It is hand-made because it
pays: fixed-width types make a message's arrays the raw little-endian bytes of numpy arrays,
so n messages take a few numpy operations, ~7x faster than protobuf's serializer message by
message on a default shard (``make bench``, section io). A JSON ``null`` (a missing reading)
is NaN.

``decode_message`` is protobuf's own parser (the message class protobuf builds from the
schema's FileDescriptorSet), with repeated fields as numpy arrays: a hand-made parser was no
more than 1.2x faster on a default shard or on a million one-bearing messages (``make
bench``), so protobuf's rules hold as protobuf applies them (fields in any order, an absent
field is its default, the last of a scalar sent twice wins, packed and unpacked repeated
fields, unknown fields skipped; bytes that do not parse raise ``DecodeError``).
"""

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import orjson

from tma.io.mcap_writer import Encoded, Ragged, gather

SCHEMA_DIR = Path(__file__).parent / "schemas"  # tma's JSON schemas, embedded in its logs
WIRE_FIXED64, WIRE_LENGTH = 1, 2
_NUMPY = {"double": np.dtype("<f8"), "sfixed64": np.dtype("<i8")}


@dataclass(frozen=True)
class ProtoField:
    name: str
    number: int
    kind: str  # "double" or "sfixed64"
    repeated: bool

    @property
    def dtype(self) -> np.dtype:
        return _NUMPY[self.kind]


@dataclass(frozen=True)
class ProtoSchema:
    """A tma message as protobuf: its full name, fields, and the FileDescriptorSet that
    MCAP files carry as the schema's data (what Foxglove and protobuf readers decode with)."""

    name: str
    fields: tuple[ProtoField, ...]

    @functools.cached_property
    def descriptor_set(self) -> bytes:
        from google.protobuf import descriptor_pb2

        package, _, message = self.name.rpartition(".")
        proto = descriptor_pb2.FieldDescriptorProto
        file = descriptor_pb2.FileDescriptorProto(
            name=f"{self.name.replace('.', '/')}.proto", package=package, syntax="proto3")
        described = file.message_type.add(name=message)
        for f in self.fields:
            described.field.add(
                name=f.name, number=f.number, json_name=f.name,
                label=proto.LABEL_REPEATED if f.repeated else proto.LABEL_OPTIONAL,
                type=proto.TYPE_DOUBLE if f.kind == "double" else proto.TYPE_SFIXED64)
        return descriptor_pb2.FileDescriptorSet(file=[file]).SerializeToString(
            deterministic=True)

    @functools.cached_property
    def message_class(self) -> type:
        """protobuf's message class of this schema, built from ``descriptor_set``."""
        from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

        pool = descriptor_pool.DescriptorPool()
        for file in descriptor_pb2.FileDescriptorSet.FromString(self.descriptor_set).file:
            pool.Add(file)
        return message_factory.GetMessageClass(pool.FindMessageTypeByName(self.name))

    def matches(self, descriptor_set: bytes) -> bool:
        """Whether a schema's FileDescriptorSet declares this message with these fields
        (numbers, types, repetition); names and other files do not matter."""
        if descriptor_set == self.descriptor_set:
            return True
        from google.protobuf import descriptor_pb2
        from google.protobuf.message import DecodeError

        try:
            found = descriptor_pb2.FileDescriptorSet.FromString(descriptor_set)
        except DecodeError:
            return False
        theirs = None
        for file in found.file:
            for message in file.message_type:
                if f"{file.package}.{message.name}".lstrip(".") == self.name:
                    theirs = {(f.number, f.type, f.label == f.LABEL_REPEATED)
                              for f in message.field}
        ours = descriptor_pb2.FileDescriptorSet.FromString(self.descriptor_set)
        ours = {(f.number, f.type, f.label == f.LABEL_REPEATED)
                for f in ours.file[0].message_type[0].field}
        return theirs == ours


def _kind(spec: dict) -> tuple[str, bool]:
    """(protobuf scalar type, repeated) of a JSON-schema property."""
    options = spec.get("oneOf", [spec])
    repeated = any(o.get("type") == "array" for o in options)
    items = [o["items"] if o.get("type") == "array" else o for o in options]
    types = {t for item in items
             for t in (item["type"] if isinstance(item["type"], list) else [item["type"]])}
    types -= {"null"}  # a missing reading: NaN
    if types == {"integer"}:
        return "sfixed64", repeated
    if types == {"number"}:
        return "double", repeated
    raise ValueError(f"a property of types {sorted(types)} has no protobuf twin")


@functools.cache
def proto_schema(name: str) -> ProtoSchema:
    """The protobuf twin of ``tma/io/schemas/<name>.json``."""
    spec = orjson.loads((SCHEMA_DIR / f"{name}.json").read_bytes())
    fields = tuple(ProtoField(key, number, *_kind(prop))
                   for number, (key, prop) in enumerate(spec["properties"].items(), 1))
    return ProtoSchema(spec["title"], fields)


# -- encoding ----------------------------------------------------------------------------------

def _varints(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Protobuf varints of non-negative integers: ``(bytes (n, 10) uint8, lengths (n,))``."""
    v = values.astype(np.uint64)
    shifts = np.arange(10, dtype=np.uint64) * np.uint64(7)
    groups = ((v[:, None] >> shifts) & np.uint64(0x7F)).astype(np.uint8)
    lengths = 1 + ((v[:, None] >> shifts[1:]) > 0).sum(1)
    groups[np.arange(10) < lengths[:, None] - 1] |= 0x80  # more bytes follow
    return groups, lengths


def encode_columns(schema: ProtoSchema, fields: dict) -> Encoded:
    """n messages of ``schema``: ``fields[name]`` is a 1-D array of n values (one per message)
    or, for a repeated field, a ``Ragged`` (one array per message); a field not given is
    left out (its default, as in protobuf). Integer fields take integer arrays only (a float
    would be truncated). The bytes are protobuf's own (see the module docstring)."""
    n = {len(c.counts) if isinstance(c, Ragged) else len(c) for c in fields.values()}
    unknown = set(fields) - {f.name for f in schema.fields}
    if unknown or len(n) != 1:
        raise ValueError(f"{schema.name}: encode_columns takes fields of "
                         f"{', '.join(f.name for f in schema.fields)}, as many values each"
                         + (f" (not {', '.join(sorted(unknown))})" if unknown else ""))
    n = n.pop()
    pieces, starts, lengths, size = [], [], [], 0

    def add(piece: np.ndarray, piece_starts, piece_lengths):
        nonlocal size
        pieces.append(piece)
        starts.append(np.broadcast_to(np.asarray(piece_starts) + size, (n,)))
        lengths.append(np.broadcast_to(piece_lengths, (n,)))
        size += piece.size

    for f in schema.fields:
        if f.name not in fields:
            continue
        column = fields[f.name]
        if not f.repeated:
            if isinstance(column, Ragged):
                raise ValueError(f"{schema.name}.{f.name} holds one value per message")
            keyed = np.empty(n, [("key", "u1"), ("value", f.dtype)])  # 9 bytes each
            keyed["key"], keyed["value"] = f.number << 3 | WIRE_FIXED64, _typed(f, column)
            present = keyed["value"].view(np.int64) != 0  # the bits: -0.0 is written
            add(keyed.view(np.uint8), np.arange(n) * keyed.itemsize,
                np.where(present, keyed.itemsize, 0))
            continue
        if not isinstance(column, Ragged):
            column = Ragged(column, np.ones(n, np.int64))
        values = np.ascontiguousarray(_typed(f, column.values))
        counts = np.asarray(column.counts, np.int64)
        if counts.sum() != values.size or np.any(counts < 0):
            raise ValueError(f"{schema.name}.{f.name}: the counts do not add up to the values")
        head = np.zeros((n, 11), np.uint8)  # key, then the varint byte length of the values
        head[:, 0] = f.number << 3 | WIRE_LENGTH
        head[:, 1:], varint_lengths = _varints(counts * f.dtype.itemsize)
        add(head.ravel(), np.arange(n) * 11, np.where(counts > 0, 1 + varint_lengths, 0))
        offsets = np.concatenate(([0], np.cumsum(counts)[:-1])) * f.dtype.itemsize
        add(values.view(np.uint8), offsets, counts * f.dtype.itemsize)
    lengths = np.stack(lengths, 1)
    data = gather(pieces, np.stack(starts, 1).ravel(), lengths.ravel())
    return Encoded(data, np.concatenate(([0], np.cumsum(lengths.sum(1)))))


def _varint_bytes(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def encode_message(schema: ProtoSchema, message: dict) -> bytes:
    """One message of ``schema`` from a dict (numbers; arrays or lists for repeated fields,
    a JSON null in a number array as NaN; a repeated field may be given one number): the
    bytes ``encode_columns`` gives, without building columns (for messages one at a time)."""
    unknown = set(message) - {f.name for f in schema.fields}
    if unknown:
        raise ValueError(f"{schema.name} has no field {', '.join(sorted(unknown))}")
    out = []
    for f in schema.fields:
        if f.name not in message:
            continue
        value = message[f.name]
        if f.repeated:
            values = _typed(f, np.array(value, float) if f.kind == "double"
                            else np.asarray(value)).reshape(-1)
            if values.size:
                out += [bytes([f.number << 3 | WIRE_LENGTH]), _varint_bytes(values.nbytes),
                        values.tobytes()]
            continue
        packed = (_typed(f, np.array([value], float) if f.kind == "double"
                         else np.asarray([value]))).tobytes()
        if packed != bytes(8):  # 0 (and +0.0) is left out, as protobuf does
            out += [bytes([f.number << 3 | WIRE_FIXED64]), packed]
    return b"".join(out)


def _typed(f: ProtoField, values) -> np.ndarray:
    values = np.asarray(values)
    integers = f.kind == "sfixed64"
    if values.ndim == 0:
        values = values.reshape(1)  # one value in a repeated field
    if values.ndim != 1 or values.dtype.kind not in ("iu" if integers else "iuf"):
        raise ValueError(f"{f.name}: needs a 1-D array of {'integers' if integers else 'numbers'}"
                         f", got {values.dtype} of shape {values.shape}")
    if integers and values.dtype.kind == "u" and values.size and values.max() >= 2**63:
        raise ValueError(f"{f.name}: a value beyond int64")
    return values.astype(f.dtype, copy=False)


# -- decoding ----------------------------------------------------------------------------------

def decode_message(schema: ProtoSchema, data: bytes) -> dict:
    """One message of ``schema`` as a dict: scalars as Python float/int, repeated fields as
    1-D numpy arrays (float64, int64), by protobuf's parser (the module docstring)."""
    message = schema.message_class.FromString(data)
    return {f.name: np.array(getattr(message, f.name), f.dtype) if f.repeated
            else getattr(message, f.name) for f in schema.fields}
