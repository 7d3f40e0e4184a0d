"""Manoeuvring underwater vehicle observed by fixed hydrophones (bearing + Doppler).

State ``(X, Y, Z, v, phi, a)``: position (m; X east, Y north, Z up), speed (m/s), heading
(rad, from +X counter-clockwise: this family keeps the paper's convention), normal
acceleration (m/s^2). Itô SDE: dX = v cos(phi) dt, dY = v sin(phi) dt, dZ = dv = 0,
dphi = a / v dt, da = (-lambda a + nu) dt + mu dW.

Per sensor S: xi = (Z - Z_S) / R (sine of elevation), eta = (X - X_S) / r (cosine of the
horizontal bearing), omega = omega0 / (1 + V / C) with V = d . velocity / R the range rate
(d = P - S, R = |d|, r = |d_xy|). Observation vector: (xi, eta, omega) per sensor, sensor by
sensor; without Doppler (xi, eta). Arrays put paths on the leading axis: states (n, 6).
"""

from dataclasses import dataclass

import numpy as np

X, Y, Z, V, PHI, A = range(6)
STATE_NAMES = ("X_m", "Y_m", "Z_m", "v_m_s", "phi_rad", "a_m_s2")


@dataclass(frozen=True)
class AuvModel:
    lam: float  # 1/s
    nu: float  # m/s^3
    mu: float  # m/s^2 / sqrt(s)
    sensors_m: np.ndarray  # (n_sensors, 3)
    omega0_hz: float
    sound_speed_m_s: float
    sd_angle: float  # std of xi and eta
    sd_doppler_hz: float
    doppler: bool = True

    @property
    def n_obs(self) -> int:
        return self.sensors_m.shape[0] * (3 if self.doppler else 2)

    @property
    def obs_sd(self) -> np.ndarray:
        per = [self.sd_angle, self.sd_angle] + ([self.sd_doppler_hz] if self.doppler else [])
        return np.tile(per, self.sensors_m.shape[0])

    def drift(self, x):
        """a(x), (n, 6)."""
        out = np.zeros_like(x)
        out[:, X] = x[:, V] * np.cos(x[:, PHI])
        out[:, Y] = x[:, V] * np.sin(x[:, PHI])
        out[:, PHI] = x[:, A] / x[:, V]
        out[:, A] = -self.lam * x[:, A] + self.nu
        return out

    def drift_jacobian(self, x):
        """d a / d x, (n, 6, 6)."""
        jac = np.zeros((x.shape[0], 6, 6))
        c, s = np.cos(x[:, PHI]), np.sin(x[:, PHI])
        jac[:, X, V], jac[:, X, PHI] = c, -x[:, V] * s
        jac[:, Y, V], jac[:, Y, PHI] = s, x[:, V] * c
        jac[:, PHI, V], jac[:, PHI, A] = -x[:, A] / x[:, V] ** 2, 1.0 / x[:, V]
        jac[:, A, A] = -self.lam
        return jac

    def predict_mean(self, x, duration_s, step_s):
        """Euler integration of dx = a(x) dt (the filters' own prediction of the mean)."""
        for _ in range(int(round(duration_s / step_s))):
            x = x + self.drift(x) * step_s
        return x

    def observe(self, x):
        """h(x), (n, n_obs)."""
        return self._observe(x, jacobian=False)[0]

    def observe_with_jacobian(self, x):
        """h(x) (n, n_obs) and dh/dx (n, n_obs, 6)."""
        return self._observe(x, jacobian=True)

    def _observe(self, x, jacobian):
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


def _unit_rotations(delta):
    """exp(i delta) for small angles by its series (exact to rounding for |delta| < 1e-2)."""
    if np.max(np.abs(delta), initial=0.0) > 1e-2:
        return np.exp(1j * delta)
    d2 = delta * delta
    out = np.empty(delta.shape, dtype=complex)
    out.real = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0 - d2 / 720.0))
    out.imag = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 / 5040.0)))
    return out


def euler_maruyama(x0, duration_s, dt_s, lam, nu, mu, rng):
    """Advance states (n, 6) by ``duration_s`` with Euler-Maruyama steps ``dt_s``.

    The recurrences a_(k+1) = (1 - lam dt) a_k + nu dt + mu sqrt(dt) xi_k,
    phi_(k+1) = phi_k + a_k / v dt, X_(k+1) = X_k + v cos(phi_k) dt, Y likewise, are evaluated
    for all steps at once, vectorised over paths: a by a linear filter, and
    exp(i phi_k) = exp(i phi_0) prod_(j<k) exp(i (phi_(j+1) - phi_j)) by a cumulative product
    (cheaper than a cosine and a sine per step; equal to them to ~1e-14). The driving normals
    are drawn in single precision (half the cost, ample resolution for noise).
    """
    from scipy.signal import lfilter

    n_steps = int(round(duration_s / dt_s))
    x = x0.copy()
    n = x.shape[0]
    v = x[:, V]
    forcing = rng.standard_normal((n, n_steps), dtype=np.float32) * np.float64(mu * np.sqrt(dt_s))
    if nu:
        forcing += nu * dt_s
    rho = 1.0 - lam * dt_s
    a_next = lfilter([1.0], [1.0, -rho], forcing, axis=1, zi=(rho * x[:, A])[:, None])[0]
    dphi = np.empty((n, n_steps))  # phi_(k+1) - phi_k = a_k dt / v
    dphi[:, 0] = x[:, A]
    dphi[:, 1:] = a_next[:, :-1]
    dphi *= (dt_s / v)[:, None]
    turns = _unit_rotations(dphi[:, :-1])
    rel = 1.0 + np.cumprod(turns, axis=1).sum(axis=1)  # sum_k exp(i (phi_k - phi_0))
    heading = rel * np.exp(1j * x[:, PHI])
    x[:, X] += v * dt_s * heading.real
    x[:, Y] += v * dt_s * heading.imag
    x[:, PHI] += dphi.sum(axis=1)
    x[:, A] = a_next[:, -1]
    return x
