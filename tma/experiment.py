"""What one command covers: its scenario points, its estimators and its datasets, from plain
configs (dicts) and the command line's overrides; no Hydra here (``pipeline/`` composes the
config and hands it over), so every rule below is tested without starting it
(``tests/test_experiment.py``).

The grid language, inside one job (``docs/architecture.md``, "Two sweeps"):

- a list given where the scenario expects a single value is an axis
  (``scenario.sigma_deg=[0.1,0.5]``: two datasets); several axes give their cartesian product,
  the last one varying fastest (``scenario_points``);
- an experiment's estimators (``grid.estimators``) are edited by the command line
  (``estimator_configs``): ``estimator=NAME`` runs NAME alone, ``estimator.KEY=VALUE`` sets KEY
  in each of them that has it, ``grid.estimators.NAME.KEY=VALUE`` sets it in NAME only. An
  override that would change nothing fails (ConfigError naming it), never is ignored.

Also the command line where Hydra does not read it for us: a bare argument (``bare_as``), a
value written as an override (``override_text``), the one line for an unknown key or option
with the nearest valid one (``unknown_key_line``, ``unknown_choice_line``), and the checks
made before Hydra creates anything (``check_output_dir``, ``check_launcher``).
"""

import contextlib
import copy
import dataclasses
import difflib
import itertools
import json
import os
import re
import shutil
import tempfile
import types
import typing
from pathlib import Path

from tma.config import to_plain
from tma.errors import ConfigError, InputError
from tma.estimation import dataset_config
from tma.estimator import name_set_error
from tma.families import build_estimator, dataset_name, load_scenario, scenario_module
from tma.io.dataset import MANIFEST, Dataset, datasets_dir
from tma.io.owned import plain_name


@dataclasses.dataclass(frozen=True)
class Override:
    """One command-line override as the grid language reads it: its dotted ``key``
    (``estimator``, ``estimator.lambda0``, ``grid.estimators.lm.max_iter``), its ``text`` as
    typed (for messages), the ``value`` of a choice (``estimator=NAME``: NAME), whether it
    deletes (``~key``) and its package (``key@pkg=...``; None when none)."""

    key: str
    text: str
    value: object = None
    delete: bool = False
    package: str | None = None


# -- scenarios: a list where the scenario expects one value is an axis of the grid ----------

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


def scenario_points(scenario: dict, grid: dict | None = None) -> list[dict]:
    """The scenario config expanded into one config per point of its grid (module
    docstring). ``grid``: the config's ``grid`` (an experiment's), which takes only
    ``estimators``."""
    extra = sorted(set(grid or {}) - {"estimators"})
    if extra:
        raise ConfigError(
            f"grid.{extra[0]}: grids take only 'estimators'; sweep a scenario value by "
            "giving the scenario key a list, e.g. scenario.sigma_deg=[0.1,0.5]")
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

def _has_key(node: dict, dotted: str) -> bool:
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


def estimator_configs(estimator: dict, grid: dict | None,
                      overrides: list[Override]) -> list[dict]:
    """Estimator configs: the single ``estimator``, or an experiment's ``grid.estimators``
    as the command line's ``overrides`` edit them (module docstring). ``estimator`` holds,
    under an experiment, every key of the family's estimators (the ``estimator_keys`` group,
    ``tma.families.register_configs``), so ``estimator.KEY=VALUE`` reaches it: its value is
    read there."""
    grid = (grid or {}).get("estimators")
    if not grid:
        named = [o for o in overrides if o.key == "estimator.name" and o.package is None]
        if named:  # as tma.estimate's name=
            raise name_set_error(named[-1].text, named[-1].text.partition("=")[2] or "NAME")
        return [estimator]
    nodes = copy.deepcopy(grid)
    chosen = [o.value for o in overrides if o.key == "estimator"
              and o.package is None and not o.delete]
    if chosen:
        if chosen[-1] not in nodes:
            raise ConfigError(f"estimator={chosen[-1]}: not an estimator of this experiment "
                              f"(estimators: {', '.join(nodes)})")
        nodes = {chosen[-1]: nodes[chosen[-1]]}
    in_grid = {}  # (estimator, key) -> override, for grid.estimators.NAME.KEY=...
    for o in overrides:
        parts = o.key.split(".")
        if parts[:2] == ["grid", "estimators"] and len(parts) > 2 and o.package is None:
            if parts[2] not in nodes:
                raise ConfigError(f"{o.text}: '{parts[2]}' is not run "
                                  f"(estimators: {', '.join(nodes)})")
            in_grid[parts[2], ".".join(parts[3:])] = o.text
    for o in overrides:
        if not o.key.startswith("estimator.") or o.package is not None:
            continue
        key = o.key.removeprefix("estimator.")
        if o.delete or key == "name":
            raise ConfigError(f"{o.text}: with an experiment, choose estimators with "
                              "estimator=NAME and set their values with estimator.KEY=VALUE")
        takers = [n for n, node in nodes.items() if _has_key(node, key)]
        if not takers:
            raise ConfigError(f"{o.text}: no estimator of this run has '{key}' "
                              f"(estimators: {', '.join(nodes)})")
        for name in takers:
            clash = in_grid.get((name, key))
            if clash:
                raise ConfigError(f"{o.text} and {clash} both set '{key}' of {name}: "
                                  "give one")
            _set_key(nodes[name], key, copy.deepcopy(_get_key(estimator, key)))
    return list(nodes.values())


