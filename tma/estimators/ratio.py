"""Ratio importance-sampling estimate of a posterior mean with its delta-method error.

For draws x ~ p with xi = x_s f2(x)/p(x) and eta = f2(x)/p(x), the estimate is
mean(xi)/mean(eta) and, by the delta method for a ratio, its standard error is
|x_hat_s| RE_s / sqrt(N) with
RE_s^2 = var(xi)/E[xi]^2 + var(eta)/E[eta]^2 - 2 cov(xi, eta)/(E[xi] E[eta]).
Sums are kept as streams, so sampling can go on batch by batch until the accuracy target.
Weights carry a fixed scale (exp of a reference log weight) that cancels in every ratio.
"""

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm


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
        """RE per coordinate (per single draw; divide by sqrt(N) for the estimate)."""
        m_xi, m_eta, var_xi, var_eta, cov = self._moments()
        re2 = var_xi / m_xi**2 + var_eta / m_eta**2 - 2 * cov / (m_xi * m_eta)
        return np.sqrt(np.maximum(re2, 0.0))

    def standard_error(self):
        return np.abs(self.estimate()) * self.relative_error() / np.sqrt(self.n)

    def correlation(self):
        """Correlation of numerator (xi) and denominator (eta) per coordinate."""
        _, _, var_xi, var_eta, cov = self._moments()
        return cov / np.sqrt(var_xi * var_eta)


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
        z = norm.ppf(0.5 + self.confidence / 2)
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
