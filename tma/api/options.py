"""The Python API's options: named as on the command line, by group or dotted, plain values
only (``tma.api``)."""

import functools
import os


@functools.cache
def _recorded() -> str:
    """The family whose logs a recording holds: the one that reads recorded logs (it has an
    ``ingest`` module; ``bearings2d``)."""
    from importlib.util import find_spec

    from tma.families import NAMES

    (name,) = [n for n in NAMES if find_spec(f"tma.families.{n}.ingest") is not None]
    return name


def _plain(value, key: str):
    """TypeError naming ``key`` for an option value that is no plain value (a number, text,
    list or dict of them, a date): a DataFrame, an array... (whose text spans lines, which no
    one-line message could show)."""
    if isinstance(value, dict):
        for k, v in value.items():
            _plain(v, f"{key}.{k}")
    elif isinstance(value, list | tuple):
        for v in value:
            _plain(v, key)
    elif "\n" in repr(value):
        raise TypeError(f"{key} must be a plain value (a number, text, or a list or dict of "
                        f"them), got {type(value).__name__}")


def _nested(options: dict | None, groups: dict) -> dict:
    """One nested option dict from dotted names (``{"columns.time": "tid"}``) and group
    keyword arguments (``columns={"time": "tid"}``); TypeError for values that are none."""
    if options is not None and not isinstance(options, dict):
        raise TypeError("options must be a dict of dotted names ({'columns.time': 'tid'}), "
                        f"got {type(options).__name__}")
    out: dict = {}
    for key, value in {**(options or {}), **groups}.items():
        _plain(value, str(key))
        node, parts = out, str(key).split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        if isinstance(value, dict) and isinstance(node.get(parts[-1]), dict):
            node[parts[-1]].update(value)
        else:
            node[parts[-1]] = value
    return out


def _split(options: dict) -> tuple[dict, dict]:
    """The family's ingest settings (``bearings2d``: ``sigma_deg``, ``min_bearings``) and the
    reading options of one nested dict."""
    from tma.stages.ingest import setting_names

    return ({k: options.pop(k) for k in setting_names(_recorded()) if k in options}, options)


def _path(value, what: str):
    """``value`` if it is a path (str or os.PathLike); TypeError naming ``what`` else."""
    if isinstance(value, str | os.PathLike):
        return value
    raise TypeError(f"{what} must be a path (str or pathlib.Path), got {type(value).__name__}")
