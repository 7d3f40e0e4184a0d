"""ranges2d bisection density: tiling, sampling, cell weights g_j x area_j with the shift, and
the compiled refinement against the plain draw-by-draw loop."""

import heapq
import math

import numpy as np
import pytest
from scipy.stats import chi2

from tma.families import build_estimator
from tma.families.ranges2d.bisection import BisectionDensity
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
    d = BisectionDensity.build(model, BOX, 3000, 5e-4, rng)
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
    d = BisectionDensity.build(model, BOX, n_bisections, shift, np.random.default_rng(1), split)
    points = d.points
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
    d0 = BisectionDensity.build(model, BOX, 2000, 0.0, np.random.default_rng(1))
    c = 0.5 * (d0.lo + d0.hi)
    zero = d0.prob / d0.area < 1e-300
    assert zero.any()
    assert np.all(np.isfinite(model.log_kernel(c[zero, 0], c[zero, 1])))
    assert build_estimator({"name": "adaptive_is", "shift": 0.02}).config.shift == 0.02


def _plain_refinement(model, box, n_bisections, shift, rng, split):
    """The refinement as first written: Python floats and lists, heapq, one draw at a time,
    f2 by its formula with math.hypot. Returns lo, hi, points, tree."""
    (mx, my), (sx, sy) = model.prior_mean_m, model.prior_sd_m
    marks = [(lx, ly, n * 0.5 / model.sigma_m**2, r) for (lx, ly), n, r in
             zip(model.landmarks_m, model.counts, model.mean_range_m, strict=True) if n]

    def log_f(x, y):
        out = -0.5 * (((x - mx) / sx) ** 2 + ((y - my) / sy) ** 2)
        for lx, ly, c, r in marks:
            out -= c * (math.hypot(x - lx, y - ly) - r) ** 2
        return out

    def weight(j, log_max):
        return (math.exp(logf[j] - log_max) + shift) * (hi[j][0] - lo[j][0]) * (
            hi[j][1] - lo[j][1])

    (x0, x1), (y0, y1) = box
    lo, hi = [[x0, y0]], [[x1, y1]]
    points = [[x0 + (x1 - x0) * rng.random(), y0 + (y1 - y0) * rng.random()]]
    logf = [log_f(*points[0])]
    log_max = logf[0]
    node_of_cell, nodes = [0], [[-1, 0.0, -1, -1, 0]]
    heap = [(-weight(0, log_max), log_max, 0)]
    for _ in range(n_bisections):
        if split == "heaviest":
            while True:
                _, stamp, j = heapq.heappop(heap)
                if stamp == log_max:
                    break
                heapq.heappush(heap, (-weight(j, log_max), log_max, j))
        else:
            w = np.array([weight(c, log_max) for c in range(len(lo))])
            j = int(np.searchsorted(np.cumsum(w), rng.random() * w.sum()))
        dim = 0 if hi[j][0] - lo[j][0] >= hi[j][1] - lo[j][1] else 1
        mid = 0.5 * (lo[j][dim] + hi[j][dim])
        k, old_in_left = len(lo), points[j][dim] < mid
        lo.append(list(lo[j]))
        hi.append(list(hi[j]))
        if old_in_left:
            lo[k][dim] = hi[j][dim] = mid
        else:
            hi[k][dim] = lo[j][dim] = mid
        points.append([lo[k][0] + (hi[k][0] - lo[k][0]) * rng.random(),
                       lo[k][1] + (hi[k][1] - lo[k][1]) * rng.random()])
        logf.append(log_f(*points[k]))
        log_max = max(log_max, logf[k])
        left, right = (j, k) if old_in_left else (k, j)
        nodes[node_of_cell[j]] = [dim, mid, len(nodes), len(nodes) + 1, -1]
        node_of_cell.append(None)
        node_of_cell[left], node_of_cell[right] = len(nodes), len(nodes) + 1
        nodes += [[-1, 0.0, -1, -1, left], [-1, 0.0, -1, -1, right]]
        if split == "heaviest":
            for c in (j, k):
                heapq.heappush(heap, (-weight(c, log_max), log_max, c))
    return np.array(lo), np.array(hi), np.array(points), np.array(nodes, dtype=float)


@pytest.mark.parametrize(("split", "n_bisections", "shift"),
                         [("heaviest", 3000, 5e-4), ("heaviest", 500, 0.0), ("draw", 300, 1e-2)])
def test_compiled_refinement_is_the_plain_loop(model, split, n_bisections, shift):
    """The same cells, points and tree, and the generator left in the same state."""
    rng_a, rng_b = np.random.default_rng(9), np.random.default_rng(9)
    d = BisectionDensity.build(model, BOX, n_bisections, shift, rng_a, split)
    lo, hi, points, tree = _plain_refinement(model, BOX, n_bisections, shift, rng_b, split)
    np.testing.assert_array_equal(d.lo, lo)
    np.testing.assert_array_equal(d.hi, hi)
    np.testing.assert_array_equal(d.points, points)
    np.testing.assert_array_equal(d._tree, tree)
    assert rng_a.random() == rng_b.random()
