"""ranges2d: quadrature reference, importance samplers, bisection density, bad input."""

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import compose_cfg
from tma.errors import ConfigError, InputError
from tma.families import build_estimator
from tma.families.ranges2d.bisection import BisectionDensity
from tma.families.ranges2d.estimators.adaptive_is import scalar_log_kernel
from tma.families.ranges2d.estimators.quadrature import Config as QuadConfig
from tma.families.ranges2d.estimators.quadrature import posterior_mean
from tma.families.ranges2d.estimators.ratio import RatioMoments
from tma.families.ranges2d.log import read_ranges_log, write_ranges_log
from tma.families.ranges2d.model import RangeModel
from tma.families.ranges2d.report import summary_row, track_metrics
from tma.families.ranges2d.scenario import Config, simulate_shard

BOX = ((-400.0, 400.0), (-400.0, 400.0))


def _log(n=1, **kw):
    return simulate_shard(Config(n_tracks=n, shard_size=n, **kw), 0)[0]


def _model():
    log = _log()
    return RangeModel.from_ranges(log.landmarks_m, log.ranges_m[0], 30.0, [0, 0], [100, 100])


def _reference():
    x, y, _, _ = posterior_mean(_model(), QuadConfig())
    return np.array([x, y])


def test_quadrature_converges():
    model = _model()
    coarse = posterior_mean(model, QuadConfig(n_panels=20, n_nodes=8))[:2]
    fine = posterior_mean(model, QuadConfig(n_panels=80, n_nodes=16))[:2]
    np.testing.assert_allclose(coarse, fine, atol=1e-6)
    # and against a plain midpoint sum on a fine grid (independent rule)
    g = np.linspace(-150, 150, 3001)
    f = np.exp(model.log_kernel(g[:, None], g[None, :]) - 0.0)
    f /= f.sum()
    np.testing.assert_allclose(fine, [f.sum(1) @ g, f.sum(0) @ g], atol=1e-6)


@pytest.mark.parametrize("name", ["prior_is", "adaptive_is"])
def test_samplers_unbiased_within_their_own_error(name):
    ref = _reference()
    est = build_estimator({"name": name, "n_samples": 40_000, "n_bisections": 2000}
                          if name == "adaptive_is" else {"name": name, "n_samples": 40_000})
    log = _log(n=60)
    out = est.estimate(log)
    for c, s in (("x_m", "se_x_m"), ("y_m", "se_y_m")):
        z = (out[c] - ref[0 if c == "x_m" else 1]) / out[s]
        assert abs(z.mean()) < 4 / np.sqrt(z.size), z.mean()  # unbiased
        assert 0.7 < z.std() < 1.35, z.std()  # the stated error is the actual error
    assert np.all(out["samples_used"] >= 40_000)


def test_delta_method_re_matches_repeated_estimates():
    log = _log(n=80)
    out = build_estimator({"name": "prior_is", "n_samples": 30_000}).estimate(log)
    predicted = np.abs(out["x_m"].mean()) * out["re_x"].mean() / np.sqrt(30_000)
    assert 0.75 < out["x_m"].std(ddof=1) / predicted < 1.3


def test_accuracy_target_stops_sampling():
    out = build_estimator({"name": "adaptive_is", "accuracy_m": 0.5}).estimate(_log(n=3))
    assert out["reached_accuracy"].all()
    assert np.all(1.96 * out["se_x_m"] <= 0.5) and np.all(1.96 * out["se_y_m"] <= 0.5)
    assert np.all(out["samples_used"] == out["n_samples"] + 10_001)


def test_bisection_density_normalised_and_sampler_matches():
    rng = np.random.default_rng(5)
    d = BisectionDensity.build(scalar_log_kernel(_model()), BOX, 3000, 5e-4, rng)
    assert d.n_cells == 3001 and d.n_evaluations == 3001
    assert d.prob.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(d.area.sum(), 800.0 * 800.0)  # the cells tile the box
    centres = 0.5 * (d.lo + d.hi)
    np.testing.assert_array_equal(d.locate(centres[:, 0], centres[:, 1]), np.arange(d.n_cells))
    assert (d.pdf(centres[:, 0], centres[:, 1]) * d.area).sum() == pytest.approx(1.0)
    points, cell = d.sample(200_000, rng)
    np.testing.assert_array_equal(d.locate(points[:, 0], points[:, 1]), cell)
    # chi-square of the cell counts against the cell probabilities (pooled to >= 20 expected)
    order = np.argsort(d.prob)
    counts = np.bincount(cell, minlength=d.n_cells)[order]
    expected = 200_000 * d.prob[order]
    starts = np.r_[0, 1 + np.flatnonzero(np.diff(np.floor(np.cumsum(expected) / 20)))]
    starts = starts[starts < d.n_cells]
    obs, exp = np.add.reduceat(counts, starts), np.add.reduceat(expected, starts)
    assert exp.min() > 5 and obs.size > 100
    stat = ((obs - exp) ** 2 / exp).sum()
    assert chi2.sf(stat, obs.size - 1) > 1e-3


