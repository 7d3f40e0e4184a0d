"""What the entry points share: the error policy (one ``error:`` line, exit status 2), Hydra's
callbacks, and the hand-over of the composed config to the core (``command``: a
``tma.plan.command.Command``)."""

import logging
import os
import re
import signal
import sys
import threading
import traceback
import uuid
from pathlib import Path

import hydra
from hydra import errors as hydra_errors
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import ConfigAttributeError, ConfigKeyError, OmegaConfBaseException

from pipeline import SWEEP_ENV  # set while a multirun runs
from pipeline._checks import check_launcher, check_output_dir, check_stage_options, job_logs
from pipeline._messages import bare_as, override_of, unknown_choice_line, unknown_key_line
from tma.errors import Interrupted, TmaError
from tma.families import NAMES, ingest_defaults, reads_logs
from tma.plan.command import Command, SweepRecord
from tma.plan.points import Override, override_text
from tma.plan.renamed import renamed_arguments
from tma.runtime.forkserver import keep_freed_memory, quick_exit
from tma.runtime.parallel import Engine, engine_from

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")
log = logging.getLogger("tma")
_stage_hydra = None  # Hydra's config of the stage run_stage is running (else None)
SWEEP_RECORD = "tma-aggregate.json"  # what an aggregate job of a multirun read
PROBE_BYTES = 1 << 16  # more than Hydra writes of its own before the stage starts
# the top-level keys of conf/config.yaml and conf/ingest.yaml, their groups and the ingest
# options they take from the families (+key adds none)
KNOWN_KEYS = {key for conf in ("config", "ingest")
              for key in OmegaConf.load(Path(CONF_DIR) / f"{conf}.yaml")} - {"defaults", "hydra"} \
    | {"scenario", "estimator", "parallel"} \
    | {key for name in NAMES if reads_logs(name) for key in ingest_defaults(name)}


# -- the entry point and the error policy -----------------------------------------------------

def stage_main(task, config_name="config", bare=None, check=None):
    """``main`` of ``python -m pipeline.<verb>``: Hydra's app running ``task`` on the config
    ``config_name`` (or ``config_name(arguments)``). Hydra is told to raise its own errors
    (``HYDRA_FULL_ERROR``) instead of printing them, and each becomes one ``error:`` line
    (``hydra_error_line``); a bare argument is ``<bare>=ARG`` (``pipeline._messages.bare_as``);
    ``check(arguments)`` runs before Hydra starts."""
    def main():
        os.environ["HYDRA_FULL_ERROR"] = "1"  # this process's Hydra: raise, we say it
        main_thread = threading.current_thread() is threading.main_thread()
        saved = {sig: signal.signal(sig, _stop) for sig in STOP_SIGNALS} if main_thread else {}
        try:
            sys.argv[1:] = renamed_arguments(guarded(bare_as, bare, _readable(sys.argv[1:]),
                                                     _overrides(sys.argv[1:])))
            if check is not None:
                check(sys.argv[1:])
            name = config_name(sys.argv[1:]) if callable(config_name) else config_name
            try:
                hydra.main(config_path=CONF_DIR, config_name=name, version_base="1.3")(task)()
            except Exception as exc:
                fail(guarded(hydra_error_line, exc, sys.argv[1:]) or guarded(_raise, exc))
        except KeyboardInterrupt as exc:  # Ctrl-C, or a signal of STOP_SIGNALS (Stopped)
            number = getattr(exc, "signal", signal.SIGINT)
            name = signal.Signals(number).name + (" (Ctrl-C)" if number == signal.SIGINT else "")
            fail(f"stopped by {name}: the tasks finished are kept and nothing complete was "
                 "replaced; run the same command again to resume", status=128 + number)
        finally:
            for sig, handler in saved.items():
                signal.signal(sig, handler)
    return main


STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)  # a scheduler's or a closed terminal's stop


