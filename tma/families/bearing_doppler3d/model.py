"""Manoeuvring underwater vehicle observed by fixed hydrophones (bearing + Doppler): the
family's model, written once. The scenario simulates with it and every estimator receives it
(``AuvModel.from_record(log.model)``), Stone Soup style.

State ``(X, Y, Z, v, phi, a)``: position (m; X east, Y north, Z up), speed (m/s), heading
(rad, from +X counter-clockwise: this family keeps the paper's convention), normal
acceleration (m/s^2). Itô SDE: dX = v cos(phi) dt, dY = v sin(phi) dt, dZ = dv = 0,
dphi = a / v dt, da = (-lambda a + nu) dt + mu dW.

Per sensor S: xi = (Z - Z_S) / R (sine of elevation), eta = (X - X_S) / r (cosine of the
horizontal bearing), omega = omega0 / (1 + V / C) with V = d . velocity / R the range rate
(d = P - S, R = |d|, r = |d_xy|). Readings: (xi, eta, omega) per sensor, sensor by sensor;
without Doppler (xi, eta).

Layout, as in FilterPy: states are columns. x (6, n) holds n paths, so ``x[PHI]`` is every
path's heading; covariances are (6, 6, n), readings h (m, n), observation Jacobians
(m, 6, n). Arrays with paths first (datasets (n, K, 6), the CMNF's samples (n, 6)) are passed
transposed (``x.T``, a view).
"""

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from tma.config import to_plain
from tma.errors import ConfigError
from tma.runtime.jit import njit

X, Y, Z, V, PHI, A = range(6)
# The drift Jacobian's non-zero entries, in the order of the rows of ``jacobian_columns``.
JACOBIAN_ENTRIES = ((X, V), (X, PHI), (Y, V), (Y, PHI), (PHI, V), (PHI, A), (A, A))
SERIES_MAX = 1e-2  # |angle| up to which ``unit_rotation``'s series is exact to rounding
STATE_NAMES = ("X_m", "Y_m", "Z_m", "v_m_s", "phi_rad", "a_m_s2")
# Keys of a scenario config the filters do not know (everything else is the model record).
SCENARIO_ONLY = ("family", "n_tracks", "seed", "shard_size", "epoch_utc")  # not the model


def model_record(scenario_config) -> dict:
    """What the filters may know of a scenario config (the ``Config`` or its plain dict, e.g.
    a dataset manifest's ``config``): everything but the seed and the number of paths. Logs
    carry it as their metadata record ``tma.model``."""
    return {k: v for k, v in to_plain(scenario_config).items() if k not in SCENARIO_ONLY}


@dataclass(frozen=True)
class InitialDistribution:
    """x_0: independent Gaussian position, uniform speed, Gaussian heading, uniform a."""

    position_mean_m: list[float]
    position_sd_m: list[float]
    speed_min_m_s: float
    speed_max_m_s: float
    heading_mean_rad: float
    heading_sd_rad: float
    accel_min_m_s2: float
    accel_max_m_s2: float

    def sample(self, n: int, rng) -> np.ndarray:
        """n draws, states as columns (6, n)."""
        x = np.empty((n, 6))
        x[:, :3] = np.asarray(self.position_mean_m) + np.asarray(
            self.position_sd_m) * rng.standard_normal((n, 3))
        x[:, V] = rng.uniform(self.speed_min_m_s, self.speed_max_m_s, n)
        x[:, PHI] = self.heading_mean_rad + self.heading_sd_rad * rng.standard_normal(n)
        x[:, A] = rng.uniform(self.accel_min_m_s2, self.accel_max_m_s2, n)
        return x.T

    def moments(self):
        """Mean (6,) and covariance (6, 6), exactly."""
        mean = np.array([*self.position_mean_m,
                         0.5 * (self.speed_min_m_s + self.speed_max_m_s),
                         self.heading_mean_rad,
                         0.5 * (self.accel_min_m_s2 + self.accel_max_m_s2)])
        f = np.float64  # numpy scalars: an absurd scale gives inf (flagged), not OverflowError
        var = np.array([*np.square(self.position_sd_m),
                        f(self.speed_max_m_s - self.speed_min_m_s) ** 2 / 12,
                        f(self.heading_sd_rad) ** 2,
                        f(self.accel_max_m_s2 - self.accel_min_m_s2) ** 2 / 12])
        return mean, np.diag(var)


