"""``prior_is``: importance sampling from the prior: ratio of the Monte Carlo means of
x_s L(x) and L(x), x ~ prior, with the delta-method error (``importance_sampling.py``)."""

from dataclasses import dataclass

from tma.families.ranges2d.estimators.base import (
    PosteriorMean,
    SamplingEstimator,
    TrackRanges,
    sampled_mean,
)
from tma.families.ranges2d.importance_sampling import SamplerConfig


@dataclass
class Config(SamplerConfig):
    pass  # the sampler's settings (importance_sampling.SamplerConfig) are all it has


class PriorIS(SamplingEstimator):
    conformance_config = {"accuracy_m": 2.0}
    Config = Config

    def solve(self, track: TrackRanges) -> PosteriorMean:
        model = track.model

        def draw(k, rng):
            points = model.prior_mean_m + model.prior_sd_m * rng.standard_normal((k, 2))
            return points, model.log_likelihood(points[:, 0], points[:, 1])

        moments, reached = self.config.budget().run(draw, *self.stream(track))
        return sampled_mean(moments, reached)
