"""A nearly-constant-velocity (NCV) target seen through bearings: the batch estimate of its
state now, with one-sigma errors that include the target's unmodelled motion.

Motion model (Bar-Shalom, Li and Kirubarajan, "Estimation with Applications to Tracking and
Navigation", Wiley 2001, sec. 6.2.2, the "continuous white noise acceleration" model): per
axis, position and velocity driven by white acceleration of power spectral density q
(m^2/s^3), so that over T seconds

    F = [[1, T], [0, 1]],  Q = q [[T^3 / 3, T^2 / 2], [T^2 / 2, T]].

q = 0 is the constant-velocity target of ``model.py``; a real ship wanders off a straight
line by about sqrt(q T^3 / 3) metres over T seconds.

State s_k = (x, y, vx, vy) at each bearing epoch (m, m/s; x east, y north). The estimate is
the maximum a posteriori trajectory given the bearings (noise sigma) and the NCV prior,
found by Gauss-Newton from a constant-velocity solution: the iterated extended Kalman
smoother (Bell, "The iterated Kalman smoother as a Gauss-Newton method", SIAM J. Optim.
4(3), 1994), each pass a Kalman filter linearised about the current trajectory and a
Rauch-Tung-Striebel smoother, with a step halved until the MAP cost falls. These passes
give the first state a wide prior about the constant-velocity start (``PRIOR_RANGES``
times its range, ``PRIOR_SPEED_M_S`` per velocity axis), kept fixed over the passes and in
the cost, so little that the answer is the bearings' and q's.

About the MAP trajectory a last pass, a square-root information filter started from no
information at all (exactly diffuse: Bierman, "Factorization Methods for Discrete
Sequential Estimation", Academic Press 1977), gives the state at the track's last bearing
and its covariance (at the last epoch the smoother is the filter), and the innovations nu_k
with their variances S_k. Under the model e_k = nu_k / sqrt(S_k) are independent N(0, 1)
(with q = 0 they are the recursive residuals of Brown, Durbin and Evans, "Techniques for
testing the constancy of regression relationships over time", JRSS B 37(2), 1975): the
sequence the fit tests read (``status``). The few that resolve a direction the earlier
bearings left undetermined (the diffuse ones, about one per state dimension: S above
``MAX_S`` in a pass with q = 0, since process noise does not change which they are) are
left out. A covariance-form pass would not do: a prior centred on the
answer, however wide, shrinks the early innovations and makes the sequence look smoother
than white (the trend test then rejects at a third of its level).

Everything runs in units of the bearing noise: R = 1, Q = (q / sigma^2) Q1, covariances
divided by sigma^2. With sigma unknown it is estimated from the innovations and the fit
repeated with it.

q is not estimated from the bearings: measured on simulated NCV targets, the likelihood of
q of one track is nearly flat over two decades (the target's wander trades against its
range), and a q fitted to a manoeuvre absorbs it and hides it from the trend test. It is
declared (a simulation knows it), set (``estimator.accel_psd_m2_s3``) or, for a recorded
log, a value measured on real ships (``RECORDED_ACCEL_PSD``).
"""

from dataclasses import dataclass

import numpy as np

from tma.families.bearings2d.kalman import (
    _bearing_cost,
    _fit,
    smoothed_positions,
    step_noise,
)
from tma.families.bearings2d.model import atan2, bearing_residuals
from tma.families.bearings2d.srif import MAX_S, _invert_upper, _srif
from tma.maths.angles import wrap_angle
from tma.runtime.jit import njit

# q (m^2/s^3) for a log that declares none (a recording): the Solent AIS tracks of
# tests/data/ais fitted from their positions give 1e-4..2e-3 for vessels holding course and
# speed (harbour traffic; ocean-going ships are steadier, and this is then conservative)
RECORDED_ACCEL_PSD = 1e-3
PRIOR_RANGES = 10.0  # prior position sd: this many times the start's range (diffuse)
PRIOR_SPEED_M_S = 100.0  # prior velocity sd per axis (diffuse for ships)
MIN_PRIOR_M = 1000.0  # prior position sd at least this


