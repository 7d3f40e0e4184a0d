"""How simulated ``bearings2d`` targets move when they do not hold course and speed: random
manoeuvres (course and speed changes at random times, at ship-like turn rates and
accelerations) and nearly-constant-velocity wander (white random acceleration), either or
both on top of the scenario's constant-velocity target.

Manoeuvres (``ManoeuvreConfig``): a share ``prob`` of the targets manoeuvre ``count`` times,
each starting at a time drawn uniform over [``start_frac``, ``end_frac``] of the observation;
or (``rate_per_h`` > 0) every target manoeuvres at the times of a Poisson process of that
rate over the whole observation (a Poisson count given, its times are uniform; counts are
drawn with room for all but a ``MISSED_POISSON`` tail, at least ``MAX_POISSON``). Start
times are sorted; one that would start before the previous has
ended starts when it ends. Each turns by an angle uniform in [``course_change_min_deg``,
``course_change_max_deg``],
left or right alike, at a rate uniform in [``turn_rate_min_deg_s``,
``turn_rate_max_deg_s``], and changes speed by a factor uniform in [1 - ``speed_change_rel``,
1 + ``speed_change_rel``] at ``accel_m_s2``; it ends when both are done. Course and speed
are then piecewise linear in time, and positions their integral (3-point Gauss-Legendre per
bearing interval: within millimetres of the exact arcs, ``tma.path``).

Or (``shape`` burst: the estimators' own model, ``manoeuvres.py``, to check them on data
drawn from it) each Poisson manoeuvre is a burst of white acceleration of density s^2 / D per
axis over a duration D, s and D (one of them alike) those the log declares
(``declared_prior``): the velocity changes by N(0, s^2) per axis (``burst_deviations``,
drawn exactly on the bearing epochs).

Wander (``accel_psd_m2_s3`` = q > 0): per axis, position and velocity deviations driven by
white acceleration of spectral density q, drawn exactly on the bearing epochs (the
discrete model of ``ncv.py``: Q = q [[T^3/3, T^2/2], [T^2/2, T]]), added to the path.

Draws come from the shard's own child streams ``SeedSequence(seed, spawn_key=(shard,
MANOEUVRE_STREAM))`` and ``(shard, WANDER_STREAM)``, the manoeuvres drawn for every target
whatever ``prob``: the targets and noise of a dataset do not change with these options (off,
a dataset's bearings are as without them), a manoeuvre of a target is the same at every
``prob`` that makes it manoeuvre, and the wander at two q differs by its scale alone.

What the log declares (``declared``): the wander q and, for Poisson manoeuvres, the prior
the estimators assume (``manoeuvres.ManoeuvrePrior``: the same rate, and the velocity
change's size and the durations implied by the turn and speed-change distributions,
``declared_prior``); targets with ``prob`` manoeuvres (a fixed count at times within a
window, not a rate) declare nothing: the estimators treat them as a recording's.
"""

import math
from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.bearings2d.manoeuvre_prior import ManoeuvrePrior, burst_step_noise
from tma.maths.angles import wrap_to_180

MANOEUVRE_STREAM, WANDER_STREAM = 2, 3  # spawn-key elements under the shard's (shard,)
DURATIONS = 3  # a declared prior's durations: the means of the thirds of their distribution
MAX_POISSON = 30  # slots for Poisson manoeuvres per target, at least (P(more) < 1e-9 for
# up to 10 expected in a run); a longer run gets slots for every count but a tail this likely:
MISSED_POISSON = 1e-9
GAUSS_NODES = (0.5 - np.sqrt(15) / 10, 0.5, 0.5 + np.sqrt(15) / 10)  # on [0, 1]
GAUSS_WEIGHTS = (5 / 18, 8 / 18, 5 / 18)


