"""The reading options of a family: the options every reader reads, declared here, with those
each reader declares (``Reader.options``), assembled into one dataclass per observation.

Each option is a ``param``: its default, its doc (with units) and what it allows, in one
place; ``check_params`` checks them all (one line naming the key, the value and what is
allowed) and ``python -m tma.options ingest`` lists them; Hydra takes their defaults from the
same dataclass (``tma.families.register_configs``: the group ``reading``), so no YAML
restates them. What relates several options stays as code: a group's ``rules``.

Read by every kind: ``<role>.units`` (the observation's units), ``time.start_utc``, ``nav.*``,
``origin.*`` and ``bad_rows``; the others by the kinds that declare them, so an option set
that no input file's kind reads is refused (``inapplicable``), never ignored.
"""

import functools
from dataclasses import MISSING as MISSING_FACTORY
from dataclasses import dataclass, field, fields, is_dataclass, make_dataclass

from omegaconf import DictConfig, OmegaConf

from tma.config import Form, Params, describe, param
from tma.config_nodes import validate
from tma.errors import ConfigError
from tma.sources.base import Dropped, Observation
from tma.utc import parse_utc

BAD_ROWS = ("drop", "fail")


def _utc_problem(value) -> str | None:
    try:
        parse_utc(str(value))
    except ValueError as exc:  # "'...' is not a valid time (...)": what is wrong, if more
        return "" if "ISO-8601" in str(exc) else str(exc).rpartition("' is ")[2]
    return None


@dataclass
class TimeStart:
    """When a relative log starts (``time.start_utc``)."""

    start_utc: str | None = param(
        None, "the UTC of time 0 of a log of relative times, which makes it absolute; null: "
        "such a log stays undated",
        form=Form("an ISO-8601 time with a zone (e.g. 2026-01-01T08:00:00Z or "
                  "2026-01-01T09:00:00+01:00)", _utc_problem))

    @property
    def start_ns(self) -> int | None:
        return None if self.start_utc is None else parse_utc(str(self.start_utc))


@dataclass
class NavLimits:
    """What own-ship's navigation may do (``nav.*``)."""

    max_extrapolation_s: float = param(1.0, "a value further than this (s) outside the "
                                       "own-ship's fixes is dropped", "[0, 1e9)")
    max_gap_s: float = param(10.0, "a gap between own-ship's fixes longer than this (s) is "
                             "reported", "(0, 1e9)")
    max_bridge_s: float = param(300.0, "values inside a gap between own-ship's fixes longer "
                                "than this (s; at least max_gap_s) are left out: own-ship's "
                                "track across it is unknown, and a straight line between its "
                                "ends would be made up", "(0, 1e9)")
    max_speed_m_s: float = param(50.0, "own-ship never moves faster (m/s): a fix farther off "
                                 "its neighbours is an outlier", "(0, 1e5)")


@dataclass
class Origin:
    """The local east-north plane's origin (``origin.*``)."""

    lat: float | None = param(None, "latitude (deg, WGS84) of the local east-north plane's "
                              "origin; null: the first own-ship fix", "(-90, 90)")
    lon: float | None = param(None, "longitude (deg, WGS84) of the origin (with lat)",
                              "[-180, 360]")
    max_distance_km: float = param(100.0, "a given origin lies at most this far (km) from an "
                                   "own-ship fix", "(0, 20000)")

    def rules(self):
        if (self.lat is None) != (self.lon is None):
            raise ConfigError("origin.lat and origin.lon go together: give both or neither")


def common(observation: Observation) -> dict:
    """The options every kind of input reads: ``{group: dataclass, ...}`` and ``bad_rows``."""
    units = observation.units
    group = make_dataclass(f"{observation.role.title()}Units", [
        ("units", str | None, param(None, f"units of the {observation.plural}: "
                                          f"{', '.join(f'{u.name} ({u.words})' for u in units)};"
                                          f" null: {units[0].name} unless a column's or field's "
                                          "name or a units row says another",
                                    choices=(None, *(u.name for u in units))))])
    return {observation.role: group, "time": TimeStart, "nav": NavLimits, "origin": Origin}


BAD_ROWS_PARAM = ("bad_rows", str, param(
    "drop", "drop: a row with a missing or unreadable value, time or fix, or a fix off the "
    "track, is left out and counted (log line, manifest); fail: the first such row refuses "
    "the file", choices=BAD_ROWS))


class ReadingOptions(Params):
    """Base of a family's ``SourceOptions`` (``options_schema``): one group per key the
    readers and ``common`` declare (``columns``, ``<role>``, ``ownship``, ``csv``, ``time``,
    ``nmea``, ``nav``, ``origin``) and the option ``bad_rows``. ``observation`` is the
    family's; ``contact`` its group. Every option's declared type and values are checked first
    (``Params``, keys as the command line writes them), then each group's ``rules``."""

    observation: Observation

    @property
    def where(self) -> str:
        return ""  # the keys say it: csv.delimiter, nav.max_gap_s

    @property
    def contact(self):
        return getattr(self, self.observation.role)

    def column(self, role: str) -> str | None:
        return getattr(self.columns, role)

    def __post_init__(self):
        super().__post_init__()
        for f in fields(self):
            value = getattr(self, f.name)
            for cls in type(value).__mro__ if is_dataclass(value) else ():
                if "rules" in vars(cls):  # each declaring reader's own rules, once
                    vars(cls)["rules"](value)

    def dropped(self) -> Dropped:
        """A new count of the rows left out, under this policy."""
        return Dropped(self.bad_rows)