def test_shift_is_applied_and_configurable():
    model = _model()
    log_f = scalar_log_kernel(model)
    for shift in (5e-4, 1e-2):
        d = BisectionDensity.build(log_f, BOX, 2000, shift, np.random.default_rng(1))
        density = d.prob / d.area
        total_weight = 1.0 / (density.min() / shift)  # min density = shift / sum of weights
        assert d.shift == shift
        assert np.all(density >= shift / total_weight * (1 - 1e-12))
    # without the shift, cells whose point misses the peak get (numerically) zero mass even
    # though f2 is positive there: the sampler can never draw from them
    d0 = BisectionDensity.build(log_f, BOX, 2000, 0.0, np.random.default_rng(1))
    c = 0.5 * (d0.lo + d0.hi)
    zero = d0.prob / d0.area < 1e-300
    assert zero.any()
    assert np.all(np.isfinite(model.log_kernel(c[zero, 0], c[zero, 1])))
    est = build_estimator({"name": "adaptive_is", "shift": 0.02})
    assert est.config.shift == 0.02


def test_ranges_log_round_trip_and_bad_input(tmp_path):
    log = _log(n=3, mode="population")
    write_ranges_log(tmp_path / "r.mcap", log)
    back = read_ranges_log(tmp_path / "r.mcap")
    np.testing.assert_array_equal(back.ranges_m, log.ranges_m)
    assert back.model == log.model
    for edit, message in [(lambda r: r.__setitem__((1, 0, 2), -5.0), "negative range"),
                          (lambda r: r.__setitem__((0, 1, 0), np.nan), "NaN range")]:
        bad = _log(n=3, mode="population")
        edit(bad.ranges_m)
        write_ranges_log(tmp_path / "bad.mcap", bad)
        with pytest.raises(InputError, match=message):
            read_ranges_log(tmp_path / "bad.mcap")
    one = _log(n=1, ranges_m=[[2981.0], [2969.0]])
    one.ranges_m = one.ranges_m[:, :1, :]
    one.landmarks_m = one.landmarks_m[:1]
    with pytest.raises(InputError, match="fewer ranges"):
        one.validate("test")


def test_a_box_without_the_posterior_is_flagged_per_track(caplog):
    """A box that misses the posterior (adaptive_is) or a search box whose edge holds
    posterior mass (quadrature) leaves the track without an estimate, flagged and logged;
    the other tracks go on."""
    est = build_estimator({"name": "adaptive_is", "box_m": [100.0, 400.0, 100.0, 400.0]})
    out = est.estimate(_log(n=2))
    assert list(out["status"]) == ["box_too_small"] * 2
    assert np.isnan(out["x_m"]).all() and not out["reached_accuracy"].any()
    assert out["mass_outside"].min() > 0.99
    assert "enlarge estimator.box_m" in caplog.text
    out = build_estimator({"name": "quadrature", "search_sd": 0.5}).estimate(_log())
    assert list(out["status"]) == ["box_too_small"] and np.isnan(out["y_m"]).all()
    assert "raise search_sd" in caplog.text


def test_sampler_status_ok_or_not_converged():
    log = _log(n=2)
    out = build_estimator({"name": "prior_is", "max_samples": 50_000}).estimate(log)
    assert list(out["status"]) == ["not_converged"] * 2  # 0.1 m needs ~10^6 prior draws
    assert np.isfinite(out["x_m"]).all()
    out = build_estimator({"name": "prior_is", "n_samples": 1000}).estimate(log)
    assert list(out["status"]) == ["ok"] * 2


def test_weights_far_above_the_first_batch_do_not_overflow():
    """A first batch far from a sharp posterior fixes the weight scale; a later draw near the
    peak used to overflow exp() to inf and the estimate to NaN."""
    m = RatioMoments()
    m.add(np.array([[0.0, 0.0]]), np.array([-2000.0]))
    m.add(np.array([[1.0, 2.0], [3.0, 4.0]]), np.array([0.0, np.log(3.0)]))
    np.testing.assert_allclose(m.estimate(), [2.5, 3.5])
    assert m.n == 3 and np.isfinite(m.standard_error()).all()


