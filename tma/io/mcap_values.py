"""Values in MCAP messages and metadata records, coerced and checked as tma reads them (a
field of the wrong type is one ``InputError`` naming the file and the message,
``schema_errors``), and JSON as tma writes it (``json_bytes``: orjson, numpy arrays as they
are)."""

import contextlib
import numbers

import numpy as np
import orjson

from tma.errors import InputError, TmaError

_JSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY


def _strided_array(obj):
    """orjson serialises contiguous arrays natively; strided views go through a copy."""
    if isinstance(obj, np.ndarray):
        return np.ascontiguousarray(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__} to JSON")


def json_bytes(value) -> bytes:
    """``value`` as JSON bytes (orjson; numpy arrays as arrays)."""
    return orjson.dumps(value, default=_strided_array, option=_JSON_OPTIONS)


def json_record(record: dict) -> dict:
    """A metadata record whose values are JSON (MCAP metadata values are strings)."""
    return {k: orjson.dumps(v, option=_JSON_OPTIONS).decode() for k, v in record.items()}


def read_json_record(metadata: dict, name: str, where: str) -> dict:
    """Decode the JSON-valued metadata record ``name``; a clear error if it is absent or a
    value is not JSON."""
    if name not in metadata:
        raise InputError(f"{where}: missing metadata record '{name}'")
    try:
        return {k: orjson.loads(v) for k, v in metadata[name].items()}
    except orjson.JSONDecodeError as exc:
        raise InputError(f"{where}: metadata record '{name}' has a value that is not JSON "
                         f"({exc})") from None


@contextlib.contextmanager
def schema_errors(where: str, what: str = "a message"):
    """Turn what a malformed decoded value raises (a missing key, a wrong type or shape, an
    integer out of range) into one InputError naming the file, not a traceback."""
    try:
        yield
    except TmaError:  # already one line naming its cause (a ValueError too)
        raise
    except KeyError as exc:
        raise InputError(f"{where}: {what} lacks the field {exc}") from None
    except (TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise InputError(f"{where}: {what} does not follow its schema ({exc})") from None


_JSON_TYPE = {str: "a string", list: "an array", dict: "an object", bool: "a boolean",
              type(None): "null", int: "an integer", float: "a number"}


def _unexpected(kinds, allowed) -> str:
    return ", ".join(sorted(_JSON_TYPE.get(k, k.__name__) for k in kinds - allowed))


def number(value) -> float:
    """A JSON number as float; a string, boolean, null, array or object raises TypeError."""
    if type(value) not in (int, float):
        raise TypeError(f"expected a number, got {_unexpected({type(value)}, set())}")
    return float(value)


def integer(value) -> int:
    """A JSON integer; anything else (a float, boolean, string...) raises TypeError."""
    if type(value) is not int:
        raise TypeError(f"expected an integer, got {_unexpected({type(value)}, set())}")
    return value


def is_number(value) -> bool:
    """For metadata values: a real number (numpy's too), not a boolean."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def float_array(values) -> np.ndarray:
    """A JSON number or array of numbers as 1-D float64, null -> NaN. Strings, booleans,
    objects and nested arrays raise TypeError (numpy would convert some of them silently);
    checking the element types with ``set(map(type, ...))`` runs at C speed. A protobuf
    message's array (float64 already) passes as it is."""
    if type(values) is np.ndarray and values.dtype == np.float64:
        return values
    if type(values) is not list:
        values = [values]  # one value per message: scalar fields
    kinds = set(map(type, values))
    if not kinds <= {int, float, type(None)}:
        raise TypeError(f"expected numbers, got {_unexpected(kinds, {int, float, type(None)})}")
    return np.array(values, dtype=float)


def int_array(values) -> np.ndarray:
    """A JSON integer or array of integers as 1-D int64 (a float without fraction counts, as
    in JSON Schema). A fraction, a value beyond int64 or any other type raises, where numpy
    would truncate or wrap silently. A protobuf message's array (int64) passes as it is."""
    if type(values) is np.ndarray and values.dtype == np.int64:
        return values
    if type(values) is not list:
        values = [values]
    kinds = set(map(type, values))
    if kinds <= {int}:
        return np.array(values, dtype=np.int64)  # OverflowError beyond int64
    if not kinds <= {int, float}:
        raise TypeError(f"expected integers, got {_unexpected(kinds, {int, float})}")
    x = np.array(values, dtype=float)
    if not np.all((x == np.round(x)) & (np.abs(x) < 2.0**63)):
        raise ValueError("expected integers, got a fraction or a value beyond int64")
    return x.astype(np.int64)