@dataclass(frozen=True)
class AuvModel:
    """Dynamics, measurement, their Jacobians, the initial distribution and the readings of
    one observation model (with or without Doppler); built from a model record."""

    lam: float  # 1/s
    nu: float  # m/s^3
    mu: float  # m/s^2 / sqrt(s): the diffusion b = (0, 0, 0, 0, 0, mu)
    sensors_m: np.ndarray  # (n_sensors, 3)
    omega0_hz: float
    sound_speed_m_s: float
    sd_angle: float  # std of xi and eta
    sd_doppler_hz: float
    initial: InitialDistribution
    duration_s: float  # observations at 0, obs_period_s, ..., duration_s
    obs_period_s: float
    truth_step_s: float  # Euler-Maruyama step of the simulation
    filter_step_s: float  # Euler step of the filters' prediction
    doppler: bool = True  # False: bearings only (xi, eta per sensor)

    @classmethod
    def from_record(cls, record: dict) -> "AuvModel":
        """The model a log's (or a dataset's) model record describes."""
        initial = record["initial"]
        return cls(
            lam=record["lam"], nu=record["nu"], mu=record["mu"],
            sensors_m=np.asarray(record["sensors_m"]), omega0_hz=record["omega0_hz"],
            sound_speed_m_s=record["sound_speed_m_s"], sd_angle=record["sd_angle"],
            sd_doppler_hz=record["sd_doppler_hz"],
            initial=InitialDistribution(**{f.name: initial[f.name]
                                           for f in fields(InitialDistribution)}),
            duration_s=record["duration_s"], obs_period_s=record["obs_period_s"],
            truth_step_s=record["truth_step_s"], filter_step_s=record["filter_step_s"],
            doppler=not record["no_doppler"])

    def epochs(self) -> np.ndarray:
        """The observation times (K,)."""
        n = int(round(self.duration_s / self.obs_period_s)) + 1
        return np.arange(n) * self.obs_period_s

    # ------------------------------------------------------------------------- dynamics

    def drift(self, x):
        """a(x) at states x (6, ...) (``drift_columns``)."""
        flat = np.asarray(x, dtype=float).reshape(6, -1)
        out = np.zeros_like(flat)
        drift_columns(flat, np.cos(flat[PHI]), np.sin(flat[PHI]), self.lam, self.nu, out)
        return out.reshape(np.shape(x))

    def drift_jacobian(self, x, dt=1.0):
        """F dt, F = da/dx the drift Jacobian at states x (6, ...), as its non-zero entries
        ``{(row, column): values}`` (``jacobian_columns``); Phi = I + F dt is the Euler
        transition of the linearised SDE (``transition_times``). dt = 1 gives F itself."""
        flat = np.asarray(x, dtype=float).reshape(6, -1)
        F = np.empty((len(JACOBIAN_ENTRIES), flat.shape[1]))
        jacobian_columns(flat, np.cos(flat[PHI]), np.sin(flat[PHI]), self.lam, float(dt), F)
        return {key: F[i].reshape(np.shape(x)[1:]) for i, key in enumerate(JACOBIAN_ENTRIES)}

    def euler_step(self, x, dt):
        """x + a(x) dt: one Euler step of the mean (the filters' prediction)."""
        return x + self.drift(x) * dt

    def n_filter_steps(self, duration_s) -> int:
        return int(round(duration_s / self.filter_step_s))

    def predict_mean(self, x, duration_s):
        """Euler steps of ``filter_step_s`` over ``duration_s``: dx = a(x) dt."""
        for _ in range(self.n_filter_steps(duration_s)):
            x = self.euler_step(x, self.filter_step_s)
        return x

    # ---------------------------------------------------------------------- measurement

    @property
    def n_obs(self) -> int:
        return self.sensors_m.shape[0] * (3 if self.doppler else 2)

    @property
    def obs_sd(self) -> np.ndarray:
        """Standard deviations of the readings (m,) (R is diagonal)."""
        per = [self.sd_angle, self.sd_angle] + ([self.sd_doppler_hz] if self.doppler else [])
        return np.tile(per, self.sensors_m.shape[0])

    def select_readings(self, full):
        """This model's readings out of full ones (..., 3 n_sensors), (xi, eta, omega) per
        sensor: without Doppler each sensor's omega is dropped."""
        if self.doppler:
            return full
        lead = full.shape[:-1]
        return full.reshape(*lead, -1, 3)[..., :2].reshape(*lead, -1)

    def observe(self, x):
        """h(x) (m, n) at states x (6, n)."""
        return self._observe(x.T, jacobian=False)[0].T

    def observe_with_jacobian(self, x):
        """h(x) (m, n) and H = dh/dx (m, 6, n) at states x (6, n)."""
        h, jac = self._observe(x.T, jacobian=True)
        return h.T, jac.transpose(1, 2, 0)

    def _observe(self, x, jacobian):
        """h (n, m) and dh/dx (n, m, 6) at states x (n, 6): computed with paths first."""
        n, k = x.shape[0], self.sensors_m.shape[0]
        d = x[:, None, :3] - self.sensors_m[None]  # (n, k, 3)
        R = np.linalg.norm(d, axis=-1)
        r = np.hypot(d[..., 0], d[..., 1])
        ones = np.ones_like(R)
        c, s = np.cos(x[:, PHI])[:, None] * ones, np.sin(x[:, PHI])[:, None] * ones
        v = x[:, V][:, None] * ones
        vel = np.stack([v * c, v * s, np.zeros_like(R)], axis=-1)  # (n, k, 3)
        rate = np.einsum("nki,nki->nk", d, vel) / R
        xi = d[..., 2] / R
        eta = d[..., 0] / r
        denom = 1.0 + rate / self.sound_speed_m_s
        omega = self.omega0_hz / denom
        parts = [xi, eta] + ([omega] if self.doppler else [])
        h = np.stack(parts, axis=-1).reshape(n, -1)
        if not jacobian:
            return h, None
        per = len(parts)
        jac = np.zeros((n, k, per, 6))
        # xi = dz / R: d/dP = e_z / R - dz d / R^3
        jac[..., 0, :3] = -(d[..., 2] / R**3)[..., None] * d
        jac[..., 0, 2] += 1.0 / R
        # eta = dx / r: d/d(x, y) = e_x / r - dx d_xy / r^3
        jac[..., 1, 0] = 1.0 / r - d[..., 0] ** 2 / r**3
        jac[..., 1, 1] = -d[..., 0] * d[..., 1] / r**3
        if self.doppler:
            # omega = omega0 / (1 + V/C): d omega = -omega0 / (C (1 + V/C)^2) dV
            g = -self.omega0_hz / (self.sound_speed_m_s * denom**2)
            dV_dP = vel / R[..., None] - (rate / R**2)[..., None] * d
            heading = np.stack([c, s, np.zeros_like(R)], -1)
            turn = np.stack([-v * s, v * c, np.zeros_like(R)], -1)
            jac[..., 2, :3] = g[..., None] * dV_dP
            jac[..., 2, V] = g * np.einsum("nki,nki->nk", d, heading) / R
            jac[..., 2, PHI] = g * np.einsum("nki,nki->nk", d, turn) / R
        return h, jac.reshape(n, k * per, 6)

    # ----------------------------------------------------------------------- simulation

    def euler_maruyama(self, x0, duration_s, rng):
        """Advance true states x0 (6, n) by ``duration_s`` with Euler-Maruyama steps of
        ``truth_step_s``.

        The recurrences a_(k+1) = (1 - lam dt) a_k + nu dt + mu sqrt(dt) xi_k,
        phi_(k+1) = phi_k + a_k / v dt, X_(k+1) = X_k + v cos(phi_k) dt, Y likewise, are
        evaluated for all steps at once, vectorised over paths: a by a linear filter, and
        exp(i phi_k) = exp(i phi_0) prod_(j<k) exp(i (phi_(j+1) - phi_j)) by a cumulative
        product (cheaper than a cosine and a sine per step; equal to them to ~1e-14). The
        driving normals are drawn in single precision (half the cost, ample resolution for
        noise).
        """
        dt_s = self.truth_step_s
        n_steps = int(round(duration_s / dt_s))
        x = x0.copy()
        n = x.shape[1]
        v = x[V]
        forcing = rng.standard_normal((n, n_steps), dtype=np.float32) * np.float64(
            self.mu * np.sqrt(dt_s))
        if self.nu:
            forcing += self.nu * dt_s
        rho = 1.0 - self.lam * dt_s
        from scipy.signal import lfilter  # here: importing scipy.signal costs every CLI ~1 s

        a_next = lfilter([1.0], [1.0, -rho], forcing, axis=1, zi=(rho * x[A])[:, None])[0]
        dphi = np.empty((n, n_steps))  # phi_(k+1) - phi_k = a_k dt / v
        dphi[:, 0] = x[A]
        dphi[:, 1:] = a_next[:, :-1]
        dphi *= (dt_s / v)[:, None]
        turns = _unit_rotations(dphi[:, :-1])
        rel = 1.0 + np.cumprod(turns, axis=1).sum(axis=1)  # sum_k exp(i (phi_k - phi_0))
        heading = rel * np.exp(1j * x[PHI])
        x[X] += v * dt_s * heading.real
        x[Y] += v * dt_s * heading.imag
        x[PHI] += dphi.sum(axis=1)
        x[A] = a_next[:, -1]
        return x

    def simulate(self, n: int, rng):
        """n paths from the initial distribution: truth at the epochs (n, K, 6) and the full
        readings (n, K, 3 n_sensors). Doppler is read whatever ``doppler`` says, so that both
        variants share truth and noise; ``select_readings`` keeps this model's own."""
        t = self.epochs()
        full = replace(self, doppler=True)
        with np.errstate(all="ignore"):  # checked below, with a message that says what to change
            x = self.initial.sample(n, rng)
            truth = np.empty((n, t.size, 6))
            truth[:, 0] = x.T
            for k in range(1, t.size):
                x = self.euler_maruyama(x, self.obs_period_s, rng)
                truth[:, k] = x.T
            clean = full.observe(truth.reshape(-1, 6).T).T.reshape(n, t.size, -1)
            obs = clean + full.obs_sd * rng.standard_normal(clean.shape)
        if not (np.isfinite(truth).all() and np.isfinite(obs).all()):
            raise ConfigError("scenario 'bearing_doppler3d': the simulated paths overflow "
                              "(non-finite states or readings): the scales of mu, nu, initial, "
                              "sensors_m or omega0_hz are beyond float64")
        return truth, obs


