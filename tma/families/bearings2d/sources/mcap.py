"""Bearing logs in MCAP, whatever wrote them: ``read_mcap(path, options) -> Recording``.

The file is read once and checked as tma checks its own logs before anything is decoded
(``tma.io.mcap_log.check_integrity``: magic, footer, summary and data-section CRCs; then each
chunk's CRC as it is read and the message and metadata counts against the summary's
statistics). Each channel is taken by what it holds, never refused for its topic name: its
message encoding picks the decoder (``cdr``: mcap-ros2-support; ``protobuf``:
mcap-protobuf-support; ``json``) and its schema name the reader:

- own-ship, found by schema (in this order of preference) or named by ``ownship.topic``:
  ``tma.OwnshipNavigation`` (``mcap_own``), ``sensor_msgs/msg/NavSatFix`` (``mcap_ros2``),
  ``foxglove.LocationFix`` (``mcap_foxglove``), ``nav_msgs/msg/Odometry`` and
  ``geometry_msgs/msg/PoseStamped`` (``mcap_ros2``, local x east, y north);
- bearings: ``bearing.topic`` (default ``/sonar/bearings``, or the one ``tma.BearingBatch``
  topic). ``tma.BearingBatch`` is read by ``mcap_own``; any other schema by the dotted field
  path ``bearing.field`` (``data`` for std_msgs/Float64, ``vector`` for Vector3Stamped,
  ``bearing_deg``; unset: the first of ``BEARING_FIELDS`` the messages have). A number (or
  array of numbers) is a bearing clockwise from north in ``bearing.units`` (deg, or rad when
  set or when the field's name ends in ``_rad``); a direction vector (fields x east, y north)
  becomes ``atan2(x, y)``. The contact is a sibling ``TRACK_FIELDS`` field (integer or text)
  when the messages have one, else the topic itself (its name as the label).

Times: ``header.stamp`` (ROS 2) or ``timestamp`` (Foxglove) when the messages have one (and it
is set), else the message's ``log_time``; ``t_s`` for tma's own schema. Stamps from 2000 on are
UTC: the recording's ``epoch_utc_ns`` is its first time and every ``t_s`` counts from it;
earlier ones are a relative clock (simulation time, tma's older logs: ``epoch_utc_ns`` None).
Messages are sorted by time (log order is not time order across channels); two bearings of one
contact at one time are an error naming the time (repeated own-ship fixes are ``assemble``'s to
judge). NaN values (and NavSatFix fixes with status NO_FIX) are dropped and counted in
``Recording.notes``, as is every automatic choice. Nothing is interpolated here: ``assemble``
puts navigation and bearings on one time base and plane.

Every failure is one ``InputError`` (``ConfigError`` for an option) naming the file; a mapping
that finds nothing lists the file's topics (schema, messages) and the option that would select
one. Cost: decoding is per message, about 0.12 s per 10,000 small JSON or CDR messages (the
``mcap`` reader's record parsing is most of it) and 0.3 s for NavSatFix or Vector3Stamped; a
``tma.BearingBatch`` message carries a whole epoch.
"""

import contextlib
import functools
import operator
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

import numpy as np
from google.protobuf.message import Message as ProtobufMessage
from mcap.reader import NonSeekingReader, SeekingReader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

from tma.errors import ConfigError, InputError
from tma.families.bearings2d.log import BEARINGS_TOPIC, nominal_sigma
from tma.families.bearings2d.sources import mcap_foxglove, mcap_own, mcap_ros2
from tma.families.bearings2d.sources.base import Bearings, Navigation, Recording, SourceOptions
from tma.io.mcap_log import (
    TmaDecoderFactory,
    check_integrity,
    float_array,
    format_utc,
    int_array,
    schema_errors,
)

