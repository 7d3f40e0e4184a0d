"""Run estimators over stored datasets: ``python -m pipeline.estimate [overrides]``."""

from pipeline._common import engine, jobs, log, run_stage, stage_main
from tma.estimation import estimate_runs


def estimate_stage(cfg):
    runs = estimate_runs(cfg.paths.data_dir, jobs(cfg), engine=engine(cfg),
                         progress=cfg.progress, force=cfg.force)
    for root, reused in runs:
        if reused:
            log.info("run %s reused (finished before and verified; force=true recomputes it)",
                     root)
        else:
            log.info("run %s", root)


main = stage_main(lambda cfg: run_stage(estimate_stage, cfg))


if __name__ == "__main__":
    main()
