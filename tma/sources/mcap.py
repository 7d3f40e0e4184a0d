"""Recorded logs in MCAP, whatever wrote them: ``read_mcap(path, options) -> Recording``.

The file is read and checked once by tma's one MCAP reader (``tma.io.mcap_log.McapFile``:
magic, footer, summary and data-section CRCs before anything is decoded; then each chunk's CRC
as it is read and the message and metadata counts against the summary's statistics). Each
channel is taken by what it holds, never refused for its topic name: its message encoding
picks the decoder (``cdr``: mcap-ros2-support; ``protobuf``: mcap-protobuf-support; ``json``)
and its schema name the reader:

- own-ship, found by schema (in this order of preference) or named by ``ownship.topic``:
  ``tma.OwnshipNavigation`` (``tma_log``), ``sensor_msgs/msg/NavSatFix`` (``ros2``),
  ``foxglove.LocationFix`` (``foxglove``), ``nav_msgs/msg/Odometry`` and
  ``geometry_msgs/msg/PoseStamped`` (``ros2``, local x east, y north);
- the contacts' values (the family's ``Observation``; ``bearing.*`` for ``bearings2d``):
  ``<role>.topic``, a topic, an fnmatch pattern (``/sonar/contact/*``) or a list of them, each
  matching topic read (default the observation's ``topic``, ``/sonar/bearings``, or the one
  topic of its ``schema``, ``tma.BearingBatch``, read by ``tma_log``); any other schema by the
  dotted field path ``<role>.field`` (``data`` for std_msgs/Float64, ``vector`` for
  Vector3Stamped, ``bearing_deg``; unset: the first of the observation's ``fields`` the
  messages have). A
  number (or array of numbers) is a value in ``<role>.units`` (the first unit, or another when
  set or when the field's name ends in ``_<unit>``); a direction vector (fields x east, y
  north) is converted by the observation's ``from_vector`` (bearings: ``atan2(x, y)``). The
  contact is a sibling ``TRACK_FIELDS`` field (integer or text) when the messages have one,
  else the topic itself (its name as the label); of several topics, a contact from a track
  field is labelled ``<topic>:<id>``.

Times: ``header.stamp`` (ROS 2) or ``timestamp`` (Foxglove) when the messages have one (and it
is set), else the message's ``log_time``; ``t_s`` for tma's own schemas. Stamps from 2000 on
are UTC (``tma.utc.UTC_FROM_NS``): the recording's ``epoch_utc_ns`` is its first time and every
``t_s`` counts from it; earlier ones are a relative clock (simulation time, tma's older logs:
``epoch_utc_ns`` None); a stamp before 2000 in a topic whose stamps are UTC is a clock that
was not set (0), a bad row, never a relative clock. Messages are sorted by time (log order is
not time order across channels); two values of one contact at one time are an error naming the
time (repeated own-ship fixes are ``align``'s to judge). Bad rows (NaN values and positions,
stamps not set) are left out and counted with their topic and time (``bad_rows=drop``; under
``fail`` the first refuses the file); NavSatFix fixes with status NO_FIX are left out and
counted under either policy. Every automatic choice is noted in ``Recording.notes``. Nothing is
interpolated here: ``align`` puts navigation and contacts on one time base and plane.

Every failure is one ``InputError`` (``ConfigError`` for an option) naming the file; a mapping
that finds nothing lists the file's topics (schema, messages) and the option that would select
one. Cost: decoding is per message, about 0.12 s per 10,000 small JSON or CDR messages (the
``mcap`` reader's record parsing is most of it) and 0.3 s for NavSatFix or Vector3Stamped; a
``tma.BearingBatch`` message carries a whole epoch.
"""

import fnmatch
import functools
import operator
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from google.protobuf.message import Message as ProtobufMessage
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

from tma.errors import ConfigError, InputError
from tma.io.mcap_log import McapFile, TmaDecoderFactory, float_array, int_array, schema_errors
from tma.sources import foxglove, ros2, tma_log
from tma.sources.base import NAMED, Contacts, Dropped, Navigation, Recording
from tma.utc import UTC_FROM_NS, stamp_text

