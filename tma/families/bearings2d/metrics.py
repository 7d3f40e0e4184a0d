"""Metrics of the ``bearings2d`` family (see the spec's "Metrics per track").

Bearing and distance are compared at the end of each track's observation (its last bearing
epoch, from own-ship then); course and speed are constant. Errors of angles are wrapped to
[-180, 180) degrees; distance and speed errors are relative to the truth.

The Cramer-Rao lower bound (CRLB) of a track: with bearings X_k = f_k(theta) + N(0, sigma^2)
the Fisher information at the true theta is I = J^T J / sigma^2 (J the analytic Jacobian
``model.bearing_jacobian``, rad per m and per m/s), so no unbiased estimator has a covariance
below C = I^-1 = (J^T J)^-1 sigma^2. It is mapped to range, bearing, course and speed at the
track's last bearing by their Jacobian G at the truth (delta method): G C G^T. Over a set of
tracks (one estimator, one dataset) ``efficiency_row`` gives the RMSE of range (m), course
(deg) and speed (m/s), the root of the mean bound, sqrt(mean_i (G C G^T)_i), and the
efficiency = mean bound / mean squared error = (root mean bound / RMSE)^2: 1 for an efficient
(unbiased, minimum-variance) estimator, the share of the estimator's mean squared error that
no estimator could avoid; biased estimators may exceed 1. The bound assumes the Gaussian noise
the dataset declares: bearings replaced by outliers are not in it.
"""

import numpy as np
import pandas as pd
from scipy.special import gammaincinv  # scipy.stats takes 0.5 s to import, for one quantile

from tma.families.bearings2d.model import bearing_jacobian
from tma.families.bearings2d.platforms import observer_now
from tma.families.bearings2d.status import STATUSES, kinematics_now
from tma.maths.angles import wrap_to_180
from tma.maths.linalg import scaled_inverse
from tma.maths.stats import wilson_interval

THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")
# an ok track's normalised error lies below this 95 % of runs: chi2.ppf(0.95, 4), which
# scipy.stats computes as 2 gammaincinv(4 / 2, 0.95)
NEES_95 = float(2 * gammaincinv(2.0, 0.95))

# region: (bearing deg, distance relative, course deg, speed relative), all with <=
REGIONS = {
    "ref1": (0.5, 0.05, 5.0, 0.05),
    "ref2": (1.0, 0.10, 10.0, 0.10),
    "ref3": (1.0, 0.15, 10.0, 0.10),
    "ref4": (1.0, 0.15, 10.0, 0.15),
}


def jtj_matrices(estimates: pd.DataFrame) -> np.ndarray:
    """The stored upper triangle ``jtj_ij`` as full matrices ``(n, 4, 4)``."""
    jtj = np.empty((len(estimates), 4, 4))
    for i in range(4):
        for j in range(i, 4):
            jtj[:, i, j] = jtj[:, j, i] = estimates[f"jtj_{i}{j}"].to_numpy()
    return jtj


def normalised_error(df: pd.DataFrame) -> np.ndarray:
    """(theta_hat - theta)^T Sigma^-1 (theta_hat - theta) with Sigma = (J^T J)^-1 sigma^2,
    i.e. e^T J^T J e / sigma^2 (no inverse needed); NaN where sigma is 0. ``df``: estimates
    merged with the truth (truth columns suffixed ``_true``)."""
    e = df[list(THETA)].to_numpy() - df[[f"{c}_true" for c in THETA]].to_numpy()
    sigma2 = np.deg2rad(df["sigma_used_deg"].to_numpy()) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        nees = np.einsum("ni,nij,nj->n", e, jtj_matrices(df), e) / sigma2
    return np.where(sigma2 > 0, nees, np.nan)


