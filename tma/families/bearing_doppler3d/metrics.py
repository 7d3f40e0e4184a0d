"""Metrics of ``bearing_doppler3d``: per epoch and component bias, RMSE, the filter's own std
beside the measured std, NEES with its chi-square band, and divergence.

A path diverges, and is lost (``track_lost``, as a ``radar2d`` run past its gate), when its
horizontal position error exceeds ``divergence_m`` (or is not finite) at any epoch
t >= ``divergence_after_s``, or when its filter flagged it (``filter_ok`` False). Heading
errors are wrapped to [-pi, pi).
"""

import numpy as np
import pandas as pd
from scipy.special import gammaincinv  # scipy.stats takes 0.5 s to import, for one quantile

from tma.families.bearing_doppler3d.model import PHI, STATE_NAMES
from tma.maths.angles import wrap_to_pi

DIVERGENCE_M = 1000.0
DIVERGENCE_AFTER_S = 10.0


def _cube(df: pd.DataFrame, columns, n_steps):
    return np.stack([df[c].to_numpy().reshape(-1, n_steps) for c in columns], axis=-1)


def errors(estimates: pd.DataFrame, truth: pd.DataFrame):
    """Errors (n, K, 6), own covariance entries, times and the filter flags, path-aligned."""
    est = estimates.sort_values(["track_id", "step"], kind="stable").reset_index(drop=True)
    tru = truth[truth["track_id"].isin(est["track_id"].unique())].sort_values(
        ["track_id", "step"], kind="stable").reset_index(drop=True)
    if not (len(tru) == len(est) and np.array_equal(tru["track_id"], est["track_id"])
            and np.array_equal(tru["step"], est["step"])):
        raise ValueError("estimates and truth do not cover the same (track, step) pairs")
    K = int(est["step"].max()) + 1
    e = _cube(est, STATE_NAMES, K) - _cube(tru, STATE_NAMES, K)
    e[..., PHI] = wrap_to_pi(e[..., PHI])
    t = est["t_s"].to_numpy()[:K]
    ok = est["filter_ok"].to_numpy().reshape(-1, K)[:, 0].astype(bool)
    return e, est, t, ok


def divergent_paths(e, t, ok, threshold_m=DIVERGENCE_M, after_s=DIVERGENCE_AFTER_S):
    horizontal = np.hypot(e[..., 0], e[..., 1])
    late = t >= after_s
    with np.errstate(invalid="ignore"):
        big = np.any(~(horizontal[:, late] <= threshold_m), axis=1)  # NaN counts as divergent
    return big | ~ok


def path_metrics(track_ids, e, t, ok) -> pd.DataFrame:
    """Per path: ``track_lost`` (it diverged), the filter's flag and the largest horizontal
    error (m) from ``DIVERGENCE_AFTER_S`` on (NaN if any is not finite)."""
    horizontal = np.hypot(e[..., 0], e[..., 1])[:, t >= DIVERGENCE_AFTER_S]
    with np.errstate(invalid="ignore"):  # NaN propagates: no finite maximum
        worst = horizontal.max(axis=1) if horizontal.size else np.full(len(ok), np.nan)
    return pd.DataFrame({"track_id": np.asarray(track_ids),
                         "track_lost": divergent_paths(e, t, ok), "filter_ok": ok,
                         "horizontal_err_max_m": worst})


def nees(e, covariance: pd.DataFrame, track_ids):
    """NEES per path at the epochs with a stored covariance: (n, n_stored) and the epochs."""
    cov = covariance.sort_values(["track_id", "step"], kind="stable")
    steps = np.unique(cov["step"].to_numpy())
    if not np.array_equal(np.unique(cov["track_id"]), np.asarray(track_ids)):
        raise ValueError("covariance and estimates cover different tracks")
    n = len(track_ids)
    P = np.empty((n, steps.size, 6, 6))
    for i in range(6):
        for j in range(i, 6):
            P[..., i, j] = P[..., j, i] = cov[f"P_{i}{j}"].to_numpy().reshape(n, steps.size)
    es = e[:, steps]
    good = np.isfinite(P).all(axis=(2, 3)) & np.isfinite(es).all(axis=2)
    sol = np.zeros_like(es)
    if good.any():
        sol[good] = np.linalg.solve(P[good], es[good][..., None])[..., 0]
    return np.where(good, np.einsum("nki,nki->nk", es, sol), np.nan), steps


def nees_band(n_paths, dof=6, level=0.95):
    """Two-sided band of the mean NEES of n_paths consistent estimates: chi-square quantiles
    chi2.ppf(p, k), computed as scipy.stats does, 2 gammaincinv(k / 2, p)."""
    k = dof * n_paths
    return (2 * gammaincinv(k / 2, (1 - level) / 2) / n_paths,
            2 * gammaincinv(k / 2, (1 + level) / 2) / n_paths)


def per_step(e, est, t, keep, K):
    """Per epoch and component: bias, RMSE, measured std, own std (RMS of reported sd)."""
    n = e.shape[0]
    sd = _cube(est, [f"sd_{c}" for c in STATE_NAMES], K)
    rows = []
    for c, name in enumerate(STATE_NAMES):
        sub, own = e[keep, :, c], sd[keep, :, c]
        rows.append(pd.DataFrame({
            "step": np.arange(K), "t_s": t, "component": name,
            "bias": sub.mean(0), "rmse": np.sqrt((sub**2).mean(0)), "std": sub.std(0, ddof=1),
            "own_sd": np.sqrt((own**2).mean(0)),
            "rmse_all_paths": np.sqrt(np.nanmean(e[:, :, c] ** 2, axis=0)),
        }))
    out = pd.concat(rows, ignore_index=True)
    out["n_paths"] = int(keep.sum())
    out["n_all_paths"] = n
    return out