# own-ship readers by schema name, in order of preference when a log holds several
NAVIGATION = {
    tma_log.OWNSHIP: tma_log.navigation,  # exact local metres (and the log's origin)
    ros2.NAVSATFIX: ros2.navsatfix,
    foxglove.LOCATION_FIX: foxglove.location_fix,
    ros2.ODOMETRY: ros2.odometry,
    ros2.POSE_STAMPED: ros2.pose_stamped,
}
TRACK_FIELDS = ("track_id", "track", "contact_id", "contact", "target_id")
DECODED = "cdr (ROS 2 ros2msg schemas), protobuf and json"
FACTORIES = (TmaDecoderFactory, Ros2DecoderFactory, ProtobufDecoderFactory)  # new per file:
# they cache decoders by schema id


@dataclass
class Messages:
    """The decoded messages of one topic, in log-time order, with their log times (ns)."""

    topic: str
    schema: str
    log_time_ns: np.ndarray
    decoded: list


class RecordedLog(McapFile):
    """An MCAP file as a source: its topics decoded by any of ``FACTORIES``; ``notes``
    collects what was found automatically (for the log)."""

    def __init__(self, path, dropped: Dropped | None = None):
        super().__init__(path)
        self.notes = []
        self.dropped = Dropped() if dropped is None else dropped

    def places(self, topic: str, t_ns: np.ndarray, clock: str = ""):
        """Row indices -> ``<topic> at <time>`` (``clock``: ``log time`` to name the message's
        log time rather than its stamp)."""
        return lambda rows: [f"{topic} at {clock + ' ' if clock else ''}"
                             f"{stamp_text(int(t_ns[i]))}" for i in rows]

    def not_absolute(self, msgs: "Messages", t_ns: np.ndarray, message: np.ndarray):
        """The rows to keep: a stamp before 2000 among UTC stamps (a clock not set: 0) is left
        out (named by its message's log time; ``message``: each row's message)."""
        absolute = t_ns.size and np.median(t_ns) >= UTC_FROM_NS
        return self.dropped.drop(
            (t_ns < UTC_FROM_NS) if absolute else np.zeros(t_ns.size, dtype=bool),
            "time not absolute among absolute times",
            self.places(msgs.topic, msgs.log_time_ns[message], "log time"),
            f"{self.where}: {msgs.topic}: a time stamp before 2000 among UTC stamps")

    def source(self, name: str) -> str:
        """A topic as a source, for messages: ``file.mcap: /gps/fix (sensor_msgs/msg/...)``."""
        return f"{self.where}: {name} ({self.topics[name].schema})"

    def topic(self, name: str, option: str):
        """The topic an option names; an InputError listing the topics if there is none."""
        if name not in self.topics:
            raise InputError(f"{self.where}: {option}={name}: no such topic; {self.describe()}")
        return self.topics[name]

    def messages(self, names: list[str]) -> dict[str, Messages]:
        """Decode every message of these topics (one pass over the file)."""
        read = self.read(names, [factory() for factory in FACTORIES], DECODED)
        return {n: Messages(n, self.topics[n].schema, self._int64(times, n), decoded)
                for n, (times, decoded) in read.items()}

    def _int64(self, log_times: np.ndarray, topic: str) -> np.ndarray:
        """Log times (uint64 ns in MCAP) as int64: the times tma computes with end in 2262."""
        if log_times.size and log_times.max() >= 2**63:
            raise InputError(f"{self.where}: {topic} has log times beyond the year 2262 "
                             f"({log_times.max()} ns): not nanoseconds since 1970")
        return log_times.astype(np.int64)

    def message_times(self, msgs: Messages) -> np.ndarray:
        """Each message's time (int64 ns): ``header.stamp`` (ROS 2), ``timestamp`` (Foxglove),
        else (or when it is unset: 0 in every message) its ``log_time``."""
        for stamps, name in ((ros2.header_stamps_ns, "header.stamp"),
                             (foxglove.timestamps_ns, "timestamp")):
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


# -- values by field path -----------------------------------------------------------------

def _value_field(msgs: Messages, field: str | None, file: RecordedLog, observation) -> str:
    sample, where = msgs.decoded[0], f"{file.where}: {msgs.topic} ({msgs.schema})"
    fields = ", ".join(_field_names(sample)) or "none"
    role = observation.role
    if field is None:
        field = next((f for f in observation.fields if _has_path(sample, f)), None)
        if field is None:
            raise InputError(f"{where} has none of the fields {', '.join(observation.fields)}; "
                             f"its fields: {fields}; set {role}.field=<dotted path>")
        file.notes.append(f"{msgs.topic}: {observation.plural} from the field '{field}' "
                          f"({role}.field)")
    elif not _has_path(sample, field):
        raise InputError(f"{where} has no field '{field}' ({role}.field); its fields: "
                         f"{fields}; set {role}.field=<dotted path>")
    return field


