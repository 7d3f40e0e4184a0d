"""``fuzzy_mm``: a bank of alpha-beta filters over the last 2..J scans, with a zero-order
Sugeno system choosing the memory length from normalised residuals (``tma.families.radar2d.fuzzy``).

At scan i (1-based), model j is the growing-memory alpha-beta fit of the last j scans (all
scans while fewer exist). Its residual is the one-step innovation r_j = z_i - H Phi x_j(i-1)
of the fit of the j scans before z_i; L_j = |r_j| / sigma_hat clipped to 3. sigma_hat is the
causal running RMS of the selected model's innovation norm with a prior of ``sigma_prior_m``
worth one sample (or fixed by ``sigma_hat_m``). The selection m_i = round_half_up(max(raw_i,
raw_(i-1))) clipped to [2, J] starts at scan 3; the output is the model-m_i estimate. A scan
without a plot keeps the previous selection and sigma_hat; a model whose window holds no plot
(missed scans) counts as Bad.
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.families.radar2d.estimators.base import (
    RadarConfig,
    RadarEstimator,
    Scans,
    Solution,
    alpha_beta_window,
)
from tma.families.radar2d.fuzzy import memory_length_selector

# The bank refits J - 1 windows of up to J scans at every scan (cost ~ J^2 per scan) and the
# rule base has J rules of J - 1 inputs: beyond this, memory is a mistake, not a setting.
MAX_MEMORY = 200


@dataclass
class Config(RadarConfig):
    memory: int = param(10, "J, the longest memory (scans) in the bank", f"[3, {MAX_MEMORY}]")
    bad_slope: float = param(5.0, "a in Bad(u) = 1 / (1 + exp(-a (u - c))) (Bad rises with the "
                             "normalised residual u)", "(0, inf)")
    bad_centre: float = param(1.5, "c in Bad(u); below residual_clip", "(0, inf)")
    residual_clip: float = param(3.0, "normalised residuals are clipped at this", "(0, inf)")
    sigma_prior_m: float = param(15.0, "weak prior of sigma_hat (m), worth one sample",
                                 "(0, inf)")
    sigma_hat_m: float | None = param(None, "a fixed plot noise sigma_hat (m); null: estimated",
                                      "(0, inf)")

    def __post_init__(self):
        super().__post_init__()
        require(self.bad_centre < self.residual_clip, self.where,
                "bad_centre must lie in (0, residual_clip): residuals are clipped there")


def bank_estimates(plots, tau, J):
    """Model j = 2..J at every scan: (pos, vel) arrays (n, n_scans, J - 1, 2)."""
    n, n_scans, _ = plots.shape
    pos, vel = np.empty((n, n_scans, J - 1, 2)), np.empty((n, n_scans, J - 1, 2))
    for i in range(n_scans):
        for j in range(2, J + 1):
            window = plots[:, max(0, i - j + 1): i + 1]
            pos[:, i, j - 2], vel[:, i, j - 2] = alpha_beta_window(window, tau)
    return pos, vel


class FuzzyMultiModel(RadarEstimator):
    outputs = ("m", "sigma_hat_m")  # selected memory length, noise estimate (m)
    Config = Config

    def solve(self, scans: Scans) -> Solution:
        cfg, J, tau = self.config, self.config.memory, scans.tau_s
        z = scans.plots_m
        n, n_scans, _ = z.shape
        selector = memory_length_selector(J, cfg.bad_slope, cfg.bad_centre)
        bank_pos, bank_vel = bank_estimates(z, tau, J)
        rows = np.arange(n)

        est_pos, est_vel = bank_pos[:, :, -1].copy(), bank_vel[:, :, -1].copy()  # growing fit
        m = np.full((n, n_scans), np.nan)
        sigma_hat = np.full((n, n_scans), np.nan)
        # a numpy scalar: an absurd prior gives inf, not OverflowError
        sum_sq, count = np.full(n, np.float64(cfg.sigma_prior_m) ** 2), np.ones(n)
        raw_prev, m_prev = None, np.full(n, J)
        for i in range(n_scans):
            sigma = (np.full(n, cfg.sigma_hat_m) if cfg.sigma_hat_m is not None
                     else np.sqrt(sum_sq / count))
            sigma_hat[:, i] = sigma
            if i < 2:
                continue
            predicted = bank_pos[:, i - 1] + bank_vel[:, i - 1] * tau  # (n, J-1, 2)
            innovation = z[:, i, None, :] - predicted
            norm = np.linalg.norm(innovation, axis=-1)  # (n, J-1)
            has = np.isfinite(z[:, i]).all(axis=1)
            # a model whose window held no plot (missed scans) has no residual: rate it Bad
            L = np.minimum(np.nan_to_num(norm / sigma[:, None], nan=cfg.residual_clip),
                           cfg.residual_clip)
            raw = np.where(has, selector(np.where(has[:, None], L, 0.0)),
                           raw_prev if raw_prev is not None else J)
            # steep memberships can leave no rule firing (0/0): then the shortest memory,
            # the choice of "all Bad"
            raw = np.where(np.isfinite(raw), raw, 2.0)
            both = raw if raw_prev is None else np.maximum(raw, raw_prev)
            chosen = np.clip(np.floor(both + 0.5), 2, J).astype(np.int64)
            chosen = np.where(has, chosen, m_prev)
            m[:, i] = chosen
            est_pos[:, i] = bank_pos[rows, i, chosen - 2]
            est_vel[:, i] = bank_vel[rows, i, chosen - 2]
            empty = ~np.isfinite(est_pos[:, i]).all(axis=1)  # only missed scans in the window
            est_pos[empty, i], est_vel[empty, i] = bank_pos[empty, i, -1], bank_vel[empty, i, -1]
            selected = norm[rows, chosen - 2]
            counted = has & np.isfinite(selected)
            sum_sq += np.where(counted, selected, 0.0) ** 2
            count += counted
            raw_prev, m_prev = raw, chosen
        return Solution(est_pos, est_vel, {"m": m, "sigma_hat_m": sigma_hat})
