"""The bearings' noise of a track whose sensor declares none, from the bearings alone.

A fit's residuals measure the noise only as far as the fit holds the target's motion: a
manoeuvre the fit leaves out inflates them (on real ship motion seen from two platforms, 2.3
deg for a true 0.5 deg, median over the tracks flagged `manoeuvring`), and the one-sigma
errors with them. Between three successive bearings of one platform the target's motion
barely bends the bearing (a target 5 km away at 5 m/s turns its bearing by about 1e-3
rad/s, which changes by about 1e-6 rad/s^2: 1e-4 rad over 10 s, a fiftieth of 0.5 deg), so
each bearing's departure from the straight line between its neighbours in time,

    r_k = b_k - (w b_{k-1} + (1 - w) b_{k+1}),  w = (t_{k+1} - t_k) / (t_{k+1} - t_{k-1}),

is noise: its variance is sigma^2 (1 + w^2 + (1 - w)^2) for independent errors. The estimate
is the normalised MAD of the r_k / sqrt(1 + w^2 + (1 - w)^2) (a few outliers, an own-ship
turn or a passing target's quick bend move a median little), over each track's bearings of
each platform (bearings of two platforms are never differenced together). It assumes errors
independent from bearing to bearing: a slowly drifting error is not seen (a declared
``sigma_deg`` is then the answer), nor at fewer than ``MIN_TRIPLES`` triples (NaN: the fit's
own estimate is used).
"""

import numpy as np

from tma.maths.angles import wrap_residual

MAD_TO_SIGMA = 1.4826  # the median absolute deviation of a normal sample, in sigma
MIN_TRIPLES = 10  # fewer: no estimate


def _neighbours(mask: np.ndarray):
    """Per cell of ``mask`` (n, K), the column of the previous and of the next True cell in
    its row (-1 where there is none)."""
    n, K = mask.shape
    cols = np.broadcast_to(np.arange(K), (n, K))
    before = np.maximum.accumulate(np.where(mask, cols, -1), axis=1)
    prev = np.concatenate([np.full((n, 1), -1), before[:, :-1]], axis=1)
    after = np.minimum.accumulate(np.where(mask, cols, K)[:, ::-1], axis=1)[:, ::-1]
    nxt = np.concatenate([after[:, 1:], np.full((n, 1), K)], axis=1)
    return prev, np.where(nxt == K, -1, nxt)


def differenced_sigma(t_s, measured_rad, valid, platform=None) -> np.ndarray:
    """Per track (rows of ``measured_rad``, n x K, rad; ``valid`` n x K or None: every one
    present; ``platform`` (K,) each epoch's platform or None: one) the noise sigma (rad)
    from its bearings' departures from the line between their neighbours (module
    docstring); NaN where a track has fewer than ``MIN_TRIPLES`` triples."""
    t = np.asarray(t_s, dtype=float)
    n, K = measured_rad.shape
    present = np.ones((n, K), dtype=bool) if valid is None else np.asarray(valid, bool)
    scaled = np.full((n, K), np.nan)
    for p in [None] if platform is None else np.unique(platform):
        mine = present if p is None else present & (platform == p)[None, :]
        prev, nxt = _neighbours(mine)
        inside = mine & (prev >= 0) & (nxt >= 0)
        rows, k = np.nonzero(inside)
        a, b = prev[rows, k], nxt[rows, k]
        span = t[b] - t[a]
        w = np.where(span > 0, (t[b] - t[k]) / np.where(span > 0, span, 1.0), 0.5)
        line = measured_rad[rows, a] + (1 - w) * wrap_residual(measured_rad[rows, b]
                                                               - measured_rad[rows, a])
        r = wrap_residual(measured_rad[rows, k] - line)
        scaled[rows, k] = np.abs(r) / np.sqrt(1 + w**2 + (1 - w) ** 2)
    count = np.sum(np.isfinite(scaled), axis=1)
    out = np.full(n, np.nan)
    has = count >= MIN_TRIPLES
    if has.any():
        out[has] = MAD_TO_SIGMA * np.nanmedian(scaled[has], axis=1)
    return out
