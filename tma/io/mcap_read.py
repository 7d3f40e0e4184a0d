"""Every MCAP file tma reads, its own or a user's, read by one checked reader
(``McapFile``, under ``read_log`` for tma's own schemas): the integrity of the whole file
checked before anything is decoded (``check_integrity``: the magic at both ends, the Footer
and DataEnd, every CRC MCAP has), then each chunk's CRC as it is read and the message and
metadata counts against the summary's statistics; a damaged file is one ``InputError`` naming
it. A CRC of 0 means "not computed" (MCAP spec; other tools may write files so): what it
would cover is then unchecked, see docs/formats.md. tma's schemas are decoded as JSON or as
their protobuf twins (``TmaDecoderFactory``).
"""

import contextlib
import functools
import struct
import zlib
from collections import Counter
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

import numpy as np
import orjson
from mcap.decoder import DecoderFactory
from mcap.reader import NonSeekingReader, SeekingReader

from tma.errors import InputError, MissingFileError, TmaError
from tma.io.atomic import VerifiedPath
from tma.io.mcap_log import ENCODINGS
from tma.io.mcap_writer import MAGIC
from tma.io.proto_columns import (
    SCHEMA_DIR,
    decode_message,
    proto_schema,
)


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


def read_log(path, expected, nonempty: bool = False):
    """Read an MCAP log of tma's schemas. ``expected`` maps topic -> schema name (or is a
    function of the metadata records and the file's name for messages that gives that map:
    a log whose records say which topics it holds); ``nonempty``: each of these topics must
    hold a message.

    Returns ``(messages, metadata)``: ``messages[topic]`` is a list of decoded dicts in
    log-time order, ``metadata`` maps metadata record names to dicts. Raises one
    ``InputError`` naming the file for a non-MCAP, truncated or damaged file (``McapFile``),
    for missing topics or mismatched schemas, for a message that is not a JSON object and for
    message counts that contradict the summary's statistics.
    """
    file = McapFile(path)
    where = file.where
    if callable(expected):
        expected = expected(file.metadata, where)
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

