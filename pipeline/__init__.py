"""Thin Hydra entry points, one verb each: ``python -m pipeline.<verb>``, or ``tma <verb>``
once installed (``pipeline.cli``)."""

import os
import sys
import uuid

from tma.runtime.forkserver import preload_workers, quick_exit, workers_from_server

SWEEP_ENV = "TMA_SWEEP_ID"  # the multirun's id, seen by its jobs (pipeline._common.SweepTable)


VERBS = ("simulate", "ingest", "estimate", "aggregate", "table")  # pipeline.<verb>, tma <verb>


def _command() -> str | None:
    """``pipeline.<verb>`` when this process is the command ``python -m pipeline.<verb>``: the
    interpreter's own options read up to the first that names what it runs."""
    argv, i = sys.orig_argv[1:], 0
    while i < len(argv) and argv[i].startswith("-") and argv[i] not in ("-", "-c", "-m"):
        i += 2 if argv[i] in ("-W", "-X", "--check-hash-based-pycs") else 1
    if argv[i:i + 1] != ["-m"] or i + 1 >= len(argv):
        return None  # a script, -c, stdin or a session
    return argv[i + 1] if argv[i + 1].startswith("pipeline.") else None


# Hydra's flags that print and exit before any stage runs (its help, the composed config, its
# version): no worker will start, so no fork server either (it would take a core while the
# command composes)
INFORMATIONAL = frozenset(("-h", "--help", "--hydra-help", "--version", "-c", "--cfg", "-i",
                           "--info", "-sc", "--shell-completion"))


def _informational(arguments) -> bool:
    """Whether the command line holds one of Hydra's ``INFORMATIONAL`` flags."""
    return any(a.startswith("-") and a.partition("=")[0] in INFORMATIONAL for a in arguments)


def _tma_command() -> bool:
    """Whether this process is the command ``tma <verb>`` (the script pip installs, which
    runs ``pipeline.cli``)."""
    return (os.path.basename(sys.argv[0]) == "tma" and len(sys.argv) > 1
            and sys.argv[1] in VERBS)


if _command() or _tma_command():
    try:
        os.getcwd()
    except FileNotFoundError:  # every relative path (data/, the log) would be relative to it
        print("error: the working directory no longer exists (deleted, or its disk "
              "unmounted): cd to a directory that exists and run the command again",
              file=sys.stderr)
        sys.exit(2)
    quick_exit()  # the collections of Python's shutdown skipped: ~0.2 s of every command
if (_command() or _tma_command()) and not _informational(sys.argv[1:]):
    # the command's local workers start from a server that imports what they need meanwhile
    # (tma.runtime.forkserver.preload_workers); they see the environment as it is now, sweep
    # id included
    multirun = "-m" in sys.argv[1:] or "--multirun" in sys.argv[1:]  # argv[0] is "-m" here
    if multirun:
        os.environ[SWEEP_ENV] = uuid.uuid4().hex  # a new sweep, whatever the shell exported
    # the command's module is what forked workers re-import as their __main__; its imports are
    # the other verbs' (runpy warns when the module itself is already imported); the tma
    # command's __main__ is its script, which imports pipeline.cli
    verbs = ["pipeline._common", "pipeline.simulate", "pipeline.estimate", "pipeline.aggregate",
             "pipeline.ingest", "pipeline.cli"]
    # the jobs of a multirun plot there only when each writes its own table (job_tables=true;
    # a recorded log's per-contact report, input=LOG)
    plotting = multirun and any(
        a.startswith("input=") or (a.partition("=")[0].lstrip("+") == "job_tables"
                                   and a.partition("=")[2].lower() not in ("false", "null"))
        for a in sys.argv[1:])
    preload_workers([v for v in verbs if v != _command()]
                    + (["matplotlib.pyplot"] if plotting else []))
    if multirun:
        workers_from_server()  # the joblib Hydra launcher's pool too

from tma.families import register_configs  # noqa: E402

register_configs()  # scenario/* and estimator/* from the Config dataclasses, before Hydra composes
