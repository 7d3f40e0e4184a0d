"""Benchmarks (not tests): ``make bench``.

(a) Batch ``lm`` vs the baseline ``scipy.optimize.least_squares(method="lm")`` with the same
    analytic Jacobian, one track at a time, on the same tracks: time per track, the ratio and
    how many minima agree.
(b) Wall time of each stage of the default table (``experiment=bearings2d_table``) on a fresh
    data directory, then of a re-run that reuses every finished shard.

Options: ``--tracks N`` (default 2000), ``--sigma DEG`` (0.5), ``--skip-stages``.
"""

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from tma.estimators import build_estimator
from tma.estimators.lm import initial_theta
from tma.models.bearings2d import bearing_jacobian, bearing_residuals
from tma.scenarios.bearings2d import Config, simulate_shard

REPO = Path(__file__).resolve().parents[1]
THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")


def bench_lm(n_tracks: int, sigma_deg: float):
    log, _ = simulate_shard(Config(n_tracks=n_tracks, shard_size=n_tracks, sigma_deg=sigma_deg), 0)
    lm = build_estimator({"name": "lm"})
    with threadpool_limits(limits=1):
        start = time.perf_counter()
        out = lm.estimate(log)
        t_batch = time.perf_counter() - start

        t, ox, oy = log.t_s, log.own_x_m, log.own_y_m
        measured = np.deg2rad(log.bearing_deg)
        theta0 = initial_theta(lm.config, t, ox, oy, measured, np.zeros(n_tracks, int))
        costs, thetas = np.empty(n_tracks), np.empty((n_tracks, 4))
        start = time.perf_counter()
        for i in range(n_tracks):
            m = measured[i:i + 1]
            res = least_squares(
                lambda th, m=m: -bearing_residuals(th[None], t, ox, oy, m, None)[0],
                theta0[i], jac=lambda th: bearing_jacobian(th[None], t, ox, oy, None)[0],
                method="lm")
            costs[i], thetas[i] = 2 * res.cost, res.x
        t_scipy = time.perf_counter() - start

    ours = np.column_stack([out[c] for c in THETA])
    agree = (np.abs(out["cost_rad2"] - costs) <= 1e-6 * costs) & np.all(
        np.isclose(ours, thetas, rtol=1e-3, atol=1.0), axis=1)
    better = out["cost_rad2"] < costs * (1 - 1e-6)
    print(f"(a) {n_tracks} tracks, sigma {sigma_deg} deg, {log.t_s.size} bearings each, "
          "one BLAS thread")
    print(f"    batch lm                           {1e3 * t_batch / n_tracks:8.3f} ms/track")
    print(f"    baseline scipy least_squares(lm)   {1e3 * t_scipy / n_tracks:8.3f} ms/track")
    print(f"    speed-up vs baseline               {t_scipy / t_batch:8.1f}x  (target >= 10x)")
    print(f"    minima agreeing                    {agree.sum():5d} / {n_tracks}"
          f"  (lm lower: {better.sum()}, scipy lower: {n_tracks - agree.sum() - better.sum()})")


def bench_stages():
    print("(b) stage wall times of `make table` (experiment=bearings2d_table, 2 workers)")
    with tempfile.TemporaryDirectory() as tmp:
        overrides = ["experiment=bearings2d_table", f"paths.data_dir={tmp}/data",
                     f"paths.tables_dir={tmp}/tables", "progress=false"]
        for label in ("fresh", "re-run"):
            total = 0.0
            for verb in ("simulate", "estimate", "aggregate"):
                start = time.perf_counter()
                subprocess.run([sys.executable, "-m", f"pipeline.{verb}", *overrides],
                               cwd=REPO, check=True, capture_output=True)
                seconds = time.perf_counter() - start
                total += seconds
                print(f"    {label:7s} {verb:10s} {seconds:7.2f} s")
            target = "  (target <= 30 s)" if label == "fresh" else ""
            print(f"    {label:7s} {'total':10s} {total:7.2f} s{target}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=2000)
    parser.add_argument("--sigma", type=float, default=0.5)
    parser.add_argument("--skip-stages", action="store_true")
    args = parser.parse_args()
    bench_lm(args.tracks, args.sigma)
    if not args.skip_stages:
        bench_stages()


if __name__ == "__main__":
    main()