@dataclass
class ManoeuvreConfig:
    """Course and speed changes (module docstring); ``prob`` 0: none."""

    prob: float = param(0.0, "share of the targets that manoeuvre", "[0, 1]")
    rate_per_h: float = param(0.0, "instead of prob: every target manoeuvres at the times of "
                              "a Poisson process of this rate (per hour) over the observation",
                              "[0, 1000]")
    count: int = param(1, "manoeuvres of each manoeuvring target", "[1, 100]")
    start_frac: float = param(0.3, "manoeuvres start within [start_frac, end_frac] of the "
                              "observation", "[0, 1]")
    end_frac: float = param(0.8, "see start_frac", "[0, 1]")
    course_change_min_deg: float = param(20.0, "smallest turn (deg), left or right alike",
                                         "[0, 360]")
    course_change_max_deg: float = param(120.0, "largest turn (deg)", "[0, 360]")
    turn_rate_min_deg_s: float = param(0.2, "slowest turn rate (deg/s; ships turn at 0.2-1, "
                                       "small craft up to 3)", "(0, 90]")
    turn_rate_max_deg_s: float = param(1.0, "fastest turn rate (deg/s)", "(0, 90]")
    speed_change_rel: float = param(0.3, "speed factor uniform in [1 - this, 1 + this]",
                                    "[0, 1)")
    accel_m_s2: float = param(0.05, "while changing speed (m/s^2; merchant ships 0.01-0.05)",
                              "(0, 100]")
    shape: str = param("turn", "how a Poisson manoeuvre moves the target: turn (as a ship: "
                       "the turn and speed change above) or burst (the estimators' own "
                       "model: a velocity change N(0, s^2) per axis as white acceleration "
                       "over one of the durations, s and the durations those the log "
                       "declares; to check an estimator on data drawn from its own model)",
                       choices=("turn", "burst"), unhashed_default=True)


@dataclass
class TargetConfig:
    """How the targets move beyond constant velocity, and whether the log says so."""

    accel_psd_m2_s3: float = param(0.0, "wander: random acceleration spectral density per "
                                   "axis (m^2/s^3); 0: none", "[0, 1e3)")
    manoeuvres: ManoeuvreConfig = param(doc="course and speed changes",
                                        factory=ManoeuvreConfig)
    declared: bool = param(True, "the log declares the targets' motion (accel_psd) when it is "
                           "a motion model (no manoeuvres): estimators then assume it; false: "
                           "as a recording, which declares none")

    @property
    def moving(self) -> bool:
        """Whether the targets do anything but hold course and speed."""
        m = self.manoeuvres
        return self.accel_psd_m2_s3 > 0 or m.prob > 0 or m.rate_per_h > 0

    def declared_psd(self) -> float | None:
        """What the log declares of the targets' wander (``BearingsLog.accel_psd_m2_s3``)."""
        return self.accel_psd_m2_s3 if self.declared and self.manoeuvres.prob == 0 else None

    def declared_manoeuvres(self, speed_m_s: float) -> ManoeuvrePrior | None:
        """What the log declares of the targets' manoeuvres (``BearingsLog.manoeuvres``):
        for Poisson manoeuvres, ``declared_prior`` at the population's RMS speed."""
        m = self.manoeuvres
        if not self.declared or m.prob > 0 or m.rate_per_h == 0:
            return None
        return declared_prior(m, speed_m_s)


def check(cfg: TargetConfig, where: str):
    """The rules between fields (each field's own range is its ``param``'s)."""
    m = cfg.manoeuvres
    require(m.prob == 0 or m.rate_per_h == 0, where,
            "target.manoeuvres takes prob (a share of the targets) or rate_per_h (a Poisson "
            "rate), not both")
    require(m.start_frac <= m.end_frac, where,
            "target.manoeuvres needs start_frac <= end_frac")
    require(m.course_change_min_deg <= m.course_change_max_deg, where,
            "target.manoeuvres needs course_change_min_deg <= course_change_max_deg")
    require(m.turn_rate_min_deg_s <= m.turn_rate_max_deg_s, where,
            "target.manoeuvres needs turn_rate_min_deg_s <= turn_rate_max_deg_s")
    require(m.shape == "turn" or m.prob == 0, where,
            "target.manoeuvres.shape=burst draws Poisson manoeuvres: set rate_per_h, not prob")


