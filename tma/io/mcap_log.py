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
by a CRC or is a fixed field checked by value (magic, DataEnd and Footer opcode and length);
``tma.io.mcap_read`` checks them all. The records every log may carry (``tma.time``,
``tma.geo``, ``tma.tracks``) are written and read here; values in messages and records are
coerced by ``tma.io.mcap_values``.
"""

import contextlib
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tma.errors import InputError
from tma.io.atomic import atomic_path
from tma.io.mcap_values import (
    integer,
    json_bytes,
    json_record,
    number,
    read_json_record,
    schema_errors,
)
from tma.io.mcap_writer import CHUNK_SIZE, Encoded, McapWriter, Ragged, interleave
from tma.io.proto_columns import (
    SCHEMA_DIR,
    encode_columns,
    encode_message,
    proto_schema,
)
from tma.utc import MAX_EPOCH_NS, format_utc
from tma.version import __version__

PROFILE = ""  # plain MCAP (JSON and protobuf channels): no ROS profile


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
            # mcap-protobuf-support loads mcap's writer and importlib.metadata (0.08 s): where
            # a log is written, not in every command's start-up
            from mcap_protobuf.schema import build_file_descriptor_set

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
            return json_bytes(message)
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



# -- the records every log may carry -----------------------------------------------------------

GEO = "tma.geo"  # {origin_lat_deg, origin_lon_deg, epoch_utc_ns}: the local plane's origin
PLATFORMS = "tma.platforms"  # {"names": [...]}: a log of several platforms, in index order
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


def platform_namespace(k: int) -> str:
    """The namespace of platform ``k``'s topics in a log of several (``/platforms/<k>``)."""
    return f"/platforms/{k}"


def platform_names(metadata: dict, where: str) -> tuple[str, ...] | None:
    """The platforms' names of a log of several (``tma.platforms``); None for one."""
    if PLATFORMS not in metadata:
        return None
    with schema_errors(where, f"the metadata record {PLATFORMS}"):
        names = read_json_record(metadata, PLATFORMS, where)["names"]
        if not isinstance(names, list) or not names or not all(
                isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
            raise TypeError("names is not a list of distinct texts")
    return tuple(names)
