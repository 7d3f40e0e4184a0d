"""``quadrature``: the exact posterior mean by tensor Gauss-Legendre quadrature on panels.

A coarse grid over the prior's +-``search_sd`` box locates the posterior mass (points with
log f2 within ``log_cut`` of the maximum); the integration box is that region's bounding box
plus a margin of two grid steps, covered by ``n_panels`` x ``n_panels`` panels with
``n_nodes`` Gauss-Legendre nodes per axis each. The reference for every sampling estimator.
A track whose posterior mass reaches the edge of the search box gets status
``box_too_small`` and no estimate (a logged warning says to raise ``search_sd``).
"""

from dataclasses import dataclass

import numpy as np

from tma.config import param, require
from tma.errors import InputError
from tma.estimator import EstimatorConfig
from tma.families.ranges2d.estimators.base import (
    PosteriorMean,
    RangesEstimator,
    TrackRanges,
    no_estimate,
)
from tma.families.ranges2d.model import RangeModel

MAX_AXIS_POINTS = 4001  # per axis of a 2-D grid: 16e6 values (128 MB) per array
MAX_LOG_CUT = 700.0  # exp(-700) ~ 1e-304: a deeper cut neglects nothing more in float64


@dataclass
class Config(EstimatorConfig):
    n_panels: int = param(40, "panels per axis", "[1, inf)")
    n_nodes: int = param(12, "Gauss-Legendre nodes per panel and axis", "[1, inf)")
    # at 1000 prior sds the prior density is exp(-5e5): nothing is further out
    search_sd: float = param(8.0, "search box: prior mean +- search_sd prior standard "
                             "deviations", "(0, 1000]")
    search_points: int = param(801, "coarse grid points per axis", f"[11, {MAX_AXIS_POINTS}]")
    log_cut: float = param(40.0, "mass with log f2 < max - log_cut is neglected (e^-log_cut)",
                           f"(0, {MAX_LOG_CUT:g}]")

    def __post_init__(self):
        super().__post_init__()
        require(self.n_panels * self.n_nodes <= MAX_AXIS_POINTS, self.where,
                f"n_panels x n_nodes must be <= {MAX_AXIS_POINTS} (nodes per axis)")


def integration_box(model: RangeModel, cfg: Config):
    """((x0, x1), (y0, y1)) holding all but a negligible share of the posterior mass."""
    half = cfg.search_sd * model.prior_sd_m
    xs = np.linspace(model.prior_mean_m[0] - half[0], model.prior_mean_m[0] + half[0],
                     cfg.search_points)
    ys = np.linspace(model.prior_mean_m[1] - half[1], model.prior_mean_m[1] + half[1],
                     cfg.search_points)
    logf = model.log_kernel(xs[:, None], ys[None, :])
    mass = logf >= logf.max() - cfg.log_cut
    if mass[0].any() or mass[-1].any() or mass[:, 0].any() or mass[:, -1].any():
        raise InputError("quadrature: the posterior has mass at the edge of the search box "
                         f"(prior mean +- {cfg.search_sd} sd): raise search_sd")
    ix, iy = np.flatnonzero(mass.any(axis=1)), np.flatnonzero(mass.any(axis=0))
    step = np.array([xs[1] - xs[0], ys[1] - ys[0]])
    return ((xs[ix[0]] - 2 * step[0], xs[ix[-1]] + 2 * step[0]),
            (ys[iy[0]] - 2 * step[1], ys[iy[-1]] + 2 * step[1]))


def gauss_legendre_panels(lo, hi, n_panels, n_nodes):
    """Nodes and weights of composite Gauss-Legendre on [lo, hi]."""
    t, w = np.polynomial.legendre.leggauss(n_nodes)
    edges = np.linspace(lo, hi, n_panels + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[:-1] + edges[1:])
    return (mid[:, None] + half[:, None] * t).ravel(), (half[:, None] * w).ravel()


def posterior_mean(model: RangeModel, cfg: Config):
    """(x_hat, y_hat, evaluations, box) by quadrature."""
    (x0, x1), (y0, y1) = box = integration_box(model, cfg)
    x, wx = gauss_legendre_panels(x0, x1, cfg.n_panels, cfg.n_nodes)
    y, wy = gauss_legendre_panels(y0, y1, cfg.n_panels, cfg.n_nodes)
    logf = model.log_kernel(x[:, None], y[None, :])
    f = np.exp(logf - logf.max()) * wx[:, None] * wy[None, :]
    total = f.sum()
    return (f.sum(axis=1) @ x / total, f.sum(axis=0) @ y / total,
            x.size * y.size + cfg.search_points**2, box)


class Quadrature(RangesEstimator):
    reference = True  # the exact posterior mean the samplers are measured against
    Config = Config

    def __init__(self, config, data_dir=None):
        super().__init__(config, data_dir)
        self._cache = {}  # repeated tracks with identical ranges are integrated once

    def solve(self, track: TrackRanges) -> PosteriorMean:
        model = track.model
        key = (model.counts.tobytes(), model.mean_range_m.tobytes(), model.sigma_m,
               model.prior_mean_m.tobytes(), model.prior_sd_m.tobytes())
        if key not in self._cache:
            try:
                x, y, n_eval, _ = posterior_mean(model, self.config)
            except InputError as exc:  # mass at the edge of the search box
                self._cache[key] = no_estimate("box_too_small", str(exc),
                                               self.config.search_points**2)
                return self._cache[key]
            finite = bool(np.isfinite([x, y]).all())
            self._cache[key] = PosteriorMean(x, y, 0.0, 0.0, np.nan, np.nan, np.nan, np.nan, 0,
                                             n_eval, finite, "ok" if finite else "failed")
        return self._cache[key]