class Stopped(KeyboardInterrupt):
    """A stop signal, raised where the command is, as Ctrl-C's KeyboardInterrupt is: joblib
    then stops its workers, ``guarded``'s last line of defence lets it through, and the
    command says it in one line (exit status 128 + the signal)."""

    def __init__(self, number: int):
        super().__init__(number)
        self.signal = number


def _stop(number, frame):
    raise Stopped(number)


def _raise(exc):
    raise exc


def _overrides(arguments: list[str]) -> list[str]:
    """The overrides among the command's arguments, as Hydra's own parser reads them."""
    from hydra._internal.utils import get_args_parser

    parser = get_args_parser()
    parser.error = lambda message: fail(message + (
        " (Hydra's flags such as -m go before the overrides)" if "unrecognized" in message
        else ""))
    return parser.parse_args(arguments).overrides


_SYNTAX = re.compile(r"""['"\[\](){},=\s]|\$\{""")  # what makes a value more than one text


def _readable(arguments: list[str]) -> list[str]:
    """The arguments with each ``key=value`` whose value is one text Hydra cannot read
    unquoted (``columns.lon=Länge``, ``input=über/journal_é.csv``, ``name=a~b``: its grammar
    takes ASCII letters, digits and a few signs only) quoted as Hydra reads text
    (``tma.plan.points.override_text``); a value with Hydra's own syntax (a list, a sweep,
    quotes, an interpolation) is left as written, for Hydra to read or refuse."""
    parser = OverridesParser.create()
    out = []
    for argument in arguments:
        key, eq, value = argument.partition("=")
        if eq and value and not key.startswith("-") and not _SYNTAX.search(value):
            try:
                parser.parse_override(argument)
            except hydra_errors.HydraException:  # OverrideParseException, a lexer's error
                quoted = override_text(key, value)
                try:
                    parser.parse_override(quoted)
                    argument = quoted
                except hydra_errors.HydraException:
                    pass  # not a value's fault (e.g. the key): Hydra says what is wrong
        out.append(argument)
    return out


NOTES = {"hydra.launcher.partition": "this launcher runs the jobs on this machine, which has "
                                     "no partitions: drop it; hydra/launcher=slurm takes it"}


def _unreadable_sign(exc) -> str | None:
    """The character Hydra's lexer stopped at in the override of ``exc`` (its report: the
    override, then a caret under the character), when it is no quote or bracket: one Hydra
    reads only inside quotes (``ü``, ``~``, ``#``)."""
    lines = str(exc).splitlines()
    head = "LexerNoViableAltException: "
    if len(lines) < 2 or not lines[0].startswith(head) or "^" not in lines[1]:
        return None
    at = lines[1].index("^") - len(head)
    sign = exc.override[at] if 0 <= at < len(exc.override) else ""
    return sign if sign and sign not in "'\"[]{}(),=" and not sign.isspace() else None


def hydra_error_line(exc: Exception, arguments: list[str]) -> str | None:
    """Hydra's error ``exc`` on the command line ``arguments`` as one line naming the override
    (and for an unknown key or option the nearest valid one); None when it is not Hydra's."""
    cause, first = exc.__cause__, (str(exc).strip().splitlines() or [""])[0]
    group, _, value = str(getattr(exc, "missing_cfg_file", "")).rpartition("/")
    if isinstance(exc, hydra_errors.MissingConfigException) and group and exc.options:
        return unknown_choice_line(group, value, exc.options)
    if isinstance(exc, hydra_errors.OverrideParseException):
        why = "" if exc.override in first else f" ({first})"
        sign = _unreadable_sign(exc)
        if sign:
            return (f"{exc.override}: cannot parse this override: Hydra reads '{sign}' "
                    "only inside quotes; quote each value holding it: key='a value' (for the "
                    "shell: \"key='a value'\")")
        return (f"{exc.override}: cannot parse this override{why}; quote a value holding "
                "quotes, brackets, commas or spaces: key='a value' (for the shell: "
                "\"key='a value'\")")
    key = getattr(cause, "full_key", None) or next(iter(re.findall(r"'([^']+)'", first)), "")
    dotted, override = override_of(key, _overrides(arguments))
    if isinstance(exc, hydra_errors.ConfigCompositionException) and isinstance(
            cause, OmegaConfBaseException):
        if isinstance(cause, ConfigAttributeError | ConfigKeyError) and cause.parent_node:
            return unknown_key_line(OmegaConf.to_container(cause.parent_node),
                                               key, override, dotted, NOTES.get(dotted))
        return f"{override}: {str(cause).splitlines()[0]}"
    if isinstance(exc, hydra_errors.HydraException):
        return first if override == key else f"{override}: {first}"
    errors = [line for line in str(exc).splitlines() if line.startswith("error: ")]
    if type(exc).__name__ in ("UncompletedJobError", "FailedJobError") and errors:
        return f"a job of the sweep failed: {errors[0].removeprefix('error: ')}"
    return None


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
    check_stage_options(plain(cfg), KNOWN_KEYS)
    engine_from(plain_value(cfg, "parallel"))  # checked; the stage's engine(cfg) logs its choice
    return fn(cfg)


