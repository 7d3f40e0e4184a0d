"""The estimator interface shared by every family."""


class Estimator:
    """One interface for every estimator, built from its validated ``Config`` dataclass:
    ``estimate(log) -> dict`` of output columns shaped ``(n_tracks, ...)`` (per-step outputs
    ``(n_tracks, n_steps)``). A family's base class implements ``estimate`` and calls the one
    hook a concrete estimator writes, ``solve`` (its arguments are the family's).

    Declared, so that the core and the reports never test estimator names:

    - ``family``: the scenario family whose logs it reads;
    - ``outputs``: columns it adds beyond its family's common ones (e.g. the fuzzy
      tracker's memory length ``m``, the IMM's model probabilities);
    - ``side_tables``: small tables it returns under ``estimate(log)["extras"]`` (written
      beside the run's estimates, e.g. sample points for a plot, covariances);
    - ``reference``: True for the exact estimator others are measured against;
    - ``prepare(config, dataset, data_dir, engine, progress)``: a step run once before the
      shards (e.g. training an artefact), returning the config the run records;
    - ``recorded_defaults``: config values that replace its defaults on a recorded log (a
      dataset not simulated) where the command line sets none (``tma.runs.dataset_config``),
      e.g. a start from the first bearing instead of the simulated scenario's prior.
    """

    family = ""
    name = ""
    outputs: tuple[str, ...] = ()
    side_tables: tuple[str, ...] = ()
    reference = False
    recorded_defaults: dict = {}
    data_dir = None  # where artefacts live; set by the estimate stage before ``estimate``

    def __init__(self, config):
        self.config = config

    @classmethod
    def prepare(cls, config: dict, dataset, data_dir, engine=1, progress=False) -> dict:
        return config

    def estimate(self, log) -> dict:
        raise NotImplementedError
