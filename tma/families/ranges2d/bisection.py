"""A piecewise-constant density on a rectangle, refined by bisection of cells.

Each cell holds one uniform random point x_j with g_j = f(x_j) / max f + c (c > 0, the shift:
without it a cell whose point misses the narrow peak of f gets zero mass and the sampler can
never reach the peak there); the cell's weight is g_j x area_j. Greedy refinement splits the
heaviest cell along its longer side (the parent's point stays in the child that contains it,
the other child draws a new point: one evaluation of f per bisection). The variant ``draw``
splits the cell hit by a draw from the current density. The frozen density samples cells by
weight and points uniformly within them; ``pdf`` locates any point through the split tree.
"""

import heapq
import math

import numpy as np


class BisectionDensity:
    """Frozen piecewise-constant density. Cells: ``lo``, ``hi`` (k, 2); ``prob`` (k,) sums to 1."""

    def __init__(self, lo, hi, prob, tree, n_evaluations, shift):
        self.lo, self.hi, self.prob = lo, hi, prob
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
    def build(cls, log_f, box, n_bisections, shift, rng, split="heaviest"):
        """Refine by ``n_bisections`` splits. ``log_f(x, y)``: log of the target density (up
        to a constant) for Python floats; ``box``: ((x0, x1), (y0, y1))."""
        if shift < 0:
            raise ValueError("shift must be >= 0")
        (x0, x1), (y0, y1) = box
        lo, hi = [[x0, y0]], [[x1, y1]]
        px, py = x0 + (x1 - x0) * rng.random(), y0 + (y1 - y0) * rng.random()
        points, logf = [[px, py]], [log_f(px, py)]
        log_max = logf[0]
        # tree nodes: [dim, value, left, right, cell]; node i starts as the leaf of cell i
        node_of_cell, nodes = [0], [[-1, 0.0, -1, -1, 0]]
        heap = [(-cls._weight(logf[0], log_max, shift, (x1 - x0) * (y1 - y0)), log_max, 0)]
        for _ in range(n_bisections):
            if split == "heaviest":
                while True:  # lazy greedy: keys only fall when max f rises, so re-key stale ones
                    key, stamp, j = heapq.heappop(heap)
                    if stamp == log_max:
                        break
                    area = (hi[j][0] - lo[j][0]) * (hi[j][1] - lo[j][1])
                    heapq.heappush(heap, (-cls._weight(logf[j], log_max, shift, area), log_max, j))
            else:
                weights = np.array([cls._weight(lf, log_max, shift,
                                                (h[0] - low[0]) * (h[1] - low[1]))
                                    for lf, low, h in zip(logf, lo, hi, strict=True)])
                j = int(np.searchsorted(np.cumsum(weights), rng.random() * weights.sum()))
            dim = 0 if hi[j][0] - lo[j][0] >= hi[j][1] - lo[j][1] else 1
            mid = 0.5 * (lo[j][dim] + hi[j][dim])
            k = len(lo)  # the new cell
            left_hi, right_lo = list(hi[j]), list(lo[j])
            left_hi[dim], right_lo[dim] = mid, mid
            old_in_left = points[j][dim] < mid
            lo.append(right_lo if old_in_left else list(lo[j]))
            hi.append(list(hi[j]) if old_in_left else left_hi)
            if old_in_left:
                hi[j] = left_hi
            else:
                lo[j] = right_lo
            nx = lo[k][0] + (hi[k][0] - lo[k][0]) * rng.random()
            ny = lo[k][1] + (hi[k][1] - lo[k][1]) * rng.random()
            points.append([nx, ny])
            logf.append(log_f(nx, ny))
            log_max = max(log_max, logf[k])
            # tree: the leaf of j becomes a split node with leaves for j and k
            parent = node_of_cell[j]
            left_cell, right_cell = (j, k) if old_in_left else (k, j)
            nodes.append([-1, 0.0, -1, -1, left_cell])
            nodes.append([-1, 0.0, -1, -1, right_cell])
            nodes[parent] = [dim, mid, len(nodes) - 2, len(nodes) - 1, -1]
            node_of_cell.append(None)  # slot for the new cell k
            node_of_cell[left_cell] = len(nodes) - 2
            node_of_cell[right_cell] = len(nodes) - 1
            if split == "heaviest":
                for c in (j, k):
                    area = (hi[c][0] - lo[c][0]) * (hi[c][1] - lo[c][1])
                    heapq.heappush(heap, (-cls._weight(logf[c], log_max, shift, area), log_max, c))
        lo, hi, logf = np.array(lo), np.array(hi), np.array(logf)
        weight = (np.exp(logf - log_max) + shift) * np.prod(hi - lo, axis=1)
        tree = np.array(nodes, dtype=float)
        return cls(lo, hi, weight / weight.sum(), tree, n_bisections + 1, shift)

    @staticmethod
    def _weight(log_f, log_max, shift, area):
        return (math.exp(log_f - log_max) + shift) * area

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
