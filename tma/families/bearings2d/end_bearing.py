"""What a log's own bearings say the bearing is at each track's last bearing time, whatever an
estimator answers: the reference of ``status.not_an_answer``'s rule that no answer may put the
target where the last bearings do not point (a fit run to the mirror side of own-ship, say).

Per track, the last ``END_BEARINGS`` bearings (all of them when a track has fewer), unwrapped
about its last bearing, are fitted by a straight line in time, first by Theil-Sen (the median
of the pairwise slopes: one or two outliers among them do not move it), then by least squares
on the bearings within ``GROSS_SIGMAS`` of that line; the line at the last bearing time is the
estimate. Its one-sigma error is the least-squares one, s sqrt(h), with h the leverage of the
last time (about 4 / m for m bearings evenly spaced) and s the larger of the noise sigma the
estimate used and the line's own residual scale (a bearing that bends within the window, own
ship turning or a near target passing, widens it by its misfit), at least
``status.NOISELESS_RMS_DEG``.

Why the last 10 bearings: the estimate must rest on the bearings at the end alone (a target's
earlier manoeuvre, or own-ship's, bends those before), on enough of them that an outlier does
not decide it (Theil-Sen breaks down at 29 % outliers: 2 of 10) and that its error is well
below the noise (0.6 sigma), and on few enough that the bearing's curvature over them stays
small beside the noise at the usual rates of a bearing every 1 s to 1 min; where it does not,
the misfit widens the error instead of biasing the rule.
"""

import numpy as np

from tma.families.bearings2d.status import NOISELESS_RMS_DEG
from tma.maths.angles import wrap_residual

END_BEARINGS = 10  # bearings of the window at each track's end
GROSS_SIGMAS = 5.0  # a bearing this many sigma off the Theil-Sen line is an outlier
MAD_TO_SIGMA = 1.4826  # the median absolute deviation of a normal sample, in sigma
FLOOR_RAD = float(np.deg2rad(NOISELESS_RMS_DEG))  # round-off: the least scale of an error


def window(valid, n_window=END_BEARINGS):
    """Indices ``(n, n_window)`` of each track's last ``n_window`` present bearings, in time
    order, and whether each is one (False where a track has fewer)."""
    counts = np.cumsum(valid, axis=1, dtype=np.int32)
    kept = valid & (counts[:, -1:] - counts < n_window)  # fewer than n_window after it
    idx = np.argsort(~kept, axis=1, kind="stable")[:, :n_window]  # the kept ones, in order
    return idx, np.take_along_axis(kept, idx, axis=1)


def end_bearing(t_s, measured_rad, valid, last, sigma_rad, n_window=END_BEARINGS,
                floor_rad=FLOOR_RAD, at_s=None) -> dict:
    """Per track the bearing at its last bearing time from its last ``n_window`` bearings
    (module docstring): ``end_bearing_deg`` in [0, 360) and its one-sigma error
    ``end_bearing_sd_deg``. ``measured_rad`` (n, K), ``valid`` (n, K; None: every bearing
    present), ``last`` (n,) each track's last bearing, ``sigma_rad`` (n,) the noise sigma the
    estimate used (NaN: none), ``floor_rad`` the least scale of the error (round-off),
    ``at_s`` (n,, s) when the line is read elsewhere than at the last bearing's time (one
    platform's bearings of a track that others saw later: at the track's last bearing)."""
    n, K = measured_rad.shape
    if valid is None:  # every bearing present: the last n_window columns
        idx = np.broadcast_to(np.arange(K - n_window, K), (n, n_window))
        idx, m = np.maximum(idx, 0), idx >= 0
    else:
        idx, m = window(valid, n_window)
    rows = np.arange(n)[:, None]
    at = t_s[last] if at_s is None else np.asarray(at_s, dtype=float)
    tau = np.where(m, t_s[idx] - at[:, None], 0.0)  # s, <= 0
    y = np.where(m, wrap_residual(measured_rad[rows, idx] - measured_rad[rows, last[:, None]]), 0.0)
    sigma = np.nan_to_num(np.asarray(sigma_rad, dtype=float), nan=0.0)

    # Theil-Sen: the median of the slopes of every pair of bearings at different times
    dt = tau[:, None, :] - tau[:, :, None]
    pair = m[:, None, :] & m[:, :, None] & (dt > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        slopes = np.where(pair, (y[:, None, :] - y[:, :, None]) / dt, np.nan).reshape(n, -1)
    slope = np.zeros(n)
    has = pair.any(axis=(1, 2))
    slope[has] = np.nanmedian(slopes[has], axis=1)
    offset = np.nanmedian(np.where(m, y - slope[:, None] * tau, np.nan), axis=1)
    r = np.abs(y - offset[:, None] - slope[:, None] * tau)
    spread = MAD_TO_SIGMA * np.nanmedian(np.where(m, r, np.nan), axis=1)
    inlier = m & (r <= GROSS_SIGMAS * np.fmax(np.fmax(sigma, spread), floor_rad)[:, None])

    # least squares on the inliers: the line's value at tau = 0 and its leverage there
    w = inlier.astype(float)
    s0, s1, s2 = w.sum(axis=1), (w * tau).sum(axis=1), (w * tau * tau).sum(axis=1)
    sy, sty = (w * y).sum(axis=1), (w * tau * y).sum(axis=1)
    det = s0 * s2 - s1 * s1
    line = det > 1e-9 * np.maximum(s0 * s2, 1e-300)  # two distinct times at least
    with np.errstate(divide="ignore", invalid="ignore"):
        at_end = np.where(line, (s2 * sy - s1 * sty) / det, sy / s0)
        rate = np.where(line, (s0 * sty - s1 * sy) / det, 0.0)
        leverage = np.where(line, s2 / det, 1.0 / s0)
        misfit = (w * (y - at_end[:, None] - rate[:, None] * tau) ** 2).sum(axis=1)
        dof = s0 - np.where(line, 2, 1)
        scale = np.where(dof > 0, np.sqrt(misfit / dof), 0.0)
    sd = np.fmax(np.fmax(sigma, scale), floor_rad) * np.sqrt(leverage)
    bearing = np.rad2deg(measured_rad[np.arange(n), last] + at_end) % 360.0
    return {"end_bearing_deg": bearing, "end_bearing_sd_deg": np.rad2deg(sd)}
