"""How far to trust a bearings-only fit: per track a ``status`` and one-sigma errors.

The covariance of theta = (x0, y0, vx, vy) is the Gauss-Newton one, (J^T J)^-1 sigma^2, with
sigma the nominal bearing noise when the log declares it, else the residual estimate
sigma^2 = F / (n - 4); for a nearly-constant-velocity fit (``ncv``) it is the smoother's at
the last bearing, which adds the target's own motion. It is propagated to range, bearing,
course and speed at each track's last bearing ("now") by their Jacobians (delta method).
``status``, first rule that applies:

- ``not_converged``: the estimator stopped for any reason other than its F tolerance;
- ``manoeuvring``: the residual sequence has a slow systematic pattern that its noise does
  not explain: the target did not move as the motion model says (a manoeuvre; or the
  own-ship navigation or the bearing bias drifted). ``trend_test_p`` on the model's
  normalised innovations (recursive residuals) rejects at ``motion_alpha``; run where the
  log does not declare its targets' motion (a recording) or sigma, or with
  ``motion_test=on``;
- ``poor_fit``: the residuals do not look like the declared noise: with sigma known
  (> 0), F / sigma^2 (for an NCV fit, the sum of its squared normalised innovations) fails
  a two-sided chi-square test at level ``fit_alpha``: too large (outliers, a sigma
  understated, some bearings in radians) or far too small (every bearing in radians, an
  overstated sigma); for a robust fit (``lm`` loss huber|cauchy), ``robust_fit_p``: the
  same two-sided test on the bearings within c sigma only, referred to the truncated
  normal, so that outliers alone do not fail it (measured: 5.5-7 % rejected at level 0.05
  with and without 5 % outliers); with sigma declared 0 (noiseless), a residual RMS above
  ``NOISELESS_RMS_DEG``; with sigma unknown there is no noise to test against (for a
  robust fit, the Wald-Wolfowitz runs test on the residual signs);
- ``unobservable``: J^T J is numerically singular (scaled by its diagonal, smallest over
  largest eigenvalue <= ``singular_rcond``), or range_sd / range > ``max_range_rel_sd``
  (range is not determined well enough to use: no own-ship manoeuvre, a target too far
  away, too much unmodelled target motion), or the trend test was due but too few bearings
  remain to run it (the motion cannot be checked); with range, the velocity is not
  determined: every output leaves its course and speed blank (``HEADING_UNDETERMINED``);
- ``approximate``: the fit passed every test, but its one-sigma errors are not honest by
  construction: the estimator is biased (``nbearings``), or it assumes a constant-velocity
  target where the log's targets are not known to move so (``accel_psd`` > 0);
- ``position_only``: for a target that may wander or manoeuvre (the log declares so, or a
  recording), the bearings fix its position now but not where it is heading: the course
  sd exceeds ``max_course_sd_deg`` or the speed sd ``max_speed_rel_sd`` of the speed (a
  manoeuvre too recent for the bearings to show where it led). Its position now (range,
  bearing, x/y, lat/lon) and their errors can be used; its course and speed are no answer,
  and every output leaves them blank (``HEADING_UNDETERMINED``). A target declared at
  constant velocity (the paper's tables) has held its course all along: its course and
  speed errors are honest however wide, and stay ``ok``;
- ``ok`` otherwise: the estimate and its one-sigma errors can be used; for a target that may
  wander or manoeuvre, its course sd is at most ``max_course_sd_deg`` and its speed sd at
  most ``max_speed_rel_sd`` of its speed.

The ``_sd`` columns are blank only where J^T J is singular (no uncertainty can be given),
which is never an ``ok`` track.
"""

import math

import numpy as np

from tma.maths.angles import bearing_from_north, course_from_velocity, wrap_to_180
from tma.maths.linalg import scaled_inverse
from tma.runtime.jit import njit

# scipy.special (the chi-square and normal tails) is imported by the functions that use it:
# every command imports this module (with the estimators, to register their defaults), few
# compute a status

# (in the order of the tables' columns; the rules' order is in the module docstring)
STATUSES = ("ok", "not_converged", "poor_fit", "unobservable", "manoeuvring", "approximate",
            "position_only")
