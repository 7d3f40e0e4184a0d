"""Per-track metrics and tables from finished runs: ``python -m pipeline.aggregate``.

In a multirun (``-m``) each job writes its own table (a ``table=`` name, or the default
name of several runs, gets the job number: ``<table>-<N>``), and when the sweep ends
``pipeline._common.SweepTable`` writes one table of all its jobs: ``<table>`` (default
``<family>-sweep``)."""

from pipeline._common import command, log, run_stage, stage_main, sweep_job, sweep_record
from tma.plan.command import run_aggregate


def aggregate_stage(cfg):
    table, suffix = cfg.table, "custom"
    number = sweep_job(cfg)
    if number is not None:  # a job of a multirun: its table is one of several
        table = f"{cfg.table}-{number}" if cfg.table else None
        suffix = f"custom-{number}"
    for path in run_aggregate(command(cfg), table, suffix, sweep_record(cfg)):
        log.info("wrote %s", path)


main = stage_main(lambda cfg: run_stage(aggregate_stage, cfg))


if __name__ == "__main__":
    main()