def checked_estimator_configs(estimator: dict, grid: dict | None,
                              overrides: list[Override]) -> list[dict]:
    """``estimator_configs`` after building each once, so a bad value fails naming its key."""
    nodes = estimator_configs(estimator, grid, overrides)
    for node in nodes:
        build_estimator(node)
    return nodes


# -- datasets --------------------------------------------------------------------------------

def dataset_roots(data_dir, dataset: str | None, scenarios: list[dict]) -> list[Path]:
    """The dataset directories a command refers to: ``dataset=NAME``, else the one each
    scenario point makes."""
    if dataset:
        return [datasets_dir(data_dir) / str(dataset)]
    roots = []
    for node in scenarios:
        module, scenario = load_scenario(node)
        roots.append(datasets_dir(data_dir) / dataset_name(module, scenario))
    return roots


def open_datasets(data_dir, dataset: str | None, scenarios: list[dict],
                  simulate: str = "") -> list[Dataset]:
    """The datasets a command reads, verified; a scenario point's dataset must be the one its
    config makes. A missing one is a ConfigError giving the command that creates it
    (``python -m pipeline.simulate`` + ``simulate``, the command line's overrides)."""
    datasets = []
    expected = [None] if dataset else [to_plain(load_scenario(n)[1]) for n in scenarios]
    for root, config in zip(dataset_roots(data_dir, dataset, scenarios), expected, strict=True):
        if not (root / MANIFEST).exists() and not dataset:
            raise ConfigError(
                f"no dataset {root.name} in {root.parent}: create it first with\n"
                f"  python -m pipeline.simulate {simulate}".rstrip()
            )
        opened = Dataset.open(root)
        if config is not None:  # the dataset this scenario config makes, not another one
            opened.check_simulated_from(config)
        datasets.append(opened)
    return datasets


def dataset_jobs(datasets: list[Dataset], estimators: list[dict],
                 overrides: list[Override]) -> list[tuple[Dataset, dict]]:
    """``(dataset, estimator config)`` of every dataset and estimator, each config as it runs
    on its dataset (``tma.estimation.dataset_config``): on a recorded log an estimator's
    ``recorded_defaults`` (``lm``: ``initial_bearing_deg`` null, from the first bearing) replace
    its defaults where the command line sets no value (``estimator.KEY=``,
    ``grid.estimators.NAME.KEY=``)."""
    given = [o.key.split(".") for o in overrides if o.package is None]
    jobs = []
    for dataset in datasets:
        for node in estimators:
            keep = ({".".join(k[1:]) for k in given if k[0] == "estimator" and len(k) > 1}
                    | {".".join(k[3:]) for k in given
                       if k[:2] == ["grid", "estimators"] and k[2:3] == [node.get("name")]})
            jobs.append((dataset, dataset_config(dataset, node, keep)))
    return jobs


def log_dataset(input_path, *, data_dir, name=None, force=False, **options) -> tuple[Path, bool]:
    """The dataset of a recorded log for a one-command table (``tma.ingest.ingest`` with these
    arguments): ingested, or, when a dataset of that name exists and ``force`` is false,
    reused if ingesting the log again gives the same dataset (content and reading config; it
    is ingested into a scratch directory under ``data_dir`` to be compared), else refused.
    Returns the dataset directory and whether it was reused."""
    from tma.ingest import ingest

    if input_path is not None and str(input_path).strip() and name is None:
        name = Path(str(input_path)).stem
    root = datasets_dir(data_dir) / plain_name(name, "name") if name is not None else None
    if force or root is None or not (root / MANIFEST).exists():
        try:
            return ingest(input_path, data_dir=data_dir, name=name, force=force, **options), False
        except InputError:
            if force or root is None or not (root / MANIFEST).exists():
                raise  # else another process (a job of the sweep) made it meanwhile: compare
    existing = Dataset.open(root)
    with tempfile.TemporaryDirectory(dir=data_dir, prefix=".tma-log-check-") as scratch:
        again = Dataset.open(ingest(input_path, data_dir=scratch, name=name, **options))
    if (again.content_hash, again.manifest["config"]) != (existing.content_hash,
                                                          existing.manifest["config"]):
        raise InputError(f"dataset {root} exists and is not what {input_path} gives with "
                         "these options (another log, or other reading options): choose "
                         "another name= or set force=true to replace it")
    return root, True


