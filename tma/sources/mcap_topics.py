"""An MCAP file's topics as a source (``tma.sources.mcap``, the MCAP reader): which topics hold
own-ship and the contacts' values, their messages decoded (``RecordedLog``), values and
contacts by field path, stamps and the time base (``read_recorded``).
"""

import fnmatch
import os
from dataclasses import dataclass

import numpy as np
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

from tma.errors import InputError
from tma.io.mcap_log import PLATFORMS, geo_origin, platform_names, platform_namespace
from tma.io.mcap_read import McapFile, TmaDecoderFactory
from tma.io.mcap_values import schema_errors
from tma.sources import foxglove, ros2, tma_log
from tma.sources.base import NAMED, Contacts, Dropped, Navigation, Recording
from tma.sources.mcap_fields import field_values, own_values
from tma.utc import UTC_FROM_NS, stamp_text

# own-ship readers by schema name, in order of preference when a log holds several
NAVIGATION = {
    tma_log.OWNSHIP: tma_log.navigation,  # exact local metres (and the log's origin)
    ros2.NAVSATFIX: ros2.navsatfix,
    foxglove.LOCATION_FIX: foxglove.location_fix,
    ros2.ODOMETRY: ros2.odometry,
    ros2.POSE_STAMPED: ros2.pose_stamped,
}
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


# -- selection, checks, time base -----------------------------------------------------------

