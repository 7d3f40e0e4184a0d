"""``prior_is``: importance sampling from the prior: ratio of the Monte Carlo means of
x_s L(x) and L(x), x ~ prior, with the delta-method error (``ratio.py``)."""

from dataclasses import dataclass

from tma.families.ranges2d.estimators.base import RangesEstimator, sampling_columns
from tma.families.ranges2d.estimators.ratio import SamplingBudget


@dataclass
class Config:
    name: str = "prior_is"
    n_samples: int | None = None  # fixed sample count; null = run to the accuracy target
    accuracy_m: float = 0.1  # half-width of the confidence interval per coordinate
    confidence: float = 0.95
    batch: int = 10_000  # draws between checks of the stopping rule
    min_samples: int = 50_000
    plot_points: int = 3000  # draws of track 0 kept for the sample plot
    max_samples: int = 100_000_000
    seed: int = 1

    def __post_init__(self):
        SamplingBudget.check(self, "estimator 'prior_is'")


def budget(cfg) -> SamplingBudget:
    return SamplingBudget(cfg.n_samples, cfg.accuracy_m, cfg.confidence, cfg.batch,
                          cfg.max_samples, cfg.min_samples)


class PriorIS(RangesEstimator):
    side_tables = ("samples",)  # its first draws of one track, for the plot
    name = "prior_is"
    Config = Config

    def solve(self, model, rng, keep=0):
        def draw(k, rng):
            points = model.prior_mean_m + model.prior_sd_m * rng.standard_normal((k, 2))
            return points, model.log_likelihood(points[:, 0], points[:, 1])

        moments, reached = budget(self.config).run(draw, rng, keep)
        return sampling_columns(moments, reached)
