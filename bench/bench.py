"""Benchmarks (not tests): ``make bench``.

(a) Batch ``lm`` vs the baseline ``scipy.optimize.least_squares(method="lm")`` with the same
    analytic Jacobian, one track at a time, on the same tracks: time per track, the ratio and
    how many minima agree.
(b) Wall time of each stage of the default table (``experiment=bearings2d_table``) on a fresh
    data directory, then of a re-run that reuses every finished shard.

(c) ``ranges2d``: time per 1e4 bisections and per 1e5 samples of each sampler, and the
    headline ratio of samples needed (prior / adaptive) for the same accuracy.

(d) ``bearing_doppler3d``: microseconds per path per observation of each filter, vectorised
    and one path at a time; (e) peak memory of CMNF training (``--cmnf-paths 100000``).

Options: ``--tracks N`` (2000), ``--sigma DEG`` (0.5), ``--runs N`` (30), ``--skip-stages``,
``--only FAMILY``, ``--paths3d N`` (2500), ``--cmnf-paths N`` (10000).
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

from tma.families import build_estimator
from tma.families.bearings2d.estimators.lm import initial_theta
from tma.families.bearings2d.model import bearing_jacobian, bearing_residuals
from tma.families.bearings2d.scenario import Config, simulate_shard

REPO = Path(__file__).resolve().parents[1]
THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")


def bench_lm(n_tracks: int, sigma_deg: float):
    from tma.parallel import keep_freed_memory

    keep_freed_memory()  # as in the pipeline's workers
    log, _ = simulate_shard(Config(n_tracks=n_tracks, shard_size=n_tracks, sigma_deg=sigma_deg), 0)
    lm = build_estimator({"name": "lm"})
    with threadpool_limits(limits=1):
        lm.estimate(log)  # warm-up (allocator, caches); scipy warms up on its first tracks
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


def bench_ranges(runs: int):
    from tma.families.ranges2d.bisection import BisectionDensity
    from tma.families.ranges2d.estimators.adaptive_is import scalar_log_kernel
    from tma.families.ranges2d.model import RangeModel
    from tma.families.ranges2d.scenario import Config as RangesConfig
    from tma.families.ranges2d.scenario import simulate_shard as simulate_ranges

    log, _ = simulate_ranges(RangesConfig(n_tracks=runs, shard_size=runs), 0)
    model = RangeModel.from_ranges(log.landmarks_m, log.ranges_m[0], 30.0, [0, 0], [100, 100])
    rng = np.random.default_rng(0)
    box = ((-400.0, 400.0), (-400.0, 400.0))
    print("(c) ranges2d, the article's concrete case, one thread")
    with threadpool_limits(limits=1):
        start = time.perf_counter()
        density = BisectionDensity.build(scalar_log_kernel(model), box, 10_000, 5e-4, rng)
        t_bisect = time.perf_counter() - start
        start = time.perf_counter()
        pts = model.prior_mean_m + model.prior_sd_m * rng.standard_normal((100_000, 2))
        model.log_likelihood(pts[:, 0], pts[:, 1])
        t_prior = time.perf_counter() - start
        start = time.perf_counter()
        pts, cell = density.sample(100_000, rng)
        model.log_kernel(pts[:, 0], pts[:, 1]) - np.log(density.cell_density(cell))
        t_adaptive = time.perf_counter() - start
        print(f"    10,000 bisections                  {1e3 * t_bisect:8.1f} ms")
        print(f"    1e5 samples + weights, prior_is    {1e3 * t_prior:8.1f} ms")
        print(f"    1e5 samples + weights, adaptive_is {1e3 * t_adaptive:8.1f} ms")
        used = {}
        for name in ("prior_is", "adaptive_is"):
            start = time.perf_counter()
            out = build_estimator({"name": name}).estimate(log)
            used[name] = (out["samples_used"].mean(), (time.perf_counter() - start) / runs)
            print(f"    {name:11s} to 0.1 m at 95 %: {used[name][0]:11,.0f} samples, "
                  f"{used[name][1]:.3f} s per run ({runs} runs)")
    ratio = used["prior_is"][0] / used["adaptive_is"][0]
    print(f"    HEADLINE samples needed, prior / adaptive: {ratio:.1f}x "
          f"(time ratio {used['prior_is'][1] / used['adaptive_is'][1]:.2f}x)")


def bench_filters3d(paths: int, single: int, duration: float):
    from tma.families.bearing_doppler3d.estimators.cmnf import apply, model_functions, train
    from tma.families.bearing_doppler3d.log import HydrophoneLog
    from tma.families.bearing_doppler3d.model import AuvModel, model_record
    from tma.families.bearing_doppler3d.scenario import Config as AuvConfig
    from tma.families.bearing_doppler3d.scenario import simulate_shard as simulate_auv
    from tma.parallel import keep_freed_memory

    keep_freed_memory()
    log, _ = simulate_auv(AuvConfig(n_tracks=paths, shard_size=paths, duration_s=duration), 0)
    n_obs = log.t_s.size
    print(f"(d) bearing_doppler3d filters, {paths} paths x {n_obs} epochs, one thread "
          "(microseconds per path per observation)")
    model = AuvModel.from_record(model_record(AuvConfig(duration_s=duration)))
    functions = model_functions(model, model.epochs())
    with threadpool_limits(limits=1):
        start = time.perf_counter()
        truth, obs = model.simulate(2000, np.random.default_rng(1))
        gains = train(truth, model.select_readings(obs), *functions, 1e-12)
        t_train = time.perf_counter() - start
        for name in ("ekf", "srekf", "cmnf"):
            if name == "cmnf":
                def run(lg):
                    return apply(gains, lg.obs, *functions)
            else:
                est = build_estimator({"name": name})
                run = est.estimate
            start = time.perf_counter()
            run(log)
            vec = (time.perf_counter() - start) / (paths * n_obs)
            start = time.perf_counter()
            for i in range(single):
                run(HydrophoneLog(log.t_s, log.track_id[i:i + 1], log.obs[i:i + 1], log.model))
            one = (time.perf_counter() - start) / (single * n_obs)
            print(f"    {name:6s} vectorised {1e6 * vec:8.2f}   one path at a time "
                  f"{1e6 * one:9.2f}   ratio {one / vec:6.1f}x")
    print(f"    cmnf training on 2,000 paths (simulation included): {t_train:.1f} s")


def bench_cmnf_memory(paths: int):
    """Peak memory of CMNF training on ``paths`` paths, in a fresh process."""
    code = f"""
