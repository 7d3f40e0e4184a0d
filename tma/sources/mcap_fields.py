"""Values and contacts by field path in an MCAP topic's decoded messages (dicts from JSON,
protobuf messages, ROS 2 objects), for the MCAP reader (``tma.sources.mcap_topics``): the
value field (``<role>.field``), its units or direction vectors, the contacts' track field.
"""

import functools
import operator
from collections.abc import Sequence

import numpy as np
from google.protobuf.message import Message as ProtobufMessage

from tma.errors import ConfigError, InputError
from tma.io.mcap_values import float_array, int_array, schema_errors
from tma.sources import tma_log

TRACK_FIELDS = ("track_id", "track", "contact_id", "contact", "target_id")


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

def _value_field(msgs, field: str | None, file, observation) -> str:
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


def _tracks(msgs, field: str, sizes, file):
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


def field_values(msgs, file, options):
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


def own_values(msgs, file, options):
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
