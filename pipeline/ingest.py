"""Turn an external bearing log into a dataset: ``python -m pipeline.ingest input=log.csv``."""

import hydra

from pipeline._common import CONF_DIR, log, run_stage
from tma.families.bearings2d.ingest import ingest


def ingest_stage(cfg):
    root = ingest(cfg.input, data_dir=cfg.paths.data_dir, name=cfg.name, fmt=cfg.format,
                  sigma_deg=cfg.sigma_deg, min_bearings=cfg.min_bearings,
                  bearing_units=cfg.bearing_units, force=cfg.force)
    log.info("dataset %s", root)
    print(f"dataset {root.name}: run  python -m pipeline.estimate dataset={root.name} "
          f"estimator=lm  then  python -m pipeline.aggregate dataset={root.name} estimator=lm")


@hydra.main(config_path=CONF_DIR, config_name="ingest", version_base="1.3")
def main(cfg):
    run_stage(ingest_stage, cfg)


if __name__ == "__main__":
    main()
