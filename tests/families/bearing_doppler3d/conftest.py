"""Fixtures of the ``bearing_doppler3d`` tests: the default model, random states near the
default scenario's, and the dense form of the drift Jacobian's entries."""

import numpy as np
import pytest

from tma.families.bearing_doppler3d.model import AuvModel, model_record
from tma.families.bearing_doppler3d.scenario import Config


@pytest.fixture
def model():
    """The model of the default scenario (with Doppler)."""
    return AuvModel.from_record(model_record(Config()))


@pytest.fixture
def states():
    """``states(n, seed)``: n states as columns (6, n), spread around the default scenario's."""

    def make(n=7, seed=0):
        rng = np.random.default_rng(seed)
        return np.array([rng.normal(0, 3000, n), rng.normal(20000, 3000, n),
                         rng.normal(-1000, 100, n), rng.uniform(5, 12, n),
                         rng.normal(-np.pi / 2, 1, n), rng.uniform(-0.2, 0.2, n)])

    return make


@pytest.fixture
def dense():
    """``dense(entries, n)``: the (6, 6, n) matrix of ``AuvModel.drift_jacobian``'s entries."""

    def make(entries, n):
        out = np.zeros((6, 6, n))
        for (i, j), value in entries.items():
            out[i, j] = value
        return out

    return make
