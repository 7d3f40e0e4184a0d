"""simulate -> estimate -> aggregate in one process: ``python -m pipeline.table [overrides]``.

What ``make table`` runs. The three stages are the same functions the three verbs run, in
order, and still meet only through the files each writes (the estimate stage reads the
dataset from disk and verifies it, and so on): one process just starts Python, composes the
config and starts the worker pool once, and its workers load the compiled kernels once,
instead of three times each (about 3 s of a 20 s table on 2 cores). A stage that fails
stops the command with its own error; what the stages before it wrote stays complete.
"""

import threading
from time import perf_counter

from pipeline._common import log, run_stage, stage_main
from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tma.families import NAMES, family

STAGES = (("simulate", simulate_stage), ("estimate", estimate_stage),
          ("aggregate", aggregate_stage))


def _import_report(name: str):
    try:
        family(name).report  # noqa: B018 (imported for its side effect: the module loaded)
    except Exception:  # left for the aggregate stage, which imports it again and says why
        pass


def prefetch_report(cfg) -> threading.Thread | None:
    """Import the scenario family's report module (matplotlib, about 0.5 s) in a thread
    while the workers estimate, when this process mostly waits for them; the aggregate
    stage then starts with it loaded. Not earlier: during simulate the thread would hold
    up the start of the worker pool (0.5 s). None when the config names no known family
    (the stages say what is wrong)."""
    name = str(cfg.get("scenario", {}).get("family"))
    if name not in NAMES:
        return None
    thread = threading.Thread(target=_import_report, args=(name,), daemon=True)
    thread.start()
    return thread


def table_stage(cfg):
    prefetch = None
    for name, stage in STAGES:
        if name == "estimate":
            prefetch = prefetch_report(cfg)
        if name == "aggregate" and prefetch is not None:
            prefetch.join()  # its imports complete before the stage that uses them
        start = perf_counter()
        stage(cfg)
        log.info("stage %s: %.2f s", name, perf_counter() - start)


main = stage_main(lambda cfg: run_stage(table_stage, cfg))


if __name__ == "__main__":
    main()
