"""Run estimators over stored datasets: ``python -m pipeline.estimate [overrides]``."""

from pipeline._common import command, log, run_stage, stage_main
from tma.plan.command import run_estimate


def estimate_stage(cfg):
    for root, reused in run_estimate(command(cfg)):
        if reused:
            log.info("run %s reused (finished before and verified; force=true recomputes it)",
                     root)
        else:
            log.info("run %s", root)


main = stage_main(lambda cfg: run_stage(estimate_stage, cfg))


if __name__ == "__main__":
    main()