# the statuses whose course and speed are no answer: every output leaves them blank (an
# unobservable answer's range is not determined, and with it neither is its velocity: its
# linearised course error can read 2 deg where the course is 120 deg off)
HEADING_UNDETERMINED = ("position_only", "unobservable")


def heading_undetermined(status) -> np.ndarray:
    """Per track whether its ``status`` says where it is heading is not determined
    (``HEADING_UNDETERMINED``): its course and speed are blank in every output."""
    return np.isin(np.asarray(status, dtype=str), HEADING_UNDETERMINED)
NOISELESS_RMS_DEG = 1e-4  # far above round-off, far below any real bearing sensor


def kinematics_now(theta, t_s, own_x_m, own_y_m, jacobian=True):
    """Range (m), bearing (rad), course (rad), speed (m/s) at times ``t_s`` from own-ship,
    and their Jacobian with respect to theta, ``(n, 4, 4)`` (rows in that order; None when
    not ``jacobian``)."""
    x0, y0, vx, vy = theta.T
    dx, dy = x0 + vx * t_s - own_x_m, y0 + vy * t_s - own_y_m
    rng, speed = np.hypot(dx, dy), np.hypot(vx, vy)
    now = (rng, bearing_from_north(dx, dy), course_from_velocity(vx, vy), speed)
    if not jacobian:
        return now, None
    with np.errstate(divide="ignore", invalid="ignore"):
        G = np.zeros((theta.shape[0], 4, 4))
        G[:, 0, :2] = np.column_stack([dx, dy]) / rng[:, None]
        G[:, 1, :2] = np.column_stack([dy, -dx]) / (rng**2)[:, None]
        G[:, :2, 2:] = G[:, :2, :2] * t_s[:, None, None]  # position now = p0 + v t
        G[:, 2, 2:] = np.column_stack([vy, -vx]) / (speed**2)[:, None]
        G[:, 3, 2:] = np.column_stack([vx, vy]) / speed[:, None]
    return now, G


def runs_test_p(residuals, valid):
    """Two-sided p-value of the Wald-Wolfowitz runs test on the signs of each row's valid
    residuals (normal approximation; exact when every sign is the same)."""
    from scipy.special import ndtr

    n_rows, K = residuals.shape
    valid = np.ones_like(residuals, dtype=bool) if valid is None else valid
    positive = residuals > 0
    index = np.where(valid, np.arange(K), -1)
    previous = np.maximum.accumulate(index, axis=1)  # last valid index <= k
    previous = np.concatenate([np.full((n_rows, 1), -1), previous[:, :-1]], axis=1)
    prev_sign = np.take_along_axis(positive, np.maximum(previous, 0), axis=1)
    runs = 1 + np.sum(valid & (previous >= 0) & (positive != prev_sign), axis=1)
    n1 = np.sum(valid & positive, axis=1).astype(float)
    n2 = np.sum(valid & ~positive, axis=1).astype(float)
    n = n1 + n2
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = 1 + 2 * n1 * n2 / n
        var = 2 * n1 * n2 * (2 * n1 * n2 - n) / (n * n * (n - 1))
        p = 2 * ndtr(-np.abs(runs - mean) / np.sqrt(var))
    one_sign = (n1 == 0) | (n2 == 0)
    return np.where(one_sign, np.minimum(1.0, 2 * 0.5**n), p)