def declared_prior(m: ManoeuvreConfig, speed_m_s: float) -> ManoeuvrePrior:
    """The estimators' prior for the Poisson manoeuvres ``m`` of targets whose RMS speed is
    ``speed_m_s``: the same rate; the velocity change's sd per axis, dv^2 = E|dv|^2 / 2 =
    v^2 (1 + a^2 / 6 - E cos(phi)) for a turn phi uniform in [min, max] and a speed factor
    uniform in [1 - a, 1 + a]; the durations, max(|phi| / turn rate, v |f - 1| / accel),
    summarised by the means of the ``DURATIONS`` parts of their distribution (over a grid of
    32 quantiles of each of phi, the turn rate and f)."""
    lo, hi = np.deg2rad(m.course_change_min_deg), np.deg2rad(m.course_change_max_deg)
    mean_cos = (math.sin(hi) - math.sin(lo)) / (hi - lo) if hi > lo else math.cos(lo)
    a = m.speed_change_rel
    dv_rel = math.sqrt(max(1.0 + a * a / 6.0 - mean_cos, 0.0))
    u = (np.arange(32) + 0.5) / 32
    phi = lo + (hi - lo) * u[:, None, None]
    rate = np.deg2rad(m.turn_rate_min_deg_s + (m.turn_rate_max_deg_s - m.turn_rate_min_deg_s)
                      * u[None, :, None])
    f = 1.0 - a + 2.0 * a * u[None, None, :]
    duration = np.sort(np.maximum(phi / rate, speed_m_s * np.abs(f - 1.0) / m.accel_m_s2),
                       axis=None)
    durations = tuple(float(part.mean()) for part in np.array_split(duration, DURATIONS))
    return ManoeuvrePrior(m.rate_per_h, dv_rel * speed_m_s, durations)


