"""MCAP logs of tma's schemas: written by ``tma.io.mcap_writer`` (the bytes of the ``mcap``
library's writer, whole columns at a time), read with the ``mcap`` library.

tma's schemas live in ``tma/io/schemas/*.json`` and are embedded in every log, so Foxglove
and any MCAP reader can decode them. A channel of a tma schema carries its messages as JSON
(``orjson``, which serialises numpy arrays directly) or as the schema's protobuf twin
(``tma.io.proto_columns``: the same fields, numbers as raw float64/int64; ~10x faster to
write and read). Readers take either, whatever wrote them. A log may add protobuf channels of
published schemas (Foxglove's ``LocationFix``, so its Map panel shows own-ship), built from
the message classes themselves. Log times are absolute (UTC ns) when the log has an epoch
(``tma.time``). Writes are atomic.

Integrity: ``LogWriter`` writes every CRC MCAP has (chunk ``uncompressed_crc``, DataEnd
``data_section_crc``, Footer ``summary_crc``), so every byte of a file tma writes is covered
by a CRC or is a fixed field checked by value (magic, DataEnd and Footer opcode and length).
``McapFile`` (under ``read_log``) checks all of them before it decodes anything and refuses
a damaged file with one ``InputError`` naming it. A CRC of 0 means "not computed" (MCAP spec;
other tools may write files so): what it would cover is then unchecked, see docs/formats.md.
"""

import contextlib
import functools
import math
import numbers
import struct
import sys
import zlib
from collections import Counter
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

import numpy as np
import orjson
from mcap.decoder import DecoderFactory
from mcap.reader import NonSeekingReader, SeekingReader
from mcap_protobuf.schema import build_file_descriptor_set

from tma import __version__
from tma.errors import InputError, MissingFileError, TmaError
from tma.io.atomic import VerifiedPath, atomic_path
from tma.io.mcap_writer import CHUNK_SIZE, MAGIC, Encoded, McapWriter, Ragged, interleave
from tma.io.proto_columns import (
    SCHEMA_DIR,
    decode_message,
    encode_columns,
    encode_message,
    proto_schema,
)
from tma.utc import MAX_EPOCH_NS, format_utc

PROFILE = ""  # plain MCAP (JSON and protobuf channels): no ROS profile
_JSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY


def _strided_array(obj):
    """orjson serialises contiguous arrays natively; strided views go through a copy."""
    if isinstance(obj, np.ndarray):
        return np.ascontiguousarray(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__} to JSON")


def json_record(record: dict) -> dict:
    """A metadata record whose values are JSON (MCAP metadata values are strings)."""
    return {k: orjson.dumps(v, option=_JSON_OPTIONS).decode() for k, v in record.items()}


def read_json_record(metadata: dict, name: str, where: str) -> dict:
    """Decode the JSON-valued metadata record ``name``; a clear error if it is absent or a
    value is not JSON."""
    if name not in metadata:
        raise InputError(f"{where}: missing metadata record '{name}'")
    try:
        return {k: orjson.loads(v) for k, v in metadata[name].items()}
    except orjson.JSONDecodeError as exc:
        raise InputError(f"{where}: metadata record '{name}' has a value that is not JSON "
                         f"({exc})") from None


