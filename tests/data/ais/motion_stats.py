"""How real ships move: wander and manoeuvre statistics measured from AIS position reports.

They set the prior of a motion model for recorded logs (nearly-constant-velocity wander plus
manoeuvres at a rate and size): ``python tests/data/ais/motion_stats.py`` prints them for
every recording of ``build_cases.RECORDINGS`` (its ``positions.csv.gz``) and pooled;
``--original SolentAIS_20160112_130211.csv`` measures the whole Solent recording instead of
the committed subset (which keeps only the case vessels, within 300 s of their windows). The
New York Harbor file holds the whole hour (fishing vessels left out), so it is measured whole.
``--thin-s 60`` first keeps one report a minute per vessel (``thin``), to see on the Solent
what MarineCadastre's one-minute reporting does; ``--check --report-s 60 80`` checks the
method on simulated tracks reported once a minute.

Everything is measured from the reported *positions* (never the COG/SOG fields): per vessel,
reports sorted by the receiver's time stamp, one per time stamp, position spikes dropped
(``build_cases.drop_spikes``: a report over the recording's ``Rules.spike_m``, 300 m in the
Solent and 2 km in New York, off the line between its neighbours),
positions linearly interpolated in latitude/longitude between reports and converted to a
local east/north plane (``pymap3d.geodetic2enu``). Angles in degrees clockwise from north,
SI units.

Coverage and underway
    A vessel's reports split into *covered segments* wherever two reports are more than
    ``MAX_GAP_S`` (60 s) apart (class A vessels underway report every 2-10 s; a longer gap is
    lost reception, class B or a vessel at anchor); in a recording reported once a minute (New
    York), more than its ``Rules.max_gap_own_s`` (150 s: one report missing). *Motion samples*
    every ``SAMPLE_S`` (10 s) inside a segment: ``v_b(t)`` and ``v_a(t)``, the mean velocities
    over the ``WINDOW_S`` (120 s) before and after ``t``. A sample is *underway* when the mean
    velocity over [t - 60 s, t + 60 s] is at least ``MIN_SPEED_M_S`` (1 m/s); underway hours are
    10 s per underway sample. Vessels that are never underway (moored, at anchor) count nowhere.

Manoeuvres
    A sample is *changing* when the course of ``v_a`` differs from that of ``v_b`` by more
    than ``TURN_DEG`` (15 deg; both speeds at least 1 m/s) or their speeds differ by more
    than ``SPEED_FRAC`` (25 %) of the larger and by ``MIN_SPEED_CHANGE_M_S`` (0.5 m/s) or
    more, the larger at least 1 m/s (the noise of a vessel at rest is no manoeuvre). A run of
    consecutive changing samples with at least one sample underway is one manoeuvre, from its
    first changing sample t_f to its last t_l. Its size: v_before = mean velocity over
    [t_f - 120 s, t_f], v_after = over [t_l, t_l + 120 s]; course change =
    wrap(course(v_after) - course(v_before)) (only when both speeds are at least 1 m/s),
    speed change = (|v_after| - |v_before|) / max of the two, and the velocity change
    dv = v_after - v_before (m/s, a vector: what a velocity-jump model needs; its RMS per axis
    is sqrt(mean |dv|^2 / 2)). Its *duration* is the 10-90 % transition time of the velocity
    divided by 0.8: on the 30 s mean velocities every 5 s over [t_f - 120 s, t_l + 120 s], the
    fraction of the change done, (v(t) - v_before) . dv / |dv|^2, first reaches 0.9 at t90,
    and t10 is the last time before t90 it was at most 0.1 (so that noise before the change
    does not start it); duration = (t90 - t10) / 0.8 (checked on simulated tracks:
    ``--check``). Turn rate = |course change| / duration. The rate is manoeuvres per underway
    hour. Samples lie 120 s or more inside their segment, so every window is covered (the
    first and last 120 s of a segment count nowhere). A run at rest before and after (both
    speeds under 1 m/s: a whole trip shorter than the windows, such as the Gosport ferry's
    crossings of a few hundred metres) is counted apart as a *short trip* and not sized.
    Manoeuvres are given all together and for those underway before and after (both speeds
    at least 1 m/s: turns and speed changes, not stops and starts at a berth).

    Why 120 s windows and 15 deg / 25 %: AIS positions carry GPS noise of a few metres and the
    receiver's time stamps jitter by up to a second (5 m at 10 kn); over 120 s that is a
    velocity error of ~0.1 m/s, 1-2 deg of course at harbour speeds, well under the
    thresholds. A slow drift (under ~15 deg in 2 min) is not a manoeuvre: it is wander.

Wander
    *Legs*: runs of consecutive underway samples of one segment, with every manoeuvre's span
    [t_f - 120 s, t_l + 120 s] cut out, lasting ``MIN_LEG_S`` (300 s) or more (longer legs cut
    into pieces of at most ``MAX_LEG_S``, 1800 s, so that a long transit does not count as
    one). On each leg the reports are fitted by maximum likelihood with a nearly-constant-
    velocity Kalman filter per axis (Bar-Shalom, Li and Kirubarajan 2001, sec. 6.2.2: white
    acceleration of spectral density q, m^2/s^3 per axis, F = [[1, T], [0, 1]], Q = q [[T^3/3,
    T^2/2], [T^2/2, T]]) plus white position noise of sd r (m) per axis, which absorbs GPS
    noise and the time-stamp jitter. The filter starts from the first report with an
    uninformative velocity; the first two innovations (which only fix the starting state) are
    left out of the likelihood. (q, r) of a leg maximise the two axes' joint likelihood (a
    grid over log10 q in [-7, 0] and log10 r in [-1, 2.5], then Nelder-Mead). The table gives
    the distribution of q over legs (median, quartiles, 90th percentile; a q at the grid's
    floor, 1e-7, means "no wander seen over the leg") and the single q (and r) that maximises
    the likelihood of all legs together ("pooled ML").

Clustering (``dispersion``)
    Whether manoeuvres come as a Poisson process, as the prior of a recording assumes: each
    run of underway samples is cut into whole 20-minute windows (the span an answer rests on)
    and the manoeuvre starts in each counted; their variance over their mean is 1 for a
    Poisson process and above 1 where manoeuvres cluster (Fisher's dispersion test gives the
    p-value of clustering). And the rate of manoeuvres in the 10 minutes after 20 minutes
    underway without one: what a target that held course through a window does next
    (Poisson: the same rate as at any other time).

One report a minute (New York): what it does to these figures (``--check --report-s 60 80``,
and the Solent ``--thin-s 60`` beside the Solent as recorded; figures in
``tests/data/ais_nyharbor/SOURCE.md``). On simulated NCV legs the fit of q stays unbiased but
a leg's q is less precise, and r is not identified where q T^3/3 dominates r^2 (a leg's r
then falls towards zero: a per-leg r median means nothing there). Real ships are not NCV:
accelerations that reverse within a minute are averaged out or absorbed in r, so the same
Solent traffic measures a lower q at one report a minute (pooled ML a third). Manoeuvres
closer than about two minutes merge (the rate drops by about 15 %), their sizes are kept, and
a manoeuvre shorter than about two reporting intervals measures 1.5-2 intervals long (its
turn rate lower). Compare New York with the thinned Solent, not with the Solent as recorded.

Pooled: the legs and manoeuvres of every recording together.
"""

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from pymap3d import geodetic2enu
from scipy.optimize import minimize

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import build_cases as bc  # noqa: E402