def transition_times(F, M, at=range(6)):
    """M <- Phi M in place (``transition``), Phi = I + F dt with F dt given by
    ``AuvModel.drift_jacobian``; M (6, ...) holds state i in row ``at[i]``, the entries of F
    broadcast against M[0]. For M Phi^T, pass M transposed (a view)."""
    entries = np.stack([np.broadcast_to(np.asarray(F[key], dtype=float), M.shape[1:])
                        for key in JACOBIAN_ENTRIES]).reshape(len(JACOBIAN_ENTRIES), -1)
    flat = M.reshape(6, 1, -1)  # a view of M when its layout allows, else a copy
    transition(flat, np.ascontiguousarray(entries), np.asarray(at, dtype=np.int64))
    if not np.shares_memory(flat, M):
        M[...] = flat.reshape(M.shape)
    return M


# --------------------------------------------------------------- compiled per-state pieces
# Loops over columns (states, or paths) that the filters call inside their compiled loops and
# the vectorised methods above call on whole arrays: the model's dynamics written once.


@njit(error_model="numpy")
def drift_columns(x, cos_phi, sin_phi, lam, nu, out):
    """a(x) for states x (6, k) into ``out`` (6, k) (rows X, Y, phi, a; the zero rows Z and v
    are not written), cos and sin of each heading given."""
    for p in range(x.shape[1]):
        v, a = x[V, p], x[A, p]
        out[X, p] = v * cos_phi[p]
        out[Y, p] = v * sin_phi[p]
        out[PHI, p] = a / v
        out[A, p] = -lam * a + nu