@contextlib.contextmanager
def schema_errors(where: str, what: str = "a message"):
    """Turn what a malformed decoded value raises (a missing key, a wrong type or shape, an
    integer out of range) into one InputError naming the file, not a traceback."""
    try:
        yield
    except TmaError:  # already one line naming its cause (a ValueError too)
        raise
    except KeyError as exc:
        raise InputError(f"{where}: {what} lacks the field {exc}") from None
    except (TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise InputError(f"{where}: {what} does not follow its schema ({exc})") from None


_JSON_TYPE = {str: "a string", list: "an array", dict: "an object", bool: "a boolean",
              type(None): "null", int: "an integer", float: "a number"}


def _unexpected(kinds, allowed) -> str:
    return ", ".join(sorted(_JSON_TYPE.get(k, k.__name__) for k in kinds - allowed))


def number(value) -> float:
    """A JSON number as float; a string, boolean, null, array or object raises TypeError."""
    if type(value) not in (int, float):
        raise TypeError(f"expected a number, got {_unexpected({type(value)}, set())}")
    return float(value)


def integer(value) -> int:
    """A JSON integer; anything else (a float, boolean, string...) raises TypeError."""
    if type(value) is not int:
        raise TypeError(f"expected an integer, got {_unexpected({type(value)}, set())}")
    return value


def is_number(value) -> bool:
    """For metadata values: a real number (numpy's too), not a boolean."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def float_array(values) -> np.ndarray:
    """A JSON number or array of numbers as 1-D float64, null -> NaN. Strings, booleans,
    objects and nested arrays raise TypeError (numpy would convert some of them silently);
    checking the element types with ``set(map(type, ...))`` runs at C speed. A protobuf
    message's array (float64 already) passes as it is."""
    if type(values) is np.ndarray and values.dtype == np.float64:
        return values
    if type(values) is not list:
        values = [values]  # one value per message: scalar fields
    kinds = set(map(type, values))
    if not kinds <= {int, float, type(None)}:
        raise TypeError(f"expected numbers, got {_unexpected(kinds, {int, float, type(None)})}")
    return np.array(values, dtype=float)


def int_array(values) -> np.ndarray:
    """A JSON integer or array of integers as 1-D int64 (a float without fraction counts, as
    in JSON Schema). A fraction, a value beyond int64 or any other type raises, where numpy
    would truncate or wrap silently. A protobuf message's array (int64) passes as it is."""
    if type(values) is np.ndarray and values.dtype == np.int64:
        return values
    if type(values) is not list:
        values = [values]
    kinds = set(map(type, values))
    if kinds <= {int}:
        return np.array(values, dtype=np.int64)  # OverflowError beyond int64
    if not kinds <= {int, float}:
        raise TypeError(f"expected integers, got {_unexpected(kinds, {int, float})}")
    x = np.array(values, dtype=float)
    if not np.all((x == np.round(x)) & (np.abs(x) < 2.0**63)):
        raise ValueError("expected integers, got a fraction or a value beyond int64")
    return x.astype(np.int64)


def schema_bytes(name: str) -> bytes:
    return (SCHEMA_DIR / f"{name}.json").read_bytes()


ENCODINGS = ("json", "protobuf")  # of tma's schemas
# the chunk compression for each: lz4 leaves float64s (which no compressor shrinks much) at
# 20x zstd's speed; JSON text is half as large with zstd
COMPRESSION = {"protobuf": "lz4", "json": "zstd"}


@dataclass(frozen=True)
class Channel:
    """A topic, the name of its schema, and metadata (units, frames) for readers.

    ``encoding``: of a tma schema (``tma/io/schemas/<schema>.json``), ``"json"`` or
    ``"protobuf"`` (its protobuf twin, ``tma.io.proto_columns``). ``message_class``: a
    protobuf message class of a published schema (e.g. Foxglove's ``LocationFix``), whose
    schema mcap-protobuf-support builds from the class itself (``Channel.protobuf``)."""

    topic: str
    schema: str
    metadata: dict = field(default_factory=dict)
    message_class: type | None = None
    encoding: str = "json"

    def __post_init__(self):
        if self.encoding not in ENCODINGS:
            raise ValueError(f"{self.topic}: encoding {self.encoding!r} not in {ENCODINGS}")

    @classmethod
    def protobuf(cls, topic: str, message_class: type, metadata=None) -> "Channel":
        return cls(topic, message_class.DESCRIPTOR.full_name, metadata or {}, message_class,
                   "protobuf")

    def schema_record(self) -> tuple[str, bytes]:
        """(schema encoding, schema data) as the log embeds them."""
        if self.message_class is not None:
            return "protobuf", build_file_descriptor_set(self.message_class).SerializeToString()
        if self.encoding == "protobuf":
            return "protobuf", proto_schema(self.schema).descriptor_set
        return "jsonschema", schema_bytes(self.schema)

    def columns(self, fields: dict) -> Encoded:
        """Messages of this tma channel from whole columns (one value, or a ``Ragged``, per
        message and field): protobuf by ``encode_columns``; JSON (tma writes none itself)
        one object after the other."""
        if self.encoding == "protobuf":
            return encode_columns(proto_schema(self.schema), fields)
        columns = {k: np.split(c.values, np.cumsum(c.counts)[:-1]) if isinstance(c, Ragged)
                   else np.asarray(c).tolist() for k, c in fields.items()}
        n = {len(c) for c in columns.values()}
        if len(n) != 1:
            raise ValueError("JSON columns need a field, and as many values in each")
        return Encoded.of([self.encode({k: c[i] for k, c in columns.items()})
                           for i in range(n.pop())])

    def encode(self, message) -> bytes:
        """One message: a dict on a tma channel, a message object on a published one."""
        if self.message_class is not None:
            return message.SerializeToString(deterministic=True)
        if self.encoding == "json":
            return orjson.dumps(message, default=_strided_array, option=_JSON_OPTIONS)
        return encode_message(proto_schema(self.schema), message)


# -- absolute time ----------------------------------------------------------------------------

TIME = "tma.time"  # metadata record: {"epoch_utc_ns", "epoch_utc"} when the log has UTC times


def read_epoch(metadata: dict, where: str) -> int | None:
    """UTC ns of t = 0 from the ``tma.time`` record, None when the log has none."""
    if TIME not in metadata:
        return None
    with schema_errors(where, f"the metadata record {TIME}"):
        ns = integer(read_json_record(metadata, TIME, where)["epoch_utc_ns"])
        if not 0 <= ns < MAX_EPOCH_NS:
            raise ValueError(f"epoch_utc_ns {ns} is not between 1970 and 2200")
        return ns


class LogWriter:
    """Write messages to an MCAP file atomically (zstd or lz4 chunks)::

        with LogWriter(path, channels, metadata={"tma.dataset": {...}},
                       epoch_utc_ns=...) as log:
            log.write("/topic", t_s, {"t_s": t_s, ...})  # one message
            log.write_epochs(t_s_array, {"/a": log.columns("/a", {...}), "/b": [...]})  # many

    Messages are dicts on tma's channels, message objects on published protobuf channels,
    or already encoded (``Encoded``, e.g. ``columns`` of whole columns: the fast way). The
    file is byte for byte what ``mcap.writer.Writer`` writes for the same messages
    (``tma.io.mcap_writer``). ``epoch_utc_ns``: UTC of t = 0; ``log_time`` = ``publish_time``
    = epoch + t (absolute time, as Foxglove and other MCAP tools expect), recorded in the
    metadata record ``tma.time``; None keeps log times relative (t in ns). Payloads keep
    relative ``t_s``. ``compression``: of the chunks, ``"zstd"`` or ``"lz4"`` (for protobuf
    payloads: as small a file as zstd's within 15 %, 20x faster).
    """

    def __init__(self, path, channels, metadata=None, epoch_utc_ns=None, compression="zstd"):
        self.path, self.channels, self.metadata = Path(path), channels, dict(metadata or {})
        self.compression = compression
        self._by_topic = {ch.topic: ch for ch in channels}
        self.epoch_utc_ns = 0 if epoch_utc_ns is None else int(epoch_utc_ns)
        if not 0 <= self.epoch_utc_ns < 2**63:
            raise InputError(f"{self.path}: epoch {self.epoch_utc_ns} ns is not a UTC time "
                             "after 1970 that MCAP log times can hold")
        if epoch_utc_ns is not None:
            self.metadata[TIME] = json_record({"epoch_utc_ns": self.epoch_utc_ns,
                                               "epoch_utc": format_utc(self.epoch_utc_ns)})
        self.n_messages = 0

    def log_times(self, t_s) -> np.ndarray:
        """The log times (uint64 ns) of relative times ``t_s`` (s): epoch + t rounded to the
        ns (half to even), exactly. One InputError for a time outside 1970 + 2^64 ns."""
        t = np.asarray(t_s, dtype=float).ravel()
        with np.errstate(over="ignore", invalid="ignore"):  # refused below, in one line
            ns = np.rint(t * 1e9)
        fits = (ns > -(2.0**63)) & (ns < 2.0**64)  # False for NaN
        before = fits & (ns < 0)
        back = np.where(before, -ns, 0).astype(np.uint64)  # exact: integers below 2^64
        ahead = np.where(fits & ~before, ns, 0).astype(np.uint64)
        epoch = np.uint64(self.epoch_utc_ns)
        fits &= np.where(before, back <= epoch, ahead <= np.uint64(2**64 - 1) - epoch)
        if not fits.all():
            raise self._outside(t[np.argmin(fits)])
        return np.where(before, epoch - back, epoch + ahead)

    def time_ns(self, t_s: float) -> int:
        """The log time (ns) of one relative time ``t_s`` (s), as ``log_times`` gives it."""
        ns = float(t_s) * 1e9
        t_ns = self.epoch_utc_ns + round(ns) if math.isfinite(ns) else -1
        if not 0 <= t_ns < 2**64:
            raise self._outside(t_s)
        return t_ns

    def _outside(self, t_s) -> InputError:
        return InputError(f"{self.path}: time {float(t_s)!r} s (epoch {self.epoch_utc_ns} ns) "
                          "is outside MCAP's log time range (0 to 2^64 ns after 1970)")

    def __enter__(self):
        self._stack = contextlib.ExitStack()
        tmp = self._stack.enter_context(atomic_path(self.path))
        self._file = self._stack.enter_context(open(tmp, "wb"))  # closed before the rename
        self._mcap = McapWriter(self._file, profile=PROFILE, library=f"tma {__version__}",
                                compression=self.compression)
        self._ids, schema_ids = {}, {}
        for ch in self.channels:
            record = ch.schema_record()
            if (ch.schema, record[0]) not in schema_ids:
                schema_ids[ch.schema, record[0]] = self._mcap.add_schema(ch.schema, *record)
            self._ids[ch.topic] = self._mcap.add_channel(
                ch.topic, ch.encoding, schema_ids[ch.schema, record[0]],
                {k: str(v) for k, v in ch.metadata.items()})
        for name, record in self.metadata.items():
            self._mcap.add_metadata(name, {k: str(v) for k, v in record.items()})
        self._loose = ([], [], [], bytearray())  # write()'s messages: ids, times, sizes, data
        return self

    def _encode(self, topic: str, message) -> bytes:
        return self._by_topic[topic].encode(message)

    def columns(self, topic: str, fields: dict) -> Encoded:
        """Messages on ``topic`` (a tma schema) from whole columns, in its encoding."""
        return self._by_topic[topic].columns(fields)

    def write(self, topic: str, t_s: float, message):
        """Write ``message`` (a dict, or a protobuf message on a protobuf channel) at
        relative time ``t_s`` (s)."""
        channel, t_ns, data = self._ids[topic], self.time_ns(t_s), self._encode(topic, message)
        ids, times, sizes, payloads = self._loose
        ids.append(channel)
        times.append(t_ns)
        sizes.append(len(data))
        payloads += data  # not kept as objects: many small bytes alive slow orjson down
        self.n_messages += 1
        if len(payloads) > CHUNK_SIZE:
            self._flush_loose()

    def _flush_loose(self):
        ids, times, sizes, payloads = self._loose
        if ids:
            self._mcap.add_messages(np.array(ids, np.uint16), np.array(times, np.uint64),
                                    [np.frombuffer(payloads, np.uint8)],
                                    np.cumsum(sizes) - sizes, np.array(sizes))
            self._loose = ([], [], [], bytearray())

    def write_epochs(self, t_s, messages: dict):
        """At each time ``t_s[i]`` (s), one message per topic of ``messages``, in its order:
        ``messages[topic]`` holds one message per time, as an ``Encoded`` or a sequence of
        what ``write`` takes."""
        times = self.log_times(t_s)
        columns = [m if isinstance(m, Encoded) else Encoded.of([self._encode(topic, x)
                                                                for x in m])
                   for topic, m in messages.items()]
        if any(len(c) != times.size for c in columns):
            raise ValueError("write_epochs needs one message per topic and time")
        if not times.size:
            return
        self._flush_loose()
        buffers, starts, lengths = interleave(columns)
        ids = np.tile(np.array([self._ids[topic] for topic in messages], np.uint16), times.size)
        self._mcap.add_messages(ids, np.repeat(times, len(columns)), buffers, starts, lengths)
        self.n_messages += ids.size

    def write_encoded(self, topics: list[str], which, t_s, payloads: Encoded):
        """Encoded messages of several topics, in this order: message k on
        ``topics[which[k]]`` at relative time ``t_s[k]`` (s); the same bytes as ``write`` of
        each in turn."""
        times = self.log_times(t_s)
        if len(payloads) != times.size:
            raise ValueError("write_encoded needs one time per message")
        if not times.size:
            return
        self._flush_loose()
        ids = np.array([self._ids[topic] for topic in topics], np.uint16)[np.asarray(which)]
        self._mcap.add_messages(ids, times, [payloads.data], payloads.offsets[:-1],
                                np.diff(payloads.offsets))
        self.n_messages += ids.size

    def write_many(self, topic: str, t_s, messages):
        """One message on ``topic`` at each time ``t_s[i]`` (s): ``write_epochs`` of one
        topic."""
        self.write_epochs(t_s, {topic: messages})

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            try:
                self._flush_loose()
                self._mcap.finish()
            except BaseException:
                if not self._stack.__exit__(*sys.exc_info()):
                    raise
                return False
        return self._stack.__exit__(exc_type, exc, tb)


@functools.cache
def tma_schema_names() -> frozenset[str]:
    """The names of tma's schemas (``tma/io/schemas/<name>.json``)."""
    return frozenset(p.name.removesuffix(".json") for p in SCHEMA_DIR.glob("*.json"))


def checked_proto_schema(schema):
    """The protobuf twin of a tma schema that an MCAP file declares with protobuf encoding;
    ValueError unless the file's FileDescriptorSet declares tma's fields."""
    ours = proto_schema(schema.name)
    if schema.encoding != "protobuf" or not ours.matches(schema.data):
        raise ValueError(f"the protobuf schema '{schema.name}' does not declare tma's fields "
                         "(see docs/formats.md)")
    return ours


class TmaDecoderFactory(DecoderFactory):
    """Decoders of tma's schemas for the mcap reader: ``json`` messages with orjson (mcap 1.6
    ships no JSON decoder), ``protobuf`` ones of a tma schema with ``decode_message``."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding == "json":
            return orjson.loads
        if (message_encoding == "protobuf" and schema is not None
                and schema.name in tma_schema_names()):
            return functools.partial(decode_message, checked_proto_schema(schema))
        return None


_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary_start, summary_offset_start, crc
_DATA_END = struct.Struct("<BQI")  # opcode, length, data_section_crc
_FOOTER_OPCODE, _DATA_END_OPCODE = 0x02, 0x0F


def check_integrity(data: bytes, crcs: bool = True) -> str | None:
    """Why ``data`` is not an intact MCAP file with a summary section, or None.

    Checks the magic at both ends, that the Footer and the DataEnd (the record just before
    the summary) are where and what they must be, and (``crcs``) the Footer's
    ``summary_crc`` (summary section + the Footer's other fields) and the DataEnd's
    ``data_section_crc`` (the magic, header, chunks, message indexes, metadata: everything
    before DataEnd). A CRC of 0 means "not computed" and is skipped. Chunk CRCs are checked
    by mcap as chunks are read.
    """
    view = memoryview(data)
    if not data.startswith(MAGIC):
        return "no MCAP magic at the start"
    footer_at = len(data) - len(MAGIC) - _FOOTER.size
    if footer_at < len(MAGIC) + _DATA_END.size or not data.endswith(MAGIC):
        return "truncated: no MCAP magic at the end"
    opcode, length, summary_start, _, summary_crc = _FOOTER.unpack_from(data, footer_at)
    if (opcode, length) != (_FOOTER_OPCODE, _FOOTER.size - 9):
        return "damaged or truncated: no footer before the closing magic"
    if summary_start == 0:
        return "no summary section (truncated?)"
    data_end_at = summary_start - _DATA_END.size
    if not len(MAGIC) <= data_end_at < summary_start <= footer_at:
        return "damaged footer: summary offset out of range"
    if crcs and summary_crc and summary_crc != zlib.crc32(
            view[footer_at:footer_at + _FOOTER.size - 4],
            zlib.crc32(view[summary_start:footer_at])):
        return "summary section or footer fails its CRC check (damaged)"
    opcode, length, data_crc = _DATA_END.unpack_from(data, data_end_at)
    if (opcode, length) != (_DATA_END_OPCODE, 4):
        return "damaged: no DataEnd record before the summary section"
    if crcs and data_crc and data_crc != zlib.crc32(view[:data_end_at]):
        return "data section fails its CRC check (damaged)"
    return None


def _detail(exc: Exception) -> str:
    return f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"


@contextlib.contextmanager
def invalid_mcap(where: str):
    """Whatever parsing untrusted bytes raises (mcap, zstd/lz4, struct, Unicode, orjson,
    KeyError on a dangling id, MemoryError on an absurd size...) means a damaged or foreign
    file: one InputError naming it."""
    try:
        yield
    except TmaError:
        raise
    except Exception as exc:
        raise InputError(f"{where}: not a valid MCAP log ({_detail(exc)})") from None


def ros2_type(name: str) -> str:
    """ROS 2 type names as ``pkg/msg/Type``; some writers drop the ``msg`` (``pkg/Type``)."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


@dataclass
class Topic:
    """A topic of an MCAP file: its schema name, message encoding, message count (from the
    statistics; None without them) and channels."""

    name: str
    schema: str
    encoding: str
    count: int | None
    channels: list
    mixed: bool = False  # channels of different schemas or encodings share the topic

    def __str__(self):
        count = "?" if self.count is None else self.count
        return f"{self.name} ({self.schema or 'no schema'}, {count})"


class McapFile:
    """An MCAP file read whole and checked once, its topics decoded on demand: the one MCAP
    reader of tma (its own logs, ``read_log``; any log a user brings, ``tma.sources.mcap``).

    Before anything is decoded: ``check_integrity`` (magic, footer, summary and data-section
    CRCs) and the metadata count against the summary's statistics; as topics are read, each
    chunk's CRC and the message counts. Bytes a dataset manifest verified
    (``VerifiedPath``) are parsed as they are, their CRCs not checked again (the sha256 covers
    them). ``topics`` maps each topic to its ``Topic`` (ROS 2 schema names as
    ``pkg/msg/Type``); ``metadata`` the metadata records by name."""

    def __init__(self, path):
        self.path, self.where = Path(path), str(path)
        self._crcs = not (isinstance(path, VerifiedPath) and path.data is not None)
        try:
            self._data = Path(path).read_bytes() if self._crcs else path.data
        except FileNotFoundError:
            raise MissingFileError(f"{path}: no such file") from None
        except OSError as exc:
            raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
        problem = check_integrity(self._data, self._crcs)
        if problem:
            raise InputError(f"{path}: not a valid MCAP log ({problem})")
        with invalid_mcap(self.where):
            self._reader = SeekingReader(BytesIO(self._data), validate_crcs=self._crcs)
            self.summary = self._reader.get_summary()
            records = list(self._reader.iter_metadata())
        stats = self.summary.statistics
        # The statistics repeat what the indexes should lead to: for a file without CRCs this
        # catches a damaged chunk or metadata index that would silently drop records.
        if stats is not None and len(records) != stats.metadata_count:
            raise InputError(f"{path}: {len(records)} metadata records, the summary counts "
                             f"{stats.metadata_count} (damaged index?)")
        self.metadata = {m.name: dict(m.metadata) for m in records}
        self.topics = {}
        for ch in sorted(self.summary.channels.values(), key=lambda c: c.id):
            schema = self.summary.schemas.get(ch.schema_id)
            name = "" if schema is None else schema.name
            if ch.message_encoding == "cdr":
                name = ros2_type(name)
            count = None if stats is None else stats.channel_message_counts.get(ch.id, 0)
            topic = self.topics.setdefault(ch.topic, Topic(ch.topic, name, ch.message_encoding,
                                                           0, []))
            if (topic.schema, topic.encoding) != (name, ch.message_encoding):
                topic.schema, topic.mixed = f"{topic.schema} | {name}", True
            topic.channels.append(ch)
            topic.count = None if count is None or topic.count is None else topic.count + count

    def describe(self) -> str:
        """What the file holds, for messages: ``topics /a (schema, messages), ...``."""
        if not self.topics:
            return "the file has no topics"
        return "topics " + ", ".join(str(t) for t in self.topics.values())

    def schema(self, channel):
        return self.summary.schemas.get(channel.schema_id)

    def _decoder(self, channel, factories, reads: str):
        schema = self.schema(channel)
        for factory in factories:
            try:
                decoder = factory.decoder_for(channel.message_encoding, schema)
            except Exception as exc:
                raise InputError(f"{self.where}: the schema of {channel.topic} "
                                 f"({schema.name}) cannot be parsed ({_detail(exc)})") from None
            if decoder is not None:
                return decoder
        raise InputError(
            f"{self.where}: cannot decode {channel.topic}: message encoding "
            f"'{channel.message_encoding}', schema encoding "
            f"'{getattr(schema, 'encoding', '')}'; tma reads {reads}")

    def read(self, names: list[str], factories, reads: str = "json and protobuf"
             ) -> dict[str, tuple[np.ndarray, list]]:
        """``{topic: (log times (uint64 ns), decoded messages)}`` of these topics, in log-time
        order (equal times keep their file order), in one pass over the file. ``factories``:
        mcap ``DecoderFactory``s, the first that decodes a channel is used; ``reads`` says
        which encodings they decode, for the message when none does. A message that does not
        decode, or counts that contradict the statistics, raise InputError."""
        mixed = [n for n in names if self.topics[n].mixed]
        if mixed:
            raise InputError(f"{self.where}: {mixed[0]} has channels of different schemas "
                             f"({self.topics[mixed[0]].schema}): tma cannot tell which to read")
        channels = {ch.id: ch for name in names for ch in self.topics[name].channels}
        decoders = {cid: self._decoder(ch, factories, reads) for cid, ch in channels.items()}
        times, decoded = {n: [] for n in names}, {n: [] for n in names}
        counts = Counter()
        with invalid_mcap(self.where):
            reader = self._reader
            if not self.summary.chunk_indexes:  # mcap would scan without checking chunk CRCs
                reader = NonSeekingReader(BytesIO(self._data), validate_crcs=self._crcs)
            # in file order (mcap's log-time order costs a heap operation per message)
            for _, channel, message in reader.iter_messages(topics=names, log_time_order=False):
                try:
                    value = decoders[channel.id](message.data)
                except Exception as exc:
                    raise InputError(
                        f"{self.where}: the message on {channel.topic} at log time "
                        f"{message.log_time} ns does not decode as "
                        f"{self.topics[channel.topic].schema} ({_detail(exc)})") from None
                times[channel.topic].append(message.log_time)
                decoded[channel.topic].append(value)
                counts[channel.id] += 1
        stats = self.summary.statistics
        for cid, ch in channels.items():
            expected = None if stats is None else stats.channel_message_counts.get(cid, 0)
            if expected is not None and counts[cid] != expected:
                raise InputError(f"{self.where}: {counts[cid]} messages on {ch.topic}, the "
                                 f"summary counts {expected} (damaged index?)")
        out = {}
        for name in names:
            log_times = np.array(times[name], np.uint64)
            messages = decoded[name]
            if np.any(log_times[1:] < log_times[:-1]):
                order = np.argsort(log_times, kind="stable")
                log_times, messages = log_times[order], [messages[i] for i in order]
            out[name] = (log_times, messages)
        return out


def read_log(path, expected: dict[str, str], nonempty: bool = False):
    """Read an MCAP log of tma's schemas. ``expected`` maps topic -> schema name;
    ``nonempty``: each of these topics must hold a message.

    Returns ``(messages, metadata)``: ``messages[topic]`` is a list of decoded dicts in
    log-time order, ``metadata`` maps metadata record names to dicts. Raises one
    ``InputError`` naming the file for a non-MCAP, truncated or damaged file (``McapFile``),
    for missing topics or mismatched schemas, for a message that is not a JSON object and for
    message counts that contradict the summary's statistics.
    """
    file = McapFile(path)
    where = file.where
    missing = [t for t in expected if t not in file.topics]
    if missing:
        raise InputError(
            f"{where}: missing topic(s) {', '.join(missing)}; "
            f"the log has: {', '.join(sorted(file.topics)) or 'no channels'}"
        )
    for topic, schema_name in expected.items():
        found = file.topics[topic]
        if found.schema != schema_name:
            raise InputError(f"{where}: topic {topic} has schema '{found.schema}', expected "
                             f"'{schema_name}'")
        if found.encoding not in ENCODINGS:
            raise InputError(f"{where}: topic {topic} has message encoding "
                             f"'{found.encoding}'; tma reads {' or '.join(ENCODINGS)}")
        if found.encoding == "protobuf":
            try:
                checked_proto_schema(file.schema(found.channels[0]))
            except ValueError as exc:
                raise InputError(f"{where}: topic {topic}: {exc}") from None
    messages = {}
    for topic, (log_times, decoded) in file.read(list(expected), [TmaDecoderFactory()]).items():
        wrong = [type(m) is not dict for m in decoded]
        if any(wrong):
            raise InputError(f"{where}: the message on {topic} at log time "
                             f"{log_times[wrong.index(True)]} ns is not a JSON object")
        messages[topic] = decoded
    empty = [topic for topic in expected if nonempty and not messages[topic]]
    if empty:
        raise InputError(f"{where}: no messages on {', '.join(empty)}")
    return messages, file.metadata


# -- the records every log may carry -----------------------------------------------------------

GEO = "tma.geo"  # {origin_lat_deg, origin_lon_deg, epoch_utc_ns}: the local plane's origin
TRACKS = "tma.tracks"  # {"track_id": [...], "label": [...]}: the contacts' text labels


def geo_origin(metadata: dict, where: str) -> tuple[float, float] | None:
    """(lat, lon) in deg of the log's local plane, from ``tma.geo``; None without it."""
    if GEO not in metadata:
        return None
    with schema_errors(where, f"the metadata record {GEO}"):
        geo = read_json_record(metadata, GEO, where)
        return number(geo["origin_lat_deg"]), number(geo["origin_lon_deg"])


def track_labels(metadata: dict, track_id: np.ndarray, where: str) -> np.ndarray | None:
    """The labels of ``track_id`` from ``tma.tracks``, as an object array, or None."""
    if TRACKS not in metadata:
        return None
    with schema_errors(where, f"the metadata record {TRACKS}"):
        record = read_json_record(metadata, TRACKS, where)
        ids = [integer(i) for i in record["track_id"]]
        labels = dict(zip(ids, record["label"], strict=True))
    missing = [int(i) for i in track_id if int(i) not in labels]
    if missing:
        raise InputError(f"{where}: the metadata record {TRACKS} has no label for track(s) "
                         f"{', '.join(map(str, missing[:10]))}")
    return np.array([labels[int(i)] for i in track_id], dtype=object)
