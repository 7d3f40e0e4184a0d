"""``adaptive_is``: importance sampling from a piecewise-constant density refined by bisection.

The density (``ranges2d/bisection.py``) lives on the square ``box_m`` (default +-400 m, the
prior's 99.99 % region); its build costs one evaluation of f2 per bisection, counted in
``samples_used``. Posterior mass outside the box is invisible to this sampler: it is measured
with ``check_samples`` draws from the prior and, above ``max_mass_outside``, the track gets
status ``box_too_small`` and no estimate (a logged warning names the share).
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.ranges2d.bisection import BisectionDensity
from tma.families.ranges2d.estimators.base import (
    PosteriorMean,
    SamplingEstimator,
    TrackRanges,
    no_estimate,
    sampled_mean,
)
from tma.families.ranges2d.importance_sampling import SamplerConfig

MAX_CHECK = 10_000_000  # prior draws held in memory at once by the mass check
MAX_BISECTIONS = 10_000_000  # cells, tree and heap take ~200 B per bisection


@dataclass
class Config(SamplerConfig):
    box_m: list[float] = param(doc="the square K of the density, [x0, x1, y0, y1] (m): the "
                               "prior's 99.99 % region", factory=lambda: [-400.0, 400.0,
                                                                         -400.0, 400.0])
    n_bisections: int = param(10_000, "bisections of the density (one f2 evaluation each)",
                              f"[0, {MAX_BISECTIONS}]")
    # without the shift a cell whose point misses the peak is never drawn: biased
    shift: float = param(5e-4, "c in the density g = f2 / max f2 + c", "(0, inf)")
    split: str = param("heaviest", "which cell is bisected next", choices=("heaviest", "draw"))
    check_samples: int = param(200_000, "prior draws that measure the posterior mass outside "
                               "the box", f"[1, {MAX_CHECK}]")
    max_mass_outside: float = param(1e-3, "mass outside the box above which a track is "
                                    "box_too_small", "[0, 1]")
    seed: int = param(2, "seed of each track's stream (SeedSequence(seed, spawn_key=(track,)))",
                      "[0, inf)")

    def __post_init__(self):
        super().__post_init__()
        require(len(self.box_m) == 4 and self.box_m[0] < self.box_m[1]
                and self.box_m[2] < self.box_m[3], self.where,
                "box_m must be [x0, x1, y0, y1] with x0 < x1 and y0 < y1")


def mass_outside(model, box, n, rng) -> float:
    """Posterior mass outside ``box`` estimated by prior importance sampling."""
    points = model.prior_mean_m + model.prior_sd_m * rng.standard_normal((n, 2))
    log_w = model.log_likelihood(points[:, 0], points[:, 1])
    w = np.exp(log_w - log_w.max())
    (x0, x1), (y0, y1) = box
    out = ((points[:, 0] < x0) | (points[:, 0] > x1) | (points[:, 1] < y0) | (points[:, 1] > y1))
    return float(w[out].sum() / w.sum())


class AdaptiveIS(SamplingEstimator):
    outputs = ("mass_outside",)  # posterior mass outside the box
    conformance_config = {"accuracy_m": 2.0}
    Config = Config

    def solve(self, track: TrackRanges) -> PosteriorMean:
        cfg, model = self.config, track.model
        rng, keep = self.stream(track)
        box = ((cfg.box_m[0], cfg.box_m[1]), (cfg.box_m[2], cfg.box_m[3]))
        outside = mass_outside(model, box, cfg.check_samples, rng)
        if outside > cfg.max_mass_outside:
            return no_estimate(
                "box_too_small",
                f"adaptive_is: about {outside:.1%} of the posterior mass lies outside the box "
                f"{cfg.box_m} m (limit {cfg.max_mass_outside:g}): enlarge estimator.box_m",
                columns={"mass_outside": outside})
        density = BisectionDensity.build(model, box, cfg.n_bisections, cfg.shift, rng, cfg.split)

        def draw(k, rng):
            points, cell = density.sample(k, rng)
            log_w = model.log_kernel(points[:, 0], points[:, 1]) - np.log(
                density.cell_density(cell))
            return points, log_w

        moments, reached = cfg.budget().run(draw, rng, keep)
        return sampled_mean(moments, reached, density.n_evaluations, {"mass_outside": outside})
