"""Simulate datasets from scenario configs: ``python -m pipeline.simulate [overrides]``."""

from pipeline._common import command, log, run_stage, stage_main
from tma.plan.command import run_simulate


def simulate_stage(cfg):
    for root in run_simulate(command(cfg)):
        log.info("dataset %s", root)


main = stage_main(lambda cfg: run_stage(simulate_stage, cfg))


if __name__ == "__main__":
    main()
