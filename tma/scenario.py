"""What every scenario config holds: ``ScenarioConfig``, the base of each family's
``scenario.Config`` (which sets its own defaults by declaring a field again: the doc and range
stay the ones declared here)."""

from dataclasses import dataclass

from tma.config import Params, param, require
from tma.utc import config_epoch_ns


@dataclass
class ScenarioConfig(Params):
    family: str = param("", "the scenario family (its one allowed value)")
    n_tracks: int = param(1, "tracks in the dataset (targets, Monte Carlo runs, paths)",
                          "[1, inf)")
    seed: int = param(0, "seed of every random draw (tma.runtime.sharding)", "[0, inf)")
    shard_size: int = param(1, "tracks per log shard and per estimation task", "[1, inf)")
    epoch_utc: str = param("2026-01-01T00:00:00Z", "UTC of t = 0 (ISO-8601 with a zone): the "
                           "logs' absolute times")

    @property
    def where(self) -> str:
        return f"scenario '{self.own_family()}'"

    @classmethod
    def own_family(cls) -> str:
        return cls.__dataclass_fields__["family"].default

    def __post_init__(self):
        where, own = self.where, self.own_family()
        config_epoch_ns(self.epoch_utc, where)
        require(self.family == own, where, f"family must be '{own}'")
        super().__post_init__()

    @property
    def epoch_ns(self) -> int:
        """``epoch_utc`` in UTC nanoseconds."""
        return config_epoch_ns(self.epoch_utc, self.where)
