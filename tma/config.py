"""Parameters declared once, and checked: each scenario and estimator declares its
parameters as a dataclass whose every field is a ``param``: its default, its doc (meaning
and units) and the values it allows (an interval, choices, or the form of a text: ``Form``),
written in one place. ``Params`` (the base of every scenario and estimator config) checks
every declared type and range on construction, in nested configs too (``check_params``: one
line naming the key, the value and what is allowed), before the class's own
``__post_init__`` checks what relates several fields; a ``param(..., nonfinite=True)`` may be
+-inf (e.g. "no limit"), never NaN. ``describe`` lists them (``python -m tma.options``). The
ingest reading options (``tma.sources.options``), the family's ingest settings and the
``parallel`` options are declared and checked the same way. A config node (Hydra's, or a
plain dict) becomes such a dataclass in ``tma.config_nodes.validate``, whose messages for
unknown keys and values of a wrong type are the same one line.
"""

import math
import numbers
import re
import types
import typing
from collections.abc import Callable
from dataclasses import MISSING, Field, asdict, dataclass, field, fields, is_dataclass

from omegaconf import DictConfig, OmegaConf

from tma.errors import ConfigError, ConfigTypeError


def message_at(where: str, text: str) -> str:
    """``where: text`` (``scenario 'bearings2d': ...``); the text alone where ``where`` is
    empty (options whose keys say where they are: ``csv.delimiter``, ``parallel.n_jobs``)."""
    return f"{where}: {text}" if where else text


def to_plain(obj):
    """Plain JSON-able dict of a dataclass (or DictConfig) for manifests and hashes. A field
    declared ``param(..., unhashed_default=True)`` is left out while it holds its default (an
    option added later: configs that do not use it keep their hash, their dataset names and
    every byte of their datasets; reading the plain dict back gives the default)."""
    if is_dataclass(obj):
        plain = asdict(obj)
        _drop_unused(obj, plain)
        return plain
    if isinstance(obj, DictConfig):
        return OmegaConf.to_container(obj, resolve=True)
    return obj


@dataclass(frozen=True)
class Interval:
    """Allowed values from ``lo`` to ``hi`` (as written: ``"1e9"``, ``"inf"`` for no bound),
    each end open or closed."""

    lo: str
    hi: str
    lo_open: bool
    hi_open: bool

    @classmethod
    def parse(cls, text: str) -> "Interval":
        """``"[0, 90)"``, ``"(0, inf)"``, ``"[1, 64]"``..."""
        match = re.fullmatch(r"\s*([\[(])\s*([^,]+?)\s*,\s*([^,]+?)\s*([\])])\s*", text)
        if match is None:
            raise ValueError(f"not an interval: {text!r}")
        left, lo, hi, right = match.groups()
        float(lo), float(hi)  # numbers, or a ValueError where they are declared
        return cls(lo, hi, left == "(", right == ")")

    def __contains__(self, value) -> bool:
        lo, hi = float(self.lo), float(self.hi)
        return ((value > lo if self.lo_open else value >= lo)
                and (value < hi if self.hi_open else value <= hi))

    def __str__(self) -> str:
        no_lo, no_hi = math.isinf(float(self.lo)), math.isinf(float(self.hi))
        if no_lo and no_hi:
            return "any number"
        if no_hi:
            return f"{'>' if self.lo_open else '>='} {self.lo}"
        if no_lo:
            return f"{'<' if self.hi_open else '<='} {self.hi}"
        return (f"{'(' if self.lo_open else '['}{self.lo}, {self.hi}"
                f"{')' if self.hi_open else ']'}")


@dataclass(frozen=True)
class Form:
    """The form a text value must have where no interval or list of choices says it (a date,
    a scheduler address, one character): ``text``, what is allowed, as messages and
    ``describe`` say it (``a date YYYY-MM-DD``); ``problem(value)``: None when the value has
    the form, else what is wrong with it ('' when ``text`` says it all). A message says
    ``key must be <text>, got <value>``, or ``key=<value>: <what is wrong>; key must be
    <text>``."""

    text: str
    problem: Callable[[typing.Any], str | None]


