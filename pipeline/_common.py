"""What the entry points share: the error policy (one ``error:`` line, exit status 2), Hydra's
callbacks, and the hand-over of the composed config to the core (``tma.experiment``)."""

import logging
import os
import sys
import traceback
import uuid
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from tma import experiment
from tma.errors import TmaError
from tma.io.atomic import write_json_atomic
from tma.parallel import Engine, engine_from, keep_freed_memory, quick_exit

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")
log = logging.getLogger("tma")
_stage_hydra = None  # Hydra's config of the stage run_stage is running (else None)
SWEEP_ENV = "TMA_SWEEP_ID"  # set by SweepTable while a multirun runs
SWEEP_RECORD = "tma-aggregate.json"  # what an aggregate job of a multirun read
PROBE_BYTES = 1 << 16  # more than Hydra writes of its own before the stage starts
# the top-level keys of conf/config.yaml and conf/ingest.yaml and their config groups (+key
# adds none)
KNOWN_KEYS = {key for conf in ("config", "ingest")
              for key in OmegaConf.load(Path(CONF_DIR) / f"{conf}.yaml")} - {"defaults", "hydra"} \
    | {"scenario", "estimator", "parallel"}


# -- the error policy --------------------------------------------------------------------------

def fail(message: str, status: int = 2):
    """Print ``error: message`` as one line on stderr and exit with ``status``."""
    print(f"error: {' '.join(str(message).split())}", file=sys.stderr)
    sys.exit(status)


def os_error_line(exc: OSError) -> str:
    where = f"{exc.filename}: " if exc.filename else ""
    return f"{where}{exc.strerror or exc} (errno {exc.errno}); nothing complete was replaced"


def run_stage(fn, cfg: DictConfig):
    """Run a stage function. A TmaError (bad input or config) or an OSError (read-only or
    full disk, permissions) is one line on stderr and exit status 2; anything else is a bug:
    one line naming the file that holds its traceback, exit status 1."""
    global _stage_hydra
    keep_freed_memory()  # the main process runs vectorised work too (training, serial shards)
    quick_exit()
    logging.raiseExceptions = False  # a full disk must not turn log writes into tracebacks
    _stage_hydra = HydraConfig.get() if HydraConfig.initialized() else None
    try:
        return guarded(_checked_stage, fn, cfg)
    finally:
        _stage_hydra = None


def _checked_stage(fn, cfg):
    experiment.check_stage_options(plain(cfg), KNOWN_KEYS)
    engine(cfg)
    return fn(cfg)


def guarded(fn, *args):
    """``fn(*args)``, its user-caused failures as one line and exit status 2."""
    try:
        return fn(*args)
    except TmaError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(os_error_line(exc))
    except OmegaConfBaseException as exc:  # e.g. an interpolation that cannot be resolved
        fail(f"config: {exc}")
    except Exception as exc:  # the last line of defence against tracebacks
        fail(f"internal error ({type(exc).__name__}: {exc}); please report it with "
             f"{_save_traceback()}", status=1)


def _save_traceback() -> str:
    try:
        path = Path(HydraConfig.get().runtime.output_dir) / "traceback.txt"
        path.write_text(traceback.format_exc())
        return f"the traceback in {path}"
    except Exception:  # no Hydra output dir, or the disk refuses it
        return "the command that caused it"


# -- callbacks ---------------------------------------------------------------------------------

class CheckOutputDir(Callback):
    """Hydra callback: before Hydra writes its logs under ``paths.data_dir``, check that the
    directory can be created, so a read-only or full disk is one line, not a traceback."""

    def _check(self, config, directory):
        guarded(experiment.check_paths, {"paths": plain_value(config, "paths")})
        directory = Path(str(directory))
        probe = directory / f".tma-probe-{os.getpid()}"
        try:  # room for Hydra's own files (resolved configs, the log): a full disk fails here
            directory.mkdir(parents=True, exist_ok=True)
            probe.write_bytes(bytes(PROBE_BYTES))
            probe.unlink()
        except OSError as exc:
            probe.unlink(missing_ok=True)
            fail(f"cannot write the output directory: {os_error_line(exc)}")

    def on_run_start(self, config, **kwargs):
        self._check(config, config.hydra.run.dir)

    def on_multirun_start(self, config, **kwargs):
        self._check(config, config.hydra.sweep.dir)