@njit(error_model="numpy")
def jacobian_columns(x, cos_phi, sin_phi, lam, dt, F):
    """The drift Jacobian's non-zero entries times dt at states x (6, k) into F (7, k), in the
    order of ``JACOBIAN_ENTRIES``. Each entry is computed with dt folded in (dt / v, not
    (1 / v) dt), as the filters always have: another order changes the last bits."""
    for p in range(x.shape[1]):
        c, s, v, a = cos_phi[p], sin_phi[p], x[V, p], x[A, p]
        F[0, p] = c * dt
        F[1, p] = -(v * s * dt)
        F[2, p] = s * dt
        F[3, p] = v * c * dt
        F[4, p] = -a / (v * v) * dt
        F[5, p] = dt / v
        F[6, p] = -lam * dt


@njit()
def transition(M, F, at):
    """M <- Phi M in place for M (6, c, k): state i in row ``at[i]``, column j of path p in
    M[:, j, p], F (7, k) from ``jacobian_columns``. Each row is updated before the rows it
    reads: X and Y read v and phi, phi reads v and a."""
    x_, y_, v_, phi_, a_ = at[X], at[Y], at[V], at[PHI], at[A]
    for j in range(M.shape[1]):
        for p in range(M.shape[2]):
            M[x_, j, p] += F[0, p] * M[v_, j, p] + F[1, p] * M[phi_, j, p]
            M[y_, j, p] += F[2, p] * M[v_, j, p] + F[3, p] * M[phi_, j, p]
            M[phi_, j, p] += F[4, p] * M[v_, j, p] + F[5, p] * M[a_, j, p]
            M[a_, j, p] *= 1.0 + F[6, p]


