"""MCAP logs with JSON-schema channels: a thin layer over the ``mcap`` library.

Messages are JSON (``orjson``, which serialises numpy arrays directly); schemas live in
``tma/io/schemas/*.json`` and are embedded in every log, so Foxglove and any MCAP reader can
decode them. Writes are atomic.

Integrity: ``LogWriter`` writes every CRC MCAP has (chunk ``uncompressed_crc``, DataEnd
``data_section_crc``, Footer ``summary_crc``), so every byte of a file tma writes is covered
by a CRC or is a fixed field checked by value (magic, DataEnd and Footer opcode and length).
``read_log`` checks all of them before it decodes anything and refuses a damaged file with
one ``InputError`` naming it. A CRC of 0 means "not computed" (MCAP spec; other tools may
write files so): what it would cover is then unchecked, see docs/formats.md.
"""

import contextlib
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
from mcap.writer import CompressionType, Writer

from tma import __version__
from tma.errors import InputError
from tma.io.atomic import atomic_path

SCHEMA_DIR = Path(__file__).parent / "schemas"
PROFILE = ""  # plain JSON channels: no ROS profile
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
    checking the element types with ``set(map(type, ...))`` runs at C speed."""
    if type(values) is not list:
        values = [values]  # one value per message: scalar fields
    kinds = set(map(type, values))
    if not kinds <= {int, float, type(None)}:
        raise TypeError(f"expected numbers, got {_unexpected(kinds, {int, float, type(None)})}")
    return np.array(values, dtype=float)


def int_array(values) -> np.ndarray:
    """A JSON integer or array of integers as 1-D int64 (a float without fraction counts, as
    in JSON Schema). A fraction, a value beyond int64 or any other type raises, where numpy
    would truncate or wrap silently."""
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


@dataclass(frozen=True)
class Channel:
    """A topic, the name of its JSON schema, and metadata (units, frames) for readers."""

    topic: str
    schema: str
    metadata: dict = field(default_factory=dict)


def seconds_to_ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


class LogWriter:
    """Write JSON messages to an MCAP file atomically (zstd chunks)::

        with LogWriter(path, channels, metadata={"tma.dataset": {...}}) as log:
            log.write("/topic", t_s, {"t_s": t_s, ...})
    """

    def __init__(self, path, channels, metadata=None):
        self.path, self.channels, self.metadata = Path(path), channels, metadata or {}
        self.n_messages = 0

    def __enter__(self):
        self._stack = contextlib.ExitStack()
        tmp = self._stack.enter_context(atomic_path(self.path))
        self._file = self._stack.enter_context(open(tmp, "wb"))  # closed before the rename
        # every CRC MCAP has: chunks, the data section (not on by default) and the summary
        self._writer = Writer(self._file, compression=CompressionType.ZSTD, enable_crcs=True,
                              enable_data_crcs=True)
        self._writer.start(profile=PROFILE, library=f"tma {__version__}")
        self._ids, schema_ids = {}, {}
        for ch in self.channels:
            if ch.schema not in schema_ids:
                schema_ids[ch.schema] = self._writer.register_schema(
                    name=ch.schema, encoding="jsonschema", data=schema_bytes(ch.schema)
                )
            self._ids[ch.topic] = self._writer.register_channel(
                topic=ch.topic, message_encoding="json", schema_id=schema_ids[ch.schema],
                metadata={k: str(v) for k, v in ch.metadata.items()},
            )
        for name, record in self.metadata.items():
            self._writer.add_metadata(name, {k: str(v) for k, v in record.items()})
        return self

    def write(self, topic: str, t_s: float, message: dict):
        t_ns = seconds_to_ns(t_s)
        self._writer.add_message(
            self._ids[topic], log_time=t_ns, publish_time=t_ns,
            data=orjson.dumps(message, default=_strided_array, option=_JSON_OPTIONS),
            sequence=self.n_messages,
        )
        self.n_messages += 1

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            try:
                self._writer.finish()
            except BaseException:
                if not self._stack.__exit__(*sys.exc_info()):
                    raise
                return False
        return self._stack.__exit__(exc_type, exc, tb)


class JsonDecoderFactory(DecoderFactory):
    """mcap 1.6 ships no JSON decoder: decode ``json`` messages with orjson."""

    def decoder_for(self, message_encoding, schema):
        return orjson.loads if message_encoding == "json" else None


MAGIC = b"\x89MCAP0\r\n"
_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary_start, summary_offset_start, crc
_DATA_END = struct.Struct("<BQI")  # opcode, length, data_section_crc
_FOOTER_OPCODE, _DATA_END_OPCODE = 0x02, 0x0F


def check_integrity(data: bytes) -> str | None:
    """Why ``data`` is not an intact MCAP file with a summary section, or None.

    Checks the magic at both ends, that the Footer and the DataEnd (the record just before
    the summary) are where and what they must be, the Footer's ``summary_crc`` (summary
    section + the Footer's other fields) and the DataEnd's ``data_section_crc`` (the magic,
    header, chunks, message indexes, metadata: everything before DataEnd). A CRC of 0 means
    "not computed" and is skipped. Chunk CRCs are checked by mcap as chunks are read.
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
    if summary_crc and summary_crc != zlib.crc32(view[footer_at:footer_at + _FOOTER.size - 4],
                                                 zlib.crc32(view[summary_start:footer_at])):
        return "summary section or footer fails its CRC check (damaged)"
    opcode, length, data_crc = _DATA_END.unpack_from(data, data_end_at)
    if (opcode, length) != (_DATA_END_OPCODE, 4):
        return "damaged: no DataEnd record before the summary section"
    if data_crc and data_crc != zlib.crc32(view[:data_end_at]):
        return "data section fails its CRC check (damaged)"
    return None


