"""Shared base of the ``ranges2d`` posterior-mean estimators: the contract between the base and
an estimator (one track's ``TrackRanges`` in, its ``PosteriorMean`` out of ``solve``).

The samplers (``SamplingEstimator``) give each track its own random stream
``SeedSequence(seed, spawn_key=(track_id,))``, so a track's estimate depends neither on its
shard nor on the number of workers.

Every estimator gives each track a ``status``: ``ok``; ``not_converged`` (a sampler stopped at
``max_samples`` before its accuracy target; the estimate is finite but less precise than
asked); ``box_too_small`` (posterior mass at the edge of the quadrature's search box or
outside the adaptive sampler's box: no estimate, x and y NaN); ``failed`` (no finite estimate
or standard error: degenerate importance weights, or scales beyond float64).
"""

import logging
from dataclasses import dataclass, field

import numpy as np

from tma.estimator import Estimates, Estimator
from tma.families.ranges2d.log import RangesLog
from tma.families.ranges2d.model import RangeModel

PLOT_TRACK = 0  # the track whose first draws are kept for the sample plot
STATUSES = ("ok", "not_converged", "box_too_small", "failed")
logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrackRanges:
    """One track's ranges as every estimator takes them: its ``track_id`` and the posterior
    they give (``model``: the ranges to each landmark, their noise and the position prior)."""

    track_id: int
    model: RangeModel


@dataclass(frozen=True)
class PosteriorMean:
    """What ``solve`` returns for one track: the posterior mean ``x_m``, ``y_m`` (m; NaN:
    no estimate), its Monte Carlo standard errors ``se_x_m``, ``se_y_m`` (m; 0 for an exact
    mean), the relative error per draw ``re_x``, ``re_y`` and the correlation of the ratio's
    numerator and denominator ``corr_x``, ``corr_y`` (NaN where there are no draws), the
    draws ``n_samples`` and density evaluations ``n_evaluations`` it took, whether it
    ``reached_accuracy``, its ``status`` (``STATUSES``), its first ``draws`` (k, 2) kept for
    the plot (None: none kept) and its own output ``columns`` (its ``outputs``)."""

    x_m: float
    y_m: float
    se_x_m: float
    se_y_m: float
    re_x: float
    re_y: float
    corr_x: float
    corr_y: float
    n_samples: int
    n_evaluations: int
    reached_accuracy: bool
    status: str
    draws: np.ndarray | None = None
    columns: dict = field(default_factory=dict)

    @property
    def samples_used(self) -> int:
        """What the estimate cost: draws and density evaluations (bisections, nodes)."""
        return self.n_samples + self.n_evaluations


# the estimates' columns every estimator gives (of its PosteriorMean), in their order
COLUMNS = ("x_m", "y_m", "se_x_m", "se_y_m", "re_x", "re_y", "corr_x", "corr_y", "n_samples",
           "n_evaluations", "samples_used", "reached_accuracy", "status")


class RangesEstimator(Estimator):
    """Base of the ``ranges2d`` estimators; subclasses implement ``solve``, one track at a
    time. Every output carries per track the columns of ``PosteriorMean`` (``COLUMNS``) and
    the estimator's own ``outputs``; a sampler's first draws of track ``PLOT_TRACK`` are the
    side table ``samples``."""

    family = "ranges2d"
    conformance_scenario = {"seed": 3}

    def estimate(self, log: RangesLog) -> Estimates:
        """The ``Estimates`` of every track of ``log``: ``read``, ``solve`` each track."""
        means, draws = [], None
        for track in self.read(log):
            # absurd but valid scales (a prior sd of 1e300 m) overflow: the track is flagged
            try:
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    mean = self.solve(track)
            except (OverflowError, ZeroDivisionError) as exc:  # Python float arithmetic
                mean = no_estimate("failed", f"{self.name}: track {track.track_id}: {exc}")
            if mean.draws is not None:
                draws = mean.draws
            means.append(mean)
        columns = {name: np.array([getattr(m, name) for m in means]) for name in COLUMNS}
        for name in self.outputs:  # a track without an estimate may lack them
            columns[name] = np.array([m.columns.get(name, np.nan) for m in means])
        side = {} if draws is None else {"samples": {
            "track_id": np.full(len(draws), PLOT_TRACK), "x_m": draws[:, 0], "y_m": draws[:, 1]}}
        return Estimates(columns, side)

    def read(self, log: RangesLog) -> list[TrackRanges]:
        """Each track of ``log`` with the posterior its ranges give."""
        return [TrackRanges(int(track), RangeModel.from_ranges(
            log.landmarks_m, log.ranges_m[i].reshape(len(log.landmarks_m), -1),
            log.model["sigma_m"], log.model["prior_mean_m"], log.model["prior_sd_m"]))
            for i, track in enumerate(log.track_id)]

    def solve(self, track: TrackRanges) -> PosteriorMean:
        """The estimator's own step: the ``PosteriorMean`` of one ``track``."""
        raise NotImplementedError


class SamplingEstimator(RangesEstimator):
    """Base of the importance samplers: their ``Config`` is an
    ``importance_sampling.SamplerConfig`` (``seed``, ``plot_points``, the budget)."""

    side_tables = ("samples",)  # the first draws of one track, for the plot

    def stream(self, track: TrackRanges) -> tuple[np.random.Generator, int]:
        """The track's own random stream, and how many of its first draws to keep for the
        plot (``plot_points`` for track ``PLOT_TRACK``, else none)."""
        rng = np.random.default_rng(np.random.SeedSequence(self.config.seed,
                                                           spawn_key=(track.track_id,)))
        return rng, self.config.plot_points if track.track_id == PLOT_TRACK else 0


def sampled_mean(moments, reached, n_evaluations=0, columns=None) -> PosteriorMean:
    """The ``PosteriorMean`` of a sampler's ``moments`` (``RatioMoments``); ``reached``: it
    stopped at its accuracy target."""
    x_hat = moments.estimate()
    se, re, corr = moments.standard_error(), moments.relative_error(), moments.correlation()
    finite = bool(np.isfinite(x_hat).all() and np.isfinite(se).all())
    return PosteriorMean(
        x_hat[0], x_hat[1], se[0], se[1], re[0], re[1], corr[0], corr[1], moments.n,
        n_evaluations, reached and finite,
        "failed" if not finite else "ok" if reached else "not_converged", moments.kept,
        columns or {})


def no_estimate(status: str, message: str, n_evaluations=0, columns=None) -> PosteriorMean:
    """The ``PosteriorMean`` of a track without an estimate (x, y and errors NaN);
    ``message`` (why, and what to change) goes to the log."""
    logger.warning(message)
    nan = float("nan")
    return PosteriorMean(nan, nan, nan, nan, nan, nan, nan, nan, 0, n_evaluations, False,
                         status, columns=columns or {})