@njit()
def unit_rotation(delta):
    """(cos delta, sin delta) by their series, exact to rounding for |delta| < SERIES_MAX."""
    d2 = delta * delta
    return (1.0 - d2 * (0.5 - d2 * (1.0 / 24.0 - d2 / 720.0)),
            delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 / 5040.0))))


@njit(error_model="numpy")
def euler_columns(x, cos_phi, sin_phi, lam, nu, dt):
    """x <- x + a(x) dt for states x (6, k) in place, and cos and sin of each heading carried
    to the new heading by a rotation through its increment a / v dt (the series; exact
    cosines and sines where the increment exceeds SERIES_MAX). Carried over the 100 filter
    steps of an epoch they stay within ~1e-14 of cos(phi), sin(phi)."""
    large = False
    for p in range(x.shape[1]):
        v, a, c, s = x[V, p], x[A, p], cos_phi[p], sin_phi[p]
        dphi = a / v * dt
        x[X, p] += v * c * dt
        x[Y, p] += v * s * dt
        x[PHI, p] += dphi
        x[A, p] += (-lam * a + nu) * dt
        cd, sd = unit_rotation(dphi)
        cos_phi[p], sin_phi[p] = c * cd - s * sd, s * cd + c * sd
        large |= not abs(dphi) <= SERIES_MAX
    if large:  # rare (a path far outside the model): a scalar pass apart keeps the above SIMD
        for p in range(x.shape[1]):
            if not abs(x[A, p] / x[V, p] * dt) <= SERIES_MAX:
                cos_phi[p], sin_phi[p] = math.cos(x[PHI, p]), math.sin(x[PHI, p])


def _unit_rotations(delta):
    """exp(i delta) for small angles by the series of ``unit_rotation``."""
    if np.max(np.abs(delta), initial=0.0) > SERIES_MAX:
        return np.exp(1j * delta)
    out = np.empty(delta.shape, dtype=complex)
    _unit_rotations_into(delta.reshape(-1), out.reshape(-1))
    return out


@njit()
def _unit_rotations_into(delta, out):
    for i in range(delta.size):
        re, im = unit_rotation(delta[i])
        out[i] = complex(re, im)
