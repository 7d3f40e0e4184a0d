"""Turn a recorded log into a dataset: ``python -m pipeline.ingest input=log.csv``."""

import sys
from pathlib import Path

import hydra
from omegaconf import OmegaConf

from pipeline._common import CONF_DIR, fail, log, run_stage
from tma.errors import ConfigError
from tma.ingest import ingest, option_groups, setting_names, unknown_option_of


def ingest_stage(cfg):
    root = ingest(cfg.input, data_dir=cfg.paths.data_dir, family=cfg.family, name=cfg.name,
                  fmt=cfg.format, force=cfg.force, navigation=cfg.navigation,
                  options={group: cfg[group] for group in option_groups(cfg.family)},
                  **{key: cfg[key] for key in setting_names(cfg.family)})
    log.info("dataset %s", root)
    print(f"dataset {root.name}: run  python -m pipeline.estimate dataset={root.name} "
          f"estimator=lm  then  python -m pipeline.aggregate dataset={root.name} estimator=lm")


@hydra.main(config_path=CONF_DIR, config_name="ingest", version_base="1.3")
def _hydra_main(cfg):
    run_stage(ingest_stage, cfg)


def check_option_keys(overrides):
    """An unknown reading option on the command line (``columns.foo=x``) is one line naming
    the options of its group, before Hydra turns it into a multi-line composition error."""
    family = OmegaConf.load(Path(CONF_DIR) / "ingest.yaml").family
    for override in overrides:
        if override.startswith("-") or "=" not in override:
            continue
        key, value = override.split("=", 1)
        if key.lstrip("+~") == "family":
            family = value
    for override in overrides:
        if override.startswith("-") or "=" not in override:
            continue
        try:
            complaint = unknown_option_of(override.split("=", 1)[0].lstrip("+~"), family)
        except ConfigError:  # an unknown family: the stage says so, in one line
            return
        if complaint:
            fail(complaint)


def main():
    check_option_keys(sys.argv[1:])
    _hydra_main()


if __name__ == "__main__":
    main()
