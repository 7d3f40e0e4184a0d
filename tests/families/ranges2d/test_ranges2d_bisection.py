"""ranges2d bisection density: tiling, sampling, and cell weights g_j x area_j with the shift."""

import numpy as np
import pytest
from scipy.stats import chi2

from tma.families import build_estimator
from tma.families.ranges2d.bisection import BisectionDensity
from tma.families.ranges2d.estimators.adaptive_is import scalar_log_kernel
from tma.families.ranges2d.model import RangeModel
from tma.families.ranges2d.scenario import Config, simulate_shard

BOX = ((-400.0, 400.0), (-400.0, 400.0))


@pytest.fixture(scope="module")
def model():
    """The article's case."""
    log = simulate_shard(Config(n_tracks=1, shard_size=1), 0)[0]
    return RangeModel.from_ranges(log.landmarks_m, log.ranges_m[0], 30.0, [0, 0], [100, 100])


def test_bisection_density_normalised_and_sampler_matches(model):
    rng = np.random.default_rng(5)
    d = BisectionDensity.build(scalar_log_kernel(model), BOX, 3000, 5e-4, rng)
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


@pytest.mark.parametrize(("shift", "split", "n_bisections"), [
    (5e-4, "heaviest", 2000), (1e-2, "heaviest", 2000), (1e-2, "draw", 300)])
def test_cell_weights_are_the_shifted_kernel_times_the_area(model, shift, split, n_bisections):
    """The spec's weights, recomputed independently: cell j holds one point x_j (the j-th
    evaluation of f2: the first cell's, then one new cell per bisection) and its probability
    is (f2(x_j) / max f2 + c) area_j normalised, with f2 from the vectorised kernel."""
    log_f, seen = scalar_log_kernel(model), []

    def recording(x, y):
        seen.append((x, y))
        return log_f(x, y)

    d = BisectionDensity.build(recording, BOX, n_bisections, shift,
                               np.random.default_rng(1), split)
    points = np.array(seen)
    assert points.shape == (d.n_cells, 2) and d.shift == shift
    assert np.all((d.lo <= points) & (points <= d.hi))  # each point lies in its cell
    logf = model.log_kernel(points[:, 0], points[:, 1])
    f = np.exp(logf - logf.max())
    g = f + shift
    np.testing.assert_allclose(d.prob, g * d.area / (g * d.area).sum(), rtol=1e-9, atol=0)
    # the check sees the shift: without it the cells away from the peak would differ
    assert not np.allclose(d.prob, f * d.area / (f * d.area).sum(), rtol=1e-3, atol=0)


def test_without_the_shift_cells_missing_the_peak_get_no_mass(model):
    """Cells whose point misses the peak get (numerically) zero mass even though f2 is
    positive there: the sampler could never draw from them; hence a positive shift."""
    d0 = BisectionDensity.build(scalar_log_kernel(model), BOX, 2000, 0.0,
                                np.random.default_rng(1))
    c = 0.5 * (d0.lo + d0.hi)
    zero = d0.prob / d0.area < 1e-300
    assert zero.any()
    assert np.all(np.isfinite(model.log_kernel(c[zero, 0], c[zero, 1])))
    assert build_estimator({"name": "adaptive_is", "shift": 0.02}).config.shift == 0.02
