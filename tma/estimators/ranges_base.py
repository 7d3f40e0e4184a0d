"""Shared base of the ``ranges2d`` posterior-mean estimators.

Each track gets its own random stream ``SeedSequence(seed, spawn_key=(track_id,))``, so a
track's estimate depends neither on its shard nor on the number of workers.
"""

import numpy as np

from tma.estimators.base import Estimator
from tma.io.ranges_log import RangesLog
from tma.models.ranges2d import RangeModel

PLOT_TRACK = 0  # the track whose first draws are kept for the sample plot


class RangesEstimator(Estimator):
    family = "ranges2d"
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
            row = self.estimate_track(model, rng, keep)
            if row.get("kept") is not None:
                kept = row["kept"]
            row.pop("kept", None)
            rows.append(row)
        columns = {key: np.array([r[key] for r in rows]) for key in rows[0]}
        if kept is not None:
            columns["extras"] = {"samples": {"track_id": np.full(len(kept), PLOT_TRACK),
                                             "x_m": kept[:, 0], "y_m": kept[:, 1]}}
        return columns

    def estimate_track(self, model: RangeModel, rng, keep: int = 0) -> dict:
        raise NotImplementedError


def sampling_columns(moments, reached, n_evaluations=0) -> dict:
    x_hat = moments.estimate()
    se, re, corr = moments.standard_error(), moments.relative_error(), moments.correlation()
    return {
        "x_m": x_hat[0], "y_m": x_hat[1], "se_x_m": se[0], "se_y_m": se[1],
        "re_x": re[0], "re_y": re[1], "corr_x": corr[0], "corr_y": corr[1],
        "n_samples": moments.n, "n_evaluations": n_evaluations,
        "samples_used": moments.n + n_evaluations, "reached_accuracy": reached,
        "kept": moments.kept,
    }
