"""Turn a recorded log into a dataset: ``python -m pipeline.ingest input=log.csv``."""

import sys
from pathlib import Path

from omegaconf import OmegaConf

from pipeline._common import CONF_DIR, guarded, log, plain, run_stage, stage_main
from pipeline._messages import check_ingest_options
from tma.plan.command import run_ingest

INGEST_YAML = Path(CONF_DIR) / "ingest.yaml"


def ingest_stage(cfg):
    root = run_ingest(plain(cfg))
    log.info("dataset %s", root)
    print(f"dataset {root.name}: estimate and aggregate it with  python -m pipeline.table "
          f"dataset={root.name}  (estimator=lm; estimator=NAME for another)")


def check_option_keys(arguments):
    """An unknown reading option (``columns.foo=x``) is one line naming the options of its
    group, before Hydra composes (it would name only the key)."""
    guarded(check_ingest_options, arguments, OmegaConf.load(INGEST_YAML).family)


def with_truth_shorthand(main):
    """``main`` reading ``truth=FILE`` as ``truth.file=FILE`` (``tma.ais.options.shorthand``)."""
    def shorthand_main():
        from tma.ais.options import shorthand

        sys.argv[1:] = shorthand(sys.argv[1:])
        main()
    return shorthand_main


main = with_truth_shorthand(stage_main(lambda cfg: run_stage(ingest_stage, cfg), "ingest",
                                       bare="input", check=check_option_keys))


if __name__ == "__main__":
    main()