def _select_navigation(file: RecordedLog, options) -> str | None:
    if options.ownship.several:  # (read_platforms reads those, a recording per platform)
        raise InputError(f"{file.where}: ownship.topic={options.ownship.topic} names the "
                         "own-ship topics of several platforms, where one recording is read: "
                         "name one topic, or read the log with tma.read_log (a recording per "
                         "platform)")
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
    t_ns, track, values, stated, message = (own_values if own else field_values)(
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


def read_recorded(path, options, need: tuple[str, ...] = (),
                  navigation: bool = True, file: RecordedLog | None = None) -> Recording:
    """``tma.sources.mcap.read_mcap`` (its arguments, its Recording); ``file``: the log
    already open (read once)."""
    file = RecordedLog(path, options.dropped()) if file is None else file
    nav_topic = _select_navigation(file, options)
    if not navigation:
        if nav_topic is not None:
            file.notes.append(f"{file.where}: own-ship from the navigation file; {nav_topic} "
                              "is not read")
        nav_topic = None
    return _recording(file, options, need, navigation, nav_topic,
                      _select_contacts(file, options))


def read_platforms(path, options, need: tuple[str, ...] = (),
                   navigation: bool = True) -> list[Recording]:
    """The MCAP reader's recordings: one (``read_recorded``), or one per platform where the
    log holds several (``_platforms``: ``ownship.topic`` a list or a pattern, or tma's own
    log of several, ``tma.platforms``), each named by it, with its own-ship topic and the
    values of the topics in its namespace."""
    if options.ownship.several and not navigation:
        raise InputError(f"{path}: ownship.topic={options.ownship.topic} names the own-ship "
                         "topics of several platforms, but own-ship comes from navigation=: "
                         "drop one of the two")
    probe = RecordedLog(path, options.dropped())
    platforms = _platforms(probe, options) if navigation else None
    if platforms is None:
        return [read_recorded(path, options, need, navigation, file=probe)]
    out = []
    for k, (name, nav_topic, contact_topics) in enumerate(platforms):
        file = probe if k == 0 else RecordedLog(path, options.dropped())
        rec = _recording(file, options, need, navigation, nav_topic, contact_topics)
        rec.platform = name
        out.append(rec)
    return out


def _namespace(topic: str) -> tuple[str, ...]:
    """A topic's namespace: its path but the last name (``/ship_a/gps/fix`` -> ship_a, gps)."""
    return tuple(p for p in topic.split("/") if p)[:-1]


def _platforms(file: RecordedLog, options):
    """``[(name, own-ship topic, value topics), ...]`` of a log of several platforms, or None
    for a log of one: own-ship topics ``ownship.topic`` names as a list or pattern (named by
    their namespace), or tma's own log of several (``tma.platforms``: its names). Each value
    topic (``<role>.topic``, else every topic of the observation's schema) goes with the
    own-ship topic whose namespace shares most of its own; none, or a tie, is refused."""
    observation, role = options.observation, options.observation.role
    names = None
    if options.ownship.several:
        given = options.ownship.topic
        given = given if isinstance(given, list) else [given]
        nav = []
        for entry in given:
            if not any(c in entry for c in "*?["):
                nav.append(file.topic(entry, "ownship.topic").name)
                continue
            matched = sorted(t.name for t in file.topics.values()
                             if fnmatch.fnmatchcase(t.name, entry) and t.count != 0
                             and t.schema in NAVIGATION)
            if not matched:
                raise InputError(f"{file.where}: ownship.topic={entry}: no own-ship topic "
                                 f"matches; {file.describe()}")
            nav += matched
        nav = list(dict.fromkeys(nav))
        for topic in nav:
            if file.topics[topic].schema not in NAVIGATION:
                raise InputError(f"{file.where}: ownship.topic={topic} has schema "
                                 f"'{file.topics[topic].schema}'; own-ship is read from "
                                 f"{', '.join(NAVIGATION)}")
    elif PLATFORMS in file.metadata:  # tma's own log of several (its names, in order)
        names = platform_names(file.metadata, file.where)
        own = {_namespace(t.name): t.name for t in file.topics.values()
               if t.schema == tma_log.OWNSHIP}  # by namespace: /platforms/<k>
        nav = [own.get(tuple(platform_namespace(k).strip("/").split("/")),
                       f"{platform_namespace(k)}/navigation") for k in range(len(names))]
        for topic in nav:
            file.topic(topic, "the record tma.platforms: the own-ship of")
    else:
        return None
    if options.contact.topics is not None:
        values = _select_contacts(file, options)
    else:
        values = sorted(t.name for t in file.topics.values()
                        if t.schema == observation.schema and t.count != 0)
    spaces = [_namespace(t) for t in nav]
    owned = {t: [] for t in nav}
    for topic in values:
        ns = _namespace(topic)
        shared = [len(os.path.commonprefix([ns, s])) for s in spaces]
        best = max(shared)
        if best == 0 or shared.count(best) > 1:
            raise InputError(f"{file.where}: {role}s on {topic}: no one own-ship topic shares "
                             f"its namespace ({', '.join(nav)}): each platform's topics go "
                             "under its own (/ship_a/gps/fix, /ship_a/sonar/bearings), or name "
                             f"them with {role}.topic=<topic>")
        owned[nav[shared.index(best)]].append(topic)
    idle = [t for t, v in owned.items() if not v]
    if idle:
        raise InputError(f"{file.where}: no {observation.plural} under the namespace of the "
                         f"own-ship topic {idle[0]} (ownship.topic): each platform's "
                         f"{observation.plural} go under its own namespace")
    if names is None:
        names = ["/" + "/".join(os.path.commonprefix([s, *map(_namespace, owned[t])]))
                 for s, t in zip(spaces, nav, strict=True)]
        names = [n if n != "/" and names.count(n) == 1 else t for n, t in zip(names, nav,
                                                                              strict=True)]
    file.notes.append(f"{len(nav)} platforms: " + "; ".join(
        f"{n!r}: {t} and {', '.join(owned[t])}" for n, t in zip(names, nav, strict=True)))
    return [(n, t, owned[t]) for n, t in zip(names, nav, strict=True)]


def _recording(file: RecordedLog, options, need, navigation, nav_topic, contact_topics
               ) -> Recording:
    """One own-ship's Recording: its topics ``nav_topic`` (None: none) and
    ``contact_topics`` decoded and checked."""
    role = options.observation.role
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
        # tma's own schema holds directions from its plane's north (its tma.geo origin)
        own = any(file.topics[t].schema == options.observation.schema for t in contact_topics)
        contacts = Contacts(seconds(t_ns), epoch, track, values,
                            "; ".join(file.source(t) for t in contact_topics),
                            units_stated=stated,
                            plane_origin_deg=geo_origin(file.metadata, file.where) if own
                            else None)
    return Recording(navigation, contacts, file.metadata, file.notes, file.dropped)
