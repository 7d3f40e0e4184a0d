"""Typed validation of config nodes against declared parameter dataclasses.

Each scenario and estimator declares its parameters as a dataclass (names with units, defaults,
docs). A Hydra node is merged onto it, so unknown keys and wrong types fail with a message that
names the key, instead of surfacing later as a numpy error.
"""

from dataclasses import asdict, is_dataclass

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from tma.errors import ConfigError


def validate(schema, node, where: str):
    """Return an instance of dataclass ``schema`` built from ``node`` (DictConfig or dict)."""
    if isinstance(node, DictConfig):
        node = OmegaConf.to_container(node, resolve=True)
    try:
        merged = OmegaConf.merge(OmegaConf.structured(schema), node or {})
        return OmegaConf.to_object(merged)
    except OmegaConfBaseException as exc:
        msg = getattr(exc, "msg", None) or str(exc).splitlines()[0]
        key = getattr(exc, "full_key", None)
        raise ConfigError(f"{where}: {msg}" + (f" (key '{key}')" if key else "")) from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


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