def guarded(fn, *args):
    """``fn(*args)``, its user-caused failures as one line and exit status 2."""
    try:
        return fn(*args)
    except TmaError as exc:
        fail(str(exc))
    except Interrupted as exc:  # a worker that died: the re-run resumes
        fail(str(exc), exc.status)
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
    """Hydra callback: before Hydra writes anything under ``paths.data_dir``, check that the
    directory can be written (a read-only or full disk, a file on the path: one line) and that
    a sweep's launcher can run here; when a sweep of submitit's launchers ends, show its jobs'
    logs, which they wrote to files."""

    @staticmethod
    def _check(config, directory):
        try:  # room for Hydra's own files (resolved configs, the log): a full disk fails here
            check_output_dir({"paths": plain_value(config, "paths")}, directory,
                                        PROBE_BYTES)
        except OSError as exc:
            fail(f"cannot write the output directory: {os_error_line(exc)}")

    def on_run_start(self, config, **kwargs):
        guarded(self._check, config, config.hydra.run.dir)

    def on_multirun_start(self, config, **kwargs):
        guarded(check_launcher, str(config.hydra.launcher.get("_target_")))
        guarded(self._check, config, config.hydra.sweep.dir)

    def on_multirun_end(self, config, **kwargs):
        if "submitit" in str(config.hydra.launcher.get("_target_")):
            for line in job_logs(str(config.hydra.sweep.dir),
                                            f"{config.hydra.job.name}.log"):
                print(line)


_prefetch = []  # SweepTable's thread importing the family's aggregate while the jobs run


class SweepTable(Callback):
    """Hydra callback: when a multirun of ``aggregate`` ends, one table of all its jobs.

    Each aggregate job of the sweep records the runs it read (``SWEEP_RECORD`` in its Hydra
    output dir, tagged with this sweep's id); the union of those runs is aggregated once more
    into ``tables/<table>.*`` (default ``<family>-sweep``,
    ``tma.stages.aggregate.aggregate_sweep``), beside the jobs' own tables."""

    sweep_id = None

    def on_multirun_start(self, config, **kwargs):
        # inherited by the jobs, in or out of process; a command sets it as it starts, before
        # its worker server (``pipeline/__init__.py``)
        self.sweep_id = os.environ.get(SWEEP_ENV) or uuid.uuid4().hex
        os.environ[SWEEP_ENV] = self.sweep_id
        if config.hydra.job.name in ("aggregate", "table"):  # while this process waits
            from tma.stages.aggregate import prefetch_aggregate

            # not an attribute: Hydra sends its callbacks to the jobs, and a thread does not
            # pickle
            _prefetch.append(prefetch_aggregate(str(config.get("scenario", {}).get("family"))))

    def on_multirun_end(self, config, **kwargs):
        os.environ.pop(SWEEP_ENV, None)
        while _prefetch:
            thread = _prefetch.pop()
            if thread is not None:
                thread.join()
        if self.sweep_id is not None:
            guarded(write_sweep_table, config, self.sweep_id)


