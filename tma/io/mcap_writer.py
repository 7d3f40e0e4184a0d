"""Writing MCAP fast: message records, chunks and indexes built from whole columns at once.

``McapWriter`` writes exactly the bytes of ``mcap.writer.Writer(compression=ZSTD or LZ4,
enable_crcs=True, enable_data_crcs=True)`` with its other defaults (1 MiB chunks, every index,
schemas and channels repeated in the summary, statistics, summary offsets) given the same
schemas, channels, metadata and messages in the same order; ``tests/test_mcap_writer.py``
compares the bytes. mcap's writer costs ~2.5 us of Python per message; here a message costs a
few array elements: its 31-byte header is a row of a numpy structured array, records are
copied into place by one fancy index (``gather``), message indexes are arrays. Records that
occur once per file or chunk are mcap's own record classes (the Chunk record's head is packed
by hand, to write its data without copying it twice).

Why it exists: it pays where messages are many and small. A default shard (601 epochs of
2,000 bearings) writes as fast with mcap's writer; a recorded log of one contact, a bearing
per message, writes ~7x faster here (a million bearings: 0.8 s against 5.4 s; ``make bench``,
section io, measures both).
"""

import struct
import zlib
from dataclasses import dataclass

import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b"\x89MCAP0\r\n"
CHUNK_SIZE = 1024 * 1024  # mcap's default: a chunk closes after the message that exceeds it
LONG_SEGMENT = 256  # bytes: segments this long on average are copied by slices
ZSTD_LEVEL = 3  # zstandard.compress's default, which mcap's writer calls
COMPRESSIONS = ("zstd", "lz4")
# A Message record: opcode, record length, then the fields (spec order), then the data.
MESSAGE_HEADER = np.dtype([("opcode", "u1"), ("length", "<u8"), ("channel_id", "<u2"),
                           ("sequence", "<u4"), ("log_time", "<u8"), ("publish_time", "<u8")])
_FIELDS_SIZE = MESSAGE_HEADER.itemsize - 9  # record length = this + len(data)
# Chunk: opcode, record length, message start and end time, uncompressed size and CRC, then
# the compression (length-prefixed), the compressed size and the compressed records
_CHUNK = struct.Struct("<BQQQQI")
_MESSAGE_INDEX = struct.Struct("<BQHI")  # opcode, record length, channel_id, entries' bytes
_FOOTER_FIELDS = struct.Struct("<BQQQ")  # opcode, length, summary_start, summary_offset_start