def options_schema(observation: Observation) -> type:
    """The reading options (a dataclass) of a family reading ``observation``, from the
    readers registered now (``tma.sources.READERS``): a group declared by several readers
    holds the fields of each (the first declaration's order)."""
    from tma.sources import readers

    return _schema(observation, tuple(readers()))


@functools.cache
def _schema(observation: Observation, registered: tuple) -> type:
    parts, scope = {}, {}
    for reader in registered:
        for group, part in reader.options(observation).items():
            parts.setdefault(group, []).append(part)
            scope.setdefault(group, {}).update({f.name: reader.kind for f in fields(part)})
    for group, part in common(observation).items():
        parts.setdefault(group, []).append(part)
    groups = []
    for group, declared in parts.items():
        names = [f.name for part in declared for f in fields(part)]
        if len(set(names)) != len(names):
            raise RuntimeError(f"reading option group {group} declares a key twice: {names}")
        merged = declared[0] if len(declared) == 1 else make_dataclass(
            declared[0].__name__, [], bases=tuple(reversed(declared)))
        groups.append((group, merged, field(default_factory=merged)))
    schema = make_dataclass("SourceOptions", [*groups, BAD_ROWS_PARAM], bases=(ReadingOptions,),
                            namespace={"observation": observation})
    schema.kinds = _kinds(registered, scope)
    return schema


def _kinds(registered, scope: dict) -> dict[str, tuple[str, ...]]:
    """``{dotted key: kinds that read it}`` for the options only some kinds read."""
    out = {}
    for group, keys in scope.items():
        for key in keys:
            out.setdefault(f"{group}.{key}", []).append(keys[key])
    return {key: tuple(kinds) for key, kinds in out.items()}


def inapplicable(options, kinds: dict[str, str]) -> str | None:
    """A one-line complaint if an option is set that no file of ``kinds`` (``{path: kind}``)
    reads (``bearing.topic`` on a CSV table, ``nmea.date`` without NMEA); None otherwise."""
    from tma.sources import reader

    only = type(options).kinds
    for key, value in _set_options(options).items():
        scope = only.get(key)
        if scope is None or any(kind in scope for kind in kinds.values()):
            continue
        path, kind = next(iter(kinds.items()))
        shown = ", ".join(map(str, value)) if isinstance(value, list) else value
        readers = " or ".join(k.upper() for k in scope)
        return (f"{key}={shown} does not apply to {path} ({reader(kind).name}): it is an "
                f"option of {readers} input; leave it unset")
    return None


def _set_options(options) -> dict:
    """The dotted options whose value is not the default."""
    out = {}
    for f in fields(options):
        value = getattr(options, f.name)
        if not is_dataclass(value):
            continue
        default = type(value)()
        for g in fields(value):
            if getattr(value, g.name) != getattr(default, g.name):
                out[f"{f.name}.{g.name}"] = getattr(value, g.name)
    return out


def groups(observation: Observation) -> tuple[str, ...]:
    """The reading options' top-level keys of the ingest config: the groups (``columns``,
    ``bearing``, ``ownship``...) and the options of their own (``bad_rows``)."""
    return tuple(f.name for f in fields(options_schema(observation)))


def _scalar(observation: Observation, key: str) -> bool:
    """True for a top-level option that is a value, not a group (``bad_rows``)."""
    f = next(f for f in fields(options_schema(observation)) if f.name == key)
    return f.default_factory is MISSING_FACTORY


def unknown_option(key: str, observation: Observation) -> str | None:
    """A one-line complaint if the dotted ``key`` (``columns.foo``) is under one of the
    reading groups but is not an option; None if it is one (or not under a group)."""
    keys = [row[0] for row in describe(options_schema(observation))]  # dotted keys
    group = key.split(".")[0]
    if group not in groups(observation) or key in keys or key == group:
        return None
    if _scalar(observation, group):
        return f"unknown option {key}: {group} is one value ({group}=...)"
    known = [k for k in keys if k.startswith(group + ".")]
    return f"unknown option {key} (the {group} options: {', '.join(known)})"


def source_options(node, observation: Observation):
    """The reading options from a config node (DictConfig, dict or None) holding some of the
    groups; an unknown key or a bad value is a ConfigError naming the key."""
    schema = options_schema(observation)
    if isinstance(node, schema):
        return node
    if isinstance(node, DictConfig):
        node = OmegaConf.to_container(node, resolve=True)
    node = {group: OmegaConf.to_container(values, resolve=True)
            if isinstance(values, DictConfig) else values for group, values in (node or {}).items()}
    known = groups(observation)
    for group, values in node.items():
        if group not in known:
            raise ConfigError(f"unknown option {group} (known: {', '.join(known)})")
        if _scalar(observation, group):
            continue
        if not isinstance(values, dict):
            raise ConfigError(f"{group} holds options ({group}.<name>=...), not a value: "
                              f"got {group}='{values}'")
        for key in values:
            complaint = unknown_option(f"{group}.{key}", observation)
            if complaint:
                raise ConfigError(complaint)
    return validate(schema, node, "")  # types, finiteness, the declared values, the rules
