"""Summary statistics used by the tables."""

import numpy as np
from scipy.special import ndtri  # the normal quantile (light to import)


def wilson_interval(successes, n, confidence=0.95):
    """Wilson score interval for a binomial proportion; arrays broadcast. n = 0 gives NaN."""
    successes, n = np.asarray(successes, dtype=float), np.asarray(n, dtype=float)
    z = ndtri(0.5 + confidence / 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = successes / n
        denom = 1 + z * z / n
        centre = (p + z * z / (2 * n)) / denom
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return centre - half, centre + half