def _drop_unused(obj, plain: dict):
    """Leave out of ``plain`` (``asdict(obj)``) the ``unhashed_default`` fields of ``obj``
    and of its nested configs that hold their default."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        if f.metadata.get("unhashed_default"):
            default = f.default_factory() if f.default_factory is not MISSING else f.default
            if value == default:
                del plain[f.name]
                continue
        if is_dataclass(value) and not isinstance(value, type):
            _drop_unused(value, plain[f.name])


def param(default=MISSING, doc: str = "", range: str | None = None, *, choices=None,
          each: str | None = None, form: Form | None = None, factory=None,
          nonfinite: bool = False, unhashed_default: bool = False):
    """A config field, declared once: its ``default`` (or ``factory``, a default factory),
    its ``doc`` (meaning and units) and the values it allows: ``range``, an interval such as
    ``"[0, 90)"`` or ``"(0, inf)"``; ``choices``, the allowed values (None among them when
    null is one); ``each``, the interval of every element of a list; ``form``, the form of a
    text (``Form``). The field's type allows what it says (a whole number, a number, true or
    false, text, None where it is optional). ``nonfinite``: the value may be +-inf.
    ``unhashed_default``: left out of ``to_plain`` (manifests, hashes) while at its default.
    ``check_params`` checks them all."""
    metadata = {"doc": doc, "nonfinite": nonfinite}
    if unhashed_default:
        metadata["unhashed_default"] = True
    if range is not None:
        metadata["range"] = Interval.parse(range)
    if each is not None:
        metadata["each"] = Interval.parse(each)
    if choices is not None:
        metadata["choices"] = tuple(choices)
    if form is not None:
        metadata["form"] = form
    if factory is not None:
        return field(default_factory=factory, metadata=metadata)
    return field(default=default, metadata=metadata)


def _shown(value) -> str:
    if value is None:
        return "null"
    return f"{value:g}" if isinstance(value, float) else repr(value) if isinstance(
        value, str) else str(value)


def _choice(value) -> str:
    return "null" if value is None else str(value)


SIMPLE = {bool: "true or false", int: "a whole number", float: "a number", str: "text"}


def _simple(tp) -> tuple[type, bool] | None:
    """``(type, optional)`` of a field declared as one of ``SIMPLE``'s types (or it or None);
    None for any other declaration (lists, nested configs, Any)."""
    union = isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union
    args = typing.get_args(tp) if union else (tp,)
    rest = [a for a in args if a is not type(None)]
    return (rest[0], len(rest) < len(args)) if len(rest) == 1 and rest[0] in SIMPLE else None


def _listed(tp):
    """The ``list[...]`` type of a field declared as one (or it or None); None otherwise."""
    union = isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union
    return next((a for a in (typing.get_args(tp) if union else (tp,))
                 if typing.get_origin(a) is list), None)


def _optional(f) -> bool:
    return f.type is typing.Any or "None" in str(f.type)


def _fits(value, tp: type) -> bool:
    """``value`` is of ``tp`` (a ``SIMPLE`` type): any integer for int, any number for float,
    never a bool for either."""
    if tp is bool or isinstance(value, bool):
        return tp is bool and isinstance(value, bool)
    return isinstance(value, {int: numbers.Integral, float: numbers.Real, str: str}[tp])


def allowed(f) -> str:
    """What field ``f`` (a ``param``) allows, as messages say it: ``one of null, deg, rad``,
    ``null or a number in (0, 90)``, ``a whole number >= 1``, ``a date YYYY-MM-DD``."""
    meta, simple = f.metadata, _simple(f.type)
    if "choices" in meta:
        text = f"one of {', '.join(map(_choice, meta['choices']))}"
        return text if None in meta["choices"] or not _optional(f) else f"null or {text}"
    if "form" in meta:
        return meta["form"].text
    if simple is not None:
        text = SIMPLE[simple[0]]
        if "range" in meta and str(meta["range"]) != "any number":
            text += f" {_in(meta['range'])}"
    elif (listed := _listed(f.type)) is not None:
        text = "a list" + (" of numbers" if typing.get_args(listed)[0] in (int, float) else "")
        text += f" each {_in(meta['each'])}" if "each" in meta else ""
    else:
        text = f"a {getattr(f.type, '__name__', f.type)}"
    return f"null or {text}" if _optional(f) else text


def check_params(config, where: str, prefix: str = ""):
    """ConfigError naming the dotted key (``observer.legs[0].duration_s``), the value and
    what is allowed, for the first field of ``config`` (a dataclass, nested ones and lists of
    them included) that is not of its declared type (``allowed``), not finite, or outside its
    declared ``range``, ``each``, ``choices`` or ``form``. ``where`` (``scenario
    'bearings2d'``) starts the message, unless empty; ``prefix`` starts every key
    (``parallel.``)."""
    for f in fields(config):
        value, key = getattr(config, f.name), f"{prefix}{f.name}"
        if is_dataclass(value):
            check_params(value, where, f"{key}.")
            continue
        if isinstance(value, list) and value and all(is_dataclass(v) for v in value):
            for i, item in enumerate(value):
                check_params(item, where, f"{key}[{i}].")
            continue
        meta, simple = f.metadata, _simple(f.type)
        if simple is not None and not (_fits(value, simple[0]) or value is None and simple[1]):
            raise ConfigTypeError(message_at(where, wrong_type_message(key, f, value)))
        if value is None or isinstance(value, bool) and "form" not in meta:
            continue
        if isinstance(value, float) and not math.isfinite(value) and not meta.get("nonfinite"):
            raise ConfigError(message_at(where, f"{key} must be finite, got {_shown(value)}"))
        interval, choices, each, form = (meta.get(k) for k in ("range", "choices", "each",
                                                               "form"))
        if choices is not None and value not in choices:
            raise ConfigError(message_at(where, f"{key} must be one of "
                                         f"{', '.join(map(_choice, choices))}, got "
                                         f"{_shown(value)}"))
        if interval is not None and value not in interval:
            raise ConfigError(message_at(where, f"{key} must be {_in(interval)}, got "
                                         f"{_shown(value)}"))
        for i, item in enumerate(value if each is not None else ()):
            if item not in each:
                raise ConfigError(message_at(where, f"{key}[{i}] must be {_in(each)}, got "
                                             f"{_shown(item)}"))
        problem = form.problem(value) if form is not None else None
        if problem:  # what is wrong, then what is allowed
            raise ConfigError(message_at(where, f"{key}={value}: {problem}; {key} must be "
                                                f"{form.text}"))
        if problem is not None:
            raise ConfigError(message_at(where, f"{key} must be {form.text}, got "
                                                f"{_shown(value)}"))


def wrong_type_message(key: str, f, value) -> str:
    """``key must be <allowed>, got <value>`` for a value of the wrong type; a float where a
    whole number is due is shown as the float it is (``1e3`` reads as 1000.0), with the
    spelling that works."""
    if isinstance(value, float) and _simple(f.type) is not None and _simple(f.type)[0] is int:
        fix = f"; write {int(value)}" if value.is_integer() else ""
        return f"{key} must be {allowed(f)}, got the float {value!r}{fix}"
    return f"{key} must be {allowed(f)}, got {_shown(value)}"


def _in(interval: Interval) -> str:
    text = str(interval)
    return text if text[0] in "<>a" else f"in {text}"


class Params:
    """Base of every scenario and estimator config (a dataclass of ``param`` fields): on
    construction the declared ranges are checked (``check_params``), then whatever a
    subclass's ``__post_init__`` adds after calling this one (rules between fields). A
    subclass that declares a field again with a plain default (``n_tracks: int = 1000``)
    changes the default only: the doc and range stay those declared first."""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        declared = {}
        for base in reversed(cls.__mro__[1:]):
            declared.update(getattr(base, "__dataclass_fields__", {}))
        for name in cls.__dict__.get("__annotations__", {}):
            value = cls.__dict__.get(name, MISSING)
            if name in declared and declared[name].metadata and value is not MISSING \
                    and not isinstance(value, Field):
                setattr(cls, name, field(default=value, metadata=declared[name].metadata))

    @property
    def where(self) -> str:
        """How messages name the config (``scenario 'bearings2d'``, ``estimator 'lm'``); ''
        where the keys say it (``parallel.n_jobs``)."""
        return type(self).__name__

    @property
    def key_prefix(self) -> str:
        """What starts every key in messages (``parallel.``)."""
        return ""

    def __post_init__(self):
        check_params(self, self.where, self.key_prefix)


def describe(schema, prefix: str = "") -> list[tuple[str, str, str, str]]:
    """``(key, default, allowed, doc)`` of every parameter of dataclass ``schema``, nested
    ones dotted (a list of configs as ``key[i].``)."""
    rows = []
    for f in fields(schema):
        default = f.default_factory() if f.default_factory is not MISSING else f.default
        key = f"{prefix}{f.name}"
        if is_dataclass(default):
            rows += describe(type(default), f"{key}.")
            continue
        if isinstance(default, list) and default and is_dataclass(default[0]):
            rows += describe(type(default[0]), f"{key}[i].")
            continue
        listed = _listed(f.type)
        element = typing.get_args(listed)[0] if listed is not None else None
        if is_dataclass(element):  # a list of configs, empty by default: its element's keys
            rows.append((key, "[]", "a list", f.metadata.get("doc", "")))
            rows += describe(element, f"{key}[i].")
            continue
        shown = []
        if "choices" in f.metadata:
            shown.append(" | ".join(map(_choice, f.metadata["choices"])))
        if "form" in f.metadata:
            shown.append(f.metadata["form"].text)
        if "range" in f.metadata:
            shown.append(str(f.metadata["range"]))
        if "each" in f.metadata:
            shown.append(f"each {f.metadata['each']}")
        if not shown and _simple(f.type) is not None:
            shown.append(SIMPLE[_simple(f.type)[0]])
        if _optional(f) and None not in f.metadata.get("choices", ()):
            shown.append("or null")
        rows.append((key, "???" if default is MISSING else _shown(default),
                     " ".join(shown), f.metadata.get("doc", "")))
    return rows


def require(condition: bool, where: str, message: str):
    """Raise ConfigError(where: message) unless ``condition`` holds."""
    if not condition:
        raise ConfigError(f"{where}: {message}")


def is_probability_vector(p, n: int, tol: float = 1e-9) -> bool:
    """``p`` has ``n`` entries in [0, 1] summing to 1 (within ``tol``)."""
    return len(p) == n and all(0.0 <= x <= 1.0 for x in p) and abs(sum(p) - 1.0) <= tol