UTC_FROM_NS = 946_684_800 * 10**9  # 2000-01-01T00:00:00Z: earlier stamps are a relative clock
# own-ship readers by schema name, in order of preference when a log holds several
NAVIGATION = {
    mcap_own.OWNSHIP: mcap_own.navigation,  # exact local metres (and the log's origin)
    mcap_ros2.NAVSATFIX: mcap_ros2.navsatfix,
    mcap_foxglove.LOCATION_FIX: mcap_foxglove.location_fix,
    mcap_ros2.ODOMETRY: mcap_ros2.odometry,
    mcap_ros2.POSE_STAMPED: mcap_ros2.pose_stamped,
}
BEARING_FIELDS = ("bearing_deg", "bearing_rad", "bearing", "data", "vector")  # bearing.field unset
TRACK_FIELDS = ("track_id", "track", "contact_id", "contact", "target_id")
DECODED = "cdr (ROS 2 ros2msg schemas), protobuf and json"


@dataclass
class Topic:
    """A topic of the file: its schema name, message encoding, message count (statistics)."""

    name: str
    schema: str
    encoding: str
    count: int | None
    channels: list
    mixed: bool = False  # channels of different schemas or encodings share the topic

    def __str__(self):
        count = "?" if self.count is None else self.count
        return f"{self.name} ({self.schema or 'no schema'}, {count})"


@dataclass
class Messages:
    """The decoded messages of one topic, in file order, with their log times (ns)."""

    topic: str
    schema: str
    log_time_ns: np.ndarray
    decoded: list


def _detail(exc: Exception) -> str:
    return f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"


@contextlib.contextmanager
def _as_input_error(where: str):
    """Whatever parsing untrusted bytes raises (mcap, zstd/lz4, struct, Unicode...) means a
    damaged or foreign file: one InputError naming it."""
    try:
        yield
    except (InputError, ConfigError):
        raise
    except Exception as exc:
        raise InputError(f"{where}: not a valid MCAP log ({_detail(exc)})") from None


class McapFile:
    """An MCAP file read whole and checked once; topics decoded on demand.

    ``topics`` maps each topic to its ``Topic``; ``metadata`` the metadata records by name;
    ``notes`` collects what was found automatically (for the log)."""

    def __init__(self, path):
        self.path, self.where, self.notes = Path(path), str(path), []
        try:
            self._data = self.path.read_bytes()
        except FileNotFoundError:
            raise InputError(f"{path}: no such file") from None
        except OSError as exc:
            raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
        problem = check_integrity(self._data)
        if problem:
            raise InputError(f"{path}: not a valid MCAP log ({problem})")
        with _as_input_error(self.where):
            self._reader = SeekingReader(BytesIO(self._data), validate_crcs=True)
            self._summary = self._reader.get_summary()
            records = list(self._reader.iter_metadata())
        stats = self._summary.statistics
        if stats is not None and len(records) != stats.metadata_count:
            raise InputError(f"{path}: {len(records)} metadata records, the summary counts "
                             f"{stats.metadata_count} (damaged index?)")
        self.metadata = {m.name: dict(m.metadata) for m in records}
        self.topics = {}
        for ch in sorted(self._summary.channels.values(), key=lambda c: c.id):
            schema = self._summary.schemas.get(ch.schema_id)
            name = "" if schema is None else schema.name
            if ch.message_encoding == "cdr":
                name = mcap_ros2.schema_name(name)
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

    def source(self, name: str) -> str:
        """A topic as a source, for messages: ``file.mcap: /gps/fix (sensor_msgs/msg/...)``."""
        return f"{self.where}: {name} ({self.topics[name].schema})"

    def topic(self, name: str, option: str) -> Topic:
        """The topic an option names; an InputError listing the topics if there is none."""
        if name not in self.topics:
            raise InputError(f"{self.where}: {option}={name}: no such topic; {self.describe()}")
        return self.topics[name]

    def _decoder(self, channel):
        schema = self._summary.schemas.get(channel.schema_id)
        for factory in (TmaDecoderFactory(), Ros2DecoderFactory(), ProtobufDecoderFactory()):
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
            f"'{getattr(schema, 'encoding', '')}'; tma reads {DECODED}")

    def read(self, names: list[str]) -> dict[str, Messages]:
        """Decode every message of these topics (one pass over the file); messages that do not
        decode, or counts that contradict the statistics, raise InputError."""
        mixed = [n for n in names if self.topics[n].mixed]
        if mixed:
            raise InputError(f"{self.where}: {mixed[0]} has channels of different schemas "
                             f"({self.topics[mixed[0]].schema}): tma cannot tell which to read")
        channels = {ch.id: ch for name in names for ch in self.topics[name].channels}
        decoders = {cid: self._decoder(ch) for cid, ch in channels.items()}
        times, decoded = {n: [] for n in names}, {n: [] for n in names}
        counts = Counter()
        with _as_input_error(self.where):
            reader = self._reader
            if not self._summary.chunk_indexes:  # mcap would scan without checking chunk CRCs
                reader = NonSeekingReader(BytesIO(self._data), validate_crcs=True)
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
        stats = self._summary.statistics
        for cid, ch in channels.items():
            expected = None if stats is None else stats.channel_message_counts.get(cid, 0)
            if expected is not None and counts[cid] != expected:
                raise InputError(f"{self.where}: {counts[cid]} messages on {ch.topic}, the "
                                 f"summary counts {expected} (damaged index?)")
        return {n: Messages(n, self.topics[n].schema, self._int64(times[n], n), decoded[n])
                for n in names}

    def _int64(self, log_times: list[int], topic: str) -> np.ndarray:
        """Log times (uint64 ns in MCAP) as int64: the times tma computes with end in 2262."""
        if log_times and max(log_times) >= 2**63:
            raise InputError(f"{self.where}: {topic} has log times beyond the year 2262 "
                             f"({max(log_times)} ns): not nanoseconds since 1970")
        return np.array(log_times, dtype=np.int64)

    def message_times(self, msgs: Messages) -> np.ndarray:
        """Each message's time (int64 ns): ``header.stamp`` (ROS 2), ``timestamp`` (Foxglove),
        else (or when it is unset: 0 in every message) its ``log_time``."""
        for stamps, name in ((mcap_ros2.header_stamps_ns, "header.stamp"),
                             (mcap_foxglove.timestamps_ns, "timestamp")):
            with schema_errors(self.where, f"a message on {msgs.topic}"):
                t_ns = stamps(msgs.decoded)
            if t_ns is not None:
                if t_ns.any():
                    return t_ns
                self.notes.append(f"{msgs.topic}: {name} is 0 (unset) in every message: "
                                  "log_time used")
                return msgs.log_time_ns
        self.notes.append(f"{msgs.topic}: no time stamp in the messages: log_time used")
        return msgs.log_time_ns