@njit(error_model="numpy")
def start_track(i, t, lo, hi, theta, nom, state, P_last, e):
    """Blank track i's outputs (its state, covariance and innovations NaN until written) and
    set ``nom`` over lo..hi to its constant-velocity line ``theta[i]``: how every per-track
    kernel starts a track."""
    for k in range(e.shape[1]):
        e[i, k] = np.nan
    for a in range(4):
        state[i, a] = np.nan
        for b in range(4):
            P_last[i, a, b] = np.nan
    for k in range(lo, hi + 1):
        nom[k, 0] = theta[i, 0] + theta[i, 2] * t[k]
        nom[k, 1] = theta[i, 1] + theta[i, 3] * t[k]
        nom[k, 2] = theta[i, 2]
        nom[k, 3] = theta[i, 3]


@njit(error_model="numpy", depends=(atan2, wrap_angle))
def finish_track(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, noisy, state, P_last, e, cost,
                 nu, S, S0, R, r, Rinv, none):
    """About the MAP trajectory ``nom`` of track i under the process noise ``Q`` (K, 3;
    ``noisy``: any step has some; ``none``: zeros of Q's shape), the exactly diffuse
    square-root information pass (``_srif``): writes the state at the last bearing and its
    covariance (units of s^2; NaN if singular), the normalised innovations ``e`` (the
    diffuse ones left out) and the squared bearing residuals of ``nom`` (rad^2): how every
    per-track kernel ends a track."""
    # the diffuse bearings are those of the information structure, which process noise
    # does not change (a pass with q = 0 finds them; with q > 0 every variance is larger
    # and, for a tiny sigma, all would pass MAX_S)
    if noisy:
        _srif(t, ox, oy, z, w, weighted, lo, hi, nom, none, nu, S0, R, r)
    _srif(t, ox, oy, z, w, weighted, lo, hi, nom, Q, nu, S, R, r)
    for k in range(lo, hi + 1):
        if nu[k] == nu[k] and (S0[k] if noisy else S[k]) <= MAX_S:
            e[i, k] = nu[k]
    if _invert_upper(R, Rinv):
        for c in range(4):
            v = 0.0
            for d in range(c, 4):
                v += Rinv[c, d] * r[d]
            state[i, c] = v
            for d in range(4):
                v = 0.0
                for m in range(max(c, d), 4):
                    v += Rinv[c, m] * Rinv[d, m]
                P_last[i, c, d] = v
    cost[i] = _bearing_cost(ox, oy, z, w, weighted, lo, hi, nom)


@njit(error_model="numpy")
def blank_path(i, path, path_cov):
    """Track i's trajectory and its covariances NaN until written."""
    for k in range(path.shape[1]):
        path[i, k, 0] = path[i, k, 1] = np.nan
    for k in range(path_cov.shape[1]):
        for j in range(3):
            path_cov[i, k, j] = np.nan


@njit(error_model="numpy", depends=(atan2, wrap_angle, start_track, step_noise, finish_track,
                                     smoothed_positions))
def smooth_tracks(t, ox, oy, measured, weight, weighted, first, last, theta, lam, scale2,
                  p0_pos, max_iter, tol_m, state, P_last, e, cost, passes, path, path_cov):
    """Per track i: the NCV MAP trajectory from the constant-velocity ``theta[i]`` with
    lam[i] = q / s^2 (``scale2[i]`` = s^2, rad^2: the noise variance the units refer to;
    ``max_iter`` 0: about the constant-velocity line itself, no iteration), then its
    exactly diffuse square-root information pass (``finish_track``). Writes the state at
    the last bearing (4,) and its covariance in units of s^2 (NaN if singular), the
    innovations over the root of their variance in units of s^2 (``e``, rad: sd s under
    the model; NaN where no bearing and for the diffuse ones), the squared bearing residuals
    of the trajectory (rad^2), the Gauss-Newton passes (-1: a covariance was not positive
    definite) and the trajectory's positions ``path`` (n, K, 2, m; NaN outside the track and
    where the fit failed) with, where ``path_cov`` has epochs, their smoothed covariances
    (``smoothed_positions``)."""
    n, K = measured.shape
    nom = np.empty((K, 4))
    mf, ms, trial = np.empty((K, 4)), np.empty((K, 4)), np.empty((K, 4))
    Pf, Pp = np.empty((K, 4, 4)), np.empty((K, 4, 4))
    nu, S, S0 = np.empty(K), np.empty(K), np.empty(K)
    R, r, Rinv = np.empty((4, 4)), np.empty(4), np.empty((4, 4))
    p0, prior = np.empty(2), np.empty(4)
    Q, none = np.empty((K, 3)), np.zeros((K, 3))  # per step: this track's noise; none
    for i in range(n):
        lo, hi = first[i], last[i]
        z, w = measured[i], (weight[i] if weighted else measured[i])
        start_track(i, t, lo, hi, theta, nom, state, P_last, e)
        cost[i] = np.nan
        blank_path(i, path, path_cov)
        p0[0] = p0_pos[i] * p0_pos[i] / scale2[i]
        p0[1] = PRIOR_SPEED_M_S * PRIOR_SPEED_M_S / scale2[i]
        step_noise(t, lo, hi, lam[i], Q)
        prior[:] = nom[lo]
        made = _fit(t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, max_iter, tol_m,
                    mf, Pf, Pp, nu, S, ms, trial)
        passes[i] = made
        if made < 0:
            continue
        finish_track(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, lam[i] > 0.0, state,
                     P_last, e, cost, nu, S, S0, R, r, Rinv, none)
        smoothed_positions(i, t, ox, oy, z, w, weighted, lo, hi, nom, Q, prior, p0, mf, Pf,
                           Pp, nu, S, path, path_cov)


