"""``mpekf``: the modified-polar-coordinates extended Kalman filter (Aidala and Hammel, "Utilization
of modified polar coordinates for bearings-only tracking", IEEE Trans. Automatic Control 28(3),
1983), recursive over the bearings, reported at each track's last bearing.

State y = (beta_dot, r_dot / r, beta, 1 / r): bearing rate (rad/s), range rate over range
(1/s), bearing (rad, clockwise from north) and inverse range (1/m) of the target relative to
own-ship. The bearing is a state, so the measurement is linear (H = [0, 0, 1, 0]); the
range, unobservable until own-ship manoeuvres, sits alone in 1 / r and cannot corrupt the
other three (the point of MPC).

Relative velocity: the log has own-ship positions only, so the velocity in the state is the
target's velocity minus u_k, own-ship's mean velocity over the next sampling interval,
(o_{k+1} - o_k) / (t_{k+1} - t_k) (the last epoch keeps the previous interval's). With a
constant-velocity target the relative position then moves exactly by w_k T and the velocity
changes by u_k - u_{k+1}: in the Cartesian coordinates divided by the range r_k,

    s = (w / r_k, d / r_k) = (y2 sin y3 + y1 cos y3, y2 cos y3 - y1 sin y3, sin y3, cos y3)
    s_v' = s_v + y4 (u_k - u_{k+1}),   s_p' = s_p + T s_v

and back to MPC (``mpc_transition``), which is exact for any own-ship path (Aidala and
Hammel's transition; no process noise: the target does not manoeuvre).

Initialisation at each track's first bearing X: beta = X (variance sigma^2), inverse range
1 / ``initial_range_m`` with standard deviation ``initial_range_sd_m`` / ``initial_range_m``^2,
target velocity 0 with ``initial_speed_sd_m_s`` per axis, mapped to MPC by the Jacobian of
the conversion. The filter assumes the bearing noise ``sigma_deg`` (null: the log's nominal
noise), at least ``min_sigma_deg``. With ``gate_sigmas`` set, a bearing whose innovation
exceeds that many standard deviations of its predicted spread, sqrt(P_beta + sigma^2), is
skipped (counted in ``n_gated``): the usual defence of a filter against outliers; after
``gate_reset`` bearings skipped in a row the track is taken as lost (or started on an outlier)
and the filter starts again at the current bearing.

Two passes (``passes``): the second starts its prior (the same spreads) about the first's
answer instead of a target at rest at ``initial_range_m``, which shortens the early
linearisation lag (Ref1 at sigma 0.5 deg: 66 -> 69 %).

Output: theta = (x0, y0, vx, vy) at the dataset's t = 0 from the state at the track's last
bearing. Its covariance is not the filter's G P G^T (G the Jacobian of the conversion):
that covered the actual error on only 72-87 % of the tracks (the chi-square(4) 95 % point;
the filter lags where it linearised early), so the covariance reported is the batch one at
the filter's estimate plus its distance from the batch optimum (``consistent_information``:
95 %). The common columns hold it as an information matrix, ``jtj`` = sigma_f^2 C^-1,
sigma_f the noise the filter assumed, so that the covariance every bearings2d output
carries, (J^T J)^-1 sigma^2 with the log's sigma, is C when the filter assumed the log's
noise (the default). ``converged`` is False (status ``not_converged``) where the filter
ended with a non-finite state, a covariance that is not positive definite or a non-positive
inverse range. On a log whose targets are not known to hold course and speed the status is
``approximate``: the filter has no process noise.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param
from tma.errors import InputError
from tma.families.bearings2d.contract import Bearings, Solution, TargetMotion
from tma.families.bearings2d.estimators.base import (
    BearingsConfig,
    BearingsEstimator,
    evaluate_in_blocks,
)
from tma.families.bearings2d.model import BearingTerms, wrap_residual
from tma.maths.linalg import scaled_inverse

SINGULAR_RCOND = 1e-14  # J^T J with a smaller scaled eigenvalue ratio: no covariance


@dataclass
class Config(BearingsConfig):
    initial_range_m: float = param(15000.0, "prior range at the first bearing (m)", "(0, 1e9)")
    initial_range_sd_m: float = param(10000.0, "its standard deviation (m; as one of 1 / range)",
                                      "(0, 1e9)")
    initial_speed_sd_m_s: float = param(10.0, "prior target velocity 0 with this standard "
                                        "deviation per axis (m/s)", "(0, 1e4)")
    sigma_deg: float | None = param(None, "bearing noise the filter assumes (deg); null: the "
                                    "log's", "[0, 90)")
    min_sigma_deg: float = param(0.001, "the assumed noise is at least this (deg; a noiseless "
                                 "log)", "(0, 90)")
    gate_sigmas: float | None = param(None, "skip a bearing whose innovation exceeds this many "
                                      "standard deviations; null: no gate", "(0, 1e6)")
    gate_reset: int = param(5, "this many bearings skipped in a row restart the filter (with a "
                            "gate)", "[1, 1e9]")
    passes: int = param(2, "filter passes; each after the first starts its prior about the "
                        "last answer", "[1, 10]")


def reference_velocity(t, own_x, own_y):
    """u_k (K, 2): own-ship's mean velocity over [t_k, t_{k+1}], the last epoch the previous
    interval's (a single epoch: 0)."""
    if t.size < 2:
        return np.zeros((t.size, 2))
    u = np.column_stack([np.diff(own_x), np.diff(own_y)]) / np.diff(t)[:, None]
    return np.vstack([u, u[-1:]])