from tma.runtime.jit import njit  # noqa: E402

MAX_GAP_S = 60.0
SAMPLE_S = 10.0
WINDOW_S = 120.0
MIN_SPEED_M_S = 1.0
TURN_DEG = 15.0
SPEED_FRAC = 0.25
MIN_SPEED_CHANGE_M_S = 0.5  # and at least this: a slow vessel's noise is no manoeuvre
FINE_WINDOW_S = 30.0  # mean velocities for the 10-90 % transition time
FINE_STEP_S = 5.0
MIN_LEG_S = 300.0
MAX_LEG_S = 1800.0
COUNT_WINDOW_S = 1200.0  # dispersion(): windows of manoeuvre counts
QUIET_S = 1200.0  # dispersion(): a quiet spell this long...
QUIET_NEXT_S = 600.0  # ...then the manoeuvres of this long after it
LOG10_Q = np.arange(-7.0, 0.01, 0.25)
LOG10_R = np.arange(-1.0, 2.51, 0.125)


@dataclass
class Stats:
    """What one recording (or the pool) yields."""

    name: str
    vessels_underway: set = field(default_factory=set)
    underway_h: float = 0.0
    legs: list = field(default_factory=list)  # dicts: mmsi, duration_s, q, r, t, e, n
    manoeuvres: list = field(default_factory=list)  # dicts, see manoeuvres()
    runs: list = field(default_factory=list)  # (mmsi, start, end, starts): underway runs