@njit(error_model="numpy")
def _trend_sums(e, t, m_max, out):
    """Per row of ``e`` (n, K; NaN where absent): the squares of e explained by the first
    m cosines cos(pi j u), u = (t - t_first) / (t_last - t_first), over its present entries
    (least squares), m = min(``m_max``, count // 3) so that a short sequence is still
    tested, the sum of squares, the count and m, into ``out`` (n, 4)."""
    n, K = e.shape
    G, b, L, y, c = (np.empty((m_max, m_max)), np.empty(m_max), np.empty((m_max, m_max)),
                     np.empty(m_max), np.empty(m_max))
    for i in range(n):
        lo, hi, count, total = -1, -1, 0, 0.0
        for k in range(K):
            if e[i, k] == e[i, k]:
                if lo < 0:
                    lo = k
                hi = k
                count += 1
                total += e[i, k] * e[i, k]
        m = min(m_max, count // 3)
        out[i, 1], out[i, 2], out[i, 3] = total, count, m
        if m < 1 or t[hi] <= t[lo]:
            out[i, 0] = np.nan
            continue
        for j in range(m):
            b[j] = 0.0
            for l in range(m):
                G[j, l] = 0.0
        span = t[hi] - t[lo]
        for k in range(lo, hi + 1):
            if e[i, k] == e[i, k]:
                u = math.pi * (t[k] - t[lo]) / span
                for j in range(m):
                    c[j] = math.cos(j * u)
                for j in range(m):
                    b[j] += c[j] * e[i, k]
                    for l in range(j + 1):
                        G[j, l] += c[j] * c[l]
        singular = False  # Cholesky of G (lower triangle), then G^-1 b
        for j in range(m):
            for l in range(j + 1):
                s = G[j, l]
                for r in range(l):
                    s -= L[j, r] * L[l, r]
                if j == l:
                    if not s > 1e-12 * G[j, j]:
                        singular = True
                        break
                    L[j, j] = math.sqrt(s)
                else:
                    L[j, l] = s / L[l, l]
            if singular:
                break
        if singular:
            out[i, 0] = np.nan
            continue
        explained = 0.0
        for j in range(m):
            s = b[j]
            for r in range(j):
                s -= L[j, r] * y[r]
            y[j] = s / L[j, j]
            explained += y[j] * y[j]
        out[i, 0] = explained


def trend_test_p(innovations, t_s, terms):
    """p-value of the smooth-trend test on each row of normalised innovations (n, K) (NaN
    where none): the generalised likelihood ratio of a bias made of the first m cosines in
    time (a constant, a drift, a bend...; m = ``terms``, fewer for a sequence shorter than
    3 m) against none, in its F form, F = (S_b / m) / ((S - S_b) / (N - m)) ~ F(m, N - m)
    with S the sum of squares, S_b the part the cosines explain and N the innovations:
    scale-free, so it asks only whether the residual sequence has a systematic slow pattern,
    whatever the noise level (that is the chi-square's question), and an isolated outlier,
    spread over all frequencies, hardly moves it. NaN where fewer than 3 innovations."""
    from scipy.special import fdtrc

    e = np.ascontiguousarray(innovations, dtype=float)
    sums = np.empty((e.shape[0], 4))
    _trend_sums(e, np.ascontiguousarray(t_s, dtype=float), int(terms), sums)
    explained, total, count, m = sums.T
    with np.errstate(divide="ignore", invalid="ignore"):
        F = (explained / m) / (np.maximum(total - explained, 0.0) / (count - m))
        return np.where(np.isfinite(explained), fdtrc(m, count - m, F), np.nan)


def truncated_moments(c):
    """Mean and variance of Z^2 for Z ~ N(0, 1) given |Z| <= c, and P(|Z| <= c)."""
    from scipy.special import ndtr

    p = 2 * ndtr(c) - 1
    phi = np.exp(-0.5 * c * c) / np.sqrt(2 * np.pi)
    m1 = (p - 2 * c * phi) / p
    m2 = (3 * p - 2 * phi * (c**3 + 3 * c)) / p
    return m1, m2 - m1 * m1, p


def robust_fit_p(residuals, valid, sigma_rad, c):
    """Two-sided p-value of the fit of a robust estimate, from the bearings it did not
    down-weight: u = r / sigma (nominal noise) with |u| <= c. Given their number m, under
    the declared noise their u are m draws of a normal truncated to [-c, c] (an outlier
    lands there with probability ~ 2 c sigma / 2 pi, negligible), so T = sum u^2 has the
    mean and variance of ``truncated_moments`` times m; T is referred to the scaled
    chi-square a chi2(nu) with those moments (nu reduced by the 4 fitted parameters). So
    outliers do not fail the test, while a misfit of the kept bearings (a manoeuvre, a wrong
    sigma) still does. A fit keeping fewer than half the bearings has p = 0."""
    u = residuals / sigma_rad
    inlier = np.abs(u) <= c
    if valid is not None:
        inlier &= valid
    n = residuals.shape[1] if valid is None else valid.sum(axis=1)
    m = inlier.sum(axis=1)
    T = np.sum(np.where(inlier, u * u, 0.0), axis=1)
    m1, v, _ = truncated_moments(c)
    a = v / (2 * m1)
    nu = np.maximum(2 * m1 * m1 / v * (m - 4), 1.0)
    return np.where(2 * m >= n, two_sided_chi2_p(nu, T / a), 0.0)


def two_sided_chi2_p(dof, statistic):
    """p-value of the two-sided chi-square(``dof``) test of ``statistic``: too small a sum of
    squares fails it as too large a one does (an overstated sigma, as an understated)."""
    from scipy.special import chdtrc

    upper = chdtrc(dof, statistic)
    return np.minimum(1.0, 2 * np.minimum(upper, 1 - upper))


def noiseless_fit_p(cost_rad2, n_bearings):
    """The fit test of a declared noiseless sensor: anything beyond round-off (an RMS
    residual above ``NOISELESS_RMS_DEG``) is a misfit (p = 0), else p = 1."""
    rms_deg = np.rad2deg(np.sqrt(cost_rad2 / np.maximum(n_bearings, 1)))
    return np.where(rms_deg > NOISELESS_RMS_DEG, 0.0, 1.0)


def range_rel_sd(theta, jtj, sigma2, t_now_s, own_x_now_m, own_y_now_m, rcond):
    """The one-sigma error of range now over the range, from jtj^-1 sigma2 (inf where
    theta is not finite or jtj singular)."""
    finite = np.isfinite(theta).all(axis=1)
    cov, singular = scaled_inverse(np.where(finite[:, None, None], jtj, np.nan), rcond)
    (rng, *_), G = kinematics_now(theta, t_now_s, own_x_now_m, own_y_now_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.sqrt(np.einsum("ni,nij,nj->n", G[:, 0], cov, G[:, 0]) * sigma2) / rng
    return np.where(singular | ~np.isfinite(rel), np.inf, rel)


def noise_fit(cost_rad2, dof, sigma_deg):
    """sigma^2 (rad^2) per track and the p-value of the two-sided chi-square(dof) test of
    the fit ``cost_rad2`` (sum of squared residuals, rad^2) against the nominal noise
    ``sigma_deg``; sigma unknown (None): F / dof and no test (NaN); sigma 0 (noiseless):
    ``noiseless_fit_p``."""
    n = cost_rad2.shape[0]
    if sigma_deg is None:
        return cost_rad2 / np.maximum(dof, 1), np.full(n, np.nan)
    sigma2 = np.full(n, np.deg2rad(sigma_deg) ** 2)
    if sigma_deg == 0:
        return sigma2, noiseless_fit_p(cost_rad2, dof + 4)
    return sigma2, two_sided_chi2_p(np.maximum(dof, 1), cost_rad2 / sigma2)


def assess(theta, jtj, sigma2, fit_p, motion_p, converged, approximate, t_now_s, own_x_now_m,
           own_y_now_m, cfg, motion_tested=False, undetermined=False,
           moving=False, tail_scale=1.0, intervals=None) -> dict:
    """Status and one-sigma errors per track (see the module docstring).

    The covariance of theta is jtj^-1 sigma2 (``sigma2`` rad^2 per track); ``fit_p``: the
    noise test's p-value (NaN: none); ``motion_p``: the trend test's (NaN: not run, or too
    few innovations); ``motion_tested``: whether the trend test was due (then a NaN, a
    motion the bearings cannot check, is ``unobservable``); ``approximate``: bool per
    track; ``undetermined``: tracks whose range the geometry does not determine, whatever
    their errors say (bool per track: ``unobservable`` before any test); ``moving``: the
    targets may wander or manoeuvre, and then a course sd above ``max_course_sd_deg`` or a
    speed sd above ``max_speed_rel_sd`` of the speed is ``position_only`` (a target declared
    at constant velocity keeps its course, however wide); ``tail_scale`` (per track, >= 1):
    the factor by which the covariance of a mixture's answer was widened so that its 95 %
    ellipsoid holds 95 % of the mixture (``mixture_tails.tail_scale``): whether range is
    determined is judged on the covariance before it (the answer's core), whether course and
    speed are on the errors stated (those a reader reads); ``intervals`` (n, 3, 4; None or
    NaN rows: none): a mixture's central intervals of range, course and speed now that hold
    68.3 and 95.4 % (``mixture_tails.quantity_intervals``), stated as they are (a single
    Gaussian's from its sd: ``interval_columns``); ``cfg`` holds
    ``singular_rcond``, ``fit_alpha``, ``motion_alpha``, ``max_range_rel_sd``,
    ``max_course_sd_deg``, ``max_speed_rel_sd``. Returns output columns."""
    finite = np.isfinite(theta).all(axis=1)
    cov, singular = scaled_inverse(np.where(finite[:, None, None], jtj, np.nan),
                                   cfg.singular_rcond)
    cov *= sigma2[:, None, None]
    (rng, bearing, course, speed), G = kinematics_now(theta, t_now_s, own_x_now_m, own_y_now_m)
    with np.errstate(invalid="ignore"):
        sd = np.sqrt(np.einsum("nij,njk,nik->ni", G, cov, G))
        poorly_fit = fit_p < cfg.fit_alpha
        drifting = motion_p < cfg.motion_alpha
        # whether the answer determines range is judged on its core: errors a mixture's
        # tails widened (``tail_scale``) are stated, not held against it
        core = sd / np.sqrt(np.broadcast_to(tail_scale, rng.shape))[:, None]
        vague = ~(core[:, 0] <= cfg.max_range_rel_sd * rng)  # a NaN sd counts as vague
        vague |= motion_tested & np.isnan(motion_p)
        # where the target may have turned or wandered since, a wide course or speed says
        # that where it is heading is not determined (a NaN sd counts as wide)
        headless = moving & ~((sd[:, 2] <= np.deg2rad(cfg.max_course_sd_deg))
                              & (sd[:, 3] <= cfg.max_speed_rel_sd * speed))
    # a geometry that cannot give the range comes first: a fit of the unobservable is
    # anything (a manoeuvring target hugging own-ship fits any bearings); an answer whose
    # errors are not honest (approximate) promises no position either
    status = np.select([~converged, undetermined, drifting, poorly_fit, singular | vague,
                        approximate, headless],
                       ["not_converged", "unobservable", "manoeuvring", "poor_fit",
                        "unobservable", "approximate", "position_only"], "ok")
    return {
        "range_now_m": rng, "range_sd_m": sd[:, 0],
        "bearing_now_deg": np.rad2deg(bearing) % 360.0, "bearing_sd_deg": np.rad2deg(sd[:, 1]),
        "course_deg": np.rad2deg(course), "course_sd_deg": np.rad2deg(sd[:, 2]),
        "speed_m_s": speed, "speed_sd_m_s": sd[:, 3],
        **interval_columns(np.column_stack([rng, course, speed]), sd[:, [0, 2, 3]],
                           intervals),
        "sigma_used_deg": np.rad2deg(np.sqrt(sigma2)),
        "fit_p_value": fit_p,
        "status": status,
    }


INTERVAL_COLUMNS = {"range": ("range_lo2_m", "range_lo1_m", "range_hi1_m", "range_hi2_m"),
                    "course": ("course_lo2_deg", "course_lo1_deg", "course_hi1_deg",
                               "course_hi2_deg"),
                    "speed": ("speed_lo2_m_s", "speed_lo1_m_s", "speed_hi1_m_s",
                              "speed_hi2_m_s")}


def interval_columns(now, sd, intervals=None) -> dict:
    """The central intervals of range (m), course (deg, clockwise from north) and speed
    (m/s) now that hold what 1 and 2 sd of a Gaussian hold (68.3 and 95.4 %):
    ``INTERVAL_COLUMNS``, lower and upper ends. Of a single Gaussian answer, whose range,
    course (rad) and speed now are ``now`` (n, 3) with one-sigma errors ``sd`` (n, 3): its
    course and speed +- 1 and 2 sd and its range r exp(+-k sd / r)
    (log-normal: a bearings-only range is known in ratio, and is positive); ``intervals``
    (n, 3, 4; rad for course), where a quantity's are finite, a mixture's own instead
    (``mixture_tails.quantity_intervals``, whose one component gives the same: asymmetric,
    reaching farther on the side a manoeuvre could have taken the target, mostly narrower
    than the sd's, which its tails widen; the estimate, the mixture's mean, may lie outside
    them where it is skewed). Range ends within ``MIN_RANGE_M`` and
    ``MAX_RANGE_M``, speed ends within 0 and ``MAX_SPEED_M_S`` (the plausible targets'). None
    where the sd is; a course interval of 360 deg or more (any course) is none; course ends
    in [0, 360)."""
    k = np.array([-2.0, -1.0, 1.0, 2.0])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        bounds = np.stack([now[:, 0, None] * np.exp(k * (sd[:, 0] / now[:, 0])[:, None]),
                           now[:, 1, None] + k * sd[:, 1, None],
                           now[:, 2, None] + k * sd[:, 2, None]], axis=1)
    if intervals is not None:  # (per quantity: one a component leaves undetermined, the sd's)
        own = np.isfinite(intervals).all(axis=2)
        bounds[own] = intervals[own]
    # within the plausible targets' (an undetermined range's would reach 1e46 m)
    bounds[:, 0] = np.clip(bounds[:, 0], MIN_RANGE_M, MAX_RANGE_M)
    bounds[:, 2] = np.clip(bounds[:, 2], 0.0, MAX_SPEED_M_S)
    bounds[~np.isfinite(sd)] = np.nan
    course = bounds[:, 1]
    with np.errstate(invalid="ignore"):
        for ends in ([0, 3], [1, 2]):  # (the 2-sd interval's ends, then the 1-sd one's)
            whole = course[:, ends[1]] - course[:, ends[0]] >= 2.0 * np.pi
            course[np.ix_(whole, ends)] = np.nan
    columns = {}
    for a, (name, names) in enumerate(INTERVAL_COLUMNS.items()):
        values = np.rad2deg(bounds[:, a]) % 360.0 if name == "course" else bounds[:, a]
        columns.update({c: values[:, j] for j, c in enumerate(names)})
    return columns


# -- what an output shows as an answer -------------------------------------------------------

# The plausible targets of a recorded log: vessels (and the aircraft a bearing sensor may see)
MIN_RANGE_M = 10.0  # own-ship's GNSS fixes err by metres: closer, a bearing has no origin
MAX_RANGE_M = 2e6  # as far as the local plane maps (tma.geo.MAX_MAPPED_M)
MAX_SPEED_M_S = 343.0  # the speed of sound in air: no ship (50 m/s at most), few aircraft
COLLAPSED_REL_SD = 1.0  # a range sd above the range itself: own-ship within one sigma
END_SIGMAS = 6.0  # an answer's bearing now this many (combined) sd off its last bearings'
END_COLUMNS = ("bearing_now_deg", "bearing_sd_deg", "end_bearing_deg", "end_bearing_sd_deg")


def off_the_last_bearings(bearings):
    """Per track the answer's bearing now, the bearing its last bearings point to
    (``end_bearing``) and how far (deg, wrapped, signed) the first lies off the second where
    that is more than ``END_SIGMAS`` times their one-sigma errors combined (NaN elsewhere);
    ``bearings`` maps ``END_COLUMNS`` to arrays. None where it lacks one."""
    if bearings is None or any(c not in bearings for c in END_COLUMNS):
        return None
    now, now_sd, end, end_sd = (np.asarray(bearings[c], dtype=float) for c in END_COLUMNS)
    off = wrap_to_180(now - end)
    with np.errstate(invalid="ignore"):
        far = np.abs(off) > END_SIGMAS * np.hypot(now_sd, end_sd)
    return now, end, np.where(far, off, np.nan)


def not_an_answer(range_m, range_sd_m, speed_m_s, max_range_rel_sd=COLLAPSED_REL_SD,
                  recorded=True, bearings=None) -> np.ndarray:
    """Why each estimate is no answer to show (an empty string where it is one): the one rule
    every output (tables, CSV, plots, map, the Python API's results) applies before it shows
    an estimate. The status says how far an answer can be trusted and why (it stays); this
    says that a number is no answer at all, diverged or collapsed, whatever the status.

    - no finite range or speed: there is no estimate;
    - a range sd NaN or infinite: the information matrix J^T J is singular (or its
      propagation to range broke down), so no one-sigma error can be given;
    - a range sd above ``max(COLLAPSED_REL_SD, max_range_rel_sd)`` times the range: own-ship
      lies within one sigma of the estimate. The sd is the delta method's, a first-order
      expansion of the bearings in the target's position, whose derivative grows as
      1 / range: it holds while the error is small beside the range, and means nothing once
      the error reaches own-ship, where a bearing can turn by anything. An estimate
      collapsed onto own-ship (11 m +- 13 m for a target 2 km away, on real ship motion) or
      run away (490 km +- 23,000 km) is such a number. ``max_range_rel_sd`` is the status's
      threshold (``unobservable`` above it): an ``ok`` track, within it, is never blanked;
    - on a ``recorded`` log, whose targets are real: a range below ``MIN_RANGE_M`` (10 m:
      own-ship's GNSS fixes, the bearings' origin, err by metres, so bearings cannot place
      a contact nearer; the estimators' fits collapse to 1e-9-1e-7 m from own-ship where it
      does not manoeuvre, with errors that look small), beyond ``MAX_RANGE_M`` (2000 km:
      the local plane is no map there, and no bearing sensor at sea reaches that far), or a
      speed beyond ``MAX_SPEED_M_S`` (343 m/s: faster than any vessel and most aircraft):
      a fit run away to where bearings barely constrain it (seen at 1e10-1e13 m and
      1e3-1e10 m/s). A simulated log declares its own scale (distances of 1e-9 m to 1e9 m,
      speeds up to 1e4 m/s are valid scenarios), so only the rules on information apply;
    - its bearing now more than ``END_SIGMAS`` (6) times the combined one-sigma errors off
      the bearing the log's own bearings point to at the last bearing time
      (``end_bearing``, their straight line in time over the last 10: ``bearings`` maps
      ``END_COLUMNS`` to arrays, the estimate's ``bearing_now_deg`` and ``bearing_sd_deg``
      and the estimate stage's ``end_bearing_deg`` and ``end_bearing_sd_deg``; no check
      without them): no answer may put the target where the last bearings do not point (a
      fit run to the mirror side of own-ship was seen ``ok`` at 172.0 +- 0.1 deg, the last
      bearings near 352 deg). The bound leaves room for the straight line's misfit where the
      bearing bends within the window; on honest fits of simulated steady and manoeuvring
      targets it never fires (``tests/families/bearings2d/test_bearings2d_answers.py``).
    """
    rng, sd, speed = (np.asarray(a, dtype=float) for a in (range_m, range_sd_m, speed_m_s))
    limit = max(COLLAPSED_REL_SD, float(max_range_rel_sd))
    with np.errstate(invalid="ignore"):
        conditions = [
            ~(np.isfinite(rng) & np.isfinite(speed)),
            ~np.isfinite(sd),
            sd > limit * rng,
            recorded & (rng < MIN_RANGE_M),
            recorded & (rng > MAX_RANGE_M),
            recorded & (speed > MAX_SPEED_M_S),
        ]
        end = off_the_last_bearings(bearings)
        off = np.full(rng.shape, np.nan) if end is None else end[2]
        conditions.append(np.isfinite(off))
    reasons = [
        "there is no finite estimate",
        "no one-sigma error can be given (J^T J is singular, or own-ship's motion cannot "
        "give the range of a target that may manoeuvre)",
        "its one-sigma range error exceeds the range itself (own-ship within one sigma: a "
        "collapsed or runaway estimate, whose linearised error means nothing)",
        f"it collapsed onto own-ship (nearer than {MIN_RANGE_M:g} m: within the error of "
        "own-ship's navigation fixes)",
        f"it diverged beyond {MAX_RANGE_M / 1e3:g} km, farther than a bearing reaches",
        f"it diverged to a speed beyond {MAX_SPEED_M_S:g} m/s, faster than a vessel goes",
        "",  # (below, with its numbers)
    ]
    why = np.select(conditions, reasons, "").astype(object)
    for k in np.flatnonzero(np.isfinite(off) & (why == "")):
        why[k] = (f"its bearing now, {end[0][k]:.1f} deg, is {abs(off[k]):.1f} deg off the "
                  f"{end[1][k]:.1f} deg its last bearings point to")
    return why
