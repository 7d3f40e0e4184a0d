"""Ratio importance-sampling estimate of a posterior mean with its delta-method error.

For draws x ~ p with xi = x_s f2(x)/p(x) and eta = f2(x)/p(x), the estimate is
mean(xi)/mean(eta) and, by the delta method for a ratio, its standard error is
|x_hat_s| RE_s / sqrt(N) with
RE_s^2 = var(xi)/E[xi]^2 + var(eta)/E[eta]^2 - 2 cov(xi, eta)/(E[xi] E[eta]).
Sums are kept as streams, so sampling can go on batch by batch until the accuracy target.
Weights carry a scale (exp of a reference log weight) that cancels in every ratio; it is
fixed by the first batch and raised only when a later draw would otherwise overflow.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.estimator import EstimatorConfig

# A weight above exp(RESCALE_LOG) times the reference rescales the sums to the new maximum:
# squared weights then stay below exp(2 x 300), far from overflow (exp(709)).
RESCALE_LOG = 300.0
MAX_BATCH = 1_000_000  # draws held in memory at once


@dataclass
class RatioMoments:
    n: int = 0
    ref: float | None = None  # log weight scale, fixed by the first batch
    s_eta: float = 0.0
    s_eta2: float = 0.0
    s_xi: np.ndarray = None
    s_xi2: np.ndarray = None
    s_xieta: np.ndarray = None
    kept: np.ndarray = None  # the first draws, if asked for

    def add(self, points, log_weight):
        """Add draws ``points`` (k, 2) with log importance weights log(f2/p) (k,)."""
        if self.ref is None:
            self.ref = float(np.max(log_weight))
            self.s_xi, self.s_xi2, self.s_xieta = np.zeros(2), np.zeros(2), np.zeros(2)
        elif np.max(log_weight) > self.ref + RESCALE_LOG:
            new = float(np.max(log_weight))
            scale = np.exp(self.ref - new)  # underflows to 0 only for negligible old weights
            self.s_eta *= scale
            self.s_xi *= scale
            self.s_xieta *= scale * scale
            self.s_eta2 *= scale * scale
            self.s_xi2 *= scale * scale
            self.ref = new
        eta = np.exp(log_weight - self.ref)
        xi = points * eta[:, None]
        self.n += eta.size
        self.s_eta += eta.sum()
        self.s_eta2 += eta @ eta
        self.s_xi += xi.sum(axis=0)
        self.s_xi2 += np.einsum("ki,ki->i", xi, xi)
        self.s_xieta += xi.T @ eta

    def estimate(self):
        return self.s_xi / self.s_eta

    def _moments(self):
        n = self.n
        m_xi, m_eta = self.s_xi / n, self.s_eta / n
        var_xi = self.s_xi2 / n - m_xi**2
        var_eta = self.s_eta2 / n - m_eta**2
        cov = self.s_xieta / n - m_xi * m_eta
        return m_xi, m_eta, var_xi, var_eta, cov

    def relative_error(self):
        """RE per coordinate (per single draw; divide by sqrt(N) for the estimate); NaN or
        inf when the draws are degenerate (a coordinate's weighted mean exactly 0)."""
        m_xi, m_eta, var_xi, var_eta, cov = self._moments()
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            re2 = var_xi / m_xi**2 + var_eta / m_eta**2 - 2 * cov / (m_xi * m_eta)
            return np.sqrt(np.maximum(re2, 0.0))

    def standard_error(self):
        with np.errstate(invalid="ignore"):  # 0 x inf: degenerate, NaN
            return np.abs(self.estimate()) * self.relative_error() / np.sqrt(self.n)

    def correlation(self):
        """Correlation of numerator (xi) and denominator (eta) per coordinate (NaN when a
        variance is 0, e.g. all draws but one with negligible weight)."""
        _, _, var_xi, var_eta, cov = self._moments()
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            product = var_xi * var_eta
            # the product can overflow for widely spread weights: then the roots separately
            scale = np.where(np.isfinite(product), np.sqrt(product),
                             np.sqrt(var_xi) * np.sqrt(var_eta))
            return cov / scale


@dataclass
class SamplerConfig(EstimatorConfig):
    """The settings every importance sampler shares: its budget (``SamplingBudget``), the
    draws kept for the plot and its seed."""

    n_samples: int | None = param(None, "a fixed count of draws per track (>= 2: the error "
                                  "estimate needs two); null: sample to the accuracy target",
                                  "[2, inf)")
    accuracy_m: float = param(0.1, "target half-width of the confidence interval of each "
                              "coordinate (m)", "(0, inf)")
    confidence: float = param(0.95, "confidence of that interval", "(0, 1)")
    batch: int = param(10_000, "draws between checks of the stopping rule", f"[1, {MAX_BATCH}]")
    min_samples: int = param(50_000, "draws before the stopping rule is first checked",
                             "[2, inf)")
    plot_points: int = param(3000, "draws of track 0 kept for the sample plot", "[0, inf)")
    max_samples: int = param(100_000_000, "draws per track at most (the run then stops "
                             "not_converged); >= min_samples", "[2, inf)")
    seed: int = param(1, "seed of each track's stream (SeedSequence(seed, spawn_key=(track,)))",
                      "[0, inf)")

    def __post_init__(self):
        super().__post_init__()
        require(self.max_samples >= self.min_samples, self.where,
                "max_samples must be >= min_samples (else the stopping rule is never checked)")

    def budget(self) -> "SamplingBudget":
        return SamplingBudget(self.n_samples, self.accuracy_m, self.confidence, self.batch,
                              self.max_samples, self.min_samples)


@dataclass
class SamplingBudget:
    """Fixed ``n_samples`` (if set) or sampling until every coordinate's half-width at
    ``confidence`` is within ``accuracy_m`` (after ``min_samples``, at most ``max_samples``),
    checked every ``batch`` draws."""

    n_samples: int | None
    accuracy_m: float
    confidence: float
    batch: int
    max_samples: int
    min_samples: int = 50_000  # the error estimate needs enough draws before it can stop

    def run(self, draw, rng, keep=0) -> tuple[RatioMoments, bool]:
        """``draw(k, rng) -> (points, log_weight)``; returns the moments and whether the
        accuracy target was reached (always True for a fixed count). The first ``keep``
        draws are kept in ``moments.kept`` (for plots)."""
        from scipy.special import ndtri  # the normal quantile; imported by samplers only

        z = ndtri(0.5 + self.confidence / 2)
        moments = RatioMoments()
        total = self.n_samples if self.n_samples else self.max_samples
        while moments.n < total:
            points, log_weight = draw(min(self.batch, total - moments.n), rng)
            if moments.n < keep:
                moments.kept = points[: keep - moments.n]
            moments.add(points, log_weight)
            if (not self.n_samples and moments.n >= self.min_samples
                    and np.all(z * moments.standard_error() <= self.accuracy_m)):
                return moments, True
        return moments, bool(self.n_samples)