def _to_first_unit(values, units: str | None, field: str, topic: str, notes: list,
                   observation):
    """Values in the observation's first unit, and whether their units were stated (by
    ``<role>.units`` or a field name ending in another unit's ``_<name>``) rather than
    assumed. A name ending in the first unit's does not count: values in another unit written
    into a field labelled with the first are the mistake the family's guard catches."""
    by_name = observation.unit_of_name(field.split(".")[-1])
    stated = units is not None or by_name is not None
    if units is None:
        unit = by_name or observation.units[0]
        said = f"{unit.words} (its name says so)" if by_name else unit.words
        choices = "|".join(u.name for u in observation.units)
        notes.append(f"{topic}: '{field}' read as {said}; {observation.role}.units={choices} "
                     "says which")
    else:
        unit = observation.unit(units)
    observation.check_range(values[np.isfinite(values)], unit, f"{topic}: '{field}'")
    return unit.to_first(values), stated


def _tracks(msgs: Messages, field: str, sizes, file: RecordedLog):
    """The contact of each value: a sibling track field (int ids or text labels), else the
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


def _field_values(msgs: Messages, file: RecordedLog, options):
    """``(t_ns, track, values, stated)`` from the field ``<role>.field`` of any schema."""
    observation, source = options.observation, options.contact
    role = observation.role
    field = _value_field(msgs, source.field, file, observation)
    get = _getter(msgs.decoded[0], field)
    t_ns, sizes = file.message_times(msgs), None
    message = np.arange(t_ns.size)
    with schema_errors(file.where, f"a message on {msgs.topic}"):
        values = [get(m) for m in msgs.decoded]
        first = values[0]
        if _is_vector(first) and observation.from_vector is not None:
            if source.units is not None:
                raise ConfigError(f"{role}.units={source.units}: '{field}' of "
                                  f"{msgs.topic} is a direction vector, which has no units; "
                                  f"leave {role}.units unset")
            x, y = (float_array([v[c] if isinstance(v, dict) else getattr(v, c)
                                 for v in values]) for c in "xy")
            converted = observation.from_vector(x, y)
            stated = True
            file.notes.append(f"{msgs.topic}: '{field}' is a direction vector (x east, y "
                              f"north): {role} = {observation.vector_rule}")
        elif _is_number(first) or first is None:
            converted, stated = _to_first_unit(float_array(values), source.units, field,
                                               msgs.topic, file.notes, observation)
        elif _is_array(first):
            arrays = [float_array(list(v)) for v in values]
            sizes = np.array([a.size for a in arrays])
            t_ns, message = np.repeat(t_ns, sizes), np.repeat(message, sizes)
            converted, stated = _to_first_unit(np.concatenate(arrays), source.units, field,
                                               msgs.topic, file.notes, observation)
        else:
            vectors = (" or direction vectors (x east, y north)"
                       if observation.from_vector is not None else "")
            raise InputError(f"{file.where}: '{field}' of {msgs.topic} holds "
                             f"{type(first).__name__} values, not numbers, arrays of numbers"
                             f"{vectors}; set {role}.field=<dotted path>")
    return t_ns, _tracks(msgs, field, sizes, file), converted, stated, message


def _own_values(msgs: Messages, file: RecordedLog, options):
    """The values of the family's own schema (``tma_log.contacts``)."""
    observation, source = options.observation, options.contact
    if source.field not in (None, observation.column):
        raise ConfigError(f"{observation.role}.field={source.field}: {msgs.topic} has tma's "
                          f"schema {msgs.schema}, whose {observation.plural} are "
                          f"'{observation.column}'; leave {observation.role}.field unset")
    t_ns, track, values, message = tma_log.contacts(msgs, file, observation.column)
    if source.units is not None:
        values = observation.unit(source.units).to_first(values)
    # the column names the first unit, yet values in another written there are what the
    # family's guard catches
    return t_ns, track, values, source.units is not None, message


# -- selection, checks, time base -----------------------------------------------------------