def scaled_cartesian(y):
    """s = (w_x, w_y, d_x, d_y) / r (n, 4) of MPC states y (n, 4) and ds/dy (n, 4, 4)."""
    y1, y2, beta = y[:, 0], y[:, 1], y[:, 2]
    c, s = np.cos(beta), np.sin(beta)
    s1, s2 = y2 * s + y1 * c, y2 * c - y1 * s
    zero = np.zeros_like(c)
    D = np.stack([np.stack([c, s, s2, zero], -1), np.stack([-s, c, -s1, zero], -1),
                  np.stack([zero, zero, c, zero], -1), np.stack([zero, zero, -s, zero], -1)],
                 axis=1)
    return np.column_stack([s1, s2, s, c]), D


def mpc_transition(y, T, du):
    """MPC state after T seconds (n, 4) and its Jacobian dy'/dy (n, 4, 4). ``du`` (2,):
    u_k - u_{k+1}, the change of the reference own-ship velocity (module docstring)."""
    s, Ds = scaled_cartesian(y)
    y4 = y[:, 3]
    s1, s2 = s[:, 0] + y4 * du[0], s[:, 1] + y4 * du[1]
    s3, s4 = s[:, 2] + T * s[:, 0], s[:, 3] + T * s[:, 1]
    # d(s1', s2', s3', s4')/dy: the linear map of s plus the y4 column of the own-ship term
    L = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [T, 0, 1, 0], [0, T, 0, 1]], dtype=float)
    Dz = L @ Ds
    Dz[:, 0, 3] += du[0]
    Dz[:, 1, 3] += du[1]
    q = s3 * s3 + s4 * s4
    y1n, y2n = (s1 * s4 - s2 * s3) / q, (s1 * s3 + s2 * s4) / q
    root = np.sqrt(q)
    y_new = np.column_stack([y1n, y2n, np.arctan2(s3, s4), y4 / root])
    zero = np.zeros_like(q)
    # d(y')/d(s1', s2', s3', s4'); y4' = y4 / sqrt(q) also depends on y4 directly
    Dphi = np.stack([
        np.stack([s4, -s3, -s2 - 2 * y1n * s3, s1 - 2 * y1n * s4], -1) / q[:, None],
        np.stack([s3, s4, s1 - 2 * y2n * s3, s2 - 2 * y2n * s4], -1) / q[:, None],
        np.stack([zero, zero, s4, -s3], -1) / q[:, None],
        np.stack([zero, zero, -y4 * s3, -y4 * s4], -1) / (q * root)[:, None],
    ], axis=1)
    F = Dphi @ Dz
    F[:, 3, 3] += 1.0 / root
    return y_new, F