@pytest.mark.parametrize(("node", "key"), [
    ({"name": "prior_is", "min_samples": 1}, "min_samples"),
    ({"name": "prior_is", "max_samples": 10, "min_samples": 100}, "max_samples"),
    ({"name": "prior_is", "seed": -1}, "seed"),
    ({"name": "adaptive_is", "box_m": [0.0, 1.0, float("nan"), 1.0]}, r"box_m\[2\]"),
    ({"name": "adaptive_is", "shift": 0.0}, "shift"),
    ({"name": "adaptive_is", "max_mass_outside": 2.0}, "max_mass_outside"),
    ({"name": "quadrature", "log_cut": float("inf")}, "log_cut"),
    ({"name": "quadrature", "search_sd": -1.0}, "search_sd"),
])
def test_impossible_estimator_configs_are_refused(node, key):
    with pytest.raises(ConfigError, match=key):
        build_estimator(node)


@pytest.mark.parametrize(("kw", "key"), [
    ({"ranges_m": [[2981.0, -5.0], [2969.0, 3002.0]]}, "ranges_m"),
    ({"mode": "population", "n_pairs": 1, "landmarks_m": [[0.0, 0.0]]}, "at least 2 ranges"),
    ({"prior_sd_m": [100.0, 0.0]}, "prior_sd_m"),
    ({"seed": -3}, "seed"),
])
def test_impossible_scenarios_are_refused(kw, key):
    with pytest.raises(ConfigError, match=key):
        Config(**kw)


def test_status_in_metrics_and_counted_in_the_table():
    est = pd.DataFrame({"track_id": [0, 1, 2], "x_m": [1.0, np.nan, 1.2],
                        "y_m": [2.0, np.nan, 2.1], "se_x_m": 0.1, "se_y_m": 0.1, "re_x": 1.0,
                        "re_y": 1.0, "corr_x": 0.5, "corr_y": 0.5, "samples_used": 100,
                        "n_evaluations": 0, "reached_accuracy": [True, False, False],
                        "status": ["ok", "box_too_small", "not_converged"]})
    ref = pd.DataFrame({"track_id": [0, 1, 2], "x_m": [1.0, 1.0, 1.0], "y_m": [2.0] * 3})
    m = track_metrics(est, ref, None, 0.95)
    assert list(m["status"]) == ["ok", "box_too_small", "not_converged"]
    row = summary_row("prior_is", m, 0.1)
    assert (row["n_ok"], row["n_not_converged"], row["n_box_too_small"], row["n_failed"]) == (
        1, 1, 1, 0)
    assert row["n_runs"] == 3 and row["reached_accuracy"] == pytest.approx(1 / 3)
    assert row["err_abs_max_m"] == pytest.approx(0.2)  # over the runs with an estimate
    assert row["x_mean_m"] == pytest.approx(1.1)


def test_pipeline_table(tmp_path):
    overrides = ["experiment=ranges2d_table", "scenario.n_tracks=6", "scenario.shard_size=3",
                 "grid.estimators.prior_is.accuracy_m=1.0",
                 "grid.estimators.adaptive_is.accuracy_m=1.0",
                 "grid.estimators.adaptive_is.n_bisections=1000", "progress=false",
                 f"paths.data_dir={tmp_path}/data", f"paths.tables_dir={tmp_path}/tables"]
    cfg = compose_cfg(overrides)
    simulate_stage(cfg)
    estimate_stage(cfg)
    aggregate_stage(cfg)
    table = pd.read_csv(tmp_path / "tables" / "ranges2d.csv")
    assert list(table.estimator) == ["quadrature", "prior_is", "adaptive_is"]
    assert (table.n_runs == 6).all()
    assert (table.loc[1:, "err_abs_max_m"] < 1.5).all()
    assert (table.n_ok + table.n_not_converged == 6).all()
    assert table.reached_accuracy.tolist() == (table.n_ok / 6).tolist()
    metrics = list((tmp_path / "data" / "runs").glob("*/*/metrics.parquet"))
    assert len(metrics) == 3
    for path in metrics:
        assert set(pd.read_parquet(path)["status"]) <= {"ok", "not_converged"}
    assert "prior / adaptive" in (tmp_path / "tables" / "ranges2d.md").read_text()
    assert (tmp_path / "tables" / "ranges2d.png").stat().st_size > 10_000