def read_log(path, expected: dict[str, str], nonempty: bool = False):
    """Read an MCAP log. ``expected`` maps topic -> schema name; ``nonempty``: each of these
    topics must hold a message.

    Returns ``(messages, metadata)``: ``messages[topic]`` is a list of decoded dicts in
    log-time order, ``metadata`` maps metadata record names to dicts. Raises one
    ``InputError`` naming the file for a non-MCAP, truncated or damaged file (CRCs, see
    ``check_integrity``), for missing topics or mismatched schemas, for a message that is
    not a JSON object and for message counts that contradict the summary's statistics.
    """
    path = Path(path)
    try:
        data = path.read_bytes()  # logs are shards of modest size: check what we parse
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    problem = check_integrity(data)
    if problem:
        raise InputError(f"{path}: not a valid MCAP log ({problem})")
    try:
        messages, metadata = _read_records(BytesIO(data), expected, str(path))
    except InputError:
        raise
    except Exception as exc:
        # Whatever parsing untrusted bytes raises (mcap, zstd/lz4, struct, Unicode, orjson,
        # KeyError on a dangling id, MemoryError on an absurd size...) means bad input.
        detail = " ".join(str(exc).split())[:200]
        raise InputError(f"{path}: not a valid MCAP log ({type(exc).__name__}: {detail})"
                         ) from None
    empty = [topic for topic in expected if nonempty and not messages[topic]]
    if empty:
        raise InputError(f"{path}: no messages on {', '.join(empty)}")
    return messages, metadata


def _read_records(stream, expected: dict[str, str], where: str):
    reader = SeekingReader(stream, validate_crcs=True, decoder_factories=[JsonDecoderFactory()])
    summary = reader.get_summary()
    found = {ch.topic: summary.schemas.get(ch.schema_id) for ch in summary.channels.values()}
    missing = [t for t in expected if t not in found]
    if missing:
        raise InputError(
            f"{where}: missing topic(s) {', '.join(missing)}; "
            f"the log has: {', '.join(sorted(found)) or 'no channels'}"
        )
    for topic, schema_name in expected.items():
        got = found[topic].name if found[topic] is not None else None
        if got != schema_name:
            raise InputError(f"{where}: topic {topic} has schema '{got}', expected '{schema_name}'")
    messages, counts = {t: [] for t in expected}, Counter()
    scan = reader
    if not summary.chunk_indexes:  # mcap would scan the file without checking chunk CRCs
        stream.seek(0)
        scan = NonSeekingReader(stream, validate_crcs=True,
                                decoder_factories=[JsonDecoderFactory()])
    for _, channel, message, decoded in scan.iter_decoded_messages(topics=list(expected)):
        if not isinstance(decoded, dict):
            raise InputError(f"{where}: the message on {channel.topic} at log time "
                             f"{message.log_time} ns is not a JSON object")
        messages[channel.topic].append(decoded)
        counts[channel.id] += 1
    records = list(reader.iter_metadata())
    # The statistics repeat what the indexes should lead to: for a file without CRCs this
    # catches a damaged chunk or metadata index that would silently drop records.
    stats = summary.statistics
    if stats is not None:
        for ch in summary.channels.values():
            n = stats.channel_message_counts.get(ch.id, 0)
            if ch.topic in expected and counts[ch.id] != n:
                raise InputError(f"{where}: {counts[ch.id]} messages on {ch.topic}, the summary "
                                 f"counts {n} (damaged index?)")
        if len(records) != stats.metadata_count:
            raise InputError(f"{where}: {len(records)} metadata records, the summary counts "
                             f"{stats.metadata_count} (damaged index?)")
    return messages, {m.name: dict(m.metadata) for m in records}
