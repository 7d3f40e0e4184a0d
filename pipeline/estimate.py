"""Run estimators over stored datasets: ``python -m pipeline.estimate [overrides]``."""

from pipeline._common import engine, estimator_nodes, log, open_datasets, run_stage, stage_main
from tma.runs import estimate_runs


def estimate_stage(cfg):
    estimators = estimator_nodes(cfg, checked=True)  # a bad estimator config fails before any I/O
    jobs = [(ds, est) for ds in open_datasets(cfg) for est in estimators]
    roots = estimate_runs(cfg.paths.data_dir, jobs, engine=engine(cfg), progress=cfg.progress,
                          force=cfg.force)
    for root in roots:
        log.info("run %s", root)


main = stage_main(lambda cfg: run_stage(estimate_stage, cfg))


if __name__ == "__main__":
    main()
