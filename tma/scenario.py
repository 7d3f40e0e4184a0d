"""What every scenario config holds: ``ScenarioConfig``, the base of each family's
``scenario.Config`` (which sets its own defaults by declaring a field again)."""

from dataclasses import dataclass, fields

from tma.config import require
from tma.utc import config_epoch_ns


@dataclass
class ScenarioConfig:
    """``family``: the family's name (its one allowed value); ``n_tracks``: tracks (targets,
    Monte Carlo runs, paths) in the dataset; ``seed``: of every random draw
    (``tma.sharding``); ``shard_size``: tracks per log shard and per estimation task;
    ``epoch_utc``: the UTC of t = 0 (ISO-8601 with a zone), the logs' absolute times."""

    family: str = ""
    n_tracks: int = 1
    seed: int = 0
    shard_size: int = 1
    epoch_utc: str = "2026-01-01T00:00:00Z"

    @property
    def where(self) -> str:
        """``scenario '<family>'``, for messages."""
        return f"scenario '{self.own_family()}'"

    @classmethod
    def own_family(cls) -> str:
        return next(f.default for f in fields(cls) if f.name == "family")

    def __post_init__(self):
        where, own = self.where, self.own_family()
        config_epoch_ns(self.epoch_utc, where)
        require(self.family == own, where, f"family must be '{own}'")
        require(self.n_tracks >= 1, where, f"n_tracks must be >= 1, got {self.n_tracks}")
        require(self.shard_size >= 1, where, f"shard_size must be >= 1, got {self.shard_size}")
        require(self.seed >= 0, where, f"seed must be >= 0, got {self.seed}")

    @property
    def epoch_ns(self) -> int:
        """``epoch_utc`` in UTC nanoseconds."""
        return config_epoch_ns(self.epoch_utc, self.where)