class SweepTable(Callback):
    """Hydra callback: when a multirun of ``aggregate`` ends, one table of all its jobs.

    Each aggregate job of the sweep records the runs it read (``SWEEP_RECORD`` in its Hydra
    output dir, tagged with this sweep's id); the union of those runs is aggregated once more
    into ``tables/<table>.*`` (default ``<family>-sweep``, ``tma.aggregate.aggregate_sweep``),
    beside the jobs' own tables."""

    sweep_id = None

    def on_multirun_start(self, config, **kwargs):
        self.sweep_id = uuid.uuid4().hex
        os.environ[SWEEP_ENV] = self.sweep_id  # inherited by the jobs, in or out of process

    def on_multirun_end(self, config, **kwargs):
        os.environ.pop(SWEEP_ENV, None)
        if self.sweep_id is not None:
            guarded(write_sweep_table, config, self.sweep_id)


def sweep_job(cfg: DictConfig):
    """The job number if this stage runs as a job of a multirun, else None."""
    hydra_cfg = cfg.hydra if "hydra" in cfg else _stage_hydra
    if hydra_cfg is None or hydra_cfg.get("mode") != RunMode.MULTIRUN:
        return None
    return int(hydra_cfg.job.num)


def record_sweep_job(cfg: DictConfig, jobs) -> None:
    """Record, for ``SweepTable``, the runs this aggregate job read (a multirun job only)."""
    from tma.aggregate import sweep_record

    number = sweep_job(cfg)
    hydra_cfg = cfg.hydra if "hydra" in cfg else _stage_hydra
    if number is None or not hydra_cfg.runtime.get("output_dir"):
        return
    write_json_atomic(Path(hydra_cfg.runtime.output_dir) / SWEEP_RECORD, sweep_record(
        os.environ.get(SWEEP_ENV), number, cfg.paths.data_dir, cfg.paths.tables_dir, jobs))


def write_sweep_table(config: DictConfig, sweep_id: str) -> list[Path]:
    """The combined table of the aggregate jobs of sweep ``sweep_id`` (see ``SweepTable``)."""
    import json

    from tma.aggregate import aggregate_sweep

    records = [record for path in Path(str(config.hydra.sweep.dir)).rglob(SWEEP_RECORD)
               if (record := json.loads(path.read_text())).get("sweep") == sweep_id]
    written = aggregate_sweep(records, config.get("table"))
    for path in written:
        log.info("sweep table: wrote %s", path)
    return written


# -- the composed config, handed to the core ---------------------------------------------------

def plain(cfg: DictConfig) -> dict:
    """The config as plain values, without Hydra's own node."""
    return {key: plain_value(cfg, key) for key in cfg if key != "hydra"}


def plain_value(cfg: DictConfig, key: str):
    value = cfg.get(key)
    return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value


def engine(cfg: DictConfig) -> Engine:
    """Where shards run (``tma.parallel.engine_from``: in this process inside a job of a
    parallel launcher)."""
    try:
        launcher = str(HydraConfig.get().launcher.get("_target_", ""))
    except ValueError:  # not running under Hydra (tests calling stage functions)
        launcher = ""
    return engine_from(plain_value(cfg, "parallel"), launcher)


def overrides(cfg: DictConfig) -> list[experiment.Override]:
    """The command line's overrides of the app config, as Hydra records them
    (``hydra.overrides.task``; from ``cfg.hydra`` when composed with it, else from the
    running stage's Hydra config; none for a bare ``compose``), for the grid language."""
    if "hydra" in cfg:
        task = list(cfg.hydra.overrides.task)
    else:
        task = list(_stage_hydra.overrides.task) if _stage_hydra is not None else []
    parsed = OverridesParser.create().parse_overrides(task) if task else []
    return [experiment.Override(o.key_or_group, o.input_line,
                                o.value() if o.key_or_group == "estimator" else None,
                                o.is_delete(), o.package) for o in parsed]


def scenario_nodes(cfg: DictConfig) -> list[dict]:
    return experiment.scenario_points(plain_value(cfg, "scenario"), plain_value(cfg, "grid"))


def estimator_nodes(cfg: DictConfig, checked: bool = False) -> list[dict]:
    make = experiment.checked_estimator_configs if checked else experiment.estimator_configs
    return make(plain_value(cfg, "estimator"), plain_value(cfg, "grid"), overrides(cfg))


def open_datasets(cfg: DictConfig):
    scenarios = [] if cfg.dataset else scenario_nodes(cfg)
    simulate = " ".join(HydraConfig.get().overrides.task) if HydraConfig.initialized() else ""
    return experiment.open_datasets(cfg.paths.data_dir, cfg.dataset, scenarios, simulate)
