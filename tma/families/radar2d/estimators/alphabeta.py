"""``alphabeta``: one alpha-beta filter with memory J (growing-memory gains up to J scans,
fixed at alpha_J, beta_J afterwards), batched over the Monte Carlo runs."""

from dataclasses import dataclass

import numpy as np

from tma.config import param
from tma.families.radar2d.estimators.base import (
    RadarConfig,
    RadarEstimator,
    Scans,
    Solution,
    alpha_beta_step,
    initial_state,
)


@dataclass
class Config(RadarConfig):
    memory: int = param(10, "J, the longest memory (scans) of the growing-memory gains",
                        "[2, inf)")


class AlphaBeta(RadarEstimator):
    Config = Config

    def solve(self, scans: Scans) -> Solution:
        n, n_scans = scans.n_tracks, scans.t_s.size
        pos, vel, k = initial_state(n)
        est_pos, est_vel = np.empty((n, n_scans, 2)), np.empty((n, n_scans, 2))
        for s in range(n_scans):
            pos, vel, k = alpha_beta_step(pos, vel, k, scans.plots_m[:, s], scans.tau_s,
                                          self.config.memory)
            est_pos[:, s], est_vel[:, s] = pos, vel
        return Solution(est_pos, est_vel)