def _ramp(t, start, duration):
    """clip(t - start, 0, duration) / duration (0 before, 1 after; 1 for a zero duration),
    ``t`` (..., K) against per-track ``start``, ``duration`` (n,)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (t - start[:, None]) / duration[:, None]
    return np.where(duration[:, None] > 0, np.clip(x, 0.0, 1.0), (t >= start[:, None]) * 1.0)


def poisson_times(rate_per_h, duration_s, n, rng):
    """Per target (n): how many manoeuvres start over ``duration_s`` at the times of a Poisson
    process of ``rate_per_h``, and their start times (slots, n; s, sorted, inf past the
    count)."""
    from scipy.stats import poisson  # (only where simulated: heavy for every command)

    mean = rate_per_h / 3600.0 * duration_s
    # room for every count but a 1e-9 tail (a log of hours at ten an hour needs more than
    # MAX_POISSON; the same slots, and so the same draws, below it)
    slots = max(MAX_POISSON, int(poisson.isf(MISSED_POISSON, mean)) + 1)
    count = np.minimum(rng.poisson(mean, n), slots)
    active = np.arange(slots)[:, None] < count
    times = np.sort(np.where(active, rng.uniform(0.0, duration_s, (slots, n)), np.inf), axis=0)
    return count, times


def manoeuvre_plan(cfg: ManoeuvreConfig, duration_s, speed0, rng):
    """Per target (n = ``speed0.size``): start, turn (rad, signed: > 0 right), turn duration,
    speed change (m/s) and its duration of each manoeuvre, arrays (slots, n) (a slot without
    a manoeuvre: no turn, no speed change, start inf), whether the target manoeuvres (n,)
    and the index of its last manoeuvre (n,; 0 where none)."""
    n = speed0.size
    if cfg.rate_per_h > 0:
        count, times = poisson_times(cfg.rate_per_h, duration_s, n, rng)
        slots = times.shape[0]
        active = np.arange(slots)[:, None] < count
        manoeuvres = count > 0
    else:
        slots, active = cfg.count, None
        manoeuvres = rng.random(n) < cfg.prob
        times = np.sort(rng.uniform(cfg.start_frac, cfg.end_frac, (slots, n)), axis=0)
        times *= duration_s
    angle = np.deg2rad(rng.uniform(cfg.course_change_min_deg, cfg.course_change_max_deg,
                                   (slots, n)))
    turn = np.where(rng.random((slots, n)) < 0.5, -angle, angle)
    rate = np.deg2rad(rng.uniform(cfg.turn_rate_min_deg_s, cfg.turn_rate_max_deg_s,
                                  (slots, n)))
    factor = rng.uniform(1 - cfg.speed_change_rel, 1 + cfg.speed_change_rel, (slots, n))
    if active is not None:
        turn, factor = np.where(active, turn, 0.0), np.where(active, factor, 1.0)
    start = np.empty((slots, n))
    turn_s, dv, dv_s = np.abs(turn) / rate, np.empty((slots, n)), np.empty((slots, n))
    speed, end = speed0.copy(), np.zeros(n)
    for j in range(slots):
        start[j] = np.maximum(times[j], end)
        dv[j] = speed * (factor[j] - 1)
        dv_s[j] = np.abs(dv[j]) / cfg.accel_m_s2
        speed = speed + dv[j]
        end = start[j] + np.maximum(turn_s[j], dv_s[j])
    off = ~manoeuvres
    turn[:, off], dv[:, off] = 0.0, 0.0
    last = np.maximum(count - 1, 0) if active is not None else np.full(n, slots - 1)
    return {"start": start, "turn": turn, "turn_s": turn_s, "dv": dv, "dv_s": dv_s,
            "manoeuvres": manoeuvres, "last": last}


def course_speed(plan, course0, speed0, t):
    """Course (rad) and speed (m/s) at times ``t`` (..., K) per target (n, K)."""
    course = np.broadcast_to(course0[:, None], (course0.size, t.shape[-1])).copy()
    speed = np.broadcast_to(speed0[:, None], course.shape).copy()
    for j in range(plan["start"].shape[0]):
        course += plan["turn"][j][:, None] * _ramp(t, plan["start"][j], plan["turn_s"][j])
        speed += plan["dv"][j][:, None] * _ramp(t, plan["start"][j], plan["dv_s"][j])
    return course, speed


def wander(q, t, n, rng):
    """Position and velocity deviations (x, y, vx, vy), each (n, K), of white random
    acceleration with spectral density ``q`` per axis, zero at t[0]."""
    T = np.diff(t)
    return _white_steps(q * T**3 / 3, q * T**2 / 2, q * T, T, n, rng)


def _white_steps(pp, pv, vv, T, n, rng):
    """Per axis, position and velocity deviations (n, K), zero at the first epoch, whose step
    into each epoch (steps ``T``, s) adds white-acceleration noise of covariance [[pp, pv],
    [pv, vv]] (each (K - 1,) or (n, K - 1): m^2, m^2/s, m^2/s^2), drawn exactly."""
    l11 = np.sqrt(pp)
    l21 = np.divide(pv, l11, out=np.zeros_like(l11), where=l11 > 0)
    l22 = np.sqrt(np.maximum(vv - l21**2, 0.0))
    u = rng.standard_normal((2, 2, n, T.size))  # (axis, position/velocity, track, step)
    out = []
    for axis in range(2):
        w_p = l11 * u[axis, 0]
        w_v = l21 * u[axis, 0] + l22 * u[axis, 1]
        v = np.concatenate([np.zeros((n, 1)), np.cumsum(w_v, axis=1)], axis=1)
        p = np.concatenate([np.zeros((n, 1)), np.cumsum(T * v[:, :-1] + w_p, axis=1)], axis=1)
        out.append((p, v))
    (px, vx), (py, vy) = out
    return px, py, vx, vy


def burst_deviations(t, start, duration, dv_m_s, rng):
    """Position and velocity deviations (x, y, vx, vy), each (n, K), at the epochs ``t`` (s)
    of white acceleration of density ``dv_m_s``^2 / D per axis over each burst [start, start
    + D] (``start``, ``duration``: (slots, n), s, inf: none), zero at t[0]: the estimators'
    manoeuvre (``manoeuvres.py``), each burst changing the velocity by N(0, dv^2) per axis.
    Drawn exactly: each step's covariance is that of the parts of the bursts within it
    (``manoeuvre_prior.burst_step_noise``)."""
    pp, pv, vv = burst_step_noise(t, start, duration, dv_m_s)
    return _white_steps(pp, pv, vv, np.diff(t), start.shape[1], rng)


def burst_plan(cfg: ManoeuvreConfig, prior: ManoeuvrePrior, t, n, rng):
    """Per target (n) of a log of epochs ``t`` (s), its manoeuvres of ``shape`` burst: how
    many (n,), their starts (slots, n; s in ``t``'s time, sorted, inf past the count: Poisson
    over the observation) and durations (slots, n; s, each one of ``prior``'s alike, 0 past
    the count). The first draws of the shard's manoeuvre stream ``rng``, so that the bursts
    of a dataset can be drawn again (``bench.py``'s check against the true manoeuvres)."""
    count, start = poisson_times(cfg.rate_per_h, float(t[-1] - t[0]), n, rng)
    durations = np.asarray(prior.durations_s, dtype=float)
    duration = np.where(np.isfinite(start), durations[rng.integers(0, durations.size,
                                                                   start.shape)], 0.0)
    return count, start + t[0], duration


def _burst_paths(cfg: ManoeuvreConfig, prior: ManoeuvrePrior, x0, y0, course0, speed0, t,
                 rng):
    """``target_paths``'s manoeuvres of ``shape`` burst (``burst_plan``), the velocity
    changed by ``prior.dv_m_s`` per axis over each (``burst_deviations``)."""
    n = x0.size
    count, start, duration = burst_plan(cfg, prior, t, n, rng)
    px, py, vx, vy = burst_deviations(t, start, duration, prior.dv_m_s, rng)
    v0 = np.column_stack([speed0 * np.sin(course0), speed0 * np.cos(course0)])
    x = x0[:, None] + v0[:, :1] * (t - t[0]) + px
    y = y0[:, None] + v0[:, 1:] * (t - t[0]) + py
    vx, vy = v0[:, :1] + vx, v0[:, 1:] + vy
    # the last burst: its course and speed change between the epochs about it
    on = count > 0
    j = np.maximum(count - 1, 0)
    last_start = np.where(on, np.take_along_axis(start, j[None], axis=0)[0], np.nan)
    last_end = last_start + np.take_along_axis(duration, j[None], axis=0)[0]
    rows = np.arange(n)
    k0 = np.clip(np.searchsorted(t, np.nan_to_num(last_start), side="right") - 1, 0, t.size - 1)
    k1 = np.clip(np.searchsorted(t, np.nan_to_num(last_end)), 0, t.size - 1)
    before = np.hypot(vx[rows, k0], vy[rows, k0])
    turn = np.rad2deg(np.arctan2(vx[rows, k1], vy[rows, k1]) - np.arctan2(vx[rows, k0],
                                                                          vy[rows, k0]))
    last = {"manoeuvre_start_s": last_start, "manoeuvre_end_s": last_end,
            "course_change_deg": np.where(on, wrap_to_180(turn), np.nan),
            "speed_change_rel": np.where(on, np.hypot(vx[rows, k1], vy[rows, k1]) / before
                                         - 1.0, np.nan),
            "n_manoeuvres": count.astype(np.int64)}
    return x, y, np.column_stack([vx[:, -1], vy[:, -1]]), last


def target_paths(cfg: TargetConfig, x0, y0, course0, speed0, t, manoeuvre_rng, wander_rng,
                 prior: ManoeuvrePrior | None = None):
    """Positions (n, K) of the targets at the bearing times ``t`` and their velocity at the
    last one (n, 2), and per target its last manoeuvre (start, end s; turn deg, speed
    factor; NaN where none) and ``n_manoeuvres``, how many manoeuvres started within the
    observation (one delayed past its end by the one before is not counted). Manoeuvres of
    ``shape`` burst take the size and durations of ``prior`` (what the log declares)."""
    if cfg.manoeuvres.shape == "burst" and cfg.manoeuvres.rate_per_h > 0:
        if prior is None:
            raise ValueError("target_paths: manoeuvres of shape burst need the prior they are "
                             "drawn from (prior=declared_prior(...))")
        x, y, v_end, last = _burst_paths(cfg.manoeuvres, prior, x0, y0, course0, speed0, t,
                                         manoeuvre_rng)
        return _wandering(cfg, t, x, y, v_end, wander_rng) + (last,)
    n = x0.size
    duration = float(t[-1] - t[0])
    plan = manoeuvre_plan(cfg.manoeuvres, duration, speed0, manoeuvre_rng)
    plan["start"] = plan["start"] + t[0]  # times of the log, as the bearings
    if plan["manoeuvres"].any():
        # velocity at the Gauss nodes of every bearing interval, integrated
        dt = np.diff(t)
        nodes = t[:-1, None] + dt[:, None] * np.array(GAUSS_NODES)  # (K - 1, 3)
        course, speed = course_speed(plan, course0, speed0, nodes.ravel())
        w = (dt[:, None] * np.array(GAUSS_WEIGHTS)).ravel()
        step_x = (speed * np.sin(course) * w).reshape(n, -1, 3).sum(axis=2)
        step_y = (speed * np.cos(course) * w).reshape(n, -1, 3).sum(axis=2)
        x = x0[:, None] + np.concatenate([np.zeros((n, 1)), np.cumsum(step_x, axis=1)], axis=1)
        y = y0[:, None] + np.concatenate([np.zeros((n, 1)), np.cumsum(step_y, axis=1)], axis=1)
        c_end, s_end = course_speed(plan, course0, speed0, t[-1:])
        v_end = np.column_stack([s_end[:, 0] * np.sin(c_end[:, 0]),
                                 s_end[:, 0] * np.cos(c_end[:, 0])])
    else:
        v0 = np.column_stack([speed0 * np.sin(course0), speed0 * np.cos(course0)])
        x = x0[:, None] + v0[:, :1] * (t - t[0])
        y = y0[:, None] + v0[:, 1:] * (t - t[0])
        v_end = v0
    x, y, v_end = _wandering(cfg, t, x, y, v_end, wander_rng)
    # the last manoeuvre that started within the observation
    # (delayed ones are sorted last; a slot without a manoeuvre starts at inf)
    j = plan["last"] - np.sum(np.isfinite(plan["start"]) & (plan["start"] > t[-1]), axis=0)
    on = plan["manoeuvres"] & (j >= 0)
    j = np.maximum(j, 0)

    def of(key):
        return np.take_along_axis(plan[key], j[None], axis=0)[0]

    last_start = np.where(on, of("start"), np.nan)
    last_end = last_start + np.maximum(of("turn_s"), of("dv_s"))
    before = np.arange(plan["dv"].shape[0])[:, None] < j
    speed_before = speed0 + np.sum(np.where(before, plan["dv"], 0.0), axis=0)
    # (read from the plan: no draw added, every other column as before)
    started = np.where(plan["manoeuvres"], np.sum(plan["start"] <= t[-1], axis=0), 0)
    last = {"manoeuvre_start_s": last_start, "manoeuvre_end_s": last_end,
            "course_change_deg": np.where(on, np.rad2deg(of("turn")), np.nan),
            "speed_change_rel": np.where(on, of("dv") / speed_before, np.nan),
            "n_manoeuvres": started.astype(np.int64)}
    return x, y, v_end, last


def _wandering(cfg: TargetConfig, t, x, y, v_end, rng):
    """The paths (n, K) and last velocities (n, 2) with the wander added (q > 0)."""
    if cfg.accel_psd_m2_s3 > 0:
        px, py, vx, vy = wander(cfg.accel_psd_m2_s3, t, x.shape[0], rng)
        x, y = x + px, y + py
        v_end = v_end + np.column_stack([vx[:, -1], vy[:, -1]])
    return x, y, v_end
