"""Shared base of the ``ranges2d`` posterior-mean estimators.

Each track gets its own random stream ``SeedSequence(seed, spawn_key=(track_id,))``, so a
track's estimate depends neither on its shard nor on the number of workers.

Every estimator gives each track a ``status``: ``ok``; ``not_converged`` (a sampler stopped at
``max_samples`` before its accuracy target; the estimate is finite but less precise than
asked); ``box_too_small`` (posterior mass at the edge of the quadrature's search box or
outside the adaptive sampler's box: no estimate, x and y NaN); ``failed`` (no finite estimate
or standard error: degenerate importance weights, or scales beyond float64).
"""

import logging

import numpy as np

from tma.estimator import Estimator
from tma.families.ranges2d.log import RangesLog
from tma.families.ranges2d.model import RangeModel

PLOT_TRACK = 0  # the track whose first draws are kept for the sample plot
STATUSES = ("ok", "not_converged", "box_too_small", "failed")
logger = logging.getLogger(__name__)


class RangesEstimator(Estimator):
    family = "ranges2d"
    conformance_scenario = {"seed": 3}
    def estimate(self, log: RangesLog) -> dict:
        """Columns per track, plus ``extras['samples']``: the first draws of the track
        ``plot_track`` (if in this shard and the estimator samples)."""
        rows, kept = [], None
        for i, track in enumerate(log.track_id):
            model = RangeModel.from_ranges(
                log.landmarks_m, log.ranges_m[i].reshape(len(log.landmarks_m), -1),
                log.model["sigma_m"], log.model["prior_mean_m"], log.model["prior_sd_m"])
            seed = getattr(self.config, "seed", 0)
            rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(track),)))
            keep = getattr(self.config, "plot_points", 0) if track == PLOT_TRACK else 0
            # absurd but valid scales (a prior sd of 1e300 m) overflow: the track is flagged
            try:
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    row = self.solve(model, rng, keep)
            except (OverflowError, ZeroDivisionError) as exc:  # Python float arithmetic
                row = no_estimate_columns("failed", f"{self.name}: track {track}: {exc}")
            if row.get("kept") is not None:
                kept = row["kept"]
            row.pop("kept", None)
            rows.append(row)
        keys = dict.fromkeys(k for r in rows for k in r)  # a failed row lacks extra columns
        columns = {key: np.array([r.get(key, np.nan) for r in rows]) for key in keys}
        if kept is not None:
            columns["extras"] = {"samples": {"track_id": np.full(len(kept), PLOT_TRACK),
                                             "x_m": kept[:, 0], "y_m": kept[:, 1]}}
        return columns

    def solve(self, model: RangeModel, rng, keep: int = 0) -> dict:
        raise NotImplementedError


def sampling_columns(moments, reached, n_evaluations=0) -> dict:
    x_hat = moments.estimate()
    se, re, corr = moments.standard_error(), moments.relative_error(), moments.correlation()
    finite = bool(np.isfinite(x_hat).all() and np.isfinite(se).all())
    return {
        "x_m": x_hat[0], "y_m": x_hat[1], "se_x_m": se[0], "se_y_m": se[1],
        "re_x": re[0], "re_y": re[1], "corr_x": corr[0], "corr_y": corr[1],
        "n_samples": moments.n, "n_evaluations": n_evaluations,
        "samples_used": moments.n + n_evaluations, "reached_accuracy": reached and finite,
        "status": "failed" if not finite else "ok" if reached else "not_converged",
        "kept": moments.kept,
    }


def no_estimate_columns(status: str, message: str, n_evaluations=0) -> dict:
    """The row of a track without an estimate (x, y and errors NaN); ``message`` (why, and
    what to change) goes to the log."""
    logger.warning(message)
    nan = float("nan")
    return {"x_m": nan, "y_m": nan, "se_x_m": nan, "se_y_m": nan, "re_x": nan, "re_y": nan,
            "corr_x": nan, "corr_y": nan, "n_samples": 0, "n_evaluations": n_evaluations,
            "samples_used": n_evaluations, "reached_accuracy": False, "status": status}