def stage_hydra(cfg: DictConfig):
    """Hydra's config of this stage: ``cfg.hydra`` when composed with it, else that of the
    stage ``run_stage`` runs; None for a stage function called outside Hydra (a test), whatever
    an earlier command in this process left in Hydra's singleton."""
    return cfg.hydra if "hydra" in cfg else _stage_hydra


def sweep_job(cfg: DictConfig):
    """The job number if this stage runs as a job of a multirun, else None."""
    hydra_cfg = stage_hydra(cfg)
    if hydra_cfg is None or hydra_cfg.get("mode") != RunMode.MULTIRUN:
        return None
    return int(hydra_cfg.job.num)


def job_tables(cfg: DictConfig) -> bool:
    """Whether a job of a multirun writes its own table (``job_tables``). The config of
    ``table input=LOG`` has no such key and its sweep no table of all jobs: each job writes
    its log's per-contact report."""
    return bool(cfg.get("job_tables", True))


def sweep_record(cfg: DictConfig) -> SweepRecord | None:
    """Where this aggregate job records the runs it read, for ``SweepTable`` (a job of a
    multirun only)."""
    number, hydra_cfg = sweep_job(cfg), stage_hydra(cfg)
    if number is None or not hydra_cfg.runtime.get("output_dir"):
        return None
    return SweepRecord(Path(hydra_cfg.runtime.output_dir) / SWEEP_RECORD,
                       os.environ.get(SWEEP_ENV), number)


def write_sweep_table(config: DictConfig, sweep_id: str) -> None:
    """The combined table of the aggregate jobs of sweep ``sweep_id`` (see ``SweepTable``)."""
    from tma.stages.aggregate import sweep_table

    for path in sweep_table(str(config.hydra.sweep.dir), sweep_id, SWEEP_RECORD,
                            config.get("table")):
        log.info("sweep table: wrote %s", path)


# -- the composed config, handed to the core ---------------------------------------------------

def plain(cfg: DictConfig) -> dict:
    """The config as plain values, without Hydra's own node."""
    return {key: plain_value(cfg, key) for key in cfg if key != "hydra"}


def plain_value(cfg: DictConfig, key: str):
    value = cfg.get(key)
    return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value


def command(cfg: DictConfig) -> Command:
    """The command as the core takes it (``tma.plan.command.Command``): the config as plain
    values, the command line's overrides, the sweep's launcher (a parallel launcher runs each
    job's shards in the job) and the overrides as text."""
    hydra_cfg = stage_hydra(cfg)
    if hydra_cfg is None:
        return Command(plain(cfg))
    return Command(plain(cfg), tuple(overrides(cfg)),
                   str(hydra_cfg.launcher.get("_target_", "")),
                   " ".join(hydra_cfg.overrides.task))


def overrides(cfg: DictConfig) -> list[Override]:
    """The command line's overrides of the app config, as Hydra records them
    (``hydra.overrides.task``; from ``cfg.hydra`` when composed with it, else from the
    running stage's Hydra config; none for a bare ``compose``), for ``tma.plan.points``."""
    hydra_cfg = stage_hydra(cfg)
    task = [] if hydra_cfg is None else list(hydra_cfg.overrides.task)
    parsed = OverridesParser.create().parse_overrides(task) if task else []
    return [Override(o.key_or_group, o.input_line,
                     o.value() if o.key_or_group == "estimator" else None,
                     o.is_delete(), o.package) for o in parsed]


# what tests and benchmarks ask of a composed config (``Command``'s, for a DictConfig)

def engine(cfg: DictConfig) -> Engine:
    return command(cfg).engine()


def scenario_nodes(cfg: DictConfig) -> list[dict]:
    return command(cfg).scenarios()


def estimator_nodes(cfg: DictConfig, checked: bool = False) -> list[dict]:
    return command(cfg).estimators(checked)


def jobs(cfg: DictConfig) -> list:
    return command(cfg).jobs()


def open_datasets(cfg: DictConfig):
    return command(cfg).datasets()
