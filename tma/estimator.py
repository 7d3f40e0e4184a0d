"""The estimator interface shared by every family."""


class Estimator:
    """One interface for every estimator: built from its validated ``Config`` dataclass,
    ``estimate(log) -> dict`` of output columns shaped ``(n_tracks, ...)`` (per-step outputs
    ``(n_tracks, n_steps)``; an optional ``extras`` dict holds small side tables).
    ``family`` names the scenario family whose logs it reads."""

    family = ""
    name = ""

    def __init__(self, config):
        self.config = config

    def estimate(self, log) -> dict:
        raise NotImplementedError