def mpc_from_relative(d, w):
    """MPC states (n, 4) of relative positions d and velocities w (n, 2 each: target minus
    own-ship reference, m and m/s)."""
    r2 = np.einsum("ni,ni->n", d, d)
    return np.column_stack([(w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / r2,
                            np.einsum("ni,ni->n", d, w) / r2,
                            np.arctan2(d[:, 0], d[:, 1]), 1.0 / np.sqrt(r2)])


def initial_state(bearing, u, cfg, sigma_rad, prior=None):
    """Mean (n, 4) and covariance (n, 4, 4) at the first bearing (module docstring).
    ``prior``: (range (m), target vx, vy (m/s)) per track, (n, 3), to centre the prior on
    instead of ``initial_range_m`` and a target at rest (the same spreads); a NaN row, or
    None, takes those."""
    prior = np.full((bearing.size, 3), np.nan) if prior is None else prior
    fresh = ~np.isfinite(prior).all(axis=1)
    rho = np.where(fresh, 1.0 / cfg.initial_range_m, 1.0 / np.where(fresh, 1.0, prior[:, 0]))
    vx, vy = np.where(fresh, 0.0, prior[:, 1]), np.where(fresh, 0.0, prior[:, 2])
    rho_sd = rho * (cfg.initial_range_sd_m / cfg.initial_range_m)  # 1 / r's relative spread
    wx, wy = vx - u[:, 0], vy - u[:, 1]  # target velocity minus own-ship's
    c, s = np.cos(bearing), np.sin(bearing)
    mean = np.column_stack([rho * (wx * c - wy * s), rho * (wx * s + wy * c), bearing, rho])
    zero, one = np.zeros_like(c), np.ones_like(c)
    # d(y)/d(wx, wy, beta, rho)
    A = np.stack([
        np.stack([rho * c, -rho * s, -rho * (wx * s + wy * c), wx * c - wy * s], -1),
        np.stack([rho * s, rho * c, rho * (wx * c - wy * s), wx * s + wy * c], -1),
        np.stack([zero, zero, one, zero], -1),
        np.stack([zero, zero, zero, one], -1),
    ], axis=1)
    var = np.column_stack([np.full_like(c, cfg.initial_speed_sd_m_s**2),
                           np.full_like(c, cfg.initial_speed_sd_m_s**2),
                           np.full_like(c, sigma_rad**2), rho_sd**2])
    return mean, np.einsum("nij,nj,nkj->nik", A, var, A)


def theta_from_mpc(y, t, own, u):
    """theta = (x0, y0, vx, vy) at t = 0 (n, 4) of the MPC states y (n, 4) at times t (n,)
    with own-ship positions ``own`` and reference velocities ``u`` (n, 2 each), and
    d theta / dy (n, 4, 4)."""
    s, Ds = scaled_cartesian(y)
    r = 1.0 / y[:, 3]
    pos = own + r[:, None] * s[:, 2:]
    vel = u + r[:, None] * s[:, :2]
    # d(px, py, vx, vy)/dy: r ds/dy plus the column of r = 1 / y4 (dr/dy4 = -r^2)
    D = r[:, None, None] * np.concatenate([Ds[:, 2:], Ds[:, :2]], axis=1)
    D[:, :, 3] = -(r**2)[:, None] * np.concatenate([s[:, 2:], s[:, :2]], axis=1)
    theta = np.column_stack([pos - vel * t[:, None], vel])
    D[:, :2] -= t[:, None, None] * D[:, 2:]  # x0 = px - t vx, y0 = py - t vy
    return theta, D


def run_filter(t, own_x, own_y, measured_rad, valid, first, last, cfg, sigma_rad, prior=None):
    """The MPC EKF over every epoch, all tracks at once; each track starts at its first
    bearing (from ``prior``, see ``initial_state``, when given) and its state is kept at its
    last. Returns y and P there ((n, 4), (n, 4, 4))."""
    n, K = measured_rad.shape
    u = reference_velocity(t, own_x, own_y)
    y, P = np.full((n, 4), np.nan), np.full((n, 4, 4), np.nan)
    y_last, P_last = y.copy(), P.copy()
    gated = np.zeros(n, dtype=np.int64)
    run = np.zeros(n, dtype=np.int64)  # consecutive bearings skipped by the gate
    R = sigma_rad**2
    for k in range(K):
        start = first == k
        if k > 0:
            live = first < k
            if live.any():
                y[live], F = mpc_transition(y[live], t[k] - t[k - 1], u[k - 1] - u[k])
                P[live] = F @ P[live] @ F.transpose(0, 2, 1)
            update = live & (valid[:, k] if valid is not None else True)
            if cfg.gate_sigmas is not None and update.any():
                innovation = wrap_residual(measured_rad[:, k] - y[:, 2])
                with np.errstate(invalid="ignore"):
                    inside = innovation**2 <= cfg.gate_sigmas**2 * (P[:, 2, 2] + R)
                skipped = update & ~inside
                gated += skipped
                run = np.where(skipped, run + 1, np.where(update, 0, run))
                restart = run >= cfg.gate_reset  # lost (or started on an outlier): again
                start |= restart
                run[restart] = 0
                update &= inside
            if update.any():
                Pu = P[update]
                gain = Pu[:, :, 2] / (Pu[:, 2, 2] + R)[:, None]
                innovation = wrap_residual(measured_rad[update, k] - y[update, 2])
                y[update] += gain * innovation[:, None]
                IKH = np.broadcast_to(np.eye(4), Pu.shape).copy()
                # Joseph form: (I - K H) P (I - K H)^T + K R K^T, H the bearing component
                # e_2 (a column of P, not a product: imm's matrix update would cost more)
                IKH[:, :, 2] -= gain
                P[update] = (IKH @ Pu @ IKH.transpose(0, 2, 1)
                             + R * gain[:, :, None] * gain[:, None, :])
        if start.any():  # a gate's restart starts afresh, without the prior
            at = None if prior is None else np.where((first[start] == k)[:, None],
                                                     prior[start], np.nan)
            y[start], P[start] = initial_state(measured_rad[start, k],
                                               np.broadcast_to(u[k], (start.sum(), 2)),
                                               cfg, sigma_rad, at)
        end = last == k
        y_last[end], P_last[end] = y[end], P[end]
    return y_last, P_last, u, gated


def consistent_information(t, own_x, own_y, measured_rad, valid, theta, sigma_rad):
    """``jtj`` for the filter's ``theta`` (n, 4), and F(theta) (rad^2): sigma^2 C^-1 with
    C = (J^T J)^-1 sigma^2 + d d^T, d = (J^T J)^-1 J^T r the Gauss-Newton step from theta
    (J = d bearing / d theta and r = measured - predicted at theta): the batch covariance of
    the bearings plus the filter's distance from the batch optimum (the lag of its early
    linearisations), so that C covers its actual error (measured: 94.7-95.1 % of tracks
    inside the chi-square(4) 95 % point at sigma 0.1-1 deg, against 72-87 % for the
    filter's own covariance). By Sherman-Morrison,
    sigma^2 C^-1 = H - (H u)(H u)^T / (1 + u^T H u), H = J^T J, u = d / sigma. NaN where
    J^T J is singular or theta is not finite."""
    finite = np.isfinite(theta).all(axis=1)
    cost, H, g = evaluate_in_blocks(BearingTerms(t, own_x, own_y, measured_rad, valid),
                                    np.where(finite[:, None], theta, 0.0))
    inverse, singular = scaled_inverse(np.where(finite[:, None, None], H, np.nan),
                                       SINGULAR_RCOND)
    u = np.einsum("nij,nj->ni", inverse, g) / sigma_rad
    Hu = np.einsum("nij,nj->ni", H, u)
    info = H - np.einsum("ni,nj->nij", Hu, Hu) / (1.0 + np.einsum("ni,ni->n", u, Hu))[:, None,
                                                                                      None]
    bad = singular | ~finite
    info[bad] = np.nan
    cost[~finite] = np.nan
    return info, cost


class ModifiedPolarEKF(BearingsEstimator):
    Config = Config
    outputs = ("n_gated",)  # bearings the innovation gate skipped (0 without a gate)
    several_platforms = False  # its relative-state model moves with one own-ship

    def solve(self, bearings: Bearings, motion: TargetMotion) -> Solution:
        t, own_x, own_y, measured_rad, valid, first = (
            bearings.t, bearings.own_x, bearings.own_y, bearings.measured, bearings.valid,
            bearings.first)
        sigma = self.config.sigma_deg if self.config.sigma_deg is not None else bearings.sigma_deg
        if sigma is None:
            raise InputError("mpekf: the log declares no bearing noise; give the noise the "
                             "filter should assume with estimator.sigma_deg=<deg>")
        sigma_rad = np.deg2rad(max(sigma, self.config.min_sigma_deg))
        n = measured_rad.shape[0]
        present = np.ones(measured_rad.shape, dtype=bool) if valid is None else valid
        last = present.shape[1] - 1 - np.argmax(present[:, ::-1], axis=1)
        own_last = np.column_stack([own_x[last], own_y[last]])
        prior = None
        for _ in range(self.config.passes):
            y, P, u, gated = run_filter(t, own_x, own_y, measured_rad, valid, first, last,
                                        self.config, sigma_rad, prior)
            with np.errstate(divide="ignore", invalid="ignore"):
                theta, G = theta_from_mpc(y, t[last], own_last, u[last])
                cov = G @ P @ G.transpose(0, 2, 1)
            prior = np.column_stack([  # the next pass starts about this one's answer
                np.hypot(theta[:, 0] + theta[:, 2] * t[first] - own_x[first],
                         theta[:, 1] + theta[:, 3] * t[first] - own_y[first]),
                theta[:, 2], theta[:, 3]])
        good = np.isfinite(theta).all(axis=1) & np.isfinite(cov).all(axis=(1, 2)) & (y[:, 3] > 0)
        theta[~good] = np.nan
        info, cost = consistent_information(t, own_x, own_y, measured_rad, valid, theta,
                                            sigma_rad)
        good &= np.isfinite(info).all(axis=(1, 2))
        info[~good] = np.nan
        theta[~good] = np.nan
        return Solution(theta=theta, converged=good,
                        stop_reason=np.where(good, 0, -1).astype(np.int64),
                        n_f_evals=np.full(n, np.nan), n_iter=np.full(n, np.nan),
                        cost_rad2=cost, jtj=info, columns={"n_gated": gated})
