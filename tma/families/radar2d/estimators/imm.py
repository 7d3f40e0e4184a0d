"""``imm``: interacting multiple model filter, constant velocity + coordinated turn (EKF on
(x, vx, y, vy, omega)) with Markov switching, batched over the Monte Carlo runs.

The modern baseline for a manoeuvring boat (beyond the article). Measurement covariance from
the log's sensor record: isotropic ``sigma_m`` or, for polar radar noise, the range/bearing
covariance converted to Cartesian at each plot. Starts from the two-point line of the first
two plots; records the model probabilities per scan.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import is_probability_vector, param, require
from tma.families.radar2d.estimators.base import RadarConfig, RadarEstimator, Scans, Solution
from tma.families.radar2d.turn import constant_velocity, coordinated_turn, white_acceleration_noise

H = np.zeros((2, 5))
H[0, 0] = H[1, 2] = 1.0


@dataclass
class Config(RadarConfig):
    p_stay: float = param(0.95, "Markov probability of keeping the model between scans",
                          "(0, 1]")
    cv_accel_psd: float = param(0.01, "acceleration noise PSD of the constant-velocity model "
                                "(m^2/s^3)", "[0, inf)")
    ct_accel_psd: float = param(0.1, "acceleration noise PSD of the coordinated-turn model "
                                "(m^2/s^3)", "[0, inf)")
    ct_omega_psd: float = param(1e-4, "PSD of the turn-rate random walk (rad^2/s^3)", "[0, inf)")
    initial_omega_sd: float = param(0.1, "initial turn-rate standard deviation (rad/s)",
                                    "[0, inf)")
    initial_probs: list[float] = param(doc="initial model probabilities (CV, CT): two, summing "
                                       "to 1", each="[0, 1]", factory=lambda: [0.9, 0.1])

    def __post_init__(self):
        super().__post_init__()
        require(is_probability_vector(self.initial_probs, 2), self.where,
                "initial_probs must be two probabilities in [0, 1] summing to 1 (CV, CT)")


def measurement_covariance(sensor: dict, plots):
    """R (n, 2, 2) per plot."""
    n = plots.shape[0]
    if sensor["noise"] == "cartesian":
        # numpy scalars: an absurd sigma gives inf (runs flagged), not OverflowError
        return np.broadcast_to(np.float64(sensor["sigma_m"]) ** 2 * np.eye(2), (n, 2, 2)).copy()
    dx, dy = plots[:, 0] - sensor["radar_x_m"], plots[:, 1] - sensor["radar_y_m"]
    r, b = np.hypot(dx, dy), np.arctan2(dx, dy)
    J = np.stack([np.stack([np.sin(b), r * np.cos(b)], -1),
                  np.stack([np.cos(b), -r * np.sin(b)], -1)], axis=1)
    D = np.diag([np.float64(sensor["range_sd_m"]) ** 2,
                 np.deg2rad(sensor["bearing_sd_deg"]) ** 2])
    return J @ D @ J.transpose(0, 2, 1)


class IMM(RadarEstimator):
    outputs = ("p_cv", "p_turn")  # model probabilities
    Config = Config

    def solve(self, scans: Scans) -> Solution:
        cfg, tau = self.config, scans.tau_s
        z = scans.plots_m
        n, n_scans, _ = z.shape
        est = np.full((n, n_scans, 5), np.nan)
        probs = np.full((n, n_scans, 2), np.nan)
        # scans 1-2: the growing-memory fit (position of the first plot, then the 2-point line)
        est[:, 0, [0, 2]] = z[:, 0]
        est[:, 0, [1, 3]] = 0.0
        est[:, 1, [0, 2]] = z[:, 1]
        est[:, 1, [1, 3]] = (z[:, 1] - z[:, 0]) / tau
        R = measurement_covariance(scans.sensor, np.nan_to_num(z[:, 1]))
        x = np.zeros((2, n, 5))
        x[:, :, :4] = est[:, 1, :4]
        P = np.zeros((2, n, 5, 5))
        for a, (p, v) in enumerate([(0, 1), (2, 3)]):
            P[:, :, p, p] = R[:, a, a]
            P[:, :, p, v] = P[:, :, v, p] = R[:, a, a] / tau
            P[:, :, v, v] = 2 * R[:, a, a] / tau**2
        P[:, :, 4, 4] = np.float64(cfg.initial_omega_sd) ** 2  # inf, not OverflowError
        mu = np.broadcast_to(np.asarray(cfg.initial_probs, float), (n, 2)).copy()
        probs[:, 1] = mu
        trans = np.array([[cfg.p_stay, 1 - cfg.p_stay], [1 - cfg.p_stay, cfg.p_stay]])
        F_cv = constant_velocity(tau)
        Q = [white_acceleration_noise(tau, cfg.cv_accel_psd),
             white_acceleration_noise(tau, cfg.ct_accel_psd, cfg.ct_omega_psd)]

        for i in range(2, n_scans):
            # 1. mixing
            c = mu @ trans  # (n, 2): predicted model probabilities
            # w[n, i, j] = P(i | j); a model with zero probability mixes from nothing
            w = mu[:, :, None] * trans[None] / np.maximum(c, 1e-300)[:, None, :]
            x0 = np.einsum("nij,ink->jnk", w, x)
            dx = x[:, None] - x0[None]  # (i, j, n, 5)
            P0 = np.einsum("nij,inkl->jnkl", w, P) + np.einsum(
                "nij,ijnk,ijnl->jnkl", w, dx, dx)
            # 2. predict
            x[0] = x0[0] @ F_cv.T
            P[0] = F_cv @ P0[0] @ F_cv.T + Q[0]
            x[1], Fj = coordinated_turn(x0[1], tau)
            P[1] = Fj @ P0[1] @ Fj.transpose(0, 2, 1) + Q[1]
            # 3. update where there is a plot
            has = np.isfinite(z[:, i]).all(axis=1)
            R = measurement_covariance(scans.sensor, np.where(has[:, None], z[:, i], 0.0))
            likelihood, log_lik = np.ones((n, 2)), np.zeros((n, 2))
            for j in range(2):
                nu = np.where(has[:, None], z[:, i] - x[j] @ H.T, 0.0)
                S = H @ P[j] @ H.T + R
                # a wrecked run (non-finite or singular S) must not stop the others: it is
                # given S = I here and its estimate made NaN below (flagged divergent)
                wrecked = ~(np.isfinite(S).all(axis=(1, 2)) & (np.linalg.det(S) > 0))
                S[wrecked] = np.eye(2)
                # the batched matrix update (2-D plots), whose S the mode likelihood needs
                K = P[j] @ H.T @ np.linalg.inv(S)
                x[j] = x[j] + np.einsum("nij,nj->ni", K, nu)
                P[j] = np.where(has[:, None, None], P[j] - K @ S @ K.transpose(0, 2, 1), P[j])
                P[j] = 0.5 * (P[j] + P[j].transpose(0, 2, 1))
                x[j][wrecked] = np.nan
                maha = np.einsum("ni,nij,nj->n", nu, np.linalg.inv(S), nu)
                det = np.linalg.det(S)
                likelihood[:, j] = np.where(
                    has, np.exp(-0.5 * maha) / (2 * np.pi * np.sqrt(det)), 1.0)
                log_lik[:, j] = np.where(has, -0.5 * (maha + np.log(det)), 0.0)
            # 4. model probabilities and the combined estimate; far from a plot both
            # likelihoods underflow (0/0): there they are normalised in log space
            mu = likelihood * c
            total = mu.sum(axis=1, keepdims=True)
            under = ~(total[:, 0] > 0)
            if under.any():
                shifted = log_lik[under] - log_lik[under].max(axis=1, keepdims=True)
                mu[under] = np.exp(shifted) * c[under]
                total[under] = mu[under].sum(axis=1, keepdims=True)
            mu /= total
            probs[:, i] = mu
            est[:, i] = np.einsum("nj,jnk->nk", mu, x)
        return Solution(est[..., [0, 2]], est[..., [1, 3]],
                        {"p_cv": probs[..., 0], "p_turn": probs[..., 1]})
