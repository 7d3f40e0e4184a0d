"""ranges2d estimators: the quadrature reference, the importance samplers and their errors,
statuses."""

import numpy as np
import pytest

from tma.families import build_estimator
from tma.families.ranges2d.estimators.quadrature import Config as QuadConfig
from tma.families.ranges2d.estimators.quadrature import posterior_mean
from tma.families.ranges2d.importance_sampling import RatioMoments
from tma.families.ranges2d.model import RangeModel
from tma.families.ranges2d.scenario import Config, simulate_shard


def _log(n=1, **kw):
    return simulate_shard(Config(n_tracks=n, shard_size=n, **kw), 0)[0]


@pytest.fixture(scope="module")
def model():
    """The article's case."""
    log = _log()
    return RangeModel.from_ranges(log.landmarks_m, log.ranges_m[0], 30.0, [0, 0], [100, 100])


@pytest.fixture(scope="module")
def reference(model):
    x, y, _, _ = posterior_mean(model, QuadConfig())
    return np.array([x, y])


def test_quadrature_converges(model):
    coarse = posterior_mean(model, QuadConfig(n_panels=20, n_nodes=8))[:2]
    fine = posterior_mean(model, QuadConfig(n_panels=80, n_nodes=16))[:2]
    np.testing.assert_allclose(coarse, fine, atol=1e-6)
    # and against a plain midpoint sum (an independent rule): on a 0.5 m grid it is exact to
    # ~1e-14 m for this smooth peak (sd ~10 m), well inside [-150, 150] m
    g = np.linspace(-150, 150, 601)
    f = np.exp(model.log_kernel(g[:, None], g[None, :]))
    f /= f.sum()
    np.testing.assert_allclose(fine, [f.sum(1) @ g, f.sum(0) @ g], atol=1e-6)


@pytest.mark.parametrize("name", ["prior_is", "adaptive_is"])
def test_samplers_unbiased_within_their_own_error(name, reference):
    # adaptive_is: fewer prior draws for its box check (a gate, not the estimate) than the
    # default; the density and the sample count are those of the property
    est = build_estimator({"name": name, "n_samples": 40_000, "n_bisections": 2000,
                           "check_samples": 20_000}
                          if name == "adaptive_is" else {"name": name, "n_samples": 40_000})
    out = est.estimate(_log(n=60))
    for c, s in (("x_m", "se_x_m"), ("y_m", "se_y_m")):
        z = (out[c] - reference[0 if c == "x_m" else 1]) / out[s]
        assert abs(z.mean()) < 4 / np.sqrt(z.size), z.mean()  # unbiased
        assert 0.7 < z.std() < 1.35, z.std()  # the stated error is the actual error
    assert np.all(out["samples_used"] >= 40_000)


def test_delta_method_re_matches_repeated_estimates():
    log = _log(n=80)
    out = build_estimator({"name": "prior_is", "n_samples": 30_000}).estimate(log)
    predicted = np.abs(out["x_m"].mean()) * out["re_x"].mean() / np.sqrt(30_000)
    assert 0.75 < out["x_m"].std(ddof=1) / predicted < 1.3


def test_accuracy_target_stops_sampling():
    out = build_estimator({"name": "adaptive_is", "accuracy_m": 0.5, "n_bisections": 2000,
                           "check_samples": 20_000}).estimate(_log(n=3))
    assert out["reached_accuracy"].all()
    assert np.all(1.96 * out["se_x_m"] <= 0.5) and np.all(1.96 * out["se_y_m"] <= 0.5)
    assert np.all(out["samples_used"] == out["n_samples"] + 2001)  # + the bisections' f2


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