def _with_truth(estimates: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    df = estimates.merge(truth, on="track_id", how="left", suffixes=("", "_true"),
                         validate="one_to_one")
    if df["x0_m_true"].isna().any():
        raise ValueError("estimates hold track ids that the truth table lacks")
    return df


def _now(df: pd.DataFrame):
    """(range, bearing, course, speed) at each track's last bearing, estimated and true."""
    at_end = (df["t_last_s"].to_numpy(), df["own_x_last_m"].to_numpy(),
              df["own_y_last_m"].to_numpy())
    est, _ = kinematics_now(df[list(THETA)].to_numpy(), *at_end, jacobian=False)
    tru, _ = kinematics_now(df[[f"{c}_true" for c in THETA]].to_numpy(), *at_end,
                            jacobian=False)
    return est, tru


def track_metrics(estimates: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """One row per track: errors, region successes, sqrt(Ka) (deg), Nf, Iter, converged,
    status and the normalised error of theta (NEES, chi-square(4) for a consistent fit)."""
    df = _with_truth(estimates, truth)
    est, tru = _now(df)
    errors = {  # numpy arrays: the regions below compare them without pandas' overhead
        "bearing_err_deg": wrap_to_180(np.rad2deg(est[1] - tru[1])),
        "distance_rel_err": (est[0] - tru[0]) / tru[0],
        "course_err_deg": wrap_to_180(np.rad2deg(est[2] - tru[2])),
        "speed_rel_err": (est[3] - tru[3]) / tru[3],
    }
    out = pd.DataFrame({
        "track_id": df["track_id"],
        **errors,
        "sqrt_ka_deg": np.rad2deg(np.sqrt(df["cost_rad2"] / df["n_bearings"])),
        "n_f_evals": df["n_f_evals"].astype(float),
        "n_iter": df["n_iter"].astype(float),
        "converged": df["converged"].astype(bool),
        "status": df["status"],
        "nees": normalised_error(df),
    })
    b, d, c, s = (np.abs(e) for e in errors.values())
    for name, (bearing, distance, course, speed) in REGIONS.items():
        out[name] = (b <= bearing) & (d <= distance) & (c <= course) & (s <= speed)
    return out


def summary_row(metrics: pd.DataFrame, estimator: str, sigma_deg: float) -> dict:
    """One table row: region success rates with 95 % Wilson intervals, sqrt(Ka), Nf, Iter."""
    n = len(metrics)
    row = {"estimator": estimator, "sigma_deg": sigma_deg, "n_tracks": n}
    for name in REGIONS:
        k = int(metrics[name].sum())
        lo, hi = wilson_interval(k, n)
        row.update({name: k / n, f"{name}_lo": float(lo), f"{name}_hi": float(hi)})
    ka = metrics["sqrt_ka_deg"]
    row.update({
        "sqrt_ka_mean": float(ka.mean()), "sqrt_ka_median": float(ka.median()),
        "nf_median": float(metrics["n_f_evals"].median()),
        "iter_median": float(metrics["n_iter"].median()),
        "n_converged": int(metrics["converged"].sum()),
        **{f"n_{s}": int((metrics["status"] == s).sum()) for s in STATUSES},
    })
    ok = metrics["status"] == "ok"
    nees = metrics.loc[ok, "nees"]
    k, m = int((nees <= NEES_95).sum()), int(nees.notna().sum())
    lo, hi = wilson_interval(k, m)
    row.update({"consistent": k / m if m else np.nan, "consistent_lo": float(lo),
                "consistent_hi": float(hi)})
    return row


TABLE_COLUMNS = [
    "estimator", "sigma_deg", "n_tracks",
    *[f"{r}{s}" for r in REGIONS for s in ("", "_lo", "_hi")],
    "sqrt_ka_mean", "sqrt_ka_median", "nf_median", "iter_median", "n_converged",
    *[f"n_{s}" for s in STATUSES], "consistent", "consistent_lo", "consistent_hi",
]


# -- the Cramer-Rao bound and the efficiency ---------------------------------------------------

def fisher_information(theta, t_s, own_x_m, own_y_m, valid, sigma_deg) -> np.ndarray:
    """I(theta) = J^T J / sigma^2 per track, ``(n, 4, 4)`` (units of theta^-2), from the
    analytic Jacobian at ``theta`` (n, 4); ``valid``: mask of present bearings or None.
    sigma = 0 gives inf where J^T J is nonzero."""
    J = bearing_jacobian(theta, t_s, own_x_m, own_y_m, valid)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.einsum("nki,nkj->nij", J, J) / np.deg2rad(sigma_deg) ** 2


def crlb_theta(theta, t_s, own_x_m, own_y_m, valid, sigma_deg, rcond=1e-12) -> np.ndarray:
    """The bound C = (J^T J)^-1 sigma^2 on the covariance of theta, ``(n, 4, 4)``; inf on
    the diagonal where J^T J is singular (scaled eigenvalue ratio <= ``rcond``: theta is not
    observable, no finite bound). sigma = 0 gives 0."""
    J = bearing_jacobian(theta, t_s, own_x_m, own_y_m, valid)
    jtj = np.einsum("nki,nkj->nij", J, J)
    cov, singular = scaled_inverse(jtj, rcond)
    cov *= np.deg2rad(sigma_deg) ** 2
    cov[singular] = np.diag(np.full(4, np.inf))
    return cov


def crlb_now(log, truth: pd.DataFrame) -> pd.DataFrame:
    """Per track of ``log`` (a ``BearingsLog`` with its nominal ``sigma_deg``): the bound's
    one-sigma values at the track's last bearing, ``crlb_range_m``, ``crlb_bearing_deg``,
    ``crlb_course_deg``, ``crlb_speed_m_s``, from the true theta in ``truth``."""
    if log.sigma_deg is None:
        raise ValueError("the CRLB needs the log's nominal bearing noise sigma_deg")
    rows = truth.set_index("track_id").loc[log.track_id]
    theta = rows[list(THETA)].to_numpy(dtype=float)
    valid = np.isfinite(log.bearing_deg)
    last = valid.shape[1] - 1 - np.argmax(valid[:, ::-1], axis=1)
    cov = crlb_theta(theta, log.t_s, log.own_x_m, log.own_y_m,
                     None if valid.all() else valid, log.sigma_deg)
    now = observer_now(log.t_s, log.own_x_m, log.own_y_m, log.platform, 0, last)
    _, G = kinematics_now(theta, log.t_s[last], *now)
    finite = np.isfinite(cov).all(axis=(1, 2))
    with np.errstate(invalid="ignore"):
        var = np.einsum("nij,njk,nik->ni", G, np.where(finite[:, None, None], cov, 0.0), G)
    var[~finite] = np.inf
    sd = np.sqrt(var)
    return pd.DataFrame({"track_id": log.track_id, "crlb_range_m": sd[:, 0],
                         "crlb_bearing_deg": np.rad2deg(sd[:, 1]),
                         "crlb_course_deg": np.rad2deg(sd[:, 2]), "crlb_speed_m_s": sd[:, 3]})


def errors_now(estimates: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Per track the absolute errors at its last bearing: ``range_err_m``,
    ``bearing_err_deg``, ``course_err_deg`` (wrapped), ``speed_err_m_s``; and the true range
    then, ``range_true_m``."""
    df = _with_truth(estimates, truth)
    est, tru = _now(df)
    return pd.DataFrame({
        "track_id": df["track_id"],
        "range_err_m": est[0] - tru[0],
        "bearing_err_deg": wrap_to_180(np.rad2deg(est[1] - tru[1])),
        "course_err_deg": wrap_to_180(np.rad2deg(est[2] - tru[2])),
        "speed_err_m_s": est[3] - tru[3],
        "range_true_m": tru[0],
    })


# quantity: (error column of errors_now, bound column of crlb_now)
EFFICIENCY = {"range": ("range_err_m", "crlb_range_m"),
              "course": ("course_err_deg", "crlb_course_deg"),
              "speed": ("speed_err_m_s", "crlb_speed_m_s")}


def efficiency_row(errors: pd.DataFrame, bounds: pd.DataFrame) -> dict:
    """RMSE, root mean bound and efficiency of range (m), course (deg) and speed (m/s) over
    the tracks whose estimate and bound are finite (``n_failed``: tracks without a finite
    estimate, left out; an estimator that fails often is judged by Ref1-4 and status too).
    Efficiency = mean bound / mean squared error (module docstring); NaN when either is 0
    (noiseless data: the bound is 0)."""
    df = errors.merge(bounds, on="track_id", validate="one_to_one")
    err = df[[e for e, _ in EFFICIENCY.values()]].to_numpy()
    bound = df[[b for _, b in EFFICIENCY.values()]].to_numpy()
    finite_estimate = np.isfinite(err).all(axis=1)
    use = finite_estimate & np.isfinite(bound).all(axis=1)
    row = {"n_failed": int((~finite_estimate).sum())}
    for i, name in enumerate(EFFICIENCY):
        mse = float(np.mean(err[use, i] ** 2)) if use.any() else np.nan
        mean_bound = float(np.mean(bound[use, i] ** 2)) if use.any() else np.nan
        eff = mean_bound / mse if mse > 0 and mean_bound > 0 else np.nan
        row.update({f"rmse_{name}": np.sqrt(mse), f"crlb_{name}": np.sqrt(mean_bound),
                    f"efficiency_{name}": eff})
    return row
