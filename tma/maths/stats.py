"""Summary statistics used by the tables."""

import numpy as np
from scipy.special import gammaincinv, ndtri  # quantiles (light to import, unlike scipy.stats)


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


def rate_columns(successes: int, n: int, name: str) -> dict:
    """A table's rate columns: ``name`` (successes / n; NaN for n = 0) and its 95 % Wilson
    interval ``<name>_lo``, ``<name>_hi``."""
    lo, hi = wilson_interval(successes, n)
    return {name: successes / n if n else np.nan, f"{name}_lo": float(lo),
            f"{name}_hi": float(hi)}


def chi2_mean_interval(n, dof, confidence=0.95):
    """The central ``confidence`` interval of the mean of ``n`` independent chi-square(``dof``)
    draws: their sum is chi-square(n dof), so (chi2.ppf(a, n dof), chi2.ppf(1 - a, n dof)) / n
    with a = (1 - confidence) / 2, where chi2.ppf(p, k) = 2 gammaincinv(k / 2, p). E.g. the
    mean NEES of n tracks whose errors are honest (dof 4) lies in it with that probability;
    arrays broadcast, n = 0 gives NaN."""
    n = np.asarray(n, dtype=float)
    alpha = (1 - confidence) / 2
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(n > 0, n * dof, np.nan)
        return 2 * gammaincinv(k / 2, alpha) / n, 2 * gammaincinv(k / 2, 1 - alpha) / n
