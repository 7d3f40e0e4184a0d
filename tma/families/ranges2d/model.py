"""Position of a static ship from ranges to point landmarks, with a Gaussian prior.

The posterior kernel f2(p) = prior(p) x likelihood(p) of a position p = (x, y) (m, x east,
y north) depends on the ranges only through each landmark's range count n_i and mean r_i:
sum_k (r_ik - d_i)^2 = n_i (d_i - r_i)^2 + const. Everything is in log space because f2 is
near zero almost everywhere.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RangeModel:
    """Sufficient statistics of one track's ranges plus the noise and prior.

    landmarks_m: (L, 2); counts: (L,) ranges per landmark; mean_range_m: (L,);
    sigma_m: range noise std; prior_mean_m: (2,); prior_sd_m: (2,).
    """

    landmarks_m: np.ndarray
    counts: np.ndarray
    mean_range_m: np.ndarray
    sigma_m: float
    prior_mean_m: np.ndarray
    prior_sd_m: np.ndarray

    @classmethod
    def from_ranges(cls, landmarks_m, ranges_m, sigma_m, prior_mean_m, prior_sd_m):
        """``ranges_m``: (L, m) ranges to each landmark, NaN where absent."""
        ranges_m = np.asarray(ranges_m, dtype=float)
        counts = np.isfinite(ranges_m).sum(axis=1)
        mean = np.where(counts > 0, np.nansum(ranges_m, axis=1) / np.maximum(counts, 1), 0.0)
        return cls(np.asarray(landmarks_m, float), counts, mean, float(sigma_m),
                   np.asarray(prior_mean_m, float), np.asarray(prior_sd_m, float))

    def log_prior(self, x, y):
        """log prior density at (x, y), up to an additive constant."""
        return -0.5 * (((x - self.prior_mean_m[0]) / self.prior_sd_m[0]) ** 2
                       + ((y - self.prior_mean_m[1]) / self.prior_sd_m[1]) ** 2)

    def log_likelihood(self, x, y):
        """log likelihood at (x, y), up to a constant: the IS weight of a draw from the prior."""
        out = None
        inv_var = 0.5 / self.sigma_m**2
        for (lx, ly), n, r in zip(self.landmarks_m, self.counts, self.mean_range_m, strict=True):
            if n:
                d = np.hypot(x - lx, y - ly) - r
                term = (-n * inv_var) * d * d
                out = term if out is None else out + term
        return np.zeros(np.broadcast_shapes(np.shape(x), np.shape(y))) if out is None else out

    def log_kernel(self, x, y):
        """log f2 = log prior + log likelihood at points (x, y), up to a constant."""
        return self.log_prior(x, y) + self.log_likelihood(x, y)