@njit(error_model="numpy")
def _ncv_loglik(t, z, q, r2):
    """Log-likelihood of positions ``z`` (m, one axis) at times ``t`` (s) under the NCV model
    with acceleration PSD ``q`` and position noise variance ``r2``; the first two innovations
    (which fix the starting state) are left out."""
    x, v = z[0], 0.0
    p00, p01, p11 = r2, 0.0, 1e6  # velocity: uninformative (1000 m/s sd)
    ll = 0.0
    for k in range(1, len(t)):
        T = t[k] - t[k - 1]
        # predict
        x = x + T * v
        a00 = p00 + 2.0 * T * p01 + T * T * p11 + q * T * T * T / 3.0
        a01 = p01 + T * p11 + q * T * T / 2.0
        a11 = p11 + q * T
        # update
        s = a00 + r2
        nu = z[k] - x
        if k >= 2:
            ll -= 0.5 * (np.log(2.0 * np.pi * s) + nu * nu / s)
        k0, k1 = a00 / s, a01 / s
        x += k0 * nu
        v += k1 * nu
        p00 = a00 - k0 * a00
        p01 = a01 - k0 * a01
        p11 = a11 - k1 * a01
    return ll


def _leg_loglik(legs, log10_q, log10_r) -> float:
    q, r2 = 10.0 ** log10_q, 10.0 ** (2 * log10_r)
    return sum(_ncv_loglik(tt, e, q, r2) + _ncv_loglik(tt, n, q, r2) for tt, e, n in legs)


def fit_ncv(legs) -> tuple[float, float]:
    """ML (log10 q, log10 r) of the legs ``[(t, east, north), ...]`` taken together."""
    grid = np.array([[_leg_loglik(legs, lq, lr) for lr in LOG10_R] for lq in LOG10_Q])
    i, j = np.unravel_index(np.argmax(grid), grid.shape)
    res = minimize(lambda p: -_leg_loglik(legs, p[0], p[1]), [LOG10_Q[i], LOG10_R[j]],
                   method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-4})
    lq, lr = res.x if res.fun <= -grid[i, j] else (LOG10_Q[i], LOG10_R[j])
    return float(np.clip(lq, LOG10_Q[0], LOG10_Q[-1])), float(lr)


def segments(track: bc.Track, max_gap_s: float = MAX_GAP_S) -> list[tuple[float, float]]:
    """Covered segments [t0, t1] of a track: no two reports more than ``max_gap_s`` apart."""
    if len(track.t) < 2:
        return []
    cut = np.flatnonzero(np.diff(track.t) > max_gap_s)
    starts = np.r_[0, cut + 1]
    ends = np.r_[cut, len(track.t) - 1]
    return [(float(track.t[a]), float(track.t[b])) for a, b in zip(starts, ends, strict=True)
            if b > a]


def _course(ve, vn):
    return np.degrees(np.arctan2(ve, vn)) % 360.0


def _wrap(d):
    return (d + 180.0) % 360.0 - 180.0