# -- field paths in decoded messages (dicts from JSON, protobuf messages, ROS 2 objects) -------

def _field_names(obj) -> list[str]:
    if isinstance(obj, dict):
        return list(obj)
    if isinstance(obj, ProtobufMessage):
        return [f.name for f in obj.DESCRIPTOR.fields]
    slots = getattr(type(obj), "__slots__", None)  # mcap-ros2-support message classes
    if slots is not None:
        return list(slots)
    return [k for k in vars(obj) if not k.startswith("_")] if hasattr(obj, "__dict__") else []


def _has_path(obj, path: str) -> bool:
    for name in path.split("."):
        if name not in _field_names(obj):
            return False
        obj = obj[name] if isinstance(obj, dict) else getattr(obj, name)
    return True


def _getter(sample, path: str):
    """A function message -> value at the dotted ``path`` (attribute access at C speed)."""
    if isinstance(sample, dict):
        parts = path.split(".")
        return lambda m: functools.reduce(operator.getitem, parts, m)
    return operator.attrgetter(path)


def _is_number(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_)


def _is_vector(value) -> bool:
    return not _is_number(value) and {"x", "y"} <= set(_field_names(value))


def _is_array(value) -> bool:
    return isinstance(value, np.ndarray) or (
        isinstance(value, Sequence) and not isinstance(value, str | bytes))


# -- bearings by field path ---------------------------------------------------------------

def _bearing_field(msgs: Messages, field: str | None, file: McapFile) -> str:
    sample, where = msgs.decoded[0], f"{file.where}: {msgs.topic} ({msgs.schema})"
    fields = ", ".join(_field_names(sample)) or "none"
    if field is None:
        field = next((f for f in BEARING_FIELDS if _has_path(sample, f)), None)
        if field is None:
            raise InputError(f"{where} has none of the fields {', '.join(BEARING_FIELDS)}; its "
                             f"fields: {fields}; set bearing.field=<dotted path>")
        file.notes.append(f"{msgs.topic}: bearings from the field '{field}' (bearing.field)")
    elif not _has_path(sample, field):
        raise InputError(f"{where} has no field '{field}' (bearing.field); its fields: "
                         f"{fields}; set bearing.field=<dotted path>")
    return field