import resource, time, numpy as np
from tma.parallel import keep_freed_memory
from tma.families.bearing_doppler3d.estimators.bundle import _bundle_shard, SHARD
from tma.families.bearing_doppler3d.estimators.cmnf import train, model_functions
from tma.families.bearing_doppler3d.model import AuvModel, model_record
from tma.families.bearing_doppler3d.scenario import Config
keep_freed_memory()
record = model_record(Config())
start = time.perf_counter()
parts = [_bundle_shard((record, 7, i, min(SHARD, {paths} - i * SHARD)))
         for i in range(-(-{paths} // SHARD))]
truth = np.concatenate([p[0] for p in parts]); obs = np.concatenate([p[1] for p in parts])
del parts
sim = time.perf_counter() - start
model = AuvModel.from_record(record)
start = time.perf_counter()
train(truth, model.select_readings(obs), *model_functions(model, model.epochs()), 1e-12)
print(f"{{sim:.0f}} {{time.perf_counter() - start:.0f}} "
      f"{{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f}}")
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True,
                         capture_output=True, text=True).stdout.split()
    print(f"(e) cmnf training on {paths:,} paths of 100 s: simulation {out[0]} s (one process), "
          f"training {out[1]} s, peak memory {int(out[2]) / 1024:.1f} GiB")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=2000)
    parser.add_argument("--sigma", type=float, default=0.5)
    parser.add_argument("--runs", type=int, default=30, help="ranges2d repeated runs")
    parser.add_argument("--skip-stages", action="store_true")
    parser.add_argument("--only", choices=["bearings2d", "ranges2d", "bearing_doppler3d"],
                        default=None)
    parser.add_argument("--paths3d", type=int, default=2500, help="3D filter benchmark paths")
    parser.add_argument("--cmnf-paths", type=int, default=10_000,
                        help="CMNF training size for the memory measurement (e.g. 100000)")
    args = parser.parse_args()
    if args.only in (None, "bearings2d"):
        bench_lm(args.tracks, args.sigma)
        if not args.skip_stages:
            bench_stages()
    if args.only in (None, "ranges2d"):
        bench_ranges(args.runs)
    if args.only in (None, "bearing_doppler3d"):
        bench_filters3d(args.paths3d, 5, 100.0)
        bench_cmnf_memory(args.cmnf_paths)


if __name__ == "__main__":
    main()
