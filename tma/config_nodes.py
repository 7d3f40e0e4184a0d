"""Config nodes (Hydra's, OmegaConf's, or plain dicts) checked into the dataclasses that
declare them (``tma.config``), and those dataclasses' defaults as nodes.

``validate(schema, node, where)`` merges a node onto its dataclass, so that unknown keys and
wrong types fail with a message that names the key instead of surfacing later as a numpy
error, checks that every float is finite (``check_finite``; a ``param(..., nonfinite=True)``
may be +-inf, never NaN) and builds the instance, whose ``__post_init__`` checks the declared
ranges (``tma.config.check_params``). ``defaults(schema)`` is every default as a plain dict,
the node Hydra's ConfigStore registers (``tma.families.register_configs``)."""

import copy
import datetime
import functools
import json
import math
import re
from dataclasses import MISSING, Field, asdict, fields, is_dataclass

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException, ValidationError

from tma.config import message_at, wrong_type_message
from tma.errors import ConfigError, ConfigTypeError, TmaError


@functools.cache
def structured(schema) -> DictConfig:
    """``OmegaConf.structured(schema)``, built once per dataclass (~8 ms each, and a command
    needs each several times: Hydra's defaults, the estimator keys, validation). Shared:
    read it or merge onto it (``OmegaConf.merge`` copies), never modify it."""
    return OmegaConf.structured(schema)


def defaults(schema) -> dict:
    """Every default of dataclass ``schema`` as a plain dict (``???`` where it has none)."""
    return copy.deepcopy(_defaults(schema))


@functools.cache
def _defaults(schema) -> dict:
    # every command registers ~20 dataclasses' defaults before Hydra composes: read them off
    # an instance (0.1 ms) rather than build each one's OmegaConf node (8 ms); a dataclass
    # with a field that has no default is OmegaConf's to mark '???'
    try:
        return _containers(asdict(schema()))
    except (TypeError, ValueError):
        return OmegaConf.to_container(structured(schema))


def _containers(value):
    """Tuples as lists, as OmegaConf's ``to_container`` gives them."""
    if isinstance(value, dict):
        return {k: _containers(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_containers(v) for v in value]
    return value


def validate(schema, node, where: str):
    """Return an instance of dataclass ``schema`` built from ``node`` (DictConfig or dict).

    OmegaConf's typed merge costs ~50 ms, and every shard task validates its config again
    (tasks carry plain dicts to worker processes): a node validated before is answered from a
    cache with a fresh copy."""
    if isinstance(node, DictConfig):
        node = OmegaConf.to_container(node, resolve=True)
    node = _times_as_text(node)
    try:
        key = json.dumps(node, sort_keys=True)
    except (TypeError, ValueError):  # not JSON-able (e.g. a tuple key): validate uncached
        return _validate(schema, node, where)
    return copy.deepcopy(_validated(schema, key, where))


@functools.lru_cache(maxsize=256)
def _validated(schema, key: str, where: str):
    return _validate(schema, json.loads(key), where)


def _times_as_text(value):
    """``value`` with every ``datetime`` (a pandas ``Timestamp`` too) as the ISO-8601 text a
    config holds (``time.start_utc``, ``epoch_utc``): one given in Python is read as written
    there; a time without a zone stays without one, for the key's check to name."""
    if isinstance(value, dict):
        return {k: _times_as_text(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_times_as_text(v) for v in value]
    return value.isoformat() if isinstance(value, datetime.datetime) else value


def _validate(schema, node, where: str):
    try:
        merged = OmegaConf.merge(structured(schema), node or {})
        check_finite(merged, where)  # before __post_init__: its range checks assume numbers
        return OmegaConf.to_object(merged)
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None)
        declared = _declared(schema, key) if key else None
        if isinstance(exc, ValidationError) and declared is not None:  # a value of a wrong type
            value = _given(node, key, getattr(exc, "value", None))
            raise ConfigTypeError(message_at(where, wrong_type_message(key, declared, value))) \
                from None
        msg = (getattr(exc, "msg", None) or str(exc)).splitlines()[0]
        raise ConfigError(message_at(where, msg + (f" (key '{key}')" if key else ""))) from None
    except TmaError:  # a check's own line (``check_params``, ``__post_init__``)
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(message_at(where, str(exc))) from None


def _path(key: str) -> list:
    """``legs[1].duration_s`` -> ``['legs', 1, 'duration_s']``."""
    return [int(p) if p.isdigit() else p for p in re.findall(r"[^.\[\]]+", key)]


def _declared(schema, key: str) -> Field | None:
    """The field of dataclass ``schema`` at dotted ``key`` (nested and listed configs
    included); None where there is none, or the key names no single value."""
    found = None
    for part in _path(key):
        if isinstance(part, int):
            continue  # an element of a list of configs: the same schema
        found = next((f for f in fields(schema) if f.name == part), None) if is_dataclass(
            schema) else None
        if found is None:
            return None
        default = (found.default_factory() if found.default_factory is not MISSING
                   else found.default)
        if isinstance(default, list) and default and is_dataclass(default[0]):
            default = default[0]
        schema = type(default) if is_dataclass(default) else None
    return found if schema is None else None


def _given(node, key: str, fallback):
    """The value given at dotted ``key`` of ``node`` (a plain dict), as written."""
    try:
        for part in _path(key):
            node = node[part]
        return node
    except (KeyError, IndexError, TypeError):
        return OmegaConf.to_container(fallback) if OmegaConf.is_config(fallback) else fallback


MAX_INT = 2**53  # larger integers are not exact as JSON numbers (and no count is that big)


def check_finite(node, where: str, key: str = "", allow_inf: bool = False,
                 numbers: bool = False):
    """Raise ConfigError naming the dotted key of the first NaN or infinite float, or integer
    beyond +-2^53, in ``node`` (a merged DictConfig/ListConfig or a value); fields whose
    metadata has ``nonfinite`` may be infinite (never NaN); elements of a field declared
    ``list[float]`` must be numbers (``numbers``)."""
    if isinstance(node, DictConfig):
        cls = OmegaConf.get_type(node)
        declared = fields(cls) if is_dataclass(cls) else ()
        inf_ok = {f.name for f in declared if f.metadata.get("nonfinite")}
        number_lists = {f.name for f in declared if f.type == list[float]}
        for k in node:
            check_finite(node[k], where, f"{key}.{k}" if key else str(k), k in inf_ok,
                         k in number_lists)
    elif isinstance(node, ListConfig):
        for i, value in enumerate(node):
            if numbers and (isinstance(value, bool) or not isinstance(value, int | float)):
                raise ConfigError(message_at(where, f"{key}[{i}] must be a number, got {value}"))
            check_finite(value, where, f"{key}[{i}]", allow_inf)
    elif isinstance(node, float) and not (math.isfinite(node)
                                          or (allow_inf and math.isinf(node))):
        raise ConfigError(message_at(where, f"{key} must be finite, got {node}"))
    elif isinstance(node, int) and not isinstance(node, bool) and abs(node) > MAX_INT:
        raise ConfigError(message_at(where, f"{key} = {node} is too large (at most 2^53)"))