def _to_degrees(values, units: str | None, field: str, topic: str, notes: list):
    """Bearings in degrees, and whether their units were stated (by ``bearing.units`` or a
    field name ending in ``_rad``) rather than assumed. A name ending in ``_deg`` does not
    count: radians written into a field labelled degrees are the mistake the guard catches."""
    name = field.split(".")[-1]
    stated = units is not None or name.endswith("_rad")
    if units is None:
        units = "rad" if name.endswith("_rad") else "deg"
        said = "radians (its name says so)" if units == "rad" else "degrees"
        notes.append(f"{topic}: '{field}' read as {said}; bearing.units=deg|rad says which")
    return (np.rad2deg(values) if units == "rad" else values), stated


def _tracks(msgs: Messages, field: str, sizes, file: McapFile):
    """The contact of each bearing: a sibling track field (int ids or text labels), else the
    topic (its name as the label)."""
    sample = msgs.decoded[0]
    parent = field.rpartition(".")[0]
    candidates = [f"{parent}.{n}" for n in TRACK_FIELDS] if parent else []
    path = next((p for p in [*candidates, *TRACK_FIELDS] if _has_path(sample, p)), None)
    n = len(msgs.decoded) if sizes is None else int(sizes.sum())
    if path is None:
        file.notes.append(f"{msgs.topic}: no track field ({', '.join(TRACK_FIELDS)}): one "
                          f"contact, labelled {msgs.topic}")
        return np.full(n, msgs.topic, dtype=object)
    get = _getter(sample, path)
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        ids = [get(m) for m in msgs.decoded]
        if sizes is not None:
            if any(not _is_array(v) for v in ids) or np.any(sizes != [len(v) for v in ids]):
                raise InputError(f"{file.where}: {msgs.topic}: '{path}' and '{field}' differ "
                                 "in length in a message")
            ids = [i for v in ids for i in v]
        kinds = set(map(type, ids))
        if kinds <= {str}:
            tracks = np.array(ids, dtype=object)
        elif str in kinds:
            raise InputError(f"{file.where}: {msgs.topic}: '{path}' mixes numbers and text")
        else:
            tracks = int_array(ids)
    file.notes.append(f"{msgs.topic}: contacts from the field '{path}'")
    return tracks


def _field_bearings(msgs: Messages, file: McapFile, options: SourceOptions):
    """``(t_ns, track, bearing_deg)`` from the field ``bearing.field`` of any schema."""
    field = _bearing_field(msgs, options.bearing.field, file)
    get = _getter(msgs.decoded[0], field)
    t_ns, sizes = file.message_times(msgs), None
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        values = [get(m) for m in msgs.decoded]
        first = values[0]
        if _is_vector(first):
            if options.bearing.units is not None:
                raise ConfigError(f"bearing.units={options.bearing.units}: '{field}' of "
                                  f"{msgs.topic} is a direction vector, which has no units; "
                                  "leave bearing.units unset")
            x, y = (float_array([v[c] if isinstance(v, dict) else getattr(v, c)
                                 for v in values]) for c in "xy")
            bearing = np.where((x == 0) & (y == 0), np.nan, np.rad2deg(np.arctan2(x, y)) % 360)
            stated = True
            file.notes.append(f"{msgs.topic}: '{field}' is a direction vector (x east, y "
                              "north): bearing = atan2(x, y)")
        elif _is_number(first) or first is None:
            bearing, stated = _to_degrees(float_array(values), options.bearing.units, field,
                                          msgs.topic, file.notes)
        elif _is_array(first):
            arrays = [float_array(list(v)) for v in values]
            sizes = np.array([a.size for a in arrays])
            t_ns = np.repeat(t_ns, sizes)
            bearing, stated = _to_degrees(np.concatenate(arrays), options.bearing.units,
                                          field, msgs.topic, file.notes)
        else:
            raise InputError(f"{file.where}: '{field}' of {msgs.topic} holds "
                             f"{type(first).__name__} values, not numbers, arrays of numbers "
                             "or direction vectors (x east, y north); set "
                             "bearing.field=<dotted path>")
    return t_ns, _tracks(msgs, field, sizes, file), bearing, stated


