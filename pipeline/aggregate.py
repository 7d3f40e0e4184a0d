"""Per-track metrics and tables from finished runs: ``python -m pipeline.aggregate``."""

import hydra

from pipeline._common import CONF_DIR, checked_estimator_nodes, log, open_datasets, run_stage
from tma.aggregate import aggregate


def aggregate_stage(cfg):
    estimators = checked_estimator_nodes(cfg)  # a bad estimator config fails before any I/O
    jobs = [(ds, est) for ds in open_datasets(cfg) for est in estimators]
    for path in aggregate(cfg.paths.data_dir, cfg.paths.tables_dir, jobs, table=cfg.table):
        log.info("wrote %s", path)


@hydra.main(config_path=CONF_DIR, config_name="config", version_base="1.3")
def main(cfg):
    run_stage(aggregate_stage, cfg)


if __name__ == "__main__":
    main()
