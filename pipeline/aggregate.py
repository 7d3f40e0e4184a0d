"""Per-track metrics and tables from finished runs: ``python -m pipeline.aggregate``.

In a multirun (``-m``) each job checks and records the runs it covers, and when the sweep ends
``pipeline._common.SweepTable`` writes their metrics and one table of all its jobs:
``<table>`` (default ``<family>-sweep``). With ``job_tables=true`` each job also writes its own
table (a ``table=`` name, or the default name of several runs, gets the job number:
``<table>-<N>``)."""

from pipeline._common import (
    command,
    job_tables,
    log,
    run_stage,
    stage_main,
    sweep_job,
    sweep_record,
)
from tma.plan.command import run_aggregate


def aggregate_stage(cfg):
    table, suffix, tables = cfg.table, "custom", True
    number = sweep_job(cfg)
    if number is not None:  # a job of a multirun: its table is one of several, if asked for
        table = f"{cfg.table}-{number}" if cfg.table else None
        suffix = f"custom-{number}"
        tables = job_tables(cfg)
    for path in run_aggregate(command(cfg), table, suffix, sweep_record(cfg), tables):
        log.info("wrote %s", path)


main = stage_main(lambda cfg: run_stage(aggregate_stage, cfg))


if __name__ == "__main__":
    main()
