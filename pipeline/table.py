"""simulate -> estimate -> aggregate in one process: ``python -m pipeline.table [overrides]``.

What ``make table`` runs. The three stages are the same functions the three verbs run, in
order, and still meet only through the files each writes (the estimate stage reads the
dataset from disk and verifies it, and so on): one process just starts Python, composes the
config and starts the worker pool once, and its workers load the compiled kernels once,
instead of three times each (about 3 s of a 20 s table on 2 cores). A stage that fails
stops the command with its own error; what the stages before it wrote stays complete.
"""

from time import perf_counter

import hydra

from pipeline._common import CONF_DIR, log, run_stage
from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage

STAGES = (("simulate", simulate_stage), ("estimate", estimate_stage),
          ("aggregate", aggregate_stage))


def table_stage(cfg):
    for name, stage in STAGES:
        start = perf_counter()
        stage(cfg)
        log.info("stage %s: %.2f s", name, perf_counter() - start)


@hydra.main(config_path=CONF_DIR, config_name="config", version_base="1.3")
def main(cfg):
    run_stage(table_stage, cfg)


if __name__ == "__main__":
    main()
