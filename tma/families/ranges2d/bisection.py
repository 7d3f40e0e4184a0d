"""A piecewise-constant density on a rectangle, refined by bisection of cells.

Each cell holds one uniform random point x_j with g_j = f(x_j) / max f + c (c > 0, the shift:
without it a cell whose point misses the narrow peak of f gets zero mass and the sampler can
never reach the peak there); the cell's weight is g_j x area_j. Greedy refinement splits the
heaviest cell along its longer side (the parent's point stays in the child that contains it,
the other child draws a new point: one evaluation of f per bisection). The variant ``draw``
splits the cell hit by a draw from the current density. The frozen density samples cells by
weight and points uniformly within them; ``pdf`` locates any point through the split tree.

f is the ``ranges2d`` posterior kernel f2 (``RangeModel.log_kernel``), evaluated one point at
a time inside the compiled refinement (``refine``). The uniforms it consumes are drawn up
front in the order the draw-by-draw algorithm draws them (two for the first point, then per
bisection one to pick the cell in ``draw`` mode and two for the new point), so the generator
is left where that algorithm leaves it.
"""

import math

import numpy as np

from tma.runtime.jit import njit


class BisectionDensity:
    """Frozen piecewise-constant density. Cells: ``lo``, ``hi`` (k, 2); ``prob`` (k,) sums to 1."""

    def __init__(self, lo, hi, prob, tree, n_evaluations, shift, points=None):
        self.lo, self.hi, self.prob = lo, hi, prob
        self.points = points  # (k, 2): the point each cell's f was evaluated at
        self.area = np.prod(hi - lo, axis=1)
        self._cum = np.cumsum(prob)
        self._cum /= self._cum[-1]
        self._tree = tree  # (dim, split value, left, right, leaf cell) per node
        self.n_evaluations = n_evaluations
        self.shift = shift

    @property
    def n_cells(self) -> int:
        return self.prob.size

    @classmethod
    def build(cls, model, box, n_bisections, shift, rng, split="heaviest"):
        """Refine by ``n_bisections`` splits towards the posterior kernel of ``model`` (a
        ``RangeModel``); ``box``: ((x0, x1), (y0, y1)) in m."""
        if shift < 0:
            raise ValueError("shift must be >= 0")
        (x0, x1), (y0, y1) = box
        heaviest = split == "heaviest"
        u = rng.random(2 + (2 if heaviest else 3) * n_bisections)
        lo, hi, points, logf, log_max, tree = refine(
            kernel_terms(model), float(x0), float(x1), float(y0), float(y1), int(n_bisections),
            float(shift), heaviest, u)
        weight = (np.exp(logf - log_max) + shift) * np.prod(hi - lo, axis=1)
        return cls(lo, hi, weight / weight.sum(), tree, n_bisections + 1, shift, points)

    def sample(self, n, rng):
        """``n`` points (n, 2) and the index of the cell each was drawn from."""
        cell = np.minimum(np.searchsorted(self._cum, rng.random(n), side="right"), self.n_cells - 1)
        u = rng.random((n, 2))
        return self.lo[cell] + u * (self.hi[cell] - self.lo[cell]), cell

    def cell_density(self, cell):
        """Density value inside the given cells."""
        return self.prob[cell] / self.area[cell]

    def locate(self, x, y):
        """Cell index containing each point (points outside the box map to an edge cell)."""
        node = np.zeros(np.shape(x), dtype=np.int64)
        tree = self._tree
        while True:
            dim = tree[node, 0]
            inner = dim >= 0
            if not inner.any():
                return tree[node, 4].astype(np.int64)
            coord = np.where(dim == 0, x, y)
            go_right = coord >= tree[node, 1]
            child = np.where(go_right, tree[node, 3], tree[node, 2]).astype(np.int64)
            node = np.where(inner, child, node)

    def pdf(self, x, y):
        """Density at points (x, y); zero outside the box."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        inside = ((x >= self.lo[:, 0].min()) & (x <= self.hi[:, 0].max())
                  & (y >= self.lo[:, 1].min()) & (y <= self.hi[:, 1].max()))
        return np.where(inside, self.cell_density(self.locate(x, y)), 0.0)


def kernel_terms(model) -> np.ndarray:
    """The posterior kernel of a ``RangeModel`` as one array for ``log_f2``: row 0 the prior
    (mean x, mean y, sd x, sd y), then per landmark with ranges (x, y, n / (2 sigma^2),
    mean range); m."""
    (mx, my), (sx, sy) = model.prior_mean_m.tolist(), model.prior_sd_m.tolist()
    rows = [(mx, my, sx, sy)]
    rows += [(lx, ly, float(n * 0.5 / model.sigma_m**2), r) for (lx, ly), n, r in
             zip(model.landmarks_m.tolist(), model.counts.tolist(),
                 model.mean_range_m.tolist(), strict=True) if n]
    return np.array(rows, dtype=float)


@njit()
def log_f2(x, y, terms):
    """log f2 at one point (x, y), up to a constant: -((x - mx) / sx)^2 / 2 - ((y - my) /
    sy)^2 / 2 - sum over landmarks of n / (2 sigma^2) (|p - l| - mean range)^2."""
    out = -0.5 * (((x - terms[0, 0]) / terms[0, 2]) ** 2 + ((y - terms[0, 1]) / terms[0, 3]) ** 2)
    for i in range(1, terms.shape[0]):
        d = math.hypot(x - terms[i, 0], y - terms[i, 1]) - terms[i, 3]
        out -= terms[i, 2] * d * d
    return out


@njit()
def _weight(log_f, log_max, shift, area):
    return (math.exp(log_f - log_max) + shift) * area


@njit()
def _before(key_a, stamp_a, cell_a, key_b, stamp_b, cell_b):
    """(key, stamp, cell) a < b lexicographically, as heapq orders its tuples."""
    if key_a != key_b:
        return key_a < key_b
    if stamp_a != stamp_b:
        return stamp_a < stamp_b
    return cell_a < cell_b


@njit()
def _push(keys, stamps, cells, size, key, stamp, cell):
    """Push (key, stamp, cell) on the binary min-heap held in the first ``size`` slots;
    returns the new size."""
    i = size
    while i > 0:
        parent = (i - 1) // 2
        if not _before(key, stamp, cell, keys[parent], stamps[parent], cells[parent]):
            break
        keys[i], stamps[i], cells[i] = keys[parent], stamps[parent], cells[parent]
        i = parent
    keys[i], stamps[i], cells[i] = key, stamp, cell
    return size + 1


@njit()
def _pop(keys, stamps, cells, size):
    """Remove the smallest entry; returns it and the new size."""
    key, stamp, cell = keys[0], stamps[0], cells[0]
    size -= 1
    last_key, last_stamp, last_cell = keys[size], stamps[size], cells[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and _before(keys[child + 1], stamps[child + 1], cells[child + 1],
                                        keys[child], stamps[child], cells[child]):
            child += 1
        if not _before(keys[child], stamps[child], cells[child],
                       last_key, last_stamp, last_cell):
            break
        keys[i], stamps[i], cells[i] = keys[child], stamps[child], cells[child]
        i = child
    if size > 0:
        keys[i], stamps[i], cells[i] = last_key, last_stamp, last_cell
    return key, stamp, cell, size


@njit()
def refine(terms, x0, x1, y0, y1, n_bisections, shift, heaviest, u):
    """Cells ``lo``, ``hi`` (k, 2), their points (k, 2) and log f2 there (k,), max log f2 and
    the split tree (dim, split value, left, right, leaf cell per node; -1 where not
    applicable) after ``n_bisections`` splits of the box, consuming the uniforms ``u`` in
    order.

    ``heaviest``: a lazy greedy heap of (-weight, max log f2 when keyed, cell): keys only fall
    when max f2 rises, so an entry popped with an older max is re-keyed and pushed back.
    Otherwise the cell to split is drawn by weight (binary search in the running sum).
    """
    n = n_bisections + 1
    lo, hi, points, logf = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2)), np.empty(n)
    tree = np.empty((2 * n - 1, 5))
    node_of_cell = np.empty(n, dtype=np.int64)
    keys, stamps, cells = np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    cum = np.empty(0 if heaviest else n)
    lo[0, 0], lo[0, 1], hi[0, 0], hi[0, 1] = x0, y0, x1, y1
    points[0, 0], points[0, 1] = x0 + (x1 - x0) * u[0], y0 + (y1 - y0) * u[1]
    used = 2
    logf[0] = log_f2(points[0, 0], points[0, 1], terms)
    log_max = logf[0]
    tree[0, 0], tree[0, 1], tree[0, 2], tree[0, 3], tree[0, 4] = -1.0, 0.0, -1.0, -1.0, 0.0
    node_of_cell[0], n_nodes = 0, 1
    size = _push(keys, stamps, cells, 0,
                 -_weight(logf[0], log_max, shift, (x1 - x0) * (y1 - y0)), log_max, 0)
    for k in range(1, n):  # k: the new cell
        if heaviest:
            while True:
                key, stamp, j, size = _pop(keys, stamps, cells, size)
                if stamp == log_max:
                    break
                area = (hi[j, 0] - lo[j, 0]) * (hi[j, 1] - lo[j, 1])
                size = _push(keys, stamps, cells, size,
                             -_weight(logf[j], log_max, shift, area), log_max, j)
        else:
            total = 0.0
            for c in range(k):
                total += _weight(logf[c], log_max, shift,
                                 (hi[c, 0] - lo[c, 0]) * (hi[c, 1] - lo[c, 1]))
                cum[c] = total
            j = np.searchsorted(cum[:k], u[used] * total)
            used += 1
        dim = 0 if hi[j, 0] - lo[j, 0] >= hi[j, 1] - lo[j, 1] else 1
        mid = 0.5 * (lo[j, dim] + hi[j, dim])
        old_in_left = points[j, dim] < mid
        lo[k], hi[k] = lo[j], hi[j]
        if old_in_left:  # k is the right part
            lo[k, dim] = mid
            hi[j, dim] = mid
        else:
            hi[k, dim] = mid
            lo[j, dim] = mid
        points[k, 0] = lo[k, 0] + (hi[k, 0] - lo[k, 0]) * u[used]
        points[k, 1] = lo[k, 1] + (hi[k, 1] - lo[k, 1]) * u[used + 1]
        used += 2
        logf[k] = log_f2(points[k, 0], points[k, 1], terms)
        log_max = logf[k] if logf[k] > log_max else log_max
        # the leaf of j becomes a split node with leaves for j and k
        left, right = (j, k) if old_in_left else (k, j)
        parent = node_of_cell[j]
        for node, cell in ((n_nodes, left), (n_nodes + 1, right)):
            tree[node, 0], tree[node, 1], tree[node, 2], tree[node, 3] = -1.0, 0.0, -1.0, -1.0
            tree[node, 4] = cell
            node_of_cell[cell] = node
        tree[parent, 0], tree[parent, 1] = dim, mid
        tree[parent, 2], tree[parent, 3], tree[parent, 4] = n_nodes, n_nodes + 1, -1.0
        n_nodes += 2
        if heaviest:
            for c in (j, k):
                area = (hi[c, 0] - lo[c, 0]) * (hi[c, 1] - lo[c, 1])
                size = _push(keys, stamps, cells, size,
                             -_weight(logf[c], log_max, shift, area), log_max, c)
    return lo, hi, points, logf, log_max, tree