# -- the command line, outside Hydra's composition -------------------------------------------

_PLAIN_VALUE = re.compile(r"[\w./@:+-]+", re.ASCII)  # Hydra reads only ASCII unquoted


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
    try:
        typed = json.loads(text) is not None or text == "null"
    except ValueError:
        typed = text.lower() in ("true", "false", "nan", "inf", "-inf")
    if _PLAIN_VALUE.fullmatch(text) and not typed:
        return text
    # Hydra's quoted text: backslashes doubled before a quote or at the end, quotes escaped;
    # ${ escaped for OmegaConf, which would read an interpolation
    text = re.sub(r"(\\+)(?='|$)", lambda m: m.group(1) * 2, text).replace("'", "\\'")
    return "'" + text.replace("${", "\\${") + "'"


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
    from tma.ingest import unknown_option_of

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
        deeper = rest and _has_key(node, ".".join([near[0], *rest]))
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


# -- the options every stage shares ----------------------------------------------------------

def check_stage_options(cfg: dict, known: set[str]):
    """Options every stage shares (``cfg``: the config without Hydra's node): no top-level
    key outside ``known``, ``paths.*`` are directory paths, ``grid`` is null or
    ``{estimators: {name: config}}``, booleans are booleans, names are plain names."""
    unknown = sorted(set(cfg) - known)
    if unknown:
        raise ConfigError(f"unknown option(s) {', '.join(unknown)} (known: "
                          f"{', '.join(sorted(set(cfg) & known))})")
    check_paths(cfg)
    grid = cfg.get("grid")
    if grid is not None and not (isinstance(grid, dict) and all(
            isinstance(v, dict) for v in (grid.get("estimators") or {}).values())):
        raise ConfigError(f"grid must be null or {{estimators: {{name: estimator config}}}}, "
                          f"got '{grid}'")
    for key in ("force", "progress"):
        if key in cfg and not isinstance(cfg[key], bool):
            raise ConfigError(f"{key} must be true or false, got '{cfg[key]}'")
    for key in ("dataset", "table", "name"):
        if cfg.get(key) is not None:
            plain_name(cfg[key], key)


def check_paths(cfg: dict):
    """``paths.*`` are directory paths (not null, a number or a list, which Hydra would
    happily turn into a folder named ``None`` in the working directory)."""
    for key in ("data_dir", "tables_dir"):
        value = (cfg.get("paths") or {}).get(key)
        if not isinstance(value, str) or not value.strip():
            raise ConfigError(f"paths.{key} must be a directory path, got '{value}'")


def check_output_dir(cfg: dict, directory, probe_bytes: int):
    """``check_paths``, then that ``directory`` can be made and holds ``probe_bytes`` more
    (a file written and removed): an OSError names what refused (read-only, full, a regular
    file on the path)."""
    check_paths(cfg)
    directory = Path(str(directory))
    probe = directory / f".tma-probe-{os.getpid()}"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe.write_bytes(bytes(probe_bytes))
    finally:
        with contextlib.suppress(OSError):
            probe.unlink(missing_ok=True)


def check_launcher(target: str):
    """A sweep's launcher (its ``_target_``) can run here: SLURM's needs ``sbatch`` and
    ``srun`` (ConfigError before anything is created)."""
    missing = [c for c in ("sbatch", "srun") if shutil.which(c) is None]
    if target.endswith(".SlurmLauncher") and missing:
        raise ConfigError(f"hydra/launcher=slurm submits the jobs to SLURM, and this machine "
                          f"has no {' or '.join(missing)}: run the sweep where SLURM is, or "
                          "try it here with hydra/launcher=slurm_local")


def job_logs(sweep_dir, log_name: str) -> list[str]:
    """The lines of the jobs' logs of a sweep (``<sweep_dir>/<job number>/<log_name>``), in
    job order, each after ``#<job number>``; submitit's own lines left out."""
    logs = [p for p in Path(sweep_dir).glob(f"*/{log_name}") if p.parent.name.isdigit()]
    return [f"#{path.parent.name} {line}"
            for path in sorted(logs, key=lambda p: int(p.parent.name))
            for line in path.read_text(errors="replace").splitlines()
            if "][submitit][" not in line]