def gather(buffers: list[np.ndarray], starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Bytes ``starts[k]`` to ``starts[k] + lengths[k]`` of the uint8 arrays ``buffers`` one
    after the other (no segment crossing from one buffer into the next), for k = 0, 1, ...
    one after the other. Long segments are copied slice by slice; short ones by one fancy
    index: the source of each byte out is the previous byte's + 1, except where a segment
    begins (a cumulative sum of those steps)."""
    some = lengths > 0
    starts, lengths = starts[some].astype(np.int64), lengths[some].astype(np.int64)
    if not lengths.size:
        return np.zeros(0, np.uint8)
    ends = np.cumsum(lengths)  # in the output
    if ends[-1] > LONG_SEGMENT * lengths.size:
        bases = np.cumsum([0] + [b.size for b in buffers])
        which = np.searchsorted(bases, starts, side="right") - 1
        starts = starts - bases[which]
        return np.concatenate([buffers[w][a:a + n] for w, a, n in zip(
            which.tolist(), starts.tolist(), lengths.tolist(), strict=True)])
    src = buffers[0] if len(buffers) == 1 else np.concatenate(buffers)
    index = np.ones(int(ends[-1]), np.int32 if src.size < 2**31 else np.int64)
    index[0] = starts[0]
    index[ends[:-1]] = starts[1:] - (starts[:-1] + lengths[:-1]) + 1
    return src[np.cumsum(index, out=index)]


@dataclass(frozen=True)
class Encoded:
    """n encoded messages one after the other: message i is ``data[offsets[i]:offsets[i+1]]``
    (``data`` uint8, ``offsets`` (n + 1,) int64 from 0)."""

    data: np.ndarray
    offsets: np.ndarray

    @classmethod
    def of(cls, payloads) -> "Encoded":
        """From a sequence of ``bytes``."""
        lengths = np.fromiter(map(len, payloads), np.int64, len(payloads))
        return cls(np.frombuffer(b"".join(payloads), np.uint8),
                   np.concatenate(([0], np.cumsum(lengths))))

    def __len__(self) -> int:
        return self.offsets.size - 1

    def __getitem__(self, i: int) -> bytes:
        return self.data[self.offsets[i]:self.offsets[i + 1]].tobytes()


def interleave(columns: list[Encoded]) -> tuple[list, np.ndarray, np.ndarray]:
    """``(buffers, starts, lengths)`` of the messages ``columns[0][0], columns[1][0], ...,
    columns[0][1], ...`` (row after row; the columns have equal lengths): message k is
    bytes ``starts[k]`` to ``starts[k] + lengths[k]`` of the buffers one after the other."""
    bases = np.cumsum([0] + [c.data.size for c in columns[:-1]])
    starts = np.stack([c.offsets[:-1] + b for c, b in zip(columns, bases, strict=True)], 1)
    lengths = np.stack([np.diff(c.offsets) for c in columns], 1)
    return [c.data for c in columns], starts.ravel(), lengths.ravel()


@dataclass(frozen=True)
class Ragged:
    """One array per message: message i holds the next ``counts[i]`` of ``values`` (the
    arrays one after the other)."""

    values: np.ndarray
    counts: np.ndarray


# -- the file ----------------------------------------------------------------------------------

def _record(record) -> bytes:
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()


@dataclass
class _Records:
    """Message records in file order: ``data`` (uint8) with record i ending at ``ends[i]``
    (exclusive, from 0), and each record's channel and log time."""

    data: np.ndarray
    ends: np.ndarray
    channel_id: np.ndarray
    log_time: np.ndarray

    def __len__(self) -> int:
        return self.ends.size

    @classmethod
    def join(cls, parts: list["_Records"]) -> "_Records":
        if len(parts) == 1:
            return parts[0]
        bases = np.cumsum([0] + [p.data.size for p in parts[:-1]])
        return _Records(np.concatenate([p.data for p in parts]),
                        np.concatenate([p.ends + b for p, b in zip(parts, bases, strict=True)]),
                        np.concatenate([p.channel_id for p in parts]),
                        np.concatenate([p.log_time for p in parts]))

    def slice(self, first: int, stop: int) -> "_Records":
        """Records first to stop - 1."""
        start = int(self.ends[first - 1]) if first else 0
        end = int(self.ends[stop - 1]) if stop > first else start
        return _Records(self.data[start:end], self.ends[first:stop] - start,
                        self.channel_id[first:stop], self.log_time[first:stop])


class McapWriter:
    """An MCAP file on ``stream`` (binary, empty): ``add_schema`` and ``add_channel`` first,
    then ``add_metadata`` and ``add_messages`` in any order, then ``finish``. The bytes are
    those of ``mcap.writer.Writer`` (see the module docstring) with ``chunk_size`` and
    ``compression`` (``"zstd"``, or ``"lz4"``: ~20x faster to write for binary payloads
    of float64s, which no compressor shrinks much, at a slightly larger file)."""

    def __init__(self, stream, profile: str = "", library: str = "",
                 chunk_size: int = CHUNK_SIZE, compression: str = "zstd"):
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression {compression!r} is not one of {COMPRESSIONS}")
        self._stream, self._position, self._data_crc = stream, 0, 0
        self._chunk_size, self._compression = chunk_size, compression
        if compression == "zstd":
            self._compress = zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress
        else:
            import lz4.frame

            self._compress = lz4.frame.compress  # with mcap's writer's (default) arguments
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._opening = b""  # schema and channel records: the first chunk begins with them
        self._pending: list[_Records] = []  # messages not yet in a chunk: less than one
        self._pending_size = 0  # their bytes
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._message_counts: dict[int, int] = {}  # per channel, in order of first message
        self._n_messages, self._time_range = 0, (0, 0)
        self._write(MAGIC + _record(Header(profile, library)))

    @property
    def n_messages(self) -> int:
        return self._n_messages

    def _write(self, data):
        self._stream.write(data)
        self._data_crc = zlib.crc32(data, self._data_crc)
        self._position += len(data)

    def _open(self, record) -> int:
        if self._n_messages:
            raise RuntimeError("schemas and channels come before the messages")
        self._opening += _record(record)
        return record.id

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Register a schema; returns its id."""
        self._schemas.append(Schema(len(self._schemas) + 1, data, encoding, name))
        return self._open(self._schemas[-1])

    def add_channel(self, topic: str, message_encoding: str, schema_id: int,
                    metadata: dict[str, str]) -> int:
        """Register a channel; returns its id."""
        self._channels.append(Channel(len(self._channels) + 1, topic, message_encoding,
                                      metadata, schema_id))
        return self._open(self._channels[-1])

    def add_metadata(self, name: str, data: dict[str, str]):
        record = _record(Metadata(name, data))
        self._metadata_indexes.append(MetadataIndex(self._position, len(record), name))
        self._write(record)

    def add_messages(self, channel_id, log_time, buffers, starts, lengths):
        """Messages in this order: message i is on ``channel_id[i]`` at ``log_time[i]`` (ns,
        also its publish time) with payload bytes ``starts[i]`` to ``starts[i] + lengths[i]``
        of the uint8 arrays ``buffers`` one after the other; sequence numbers count the
        messages of the file from 0."""
        n = len(lengths)
        if not n:
            return
        if self._n_messages + n > 2**32:
            raise ValueError("an MCAP sequence number holds at most 2^32 messages")
        headers = np.empty(n, MESSAGE_HEADER)
        headers["opcode"] = Opcode.MESSAGE
        headers["length"] = _FIELDS_SIZE + lengths
        headers["channel_id"] = channel_id
        headers["sequence"] = np.arange(self._n_messages, self._n_messages + n)
        headers["log_time"] = headers["publish_time"] = log_time
        size = MESSAGE_HEADER.itemsize
        segments = np.stack((np.arange(n) * size, starts + n * size), 1).ravel()
        segment_lengths = np.stack((np.full(n, size), lengths), 1).ravel()
        records = gather([headers.view(np.uint8), *buffers], segments, segment_lengths)
        self._count(headers["channel_id"], headers["log_time"])
        self._write_full_chunks(_Records(records, np.cumsum(size + lengths),
                                         headers["channel_id"], headers["log_time"]))

    def _count(self, channel_id, log_time):
        ids, first, counts = np.unique(channel_id, return_index=True, return_counts=True)
        for k in np.argsort(first, kind="stable"):
            key = int(ids[k])
            self._message_counts[key] = self._message_counts.get(key, 0) + int(counts[k])
        low, high = int(log_time.min()), int(log_time.max())
        if self._n_messages:
            low, high = min(low, self._time_range[0]), max(high, self._time_range[1])
        self._n_messages += channel_id.size
        self._time_range = (low, high)

    def _write_full_chunks(self, records: _Records):
        """Write every chunk the pending messages and ``records`` complete, keep the rest:
        mcap closes a chunk after the first message that takes it past ``chunk_size`` bytes
        (the opening records included)."""
        done = 0  # records written
        while done < len(records):
            opening = 0 if self._chunk_indexes else len(self._opening)
            base = int(records.ends[done - 1]) if done else 0
            last = int(np.searchsorted(records.ends, base + self._chunk_size - opening
                                       - self._pending_size, side="right"))
            if last == len(records):
                break
            self._write_chunk(_Records.join([*self._pending, records.slice(done, last + 1)]))
            self._pending, self._pending_size, done = [], 0, last + 1
        if done < len(records):
            self._pending.append(records.slice(done, len(records)))
            self._pending_size += self._pending[-1].data.size

    def _write_chunk(self, messages: _Records):
        opening = b"" if self._chunk_indexes else self._opening
        content = (np.concatenate((np.frombuffer(opening, np.uint8), messages.data)) if opening
                   else messages.data)  # a view of the records: most chunks copy nothing
        compressed = self._compress(content)
        start_time, end_time = int(messages.log_time.min()), int(messages.log_time.max())
        chunk_start = self._position
        # the Chunk record as mcap.records.Chunk writes it, without copying its data twice
        name = self._compression.encode()
        tail = struct.pack(f"<I{len(name)}sQ", len(name), name, len(compressed))
        head = _CHUNK.pack(Opcode.CHUNK, _CHUNK.size + len(tail) - 9 + len(compressed),
                           start_time, end_time, content.size, zlib.crc32(content)) + tail
        self._write(head)
        self._write(compressed)
        offsets = len(opening) + np.concatenate(([0], messages.ends[:-1]))
        ids, first = np.unique(messages.channel_id, return_index=True)
        indexes, index_offsets = [], {}
        for channel in ids[np.argsort(first, kind="stable")]:
            mine = messages.channel_id == channel
            entries = np.empty((int(mine.sum()), 2), "<u8")
            entries[:, 0], entries[:, 1] = messages.log_time[mine], offsets[mine]
            index_offsets[int(channel)] = self._position + sum(map(len, indexes))
            indexes.append(_MESSAGE_INDEX.pack(Opcode.MESSAGE_INDEX, 6 + entries.nbytes,
                                               channel, entries.nbytes) + entries.tobytes())
        index_bytes = b"".join(indexes)
        self._write(index_bytes)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start_time, message_end_time=end_time,
            chunk_start_offset=chunk_start, chunk_length=len(head) + len(compressed),
            message_index_offsets=index_offsets, message_index_length=len(index_bytes),
            compression=self._compression, compressed_size=len(compressed),
            uncompressed_size=content.size))

    def finish(self):
        """Write the last chunk, the summary and the footer (the stream stays open)."""
        if self._pending:
            self._write_chunk(_Records.join(self._pending))
            self._pending, self._pending_size = [], 0
        self._write(_record(DataEnd(self._data_crc)))
        summary_start = self._position
        statistics = Statistics(
            attachment_count=0, channel_count=len(self._channels),
            channel_message_counts=self._message_counts, chunk_count=len(self._chunk_indexes),
            message_count=self._n_messages, message_start_time=self._time_range[0],
            message_end_time=self._time_range[1], metadata_count=len(self._metadata_indexes),
            schema_count=len(self._schemas))
        groups = [(Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                  (Opcode.STATISTICS, [statistics]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.ATTACHMENT_INDEX, []), (Opcode.METADATA_INDEX, self._metadata_indexes)]
        summary, offsets = b"", []
        for opcode, records in groups:
            group = b"".join(map(_record, records))
            offsets.append(SummaryOffset(opcode, summary_start + len(summary), len(group)))
            summary += group
        offsets_start = summary_start + len(summary)
        summary += b"".join(map(_record, offsets))
        crc = zlib.crc32(_FOOTER_FIELDS.pack(Opcode.FOOTER, 20, summary_start, offsets_start),
                         zlib.crc32(summary))
        self._stream.write(summary + _record(Footer(summary_start, offsets_start, crc)) + MAGIC)