def _select_navigation(file: RecordedLog, options) -> str | None:
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


def _select_contacts(file: RecordedLog, options) -> list[str]:
    """The topics of the contacts' values: those ``<role>.topic`` names or matches (fnmatch
    patterns), else the family's own topic, or the one topic of its schema; [] if none."""
    observation = options.observation
    role = observation.role
    given = options.contact.topics
    if given is not None:
        chosen = []
        for entry in given:
            if not any(c in entry for c in "*?["):
                chosen.append(file.topic(entry, f"{role}.topic").name)
                continue
            matched = sorted(t.name for t in file.topics.values()
                             if fnmatch.fnmatchcase(t.name, entry) and t.count != 0)
            if not matched:
                raise InputError(f"{file.where}: {role}.topic={entry}: no topic matches; "
                                 f"{file.describe()}")
            chosen += matched
        chosen = list(dict.fromkeys(chosen))
        if len(chosen) > 1:
            file.notes.append(f"{observation.plural}: {len(chosen)} topics, each its contacts "
                              f"({', '.join(chosen)}; {role}.topic)")
        return chosen
    own = observation.topic
    if own in file.topics and file.topics[own].count != 0:
        found = [file.topics[own]]
    else:
        found = [t for t in file.topics.values()
                 if observation.schema is not None and t.schema == observation.schema
                 and t.count != 0]
    if len(found) > 1:
        raise InputError(f"{file.where}: {len(found)} {role} topics of schema "
                         f"{observation.schema}: {', '.join(t.name for t in found)}; set "
                         f"{role}.topic=<topic> (or a list, or a pattern such as /sonar/*)")
    if not found:
        return []
    file.notes.append(f"{observation.plural}: {found[0]} ({role}.topic)")
    return [found[0].name]


def _navigation_part(file: RecordedLog, msgs: Messages):
    """Own-ship fixes of a topic, sorted by time; fixes the receiver flags (NavSatFix
    NO_FIX), with a stamp not absolute among absolute ones or with NaN coordinates left out
    and counted."""
    t_ns, columns, no_fix = NAVIGATION[msgs.schema](msgs, file)
    keep = file.not_absolute(msgs, t_ns, np.arange(t_ns.size))
    if no_fix is not None and (no_fix & keep).any():  # the receiver's own verdict
        rows = np.flatnonzero(no_fix & keep)
        file.dropped.add("own-ship fix flagged no fix", rows.size,
                         file.places(msgs.topic, t_ns)(rows[:NAMED]))
        keep &= ~no_fix
    a, b = columns.values()
    finite = np.isfinite(a) & np.isfinite(b) | ~keep
    keep &= file.dropped.drop(~finite, "own-ship position missing or not a number",
                              file.places(msgs.topic, t_ns),
                              f"{file.where}: {msgs.topic}: an own-ship fix with NaN or "
                              "infinite coordinates")
    if not keep.any():
        raise InputError(f"{file.where}: no usable own-ship fix on {msgs.topic}: all "
                         f"{len(msgs.decoded)} dropped (status NO_FIX or NaN coordinates)")
    order = np.argsort(t_ns[keep], kind="stable")  # repeated times: align's to judge
    return t_ns[keep][order], {k: v[keep][order] for k, v in columns.items()}


def _together(parts):
    """The contacts of several topics as one, by time then contact: ``(t_ns, track, values,
    stated)``."""
    if len(parts) == 1:
        return parts[0]
    t_ns, track, values = (np.concatenate([p[k] for p in parts]) for k in range(3))
    order = np.argsort(t_ns, kind="stable")
    return t_ns[order], track[order], values[order], all(p[3] for p in parts)


