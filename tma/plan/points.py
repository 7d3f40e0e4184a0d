"""The points one command runs, inside one job (``docs/architecture.md``, "Two sweeps"):
scenario points times estimators, from plain configs (dicts) and the command line's
overrides:

- a list given where the scenario expects a single value is an axis
  (``scenario.sigma_deg=[0.1,0.5]``: two datasets); several axes give their cartesian product,
  the last one varying fastest (``scenario_points``);
- an experiment's estimators (``estimators``) are edited by the command line
  (``estimator_configs``): ``estimator=NAME`` runs NAME alone, ``estimator.KEY=VALUE`` sets KEY
  in each of them that has it, ``estimators.NAME.KEY=VALUE`` sets it in NAME only. An
  override that would change nothing fails (ConfigError naming it), never is ignored.

And an override as the command line writes it (``override_text``), for messages that say
which override selects what.
"""

import copy
import dataclasses
import itertools
import json
import re
import types
import typing

from tma.errors import ConfigError
from tma.estimator import name_set_error
from tma.families import build_estimator, scenario_module


@dataclasses.dataclass(frozen=True)
class Override:
    """One command-line override as this module reads it: its dotted ``key``
    (``estimator``, ``estimator.lambda0``, ``estimators.lm.max_iter``), its ``text`` as
    typed (for messages), the ``value`` of a choice (``estimator=NAME``: NAME), whether it
    deletes (``~key``) and its package (``key@pkg=...``; None when none)."""

    key: str
    text: str
    value: object = None
    delete: bool = False
    package: str | None = None


# -- scenarios: a list where the scenario expects one value is an axis of the points --------

def _holds_a_list(annotation) -> bool:
    """True if a field of this type may hold a list (then a list is its value, not an axis)."""
    if annotation is typing.Any:
        return True
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return any(_holds_a_list(a) for a in typing.get_args(annotation) if a is not type(None))
    return (origin or annotation) in (list, tuple, set, frozenset)


def _axes(node: dict, schema, prefix: str = "") -> list[tuple[str, list]]:
    """``(dotted key, values)`` of every list in ``node`` where ``schema`` (a dataclass)
    declares a single value, in the order of the config."""
    hints = typing.get_type_hints(schema)
    axes = []
    for key, value in node.items():
        if key not in hints:
            continue  # an unknown key: validation names it
        tp = hints[key]
        if isinstance(value, dict) and dataclasses.is_dataclass(tp):
            axes += _axes(value, tp, f"{prefix}{key}.")
        elif isinstance(value, list) and not _holds_a_list(tp):
            if not value:
                raise ConfigError(f"scenario.{prefix}{key}: an empty list of values")
            axes.append((f"{prefix}{key}", value))
    return axes


def scenario_points(scenario: dict) -> list[dict]:
    """The scenario config expanded into one config per point of its axes (module
    docstring)."""
    try:
        schema = scenario_module(scenario.get("family")).Config
    except ConfigError:
        return [scenario]  # an unknown or missing family: load_scenario says so
    axes = _axes(scenario, schema)
    points = []
    for values in itertools.product(*(v for _, v in axes)):
        point = copy.deepcopy(scenario)
        for (dotted, _), value in zip(axes, values, strict=True):
            _set_key(point, dotted, value)
        points.append(point)
    return points


# -- estimators: an experiment's estimators, edited by the command line ----------------------

def has_key(node: dict, dotted: str) -> bool:
    for key in dotted.split("."):
        if not isinstance(node, dict) or key not in node:
            return False
        node = node[key]
    return True


def _get_key(node: dict, dotted: str):
    for key in dotted.split("."):
        node = node[key]
    return node


def _set_key(node: dict, dotted: str, value):
    *path, last = dotted.split(".")
    for key in path:
        node = node[key]
    node[last] = value