def analyse_segment(track: bc.Track, t0: float, t1: float, stats: Stats) -> None:
    """Adds the segment's underway time, manoeuvres and legs to ``stats``."""
    w = WINDOW_S
    t = np.arange(t0 + w, t1 - w + 1e-6, SAMPLE_S)
    if len(t) < 2:
        return
    vbe, vbn = bc.mean_velocity(track, t - w, t)
    vae, van = bc.mean_velocity(track, t, t + w)
    vce, vcn = bc.mean_velocity(track, t - w / 2, t + w / 2)
    underway = np.hypot(vce, vcn) >= MIN_SPEED_M_S
    if not underway.any():
        return
    stats.vessels_underway.add(track.mmsi)
    stats.underway_h += underway.sum() * SAMPLE_S / 3600.0
    sb, sa = np.hypot(vbe, vbn), np.hypot(vae, van)
    turn = np.abs(_wrap(_course(vae, van) - _course(vbe, vbn)))
    has_course = (sb >= MIN_SPEED_M_S) & (sa >= MIN_SPEED_M_S)
    fast = np.maximum(sa, sb)
    changing = ((has_course & (turn > TURN_DEG))
                | ((fast >= MIN_SPEED_M_S)
                   & (np.abs(sa - sb) > np.maximum(SPEED_FRAC * fast, MIN_SPEED_CHANGE_M_S))))
    runs = np.split(np.flatnonzero(changing), np.flatnonzero(np.diff(np.flatnonzero(changing)) > 1)
                    + 1) if changing.any() else []
    first_moving = len(stats.manoeuvres)
    cut = np.zeros(len(t), dtype=bool)  # samples inside a manoeuvre's span
    for run in runs:
        tf, tl = t[run[0]], t[run[-1]]
        cut |= (t >= tf - w) & (t <= tl + w)
        if not underway[run].any():
            continue
        stats.manoeuvres.append(_manoeuvre(track, tf, tl))
    _underway_runs(track.mmsi, t, underway, stats, first_moving)
    # legs: underway, outside every manoeuvre span, long enough
    good = underway & ~cut
    for run in np.split(np.flatnonzero(good), np.flatnonzero(np.diff(np.flatnonzero(good)) > 1)
                        + 1) if good.any() else []:
        a, b = t[run[0]] - w / 2, t[run[-1]] + w / 2  # the samples' 120 s means cover this
        n_pieces = int(np.ceil((b - a) / MAX_LEG_S))
        for k in range(n_pieces):
            pa, pb = a + k * (b - a) / n_pieces, a + (k + 1) * (b - a) / n_pieces
            if pb - pa >= MIN_LEG_S:
                stats.legs.append(_leg(track, pa, pb))


def _underway_runs(mmsi, t, underway, stats: Stats, first: int) -> None:
    """The segment's runs of underway samples (each sample standing for ``SAMPLE_S``), with
    the starts of the manoeuvres (from ``stats.manoeuvres[first:]``, those underway before or
    after: not short trips) that fall in each: what ``dispersion`` counts."""
    starts = np.sort([m["t_first"] for m in stats.manoeuvres[first:]
                      if max(m["speed_before_m_s"], m["speed_after_m_s"]) >= MIN_SPEED_M_S])
    idx = np.flatnonzero(underway)
    for run in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []:
        a, b = t[run[0]] - SAMPLE_S / 2, t[run[-1]] + SAMPLE_S / 2
        stats.runs.append((mmsi, a, b, starts[(starts >= a) & (starts < b)]))