MAX_PASSES = 30  # Gauss-Newton passes
# the motion fit assumes at least this bearing noise (rad; 1e-3 deg, finer than any bearing
# sensor): with a noiseless log, q / sigma^2 would be numerically infinite
MIN_SIGMA_RAD = float(np.deg2rad(1e-3))
TOL_M = 1e-3  # a pass moving no position by more than this (m) ends the iteration


@dataclass
class MotionFit:
    """What a motion fit returns per track (n,): ``ncv.smooth`` (the NCV MAP state) and
    ``manoeuvres.mixture`` (averaged over the target's manoeuvres).

    ``state`` (n, 4: x, y (m), vx, vy (m/s)) at the last bearing and its covariance ``cov``
    (n, 4, 4); the same as ``theta`` (n, 4: the constant-velocity line through it, x0, y0 at
    t = 0) with ``cov_theta``; ``innovations`` (n, K) normalised by sigma (NaN where none,
    and the diffuse ones); ``sigma2`` (rad^2) used; ``cost_rad2`` (squared bearing residuals
    of the trajectory); ``passes`` (Gauss-Newton passes of the no-manoeuvre fit; -1:
    failed); ``path_m`` (n, K, 2: the most probable trajectory's positions, m; NaN outside the
    track) and, where asked, ``path_cov_m2`` (n, K, 3: their smoothed covariances xx, xy, yy,
    m^2). A mixture's own (None from ``ncv.smooth``): ``p_manoeuvre`` (posterior probability
    of a manoeuvre in the window), ``p_omitted`` (the share of the posterior it leaves out),
    ``n_manoeuvres`` (their posterior mean number), ``tail_scale`` (the factor its
    covariance was widened by) and ``intervals`` (n, 3, 4: range, course, speed now, the
    central intervals holding 68.3 and 95.4 % of the mixture, ``manoeuvres.mixture``)."""

    state: np.ndarray
    cov: np.ndarray
    theta: np.ndarray
    cov_theta: np.ndarray
    innovations: np.ndarray
    sigma2: np.ndarray
    cost_rad2: np.ndarray
    passes: np.ndarray
    path_m: np.ndarray
    path_cov_m2: np.ndarray | None = None
    p_manoeuvre: np.ndarray | None = None
    p_omitted: np.ndarray | None = None
    n_manoeuvres: np.ndarray | None = None
    tail_scale: np.ndarray | None = None
    intervals: np.ndarray | None = None


def theta_of_state(state, P, t_now):
    """theta = (x0, y0, vx, vy) of the straight line through the state (x, y, vx, vy) at
    ``t_now`` (extrapolated back to t = 0: what every ``bearings2d`` output holds), and its
    covariance A P A^T."""
    A = np.broadcast_to(np.eye(4), P.shape).copy()
    A[:, 0, 2] = A[:, 1, 3] = -t_now
    theta = np.einsum("nij,nj->ni", A, state)
    return theta, A @ P @ np.swapaxes(A, 1, 2)