def estimator_configs(estimator: dict, estimators: dict | None,
                      overrides: list[Override]) -> list[dict]:
    """Estimator configs: the single ``estimator``, or an experiment's ``estimators``
    (name -> config) as the command line's ``overrides`` edit them (module docstring).
    ``estimator`` holds, under an experiment, every key of the family's estimators (the
    ``estimator_keys`` group, ``tma.families.register_configs``), so ``estimator.KEY=VALUE``
    reaches it: its value is
    read there."""
    if not estimators:
        named = [o for o in overrides if o.key == "estimator.name" and o.package is None]
        if named:  # as tma.estimate's name=
            raise name_set_error(named[-1].text, named[-1].text.partition("=")[2] or "NAME")
        return [estimator]
    nodes = copy.deepcopy(estimators)
    chosen = [o.value for o in overrides if o.key == "estimator"
              and o.package is None and not o.delete]
    if chosen:
        if chosen[-1] not in nodes:
            raise ConfigError(f"estimator={chosen[-1]}: not an estimator of this experiment "
                              f"(estimators: {', '.join(nodes)})")
        nodes = {chosen[-1]: nodes[chosen[-1]]}
    by_name = {}  # (estimator, key) -> override, for estimators.NAME.KEY=...
    for o in overrides:
        parts = o.key.split(".")
        if parts[0] == "estimators" and len(parts) > 1 and o.package is None:
            if parts[1] not in nodes:
                raise ConfigError(f"{o.text}: '{parts[1]}' is not run "
                                  f"(estimators: {', '.join(nodes)})")
            by_name[parts[1], ".".join(parts[2:])] = o.text
    for o in overrides:
        if not o.key.startswith("estimator.") or o.package is not None:
            continue
        key = o.key.removeprefix("estimator.")
        if o.delete or key == "name":
            raise ConfigError(f"{o.text}: with an experiment, choose estimators with "
                              "estimator=NAME and set their values with estimator.KEY=VALUE")
        takers = [n for n, node in nodes.items() if has_key(node, key)]
        if not takers:
            raise ConfigError(f"{o.text}: no estimator of this run has '{key}' "
                              f"(estimators: {', '.join(nodes)})")
        for name in takers:
            clash = by_name.get((name, key))
            if clash:
                raise ConfigError(f"{o.text} and {clash} both set '{key}' of {name}: "
                                  "give one")
            _set_key(nodes[name], key, copy.deepcopy(_get_key(estimator, key)))
    return list(nodes.values())


def checked_estimator_configs(estimator: dict, estimators: dict | None,
                              overrides: list[Override]) -> list[dict]:
    """``estimator_configs`` after building each once, so a bad value fails naming its key."""
    nodes = estimator_configs(estimator, estimators, overrides)
    for node in nodes:
        build_estimator(node)
    return nodes


# -- an override as the command line writes it -------------------------------------------------

_PLAIN_VALUE = re.compile(r"[\w./@:+-]+", re.ASCII)  # Hydra reads only ASCII unquoted


_HYDRA_TYPED = re.compile(r"[+-]?(?:[\d_]+\.?[\d_]*|\.[\d_]+)(?:[eE][+-]?[\d_]+)?"
                          r"|[+-]?(?:inf|nan)|true|false|null", re.IGNORECASE)


def override_text(key: str, value) -> str:
    """``key=value`` as the command line takes it: null, true/false, numbers, lists and
    mappings as Hydra writes them; text quoted when it holds anything but letters, digits and
    ``_ . / @ : + -``, or when unquoted it would read as another type."""
    return f"{key}={_value_text(value)}"


def _value_text(value) -> str:
    if value is None or isinstance(value, bool | int | float):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ",".join(_value_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{_value_text(v)}" for k, v in value.items()) + "}"
    text = str(value)
    # a text Hydra would read unquoted as a number, bool or null (+0, 1_000, 1e3, .5, INF,
    # True, NULL): quoted (quoting more than needed is harmless)
    typed = _HYDRA_TYPED.fullmatch(text) is not None
    if _PLAIN_VALUE.fullmatch(text) and not typed:
        return text
    # Hydra's quoted text: backslashes doubled before a quote or at the end, quotes escaped;
    # ${ escaped for OmegaConf, which would read an interpolation
    text = re.sub(r"(\\+)(?='|$)", lambda m: m.group(1) * 2, text).replace("'", "\\'")
    return "'" + text.replace("${", "\\${") + "'"

