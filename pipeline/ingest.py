"""Turn a recorded bearing log into a dataset: ``python -m pipeline.ingest input=log.csv``."""

import sys

import hydra

from pipeline._common import CONF_DIR, fail, log, run_stage
from tma.families.bearings2d.ingest import ingest
from tma.families.bearings2d.sources.base import GROUPS, unknown_option


def ingest_stage(cfg):
    root = ingest(cfg.input, data_dir=cfg.paths.data_dir, name=cfg.name, fmt=cfg.format,
                  sigma_deg=cfg.sigma_deg, min_bearings=cfg.min_bearings, force=cfg.force,
                  navigation=cfg.navigation, options={group: cfg[group] for group in GROUPS})
    log.info("dataset %s", root)
    print(f"dataset {root.name}: run  python -m pipeline.estimate dataset={root.name} "
          f"estimator=lm  then  python -m pipeline.aggregate dataset={root.name} estimator=lm")


@hydra.main(config_path=CONF_DIR, config_name="ingest", version_base="1.3")
def _hydra_main(cfg):
    run_stage(ingest_stage, cfg)


def check_option_keys(overrides):
    """An unknown reading option on the command line (``columns.foo=x``) is one line naming
    the options of its group, before Hydra turns it into a multi-line composition error."""
    for override in overrides:
        if override.startswith("-") or "=" not in override:
            continue
        key = override.split("=", 1)[0].lstrip("+~")
        complaint = unknown_option(key)
        if complaint:
            fail(complaint)


def main():
    check_option_keys(sys.argv[1:])
    _hydra_main()


if __name__ == "__main__":
    main()