def dispersion(s: Stats) -> dict:
    """Whether manoeuvres come as a Poisson process, the form of the prior a recording gets
    (``manoeuvre_prior``): the underway runs cut into whole windows of ``COUNT_WINDOW_S`` (20
    minutes, the span an answer rests on), the manoeuvres starting in each counted; their
    variance over their mean (Poisson: 1; more: manoeuvres cluster, some windows busy and
    others quiet) with the p-value of Fisher's dispersion test (the sum of (n - mean)^2 /
    mean, chi-square with windows - 1 degrees of freedom) for clustering; and the rate of
    manoeuvres in the ``QUIET_NEXT_S`` (10 minutes) after ``QUIET_S`` (20 minutes) underway
    without one (Poisson: the same as any other time), which is what the prior says of a
    target that held course through a window."""
    from scipy.stats import chi2

    counts, quiet_n, quiet_s = [], 0, 0.0
    for _, a, b, starts in s.runs:
        for k in range(int((b - a) // COUNT_WINDOW_S)):
            lo = a + k * COUNT_WINDOW_S
            counts.append(int(np.sum((starts >= lo) & (starts < lo + COUNT_WINDOW_S))))
        edges = np.r_[a, starts, b]
        for g0, g1 in zip(edges[:-1], edges[1:], strict=True):
            if g1 - g0 > QUIET_S:  # quiet from g0 for QUIET_S: watch the next QUIET_NEXT_S
                quiet_s += min(g1 - g0 - QUIET_S, QUIET_NEXT_S)
                quiet_n += int(g1 < b and g1 - g0 - QUIET_S <= QUIET_NEXT_S)
    c = np.asarray(counts, dtype=float)
    out = {"20-min windows underway": c.size}
    if c.size > 1 and c.mean() > 0:
        out["manoeuvres per window, mean"] = c.mean()
        out["  variance / mean (Poisson 1)"] = c.var(ddof=1) / c.mean()
        out["  dispersion test p (clustered)"] = float(
            chi2.sf(np.sum((c - c.mean()) ** 2) / c.mean(), c.size - 1))
    out["after 20 quiet min: manoeuvres"] = quiet_n
    out["  in hours watched"] = quiet_s / 3600.0
    out["  per h"] = quiet_n / (quiet_s / 3600.0) if quiet_s else np.nan
    return out


def _manoeuvre(track: bc.Track, tf: float, tl: float) -> dict:
    w = WINDOW_S
    ve_b, vn_b = (float(x) for x in bc.mean_velocity(track, tf - w, tf))
    ve_a, vn_a = (float(x) for x in bc.mean_velocity(track, tl, tl + w))
    sb, sa = np.hypot(ve_b, vn_b), np.hypot(ve_a, vn_a)
    dve, dvn = ve_a - ve_b, vn_a - vn_b
    dv2 = dve * dve + dvn * dvn
    course = (float(_wrap(_course(ve_a, vn_a) - _course(ve_b, vn_b)))
              if min(sb, sa) >= MIN_SPEED_M_S else np.nan)
    tt = np.arange(tf - w + FINE_WINDOW_S / 2, tl + w - FINE_WINDOW_S / 2 + 1e-6, FINE_STEP_S)
    fe, fn = bc.mean_velocity(track, tt - FINE_WINDOW_S / 2, tt + FINE_WINDOW_S / 2)
    frac = ((fe - ve_b) * dve + (fn - vn_b) * dvn) / dv2 if dv2 > 0 else np.zeros_like(tt)
    duration = np.nan
    i90 = np.flatnonzero(frac >= 0.9)
    if len(i90):  # the last time under 10 % before 90 % is first reached (noise-proof)
        i10 = np.flatnonzero(frac[: i90[0]] <= 0.1)
        if len(i10):
            duration = max(float(tt[i90[0]] - tt[i10[-1]]), FINE_STEP_S) / 0.8
    return {"mmsi": track.mmsi, "t_first": tf, "t_last": tl, "course_change_deg": course,
            "speed_before_m_s": sb, "speed_after_m_s": sa,
            "speed_change_frac": (sa - sb) / max(sa, sb), "dv_east": dve, "dv_north": dvn,
            "dv_m_s": float(np.sqrt(dv2)), "duration_s": duration,
            "turn_rate_deg_s": abs(course) / duration if np.isfinite(course) else np.nan}


def _leg(track: bc.Track, a: float, b: float) -> dict:
    i = (track.t >= a) & (track.t <= b)
    tt, lat, lon = track.t[i], track.lat[i], track.lon[i]
    e, n, _ = geodetic2enu(lat, lon, 0.0, lat[0], lon[0], 0.0)
    tt = tt - tt[0]
    lq, lr = fit_ncv([(tt, e, n)])
    return {"mmsi": track.mmsi, "start_s": a, "duration_s": b - a, "n_reports": int(i.sum()),
            "log10_q": lq, "log10_r": lr, "data": (tt, np.asarray(e), np.asarray(n))}


def analyse(name: str, tracks: dict[int, bc.Track], max_gap_s: float = MAX_GAP_S) -> Stats:
    stats = Stats(name)
    for track in tracks.values():
        for t0, t1 in segments(track, max_gap_s):
            analyse_segment(track, t0, t1, stats)
    return stats


def pool(parts: list[Stats]) -> Stats:
    out = Stats("pooled")
    for p in parts:
        out.vessels_underway |= {(p.name, m) for m in p.vessels_underway}
        out.underway_h += p.underway_h
        out.legs += p.legs
        out.manoeuvres += p.manoeuvres
        out.runs += p.runs
    return out


def _pct(x, p):
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.percentile(x, p)) if len(x) else np.nan


def summarise(s: Stats) -> dict:
    """The figures of one recording (or the pool)."""
    q = 10.0 ** np.array([leg["log10_q"] for leg in s.legs]) if s.legs else np.array([])
    m = pd.DataFrame(s.manoeuvres)
    short = (m[["speed_before_m_s", "speed_after_m_s"]].max(axis=1) < MIN_SPEED_M_S
             if len(m) else pd.Series(dtype=bool))
    n_short = int(short.sum())
    m = m[~short] if len(m) else m
    out = {"recording": s.name, "vessels underway": len(s.vessels_underway),
           "underway h": s.underway_h, "legs": len(s.legs),
           "leg h": sum(leg["duration_s"] for leg in s.legs) / 3600.0}
    for p, lab in ((25, "q p25"), (50, "q median"), (75, "q p75"), (90, "q p90")):
        out[lab] = _pct(q, p)
    if s.legs:
        lq, lr = fit_ncv([leg["data"] for leg in s.legs])
        out["q pooled ML"], out["r pooled ML m"] = 10.0 ** lq, 10.0 ** lr
        out["r median m"] = _pct(10.0 ** np.array([leg["log10_r"] for leg in s.legs]), 50)
    out["short trips (not sized)"] = n_short
    out["manoeuvres"] = len(m)
    out["per underway h"] = len(m) / s.underway_h if s.underway_h else np.nan
    if len(m):
        moving = (m[["speed_before_m_s", "speed_after_m_s"]].min(axis=1) >= MIN_SPEED_M_S)
        out["stops/starts per underway h"] = (~moving).sum() / s.underway_h
        out["underway->underway per h"] = moving.sum() / s.underway_h
        mm = m[moving]
        out["  of which turns > 15 deg"] = int((mm["course_change_deg"].abs() > TURN_DEG).sum())
        out["  |course change| median deg"] = _pct(mm["course_change_deg"].abs(), 50)
        out["  |speed change| median frac"] = _pct(mm["speed_change_frac"].abs(), 50)
        out["  |dv| RMS per axis m/s"] = float(np.sqrt(np.mean(mm["dv_m_s"] ** 2) / 2.0))
        turns = m["course_change_deg"].abs()
        out["|course change| median deg"] = _pct(turns, 50)
        out["|course change| p90 deg"] = _pct(turns, 90)
        out["turns > 15 deg share"] = float((turns > TURN_DEG).mean())
        sp = m["speed_change_frac"].abs()
        out["|speed change| median frac"] = _pct(sp, 50)
        out["|speed change| p90 frac"] = _pct(sp, 90)
        out["duration median s"] = _pct(m["duration_s"], 50)
        out["duration p25 s"] = _pct(m["duration_s"], 25)
        out["duration p75 s"] = _pct(m["duration_s"], 75)
        out["turn rate median deg/s"] = _pct(m["turn_rate_deg_s"], 50)
        out["turn rate p90 deg/s"] = _pct(m["turn_rate_deg_s"], 90)
        out["|dv| median m/s"] = _pct(m["dv_m_s"], 50)
        out["|dv| RMS per axis m/s"] = float(np.sqrt(np.mean(m["dv_m_s"] ** 2) / 2.0))
    out.update(dispersion(s))
    return out


def simulate_legs(rng: np.random.Generator, q: float, r: float,
                  report_s: tuple[float, float], n_reports: int, n_legs: int = 20) -> list:
    """``n_legs`` NCV legs ``[(t, east, north), ...]`` of ``n_reports`` reports each at
    intervals drawn uniformly from ``report_s`` (s): acceleration PSD ``q`` (m^2/s^3 per axis)
    from 5 m/s on each axis, position noise sd ``r`` (m)."""
    legs = []
    for _ in range(n_legs):
        t = np.r_[0.0, np.cumsum(rng.uniform(report_s[0], report_s[1], n_reports - 1))]
        axes = []
        for _axis in range(2):
            x, v, out = 0.0, 5.0, [0.0]
            for dt in np.diff(t):
                cov = q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
                w = rng.multivariate_normal([0.0, 0.0], cov)
                x, v = x + dt * v + w[0], v + w[1]
                out.append(x)
            axes.append(np.array(out) + rng.normal(0.0, r, len(t)))
        legs.append((t, axes[0], axes[1]))
    return legs


def check(seed: int = 20160112, report_s: tuple[float, float] = (2.0, 10.0)) -> str:
    """The method on simulated tracks of known motion, with report intervals drawn uniformly
    from ``report_s`` (s): the wander fit on NCV legs of known (q, r) (20 legs of about 900 s,
    150 reports at the default 2-10 s, 5 m/s, per case: the per-leg median and pooled fits),
    and the manoeuvre detection on a track with one turn and one slow-down (reports every
    5 s at the default, else at intervals drawn from ``report_s``)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    lo, hi = report_s
    n_leg = max(5, round(900.0 / ((lo + hi) / 2)))
    lines = [f"report intervals {lo:g}-{hi:g} s; legs of {n_leg} reports"]
    for q, r in ((1e-4, 3.0), (1e-3, 5.0), (1e-2, 3.0)):
        legs = simulate_legs(rng, q, r, report_s, n_leg)
        per_leg = np.array([fit_ncv([leg]) for leg in legs])
        lq, lr = fit_ncv(legs)
        mq, mr = 10.0 ** np.median(per_leg, axis=0)
        q25, q75 = 10.0 ** np.percentile(per_leg[:, 0], [25, 75])
        lines.append(f"true q {q:.0e} r {r:.1f} m: per-leg median q {mq:.3g} (quartiles "
                     f"{q25:.3g}-{q75:.3g}) r {mr:.3g}; pooled q {10 ** lq:.3g} r {10 ** lr:.3g}")
    # manoeuvres: 5 m/s north, a 90 deg turn at 0.5 deg/s (180 s) from t = 600 s, then a
    # slow-down to 2.5 m/s over 60 s from t = 1200 s (the path integrated every 5 s); reports
    # with 3 m noise
    from pymap3d import enu2geodetic
    tf = np.arange(0.0, 1800.0 + hi, 5.0)
    psi = np.radians(np.clip((tf - 600.0) * 0.5, 0.0, 90.0))
    speed = np.interp(tf, [1200.0, 1260.0], [5.0, 2.5])
    ef = np.r_[0.0, np.cumsum(speed[:-1] * np.sin(psi[:-1]) * 5.0)]
    nf = np.r_[0.0, np.cumsum(speed[:-1] * np.cos(psi[:-1]) * 5.0)]
    for k in range(3):
        t = (np.arange(0.0, 1800.0, 5.0) if report_s == (2.0, 10.0)
             else np.r_[0.0, np.cumsum(rng.uniform(lo, hi, int(1800.0 / lo)))])
        t = t[t < 1800.0]
        e, n = np.interp(t, tf, ef), np.interp(t, tf, nf)
        lat, lon, _ = enu2geodetic(e + rng.normal(0.0, 3.0, len(t)),
                                   n + rng.normal(0.0, 3.0, len(t)), 0.0, 50.7, -1.1, 0.0)
        stats = Stats("check")
        analyse_segment(bc.Track(k, t, np.asarray(lat), np.asarray(lon)), t[0], t[-1], stats)
        found = "; ".join(f"course {m['course_change_deg']:+.1f} deg, speed "
                          f"{m['speed_change_frac']:+.2f}, duration {m['duration_s']:.0f} s"
                          for m in stats.manoeuvres)
        lines.append(f"turn +90 deg in 180 s, then speed -0.50 in 60 s: found {found}")
    return "\n".join(lines)


def thin(track: bc.Track, every_s: float) -> bc.Track:
    """The track with one report per ``every_s`` seconds at most: its first report, then each
    first report ``every_s`` or more after the last one kept (as MarineCadastre keeps about
    one a minute)."""
    keep, last = [], -np.inf
    for i, t in enumerate(track.t):
        if t - last >= every_s:
            keep.append(i)
            last = t
    return bc.Track(track.mmsi, track.t[keep], track.lat[keep], track.lon[keep])


def load_tracks(positions=None, original=None, recording: str = "solent"
                ) -> dict[int, bc.Track]:
    """Tracks of ``recording`` from a positions file (``build_cases`` format) or from its
    original file (``extract_subset.read_original``), spikes dropped by its rule."""
    rec = bc.get_recording(recording)
    if original is not None:
        import extract_subset
        return bc.tracks_from(extract_subset.read_original(original, rec.name), rec.rules)
    return bc.tracks_from(bc.load_positions(positions), rec.rules)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--original", help="the whole Solent recording (Stone Soup CSV) "
                        "instead of the committed Solent subset")
    parser.add_argument("--csv", help="also write the legs and manoeuvres here (prefix)")
    parser.add_argument("--thin-s", type=float, help="keep one report per THIN_S s per vessel "
                        "(60: one a minute, as MarineCadastre; gaps up to 150 s covered)")
    parser.add_argument("--check", action="store_true",
                        help="only the method's check on simulated tracks of known motion")
    parser.add_argument("--report-s", type=float, nargs=2, default=(2.0, 10.0),
                        metavar=("LO", "HI"), help="--check: report intervals drawn uniformly "
                        "from LO-HI s (default 2 10; 60 80 is one report a minute)")
    args = parser.parse_args(argv)
    if args.check:
        print(check(report_s=tuple(args.report_s)))
        return 0
    parts = []
    for name, rec in bc.RECORDINGS.items():
        original = args.original if name == "solent" else None
        label = (f"{name} (whole recording)" if original or name == "nyharbor"
                 else f"{name} (committed subset)")
        tracks = load_tracks(rec.positions_path, original, name)
        max_gap_s = rec.rules.max_gap_own_s
        if args.thin_s:
            tracks = {m: thin(tr, args.thin_s) for m, tr in tracks.items()}
            max_gap_s = max(max_gap_s, bc.NYHARBOR_RULES.max_gap_own_s)
            label = f"{name} (thinned to {args.thin_s:g} s)"
        parts.append(analyse(label, tracks, max_gap_s))
    stats = parts + ([pool(parts)] if len(parts) > 1 else [])
    table = pd.DataFrame([summarise(s) for s in stats]).set_index("recording").T
    with pd.option_context("display.float_format", lambda x: f"{x:.4g}",
                           "display.width", 160):
        print(table.to_string())
    if args.csv:
        for s in stats:
            pd.DataFrame([{k: v for k, v in leg.items() if k != "data"} for leg in s.legs]
                         ).to_csv(f"{args.csv}_{s.name.split()[0]}_legs.csv", index=False)
            pd.DataFrame(s.manoeuvres).to_csv(f"{args.csv}_{s.name.split()[0]}_manoeuvres.csv",
                                              index=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
