"""``lm`` on targets drawn from its own manoeuvre model (``target.manoeuvres.shape=burst``:
Poisson starts, Gaussian velocity changes as white-acceleration bursts of the declared
durations), beside ship-like turns of the same declared prior; and the component of the
true manoeuvres (the Laplace approximation alone, no search). Issue 36: where the ``ok``
answers' misses come from (``docs/manoeuvres.md``; ``make bench ARGS="--only own_model"``
gives the same on 2,000 targets)."""

import numpy as np
import pytest

from tma.families.bearings2d.calibration import CONSISTENT_TARGET as CONSISTENT
from tma.families.bearings2d.known_manoeuvres import true_manoeuvres_nees
from tma.families.bearings2d.manoeuvre_components import burst_levels
from tma.families.bearings2d.metrics import NEES_95


@pytest.fixture(scope="module")
def runs(own_model_runs):
    return own_model_runs


def _consistent(result):
    ok = result.status.to_numpy() == "ok"
    return np.mean(result.nees.to_numpy()[ok] <= NEES_95), ok


def test_lm_is_as_consistent_on_its_own_model_as_on_ship_turns(runs):
    """The ok answers' consistency within issue 36's band on both, and within 4 points of
    each other: the turns' shape (arcs, sizes tied to the speed) is not what the misses come
    from."""
    own, _ = _consistent(runs["burst"][1])
    turns, _ = _consistent(runs["turn"][1])
    assert CONSISTENT[0] <= own <= CONSISTENT[1], own
    assert CONSISTENT[0] <= turns <= CONSISTENT[1], turns
    assert abs(own - turns) <= 0.04, (own, turns)


def test_the_true_manoeuvres_component_is_consistent_where_it_was_made(runs):
    """The component of each burst target's true manoeuvres (drawn again from the shard's
    stream), refined to its MAP trajectory and linearised there as the mixture's are: on the
    ok tracks of targets that made at most one manoeuvre, consistent on 90-98 % (the Laplace
    approximation on data drawn from its own model); stated through log-polar coordinates
    (the second column), the same."""
    ds, result = runs["burst"]
    _, ok = _consistent(result)
    few = ok & (ds.truth.n_manoeuvres.to_numpy() <= 1)
    shares = np.mean(true_manoeuvres_nees(ds, np.flatnonzero(few)) <= NEES_95, axis=0)
    assert few.sum() >= 300 and np.all((0.90 <= shares) & (shares <= 0.98)), (few.sum(), shares)


@pytest.mark.xfail(strict=True, reason="0.85 manoeuvres weighed where 0.95 were made: the "
                   "sets of manoeuvres the bearings partly show that no base of the search "
                   "reaches are not counted (docs/manoeuvres.md, 'The search weighs too few')")
def test_the_search_weighs_as_many_manoeuvres_as_the_targets_made(runs):
    """On data drawn from the model itself, the posterior mean number of manoeuvres averages
    to the number made (the expectation of a posterior mean over the prior is the prior's):
    over the answered burst targets, within 0.06 of it (three standard errors)."""
    ds, result = runs["burst"]
    weighed = result.tma.estimates.n_manoeuvres.to_numpy(dtype=float)
    answered = np.isfinite(weighed)
    made = ds.truth.n_manoeuvres.to_numpy()[answered]
    assert answered.sum() >= 900
    assert abs(weighed[answered].mean() - made.mean()) <= 0.06, (weighed[answered].mean(),
                                                                 made.mean())


def test_burst_levels_carry_each_bursts_velocity_variance():
    """Summed over the steps, each burst's levels give its dv^2, wherever its ends fall."""
    t = np.arange(0.0, 601.0, 7.0)
    levels = burst_levels(t, np.array([100.3, 590.0, np.inf]), np.array([61.0, 200.0, 0.0]),
                          4.0)
    step = np.diff(t, prepend=t[0])
    assert np.sum(levels * step) == pytest.approx(16.0 + 16.0 * (t[-1] - 590.0) / 200.0)
    assert np.all(levels[t <= 100.3] == 0.0)
