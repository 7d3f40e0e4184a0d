"""The MCAP reader: recorded logs in MCAP, whatever wrote them: ``read_mcap(path, options) ->
Recording`` (kind ``mcap``: the MCAP magic, or ``.mcap``; options ``ownship.topic``,
``<role>.topic``, ``<role>.field``). The topics are read by ``tma.sources.mcap_topics``.

The file is read and checked once by tma's one MCAP reader (``tma.io.mcap_read.McapFile``:
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

from dataclasses import dataclass, make_dataclass
from typing import Any

from tma.config import Form, param
from tma.sources.base import Reader, Recording

MAGIC = b"\x89MCAP"


def _topics_problem(value) -> str | None:
    entries = list(value) if isinstance(value, list | tuple) else [value]
    fine = entries and all(isinstance(e, str | int | float) and not isinstance(e, bool)
                           and str(e).strip() for e in entries)
    return None if fine else ""


TOPICS = Form("a topic, a pattern or a list of them", _topics_problem)


class ContactSource:
    """Where the values are in an MCAP log: ``topic`` (a topic, a pattern or a list of them)
    and ``field``, declared in the observation's words (``options``)."""

    topic: Any
    field: str | None

    @property
    def topics(self) -> list[str] | None:
        """The topics or patterns given, as a list; None when none is."""
        return None if self.topic is None else (
            list(self.topic) if isinstance(self.topic, list) else [self.topic])

    def rules(self):
        """A topic's number is its text."""
        if self.topic is not None:
            self.topic = ([str(e) for e in self.topic] if isinstance(self.topic, list | tuple)
                          else str(self.topic))


@dataclass
class OwnshipSource:
    """Where the own-ship's fixes are in an MCAP log (``ownship.*``)."""

    topic: Any = param(None, "MCAP topic of the own-ship's fixes; a list or a pattern "
                       "(fnmatch: /*/gps/fix): several platforms (ships, buoys, stations), "
                       "each its own topic, whose values are the topics in its namespace "
                       "(/ship_a/...); null: found by its schema (NavSatFix, LocationFix, "
                       "Odometry, PoseStamped...)", form=TOPICS)

    def rules(self):
        """A topic's number is its text; a list of one is that topic."""
        if isinstance(self.topic, list | tuple):
            self.topic = [str(e) for e in self.topic]
            if len(self.topic) == 1:
                self.topic = self.topic[0]
        elif self.topic is not None:
            self.topic = str(self.topic)

    @property
    def several(self) -> bool:
        """Several platforms' topics named: a list or a pattern."""
        return isinstance(self.topic, list) or (
            self.topic is not None and any(c in self.topic for c in "*?["))




def options(observation) -> dict:
    """The options only MCAP logs are read with: where the values are (``<role>.topic``,
    ``<role>.field``) and the own-ship (``ownship.topic``)."""
    role, plural = observation.role, observation.plural
    source = make_dataclass(f"{role.title()}Source", [
        ("topic", Any, param(None, f"MCAP topic(s) of the {plural}: a topic, a pattern "
                                   "(fnmatch: /sonar/contact/*) or a list of them; each topic "
                                   "is a contact (named by its topic) unless its messages "
                                   f"name contacts (track_id); null: {observation.topic} or "
                                   "the family's schema", form=TOPICS)),
        ("field", str | None, param(None, f"dotted field path of the {role} in its messages; "
                                          f"null: the first of {', '.join(observation.fields)} "
                                          "found"))],
        bases=(ContactSource,))
    return {role: source, "ownship": OwnshipSource}


def read_mcap(path, options, need: tuple[str, ...] = (), navigation: bool = True) -> Recording:
    """Own-ship fixes and contacts from an MCAP file of any source kind (module docstring),
    with a family's reading ``options``.

    ``need``: the parts the caller requires (``"navigation"``, ``"contacts"``): a missing one
    raises an InputError listing the file's topics and the option that selects one. A part
    not needed and not found is None (noted); a file with neither always raises.
    ``navigation`` False: own-ship comes from elsewhere (``navigation=FILE``), so the file's
    own-ship topic is neither decoded nor checked, and its rows count nowhere (noted).
    """
    from tma.sources.mcap_topics import read_recorded

    return read_recorded(path, options, need, navigation)


def read(path, options, *, navigation: bool, contacts: bool,
         date_hint_ns: int | None = None) -> list[Recording]:
    """``read_mcap`` as a reader (``Reader.read``)."""
    need = (("navigation",) if navigation else ()) + (("contacts",) if contacts else ())
    from tma.sources.mcap_topics import read_platforms

    return read_platforms(path, options, need, navigation)


READER = Reader(kind="mcap", name="an MCAP log", extensions=(".mcap",), read=read,
                sniff=lambda head: head.startswith(MAGIC), options=options,
                selects_contacts="{role}.topic=<topic> [{role}.field=<field>]",
                selects_navigation="ownship.topic=<topic>")
