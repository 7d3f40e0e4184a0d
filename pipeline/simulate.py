"""Simulate datasets from scenario configs: ``python -m pipeline.simulate [overrides]``."""

from pipeline._common import engine, estimator_nodes, log, run_stage, scenario_nodes, stage_main
from tma.errors import ConfigError
from tma.simulation import simulate_datasets


def simulate_stage(cfg):
    if cfg.dataset:
        raise ConfigError("simulate creates datasets from the scenario config; "
                          "'dataset=' names an existing one (use it with estimate, aggregate or "
                          "table)")
    estimator_nodes(cfg)  # the command line's estimator overrides fail here too, not later
    roots = simulate_datasets(scenario_nodes(cfg), cfg.paths.data_dir, engine=engine(cfg),
                              force=cfg.force, progress=cfg.progress)
    for root in roots:
        log.info("dataset %s", root)


main = stage_main(lambda cfg: run_stage(simulate_stage, cfg))


if __name__ == "__main__":
    main()