def in_units(out, sigma2, t_now, theta_cv) -> MotionFit:
    """A kernel's ``out`` (a dict; covariance and innovations in units of the noise variance)
    as a ``MotionFit`` in physical units under ``sigma2`` (rad^2, (n,)), with
    ``theta``/``cov_theta`` of the state at ``t_now`` (n,) and NaN for the tracks without a
    constant-velocity start."""
    out["cov"] *= sigma2[:, None, None]
    out["innovations"] = out["innovations"] / np.sqrt(sigma2)[:, None]
    out["theta"], out["cov_theta"] = theta_of_state(out["state"], out["cov"], t_now)
    out["sigma2"] = sigma2
    if "path_cov_m2" in out:
        out["path_cov_m2"] *= sigma2[:, None, None]
    fail = ~np.isfinite(theta_cv).all(axis=1)
    for key in ("state", "cov", "innovations", "theta", "cov_theta", "path_m", "path_cov_m2",
                "intervals"):
        if key in out:
            out[key][fail] = np.nan
    return MotionFit(**out)


def smooth(t, own_x, own_y, measured_rad, valid, first, last, theta_cv, accel_psd, sigma_rad,
           iterate=True, path_cov=False) -> MotionFit:
    """The NCV MAP state at each track's last bearing from the constant-velocity start
    ``theta_cv`` (n, 4), with q = ``accel_psd`` (m^2/s^3, (n,)); ``iterate`` False keeps the
    constant-velocity line itself (only its innovations and covariance are computed).

    ``sigma_rad``: the known bearing noise (n,); NaN where unknown: then sigma^2 is
    estimated from the innovations and the fit repeated with it (twice: q is absolute, so
    q / sigma^2 changes with the estimate; the first pass starts from the residual RMS of
    ``theta_cv``). Returns its ``MotionFit`` (the state and covariance NaN where singular;
    with ``path_cov``, the trajectory's covariances, ``kalman.smoothed_positions``)."""
    n, K = measured_rad.shape
    sigma = np.asarray(sigma_rad, dtype=float)
    known = np.isfinite(sigma)
    weighted = valid is not None
    weight = valid.astype(float) if weighted else np.empty((0, 0))
    start_range = np.hypot(theta_cv[:, 0] + theta_cv[:, 2] * t[first] - own_x[first],
                           theta_cv[:, 1] + theta_cv[:, 3] * t[first] - own_y[first])
    p0_pos = np.maximum(PRIOR_RANGES * np.nan_to_num(start_range, nan=0.0), MIN_PRIOR_M)
    args = (np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(own_x, float),
            np.ascontiguousarray(own_y, float), np.ascontiguousarray(measured_rad, float),
            weight, weighted, np.asarray(first, np.int64), np.asarray(last, np.int64),
            np.ascontiguousarray(np.nan_to_num(theta_cv), float))
    if known.all():
        sigma2, rounds = sigma**2, 1
    else:  # start from the constant-velocity fit's residual RMS
        r = bearing_residuals(np.nan_to_num(theta_cv), t, own_x, own_y, measured_rad, valid)
        count = np.maximum(valid.sum(axis=1) if weighted else K, 5) - 4
        sigma2, rounds = np.where(known, sigma**2, np.einsum("nk,nk->n", r, r) / count), 3
    q = np.broadcast_to(np.asarray(accel_psd, dtype=float), (n,))
    for round_ in range(rounds):
        scale2 = np.maximum(sigma2, MIN_SIGMA_RAD**2)
        out = {"state": np.empty((n, 4)), "cov": np.empty((n, 4, 4)),
               "innovations": np.empty((n, K)), "cost_rad2": np.empty(n),
               "passes": np.zeros(n, dtype=np.int64), "path_m": np.empty((n, K, 2))}
        # the covariances of the trajectory: in the last round only (the others' are not kept)
        covs = np.empty((n, K if path_cov and round_ == rounds - 1 else 0, 3))
        smooth_tracks(*args, q / scale2, scale2, p0_pos, MAX_PASSES if iterate else 0, TOL_M,
                      out["state"], out["cov"], out["innovations"], out["cost_rad2"],
                      out["passes"], out["path_m"], covs)
        if covs.shape[1]:
            out["path_cov_m2"] = covs
        e2 = out["innovations"] ** 2  # rad^2: mean s^2 under the model
        count = np.sum(np.isfinite(e2), axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            estimated = np.nansum(e2, axis=1) / count
        if round_ < rounds - 1:
            sigma2 = np.where(known, sigma2, estimated)
    sigma2 = np.where(known, scale2, np.where(count > 0, estimated, scale2))
    return in_units(out, sigma2, t[last], theta_cv)
