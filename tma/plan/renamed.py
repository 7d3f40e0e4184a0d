"""Config keys renamed after tma 0.6.0, still read for one release with a one-line note each,
then refused as unknown keys:

- ``grid.estimators`` (an experiment's estimators) is ``estimators``
  (``estimators.NAME.KEY=VALUE``, ``+estimator@estimators.NAME=NAME``): "grid" said nothing of
  what it held, and was also the name of the track x epoch arrays (``tma.io.track_epochs``);
- ``report`` (the kind of table aggregate writes) is ``table_kind``: "report" is the per-track
  report of a recorded log.

The command line's arguments are read in the new spelling before Hydra composes them
(``renamed_arguments``), an experiment's file when the command is built
(``renamed_config``), so nothing past them reads an old one.
"""

import logging
import re

from tma.errors import ConfigError

log = logging.getLogger("tma")

OLD_ESTIMATORS, NEW_ESTIMATORS = "grid.estimators", "estimators"
OLD_TABLE_KIND, NEW_TABLE_KIND = "report", "table_kind"
_noted: set[str] = set()  # a note once per process, however many commands it builds


def deprecation_note(old: str, new: str) -> str:
    """The one line that says an old spelling was read."""
    return (f"'{old}' is deprecated: write '{new}' (the old spelling is read for one more "
            "release)")


def _note(old: str, new: str):
    if old not in _noted:
        _noted.add(old)
        log.warning(deprecation_note(old, new))


def _renamed_key(dotted: str) -> str:
    """``dotted`` (an override's key or package) in the new spelling, noted when it was old."""
    if dotted == OLD_ESTIMATORS or dotted.startswith(OLD_ESTIMATORS + "."):
        _note(OLD_ESTIMATORS, NEW_ESTIMATORS)
        return NEW_ESTIMATORS + dotted.removeprefix(OLD_ESTIMATORS)
    if dotted == OLD_TABLE_KIND:
        _note(OLD_TABLE_KIND, NEW_TABLE_KIND)
        return NEW_TABLE_KIND
    return dotted


def _merged(node: dict, over: dict) -> dict:
    """``node`` with the values of ``over`` set on it, nested dicts key by key (an old
    ``grid.estimators.lm.max_iter=3`` sets one value of the experiment's ``estimators.lm``)."""
    out = dict(node)
    for key, value in over.items():
        out[key] = (_merged(out[key], value) if isinstance(value, dict)
                    and isinstance(out.get(key), dict) else value)
    return out


# an override as Hydra reads it: ~ + or ++, its key, @package, =value
_OVERRIDE = re.compile(r"(~|\+\+|\+)?([^=@~+][^=@]*)(?:@([^=]*))?(=.*)?", re.S)


def renamed_arguments(arguments: list[str]) -> list[str]:
    """The command line's overrides with the old keys and packages in the new spelling
    (``grid.estimators.lm.max_iter=3``: ``estimators.lm.max_iter=3``;
    ``+estimator@grid.estimators.iv=iv``: ``+estimator@estimators.iv=iv``; ``report=K``:
    ``table_kind=K``), each noted once; flags and other arguments as they are."""
    out = []
    for argument in arguments:
        m = None if argument.startswith("-") else _OVERRIDE.fullmatch(argument)
        if m is None:
            out.append(argument)
            continue
        prefix, key, package, value = m.groups()
        package = "" if package is None else "@" + _renamed_key(package)
        out.append(f"{prefix or ''}{_renamed_key(key)}{package}{value or ''}")
    return out


def renamed_config(config: dict) -> dict:
    """``config`` with the old spellings (module docstring) moved to the new keys:
    ``grid.estimators`` joins ``estimators`` (set on it value by value), ``report`` is
    ``table_kind`` (both set to different kinds: a ConfigError); ``grid`` may hold nothing
    else."""
    config = dict(config)
    grid = config.pop("grid", None)
    if grid is not None:
        if not isinstance(grid, dict):
            raise ConfigError(f"grid must be null or {{estimators: {{name: estimator config}}}} "
                              f"(now written estimators: {{name: estimator config}}), got "
                              f"'{grid}'")
        extra = sorted(set(grid) - {"estimators"})
        if extra:
            raise ConfigError(
                f"grid.{extra[0]}: grid took only 'estimators' (now 'estimators' alone); sweep "
                "a scenario value by giving the scenario key a list, e.g. "
                "scenario.sigma_deg=[0.1,0.5]")
        old = grid.get("estimators") or {}
        if old:
            _note(OLD_ESTIMATORS, NEW_ESTIMATORS)
            config[NEW_ESTIMATORS] = _merged(config.get(NEW_ESTIMATORS) or {}, old)
    if config.get(OLD_TABLE_KIND) is not None:
        _note(OLD_TABLE_KIND, NEW_TABLE_KIND)
        kind = config.get(NEW_TABLE_KIND)
        if kind is not None and kind != config[OLD_TABLE_KIND]:
            raise ConfigError(f"{OLD_TABLE_KIND}={config[OLD_TABLE_KIND]} and "
                              f"{NEW_TABLE_KIND}={kind}: give {NEW_TABLE_KIND} alone")
        config[NEW_TABLE_KIND] = config[OLD_TABLE_KIND]
    config.pop(OLD_TABLE_KIND, None)
    return config
