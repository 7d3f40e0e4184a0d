"""What the entry points check before a stage starts, without Hydra (tested on plain dicts,
``tests/test_experiment.py``): the options every stage shares (``check_stage_options``), that
the output directory can be written (``check_output_dir``) and that a sweep's launcher can
run here (``check_launcher``); and the logs submitit's jobs wrote (``job_logs``)."""

import contextlib
import os
import shutil
from pathlib import Path

from tma.errors import ConfigError
from tma.io.owned import plain_name


def check_stage_options(cfg: dict, known: set[str]):
    """Options every stage shares (``cfg``: the config without Hydra's node): no top-level
    key outside ``known``, ``paths.*`` are directory paths, ``estimators`` is null or
    ``{name: config}`` (and the deprecated ``grid`` null or ``{estimators: {name: config}}``),
    booleans are booleans, names are plain names."""
    unknown = sorted(set(cfg) - known)
    if unknown:
        raise ConfigError(f"unknown option(s) {', '.join(unknown)} (known: "
                          f"{', '.join(sorted(set(cfg) & known))})")
    check_paths(cfg)
    estimators = cfg.get("estimators")
    if estimators is not None and not (isinstance(estimators, dict) and all(
            isinstance(v, dict) for v in estimators.values())):
        raise ConfigError(f"estimators must be null or {{name: estimator config}}, "
                          f"got '{estimators}'")
    grid = cfg.get("grid")
    if grid is not None and not (isinstance(grid, dict) and all(
            isinstance(v, dict) for v in (grid.get("estimators") or {}).values())):
        raise ConfigError(f"grid must be null or {{estimators: {{name: estimator config}}}} "
                          f"(deprecated: now estimators), got '{grid}'")
    for key in ("force", "progress", "job_tables"):
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
