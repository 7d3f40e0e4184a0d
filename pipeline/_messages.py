"""The command line's text where Hydra does not read it for us (no Hydra here: tested on
plain lists, ``tests/test_experiment.py``): a bare argument (``bare_as``), which override
sets a key (``override_of``), an unknown reading option (``check_ingest_options``) and the
one line for an unknown key or option with the nearest valid one (``unknown_key_line``,
``unknown_choice_line``)."""

import difflib
from pathlib import Path

from tma.errors import ConfigError
from tma.plan.points import has_key, override_text


def bare_as(key: str | None, arguments: list[str], overrides: list[str]) -> list[str]:
    """The command-line ``arguments`` (``overrides``: those of them that are overrides), with
    one bare argument (neither KEY=VALUE nor ~KEY) taken as ``key=ARG`` where the stage has
    such a key and no ``key=`` is given; else a ConfigError naming it."""
    bare = [o for o in overrides if "=" not in o and not o.startswith("~")]
    if not bare:
        return arguments
    if key and len(bare) == 1 and not any(a.startswith(f"{key}=") for a in arguments):
        at = len(arguments) - 1 - arguments[::-1].index(bare[0])
        return [*arguments[:at], override_text(key, bare[0]), *arguments[at + 1:]]
    if key is None and _names_a_log(bare[-1]):  # a stage that reads datasets, given a log
        raise ConfigError(f"'{bare[-1]}' is not KEY=VALUE; this stage reads stored datasets "
                          f"(dataset=NAME): read a log with  python -m pipeline.ingest "
                          f"{override_text('input', bare[-1])}  or, ingest, estimate and "
                          f"aggregate in one command,  python -m pipeline.table "
                          f"{override_text('input', bare[-1])}")
    raise ConfigError(f"'{bare[-1]}' is not KEY=VALUE (did you mean "
                      f"{override_text(key or 'dataset', bare[-1])}?)")


def _names_a_log(text: str) -> bool:
    """Whether a bare argument names a log file rather than a dataset: a file, or a name
    with the extension of a kind of log (``tma.sources.extensions``) or a directory part
    (dataset names are plain names)."""
    from tma.sources import extensions

    path = Path(text)
    return path.is_file() or path.suffix.lower() in extensions() or path.name != text


def override_of(key: str, overrides: list[str]) -> tuple[str, str]:
    """``(dotted key, text)`` of the override that sets ``key`` or a key under it."""
    given = [(o.split("=", 1)[0].lstrip("+~").split("@")[0], o) for o in overrides]
    return next((g for g in given if g[0] == key), None) or next(
        (g for g in given if g[0].startswith(f"{key}.")), (key, key))


def check_ingest_options(overrides: list[str], family: str):
    """A ConfigError for an unknown reading option among the ``overrides`` (``columns.foo=x``:
    it names the options of its group), for the family they name (``family=``) or
    ``family``; none for an unknown family (the stage says so)."""
    from tma.stages.ingest import unknown_option_of

    pairs = [o.split("=", 1) for o in overrides if "=" in o and not o.startswith("-")]
    family = next((v for k, v in reversed(pairs) if k.lstrip("+~") == "family"), family)
    try:
        complaint = next(filter(None, (unknown_option_of(k.lstrip("+~"), family)
                                       for k, _ in pairs)), None)
    except ConfigError:
        return
    if complaint:
        raise ConfigError(complaint)


def unknown_key_line(node: dict, full_key: str, override: str, dotted: str,
                     note: str | None = None) -> str:
    """One line for ``override`` (of key ``dotted``), whose key ``full_key`` is not in
    ``node`` (the config under it): the nearest valid key (``difflib``) or, when none is
    close, ``note`` or the keys there."""
    where, _, part = full_key.rpartition(".")
    rest = dotted[len(full_key) + 1:].split(".") if dotted.startswith(f"{full_key}.") else []
    keys = sorted(str(k) for k in node)
    near = difflib.get_close_matches(part, keys, n=1)
    if near:
        deeper = rest and has_key(node, ".".join([near[0], *rest]))
        hint = "nearest: " + ".".join(filter(None, [where, near[0], *(rest if deeper else [])]))
    else:
        hint = note or f"{where or 'the config'} has: {', '.join(keys)}"
    return f"{override}: no key '{part}'{f' in {where}' if where else ''} ({hint})"


def unknown_choice_line(group: str, value: str, options) -> str:
    """One line for ``group=value`` naming an option that does not exist: the nearest valid
    one, or the options."""
    options = sorted(options or [])
    near = difflib.get_close_matches(value, options, n=1)
    what = group.rsplit("/", 1)[-1]
    hint = f"nearest: {near[0]}" if near else f"options: {', '.join(options)}"
    return f"{group}={value}: no {what} '{value}' ({hint})"