def _own_bearings(msgs: Messages, file: McapFile, options: SourceOptions):
    field = options.bearing.field
    if field not in (None, "bearing_deg"):
        raise ConfigError(f"bearing.field={field}: {msgs.topic} has tma's schema "
                          f"{msgs.schema}, whose bearings are 'bearing_deg'; leave "
                          "bearing.field unset")
    t_ns, track, values = mcap_own.bearings(msgs, file)
    if options.bearing.units == "rad":
        values = np.rad2deg(values)
    # bearing_deg names degrees, yet radians written there are what the radians guard catches
    return t_ns, track, values, options.bearing.units is not None


# -- selection, checks, time base -----------------------------------------------------------

def _select_navigation(file: McapFile, options: SourceOptions) -> str | None:
    if options.ownship.topic is not None:
        topic = file.topic(options.ownship.topic, "ownship.topic")
        if topic.schema not in NAVIGATION:
            raise InputError(f"{file.where}: ownship.topic={topic.name} has schema "
                             f"'{topic.schema}'; own-ship is read from {', '.join(NAVIGATION)}")
        return topic.name
    found = [t for t in file.topics.values() if t.schema in NAVIGATION and t.count != 0]
    if not found:
        return None
    order = list(NAVIGATION)
    best = min(found, key=lambda t: order.index(t.schema))
    same = [t.name for t in found if t.schema == best.schema]
    if len(same) > 1:
        raise InputError(f"{file.where}: {len(same)} own-ship topics of schema {best.schema}: "
                         f"{', '.join(same)}; set ownship.topic=<topic>")
    others = [str(t) for t in found if t is not best]
    file.notes.append(f"own-ship: {best} found by its schema" + (
        f" (not used: {', '.join(others)}; ownship.topic= selects one)" if others else ""))
    return best.name


def _select_bearings(file: McapFile, options: SourceOptions) -> str | None:
    if options.bearing.topic is not None:
        return file.topic(options.bearing.topic, "bearing.topic").name
    if BEARINGS_TOPIC in file.topics and file.topics[BEARINGS_TOPIC].count != 0:
        found = [file.topics[BEARINGS_TOPIC]]
    else:
        found = [t for t in file.topics.values()
                 if t.schema == mcap_own.BEARING_BATCH and t.count != 0]
    if len(found) > 1:
        raise InputError(f"{file.where}: {len(found)} bearing topics of schema "
                         f"{mcap_own.BEARING_BATCH}: {', '.join(t.name for t in found)}; set "
                         "bearing.topic=<topic>")
    if not found:
        return None
    file.notes.append(f"bearings: {found[0]} (bearing.topic)")
    return found[0].name


def _when(t_ns: int) -> str:
    return format_utc(t_ns) if t_ns >= UTC_FROM_NS else f"t = {t_ns / 1e9!r} s"


def _drop_nonfinite(keep, values_desc: str, topic: str, notes: list):
    if not keep.all():
        notes.append(f"{topic}: {int((~keep).sum())} {values_desc} NaN or infinite: dropped")
    return keep


def _navigation_part(file: McapFile, msgs: Messages):
    t_ns, columns = NAVIGATION[msgs.schema](msgs, file)
    a, b = columns.values()
    keep = _drop_nonfinite(np.isfinite(a) & np.isfinite(b), "fix(es)", msgs.topic, file.notes)
    if not keep.any():
        raise InputError(f"{file.where}: no usable own-ship fix on {msgs.topic}: all "
                         f"{len(msgs.decoded)} dropped (status NO_FIX or NaN coordinates)")
    order = np.argsort(t_ns[keep], kind="stable")  # repeated times: assemble's to judge
    return t_ns[keep][order], {k: v[keep][order] for k, v in columns.items()}


