"""Turn a recorded log into a dataset: ``python -m pipeline.ingest input=log.csv``."""

import sys
from pathlib import Path

from omegaconf import OmegaConf

from pipeline._common import CONF_DIR, guarded, log, run_stage, stage_main
from tma.experiment import check_ingest_options
from tma.ingest import ingest, option_groups, setting_names

INGEST_YAML = Path(CONF_DIR) / "ingest.yaml"


def ingest_arguments(cfg) -> dict:
    """``tma.ingest.ingest``'s arguments from the composed config."""
    return dict(input_path=cfg.input, data_dir=cfg.paths.data_dir, family=cfg.family,
                name=cfg.name, fmt=cfg.format, force=cfg.force, navigation=cfg.navigation,
                options={group: cfg[group] for group in option_groups(cfg.family)},
                truth=cfg.get("truth"),
                **{key: cfg[key] for key in setting_names(cfg.family)})


def ingest_stage(cfg):
    root = ingest(**ingest_arguments(cfg))
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
