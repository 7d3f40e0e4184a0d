"""MCAP logs with JSON-schema channels: a thin layer over the ``mcap`` library.

Messages are JSON (``orjson``, which serialises numpy arrays directly); schemas live in
``tma/io/schemas/*.json`` and are embedded in every log, so Foxglove and any MCAP reader can
decode them. Writes are atomic; reads check that the file is a complete MCAP (it has a
summary section) and that the expected topics and schemas are present.
"""

import contextlib
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import orjson
from mcap.decoder import DecoderFactory
from mcap.exceptions import McapError
from mcap.reader import make_reader
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
    """Decode the JSON-valued metadata record ``name``; a clear error if it is absent."""
    if name not in metadata:
        raise InputError(f"{where}: missing metadata record '{name}'")
    return {k: orjson.loads(v) for k, v in metadata[name].items()}


def float_array(values) -> np.ndarray:
    """A JSON number array as float64, null -> NaN (fast path when there is no null)."""
    try:
        return np.asarray(values, dtype=float)
    except TypeError:
        return np.array([np.nan if v is None else v for v in values], dtype=float)


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
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
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


def read_log(path, expected: dict[str, str]):
    """Read an MCAP log. ``expected`` maps topic -> schema name.

    Returns ``(messages, metadata)``: ``messages[topic]`` is a list of decoded dicts in
    log-time order, ``metadata`` maps metadata record names to dicts. Raises ``InputError``
    for a non-MCAP or truncated file and for missing topics or mismatched schemas.
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[JsonDecoderFactory()])
            summary = reader.get_summary()
            if summary is None:
                raise InputError(f"{path}: MCAP file has no summary section (truncated?)")
            found = {ch.topic: summary.schemas.get(ch.schema_id)
                     for ch in summary.channels.values()}
            missing = [t for t in expected if t not in found]
            if missing:
                raise InputError(
                    f"{path}: missing topic(s) {', '.join(missing)}; "
                    f"the log has: {', '.join(sorted(found)) or 'no channels'}"
                )
            for topic, schema_name in expected.items():
                got = found[topic].name if found[topic] is not None else None
                if got != schema_name:
                    raise InputError(
                        f"{path}: topic {topic} has schema '{got}', expected '{schema_name}'"
                    )
            messages = {t: [] for t in expected}
            for _, channel, _, decoded in reader.iter_decoded_messages(topics=list(expected)):
                messages[channel.topic].append(decoded)
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (McapError, orjson.JSONDecodeError, ValueError, EOFError, KeyError) as exc:
        raise InputError(f"{path}: not a valid MCAP log ({type(exc).__name__}: {exc})") from None
    return messages, metadata