def _contacts_part(file: RecordedLog, msgs: Messages, options, several=False):
    """``(t_ns, track, values, stated)`` of one topic, by time then contact. ``several``: one
    of several topics, whose contacts from a track field are labelled ``<topic>:<id>`` (a
    topic without one is its own contact, labelled by its name)."""
    observation = options.observation
    role = observation.role
    own = observation.schema is not None and msgs.schema == observation.schema
    t_ns, track, values, stated, message = (_own_values if own else _field_values)(
        msgs, file, options)
    if several and not (track.dtype == object and np.all(track == msgs.topic)):
        track = np.array([f"{msgs.topic}:{i}" for i in track], dtype=object)
    keep = file.not_absolute(msgs, t_ns, message)
    finite = np.isfinite(values) | ~keep
    keep &= file.dropped.drop(~finite, f"{role} missing or not a number",
                              file.places(msgs.topic, t_ns),
                              f"{file.where}: {msgs.topic}: a {role} missing or not a number")
    if not keep.any():
        raise InputError(f"{file.where}: no usable {role} on {msgs.topic} (none, or all NaN)")
    t_ns, track, values = t_ns[keep], track[keep], values[keep]
    codes = np.unique(track, return_inverse=True)[1]
    order = np.lexsort((codes, t_ns))  # by time, then contact
    t_ns, track, values, codes = t_ns[order], track[order], values[order], codes[order]
    dup = (t_ns[1:] == t_ns[:-1]) & (codes[1:] == codes[:-1])
    if dup.any():
        i = int(np.argmax(dup))
        raise InputError(f"{file.where}: {msgs.topic}: two {observation.plural} of contact "
                         f"{track[i]} at {stamp_text(int(t_ns[i]))}; a contact has one {role} "
                         "per time")
    return t_ns, track, values, stated


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


def read_mcap(path, options, need: tuple[str, ...] = (), navigation: bool = True) -> Recording:
    """Own-ship fixes and contacts from an MCAP file of any source kind (module docstring),
    with a family's reading ``options``.

    ``need``: the parts the caller requires (``"navigation"``, ``"contacts"``): a missing one
    raises an InputError listing the file's topics and the option that selects one. A part
    not needed and not found is None (noted); a file with neither always raises.
    ``navigation`` False: own-ship comes from elsewhere (``navigation=FILE``), so the file's
    own-ship topic is neither decoded nor checked, and its rows count nowhere (noted).
    """
    file = RecordedLog(path, options.dropped())
    role = options.observation.role
    nav_topic = _select_navigation(file, options)
    if not navigation:
        if nav_topic is not None:
            file.notes.append(f"{file.where}: own-ship from the navigation file; {nav_topic} "
                              "is not read")
        nav_topic = None
    contact_topics = _select_contacts(file, options)
    hint = {"navigation": ("no own-ship navigation: own-ship is read from a topic of schema "
                           f"{', '.join(NAVIGATION)}; set ownship.topic=<topic> or give "
                           "navigation=FILE"),
            "contacts": (f"no {options.observation.plural} selected: set {role}.topic=<topic> "
                         f"[{role}.field=data]")}
    absent = [p for p, t in (("navigation", nav_topic), ("contacts", contact_topics or None))
              if t is None and (navigation or p == "contacts")]
    fatal = [p for p in absent if p in need] or (absent if len(absent) == 2 else [])
    if fatal:
        raise InputError(f"{file.where}: {'; '.join(hint[p] for p in fatal)}; "
                         f"{file.describe()}")
    file.notes.extend(f"{file.where}: {hint[p]}" for p in absent)

    topics = ([] if nav_topic is None else [nav_topic]) + contact_topics
    if nav_topic in contact_topics:
        raise InputError(f"{file.where}: {nav_topic} is both the own-ship and the {role} topic; "
                         f"set {role}.topic= or ownship.topic= to another topic")
    messages = file.messages(topics)
    for topic in topics:
        if not messages[topic].decoded:
            raise InputError(f"{file.where}: no messages on {topic}; {file.describe()}")
    parts = {}
    if nav_topic is not None:
        parts[nav_topic] = _navigation_part(file, messages[nav_topic])
    for topic in contact_topics:
        parts[topic] = _contacts_part(file, messages[topic], options,
                                      several=len(contact_topics) > 1)
    epoch = _epoch({topic: part[0] for topic, part in parts.items()}, file.where)

    def seconds(t_ns):
        return (t_ns - (epoch or 0)) / 1e9

    navigation = contacts = None
    if nav_topic is not None:
        t_ns, columns = parts[nav_topic]
        navigation = Navigation(seconds(t_ns), epoch, file.source(nav_topic), **columns,
                                topic=nav_topic)
    if contact_topics:
        t_ns, track, values, stated = _together([parts[t] for t in contact_topics])
        contacts = Contacts(seconds(t_ns), epoch, track, values,
                            "; ".join(file.source(t) for t in contact_topics),
                            units_stated=stated)
    return Recording(navigation, contacts, file.metadata, file.notes, file.dropped)
