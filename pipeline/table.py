"""The stages in one process: ``python -m pipeline.table [overrides]`` (what ``make table``
runs) simulates, estimates and aggregates; ``input=FILE`` ingests a recorded log instead
(config ``log_table``: ingest's options and an estimator), ``dataset=NAME`` starts from a
stored dataset. The stages are the functions the verbs run and meet only through the files
each writes: one process starts Python, composes the config and starts the worker pool once
(about 3 s of a 20 s table on 2 cores). A stage that fails stops the command with its own
error; what the stages before it wrote stays complete."""

from time import perf_counter

from omegaconf import open_dict

from pipeline._common import command, job_tables, log, plain, run_stage, stage_main, sweep_job
from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.ingest import check_option_keys, with_truth_shorthand
from pipeline.simulate import simulate_stage
from tma.plan.command import run_log_dataset
from tma.stages.aggregate import prefetch_aggregate

STAGES = (("simulate", simulate_stage), ("estimate", estimate_stage),
          ("aggregate", aggregate_stage))


def ingest_stage(cfg):
    """The log's dataset: ingested, or reused when ingesting it again gives the same one
    (``tma.plan.command.run_log_dataset``); the next stages read it by name."""
    root, reused = run_log_dataset(plain(cfg))
    log.info("dataset %s%s", root, " reused (ingesting the log again gives the same dataset)"
             if reused else "")
    with open_dict(cfg):
        cfg.dataset = root.name


def _compile_ahead(cfg):
    """The kernels the table's estimators run, compiled while it simulates, on a machine whose
    numba cache is empty (``tma.runtime.compile_ahead``; nothing when it is warm, or
    when the shards run on a Dask cluster, whose workers have caches of their own)."""
    from tma.runtime.compile_ahead import compile_ahead

    try:
        todo = command(cfg)
        if todo.engine().engine != "dask":
            compile_ahead(todo.scenarios(), todo.estimators())
    except Exception:  # a bad config: the stages say what is wrong with it
        return


def campaign_stage(cfg):
    """``input=`` a folder or a glob of logs: each log's table as ``input=LOG`` writes it, and
    the campaign's table and plot (``tma.ais.campaign``)."""
    import copy
    from pathlib import Path

    from tma.ais.campaign import (
        campaign_logs,
        campaign_name,
        log_name,
        run_campaign,
        write_campaign_tables,
    )

    truth = cfg.get("truth", {}) or {}
    pairs = campaign_logs(cfg.input, truth.get("file"))
    estimator = str(cfg.estimator.get("name", "estimator"))
    name = campaign_name(cfg.input, cfg.name)
    tables_dir = Path(str(cfg.paths.tables_dir))

    def score(log, ais, stem):
        one = copy.deepcopy(cfg)
        dataset = log_name(name, stem, cfg.name is not None)
        with open_dict(one):
            one.input, one.name, one.dataset = str(log), dataset, None
            one.truth.file, one.table = str(ais), f"{dataset}-{estimator}"
        table_stage(one)
        import pandas as pd

        return pd.read_csv(tables_dir / f"{one.table}.csv")

    reports, refused = run_campaign(pairs, score, f"input={cfg.input}")
    for path in write_campaign_tables(reports, refused, tables_dir,
                                      f"{name}-campaign-{estimator}"):
        log.info("wrote %s", path)


def table_stage(cfg):
    if "input" in cfg and cfg.input is not None and _is_campaign(cfg.input):
        return campaign_stage(cfg)
    prefetch = None
    if "input" not in cfg and not cfg.dataset:
        _compile_ahead(cfg)
    for name, stage in STAGES:
        if name == "simulate" and "input" in cfg:
            name, stage = "ingest", ingest_stage
        elif name == "simulate" and cfg.dataset:
            continue  # a stored dataset: nothing to simulate
        if name == "estimate" and (sweep_job(cfg) is None or job_tables(cfg)):
            # not during simulate: it would delay the worker pool's start; a job of a sweep
            # writes no table unless asked (job_tables)
            prefetch = prefetch_aggregate(str(cfg.get("scenario", {}).get("family",
                                                                       cfg.get("family"))))
        if name == "aggregate" and prefetch is not None:
            prefetch.join()  # its imports complete before the stage that uses them
        start = perf_counter()
        stage(cfg)
        log.info("stage %s: %.2f s", name, perf_counter() - start)


def _is_campaign(input_path) -> bool:
    from tma.ais.campaign import is_campaign

    return is_campaign(input_path)


def _config_name(arguments) -> str:
    return "log_table" if any(a.startswith("input=") for a in arguments) else "config"


main = with_truth_shorthand(stage_main(
    lambda cfg: run_stage(table_stage, cfg), _config_name, bare="input",
    check=lambda a: _config_name(a) == "config" or check_option_keys(a)))


if __name__ == "__main__":
    main()