def _bearings_part(file: McapFile, msgs: Messages, options: SourceOptions):
    read = _own_bearings if msgs.schema == mcap_own.BEARING_BATCH else _field_bearings
    t_ns, track, bearing, stated = read(msgs, file, options)
    keep = _drop_nonfinite(np.isfinite(bearing), "bearing(s)", msgs.topic, file.notes)
    if not keep.any():
        raise InputError(f"{file.where}: no usable bearing on {msgs.topic} (none, or all NaN)")
    t_ns, track, bearing = t_ns[keep], track[keep], bearing[keep]
    codes = np.unique(track, return_inverse=True)[1]
    order = np.lexsort((codes, t_ns))  # by time, then contact
    t_ns, track, bearing, codes = t_ns[order], track[order], bearing[order], codes[order]
    dup = (t_ns[1:] == t_ns[:-1]) & (codes[1:] == codes[:-1])
    if dup.any():
        i = int(np.argmax(dup))
        raise InputError(f"{file.where}: {msgs.topic}: two bearings of contact {track[i]} at "
                         f"{_when(int(t_ns[i]))}; a contact has one bearing per time")
    return t_ns, track, bearing, stated


def _epoch(parts: dict[str, np.ndarray], where: str) -> int | None:
    """UTC ns of t = 0 (the first time) when every part is on the UTC clock, None when all
    are on a relative clock; a mixture raises."""
    utc = {topic: bool(t.min() >= UTC_FROM_NS) for topic, t in parts.items()}
    if all(utc.values()):
        return min(int(t.min()) for t in parts.values())
    if not any(utc.values()):
        return None
    raise InputError(f"{where}: times of {', '.join(t for t, u in utc.items() if u)} are UTC "
                     f"but those of {', '.join(t for t, u in utc.items() if not u)} are before "
                     "2000 (a relative clock): the two cannot be put on one time base")


def read_mcap(path, options: SourceOptions, need: tuple[str, ...] = ()) -> Recording:
    """Own-ship fixes and bearings from an MCAP file of any source kind (module docstring).

    ``need``: the parts the caller requires (``"navigation"``, ``"bearings"``): a missing one
    raises an InputError listing the file's topics and the option that selects one. A part
    not needed and not found is None (noted); a file with neither always raises.
    """
    file = McapFile(path)
    nav_topic = _select_navigation(file, options)
    bearing_topic = _select_bearings(file, options)
    hint = {"navigation": ("no own-ship navigation: own-ship is read from a topic of schema "
                           f"{', '.join(NAVIGATION)}; set ownship.topic=<topic> or give "
                           "navigation=FILE"),
            "bearings": "no bearings selected: set bearing.topic=<topic> [bearing.field=data]"}
    absent = [p for p, t in (("navigation", nav_topic), ("bearings", bearing_topic)) if t is None]
    fatal = [p for p in absent if p in need] or (absent if len(absent) == 2 else [])
    if fatal:
        raise InputError(f"{file.where}: {'; '.join(hint[p] for p in fatal)}; "
                         f"{file.describe()}")
    file.notes.extend(f"{file.where}: {hint[p]}" for p in absent)

    topics = [t for t in (nav_topic, bearing_topic) if t is not None]
    if len(set(topics)) < len(topics):
        raise InputError(f"{file.where}: {nav_topic} is both the own-ship and the bearing topic; "
                         "set bearing.topic= or ownship.topic= to another topic")
    messages = file.read(topics)
    for topic in topics:
        if not messages[topic].decoded:
            raise InputError(f"{file.where}: no messages on {topic}; {file.describe()}")
    parts = {}
    if nav_topic is not None:
        parts[nav_topic] = _navigation_part(file, messages[nav_topic])
    if bearing_topic is not None:
        parts[bearing_topic] = _bearings_part(file, messages[bearing_topic], options)
    epoch = _epoch({topic: part[0] for topic, part in parts.items()}, file.where)

    def seconds(t_ns):
        return (t_ns - (epoch or 0)) / 1e9

    navigation = bearings = None
    if nav_topic is not None:
        t_ns, columns = parts[nav_topic]
        navigation = Navigation(seconds(t_ns), epoch, file.source(nav_topic), **columns)
    if bearing_topic is not None:
        t_ns, track, bearing, stated = parts[bearing_topic]
        bearings = Bearings(seconds(t_ns), epoch, track, bearing, file.source(bearing_topic),
                            units_stated=stated)
    return Recording(navigation, bearings, nominal_sigma(file.metadata, file.where),
                     file.notes)
