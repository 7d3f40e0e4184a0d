"""Typed validation of config nodes against declared parameter dataclasses.

Each scenario and estimator declares its parameters as a dataclass (names with units, defaults,
docs). A Hydra node is merged onto it, so unknown keys and wrong types fail with a message that
names the key, instead of surfacing later as a numpy error. Every float anywhere in the config
(nested dataclasses and lists included) must be finite; a field declared with
``field(metadata={"nonfinite": True})`` may be +-inf (e.g. "no limit"), never NaN. The
dataclass's ``__post_init__`` then checks ranges and consistency.
"""

import copy
import functools
import json
import math
from dataclasses import asdict, fields, is_dataclass

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from tma.errors import ConfigError


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
    try:
        key = json.dumps(node, sort_keys=True)
    except (TypeError, ValueError):  # not JSON-able (e.g. a tuple key): validate uncached
        return _validate(schema, node, where)
    return copy.deepcopy(_validated(schema, key, where))


@functools.lru_cache(maxsize=256)
def _validated(schema, key: str, where: str):
    return _validate(schema, json.loads(key), where)


def _validate(schema, node, where: str):
    try:
        merged = OmegaConf.merge(structured(schema), node or {})
        check_finite(merged, where)  # before __post_init__: its range checks assume numbers
        return OmegaConf.to_object(merged)
    except OmegaConfBaseException as exc:
        msg = getattr(exc, "msg", None) or str(exc).splitlines()[0]
        key = getattr(exc, "full_key", None)
        raise ConfigError(f"{where}: {msg}" + (f" (key '{key}')" if key else "")) from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


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
                raise ConfigError(f"{where}: {key}[{i}] must be a number, got {value}")
            check_finite(value, where, f"{key}[{i}]", allow_inf)
    elif isinstance(node, float) and not (math.isfinite(node)
                                          or (allow_inf and math.isinf(node))):
        raise ConfigError(f"{where}: {key} must be finite, got {node}")
    elif isinstance(node, int) and not isinstance(node, bool) and abs(node) > MAX_INT:
        raise ConfigError(f"{where}: {key} = {node} is too large (at most 2^53)")


def to_plain(obj):
    """Plain JSON-able dict of a dataclass (or DictConfig) for manifests and hashes."""
    if is_dataclass(obj):
        return asdict(obj)
    if isinstance(obj, DictConfig):
        return OmegaConf.to_container(obj, resolve=True)
    return obj


def require(condition: bool, where: str, message: str):
    """Raise ConfigError(where: message) unless ``condition`` holds."""
    if not condition:
        raise ConfigError(f"{where}: {message}")


def is_probability_vector(p, n: int, tol: float = 1e-9) -> bool:
    """``p`` has ``n`` entries in [0, 1] summing to 1 (within ``tol``)."""
    return len(p) == n and all(0.0 <= x <= 1.0 for x in p) and abs(sum(p) - 1.0) <= tol
