"""Fuzzed configs of the bearings-only estimators (issue 8, item 5): a config is refused with a
ConfigError naming a key, or every track gets finite estimates with finite one-sigma errors,
or an explicit non-ok ``status``: never a crash, never a silent NaN.

Each example draws every field from a wide range (far beyond sensible values) and replaces
at most one field by a bad value (0, negative, NaN, +-inf, huge), so that most examples reach
the estimator and each bad value is met alone; the cases the fuzzing user reported are
explicit examples.
"""

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tests.test_estimator_configs import FUZZ, refused_or_built
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.families.bearings2d.status import STATUSES

LOG, _ = simulate_shard(Config(n_tracks=6, shard_size=6, sigma_deg=0.5, seed=12), 0)
LOG.bearing_deg[2, :40] = np.nan  # a contact that appears late
BAD = [float("nan"), float("inf"), float("-inf"), 0.0, -1.0, -1e300, 1e300]
ESTIMATE_COLUMNS = ("x0_m", "y0_m", "vx_m_s", "vy_m_s", "range_now_m", "bearing_now_deg",
                    "course_deg", "speed_m_s", "cost_rad2")


def log_uniform(lo, hi):
    return st.floats(np.log10(lo), np.log10(hi)).map(lambda e: 10.0**e)


SHARED = {"min_bearings": st.integers(0, 700), "max_range_rel_sd": log_uniform(1e-4, 1e4),
          "fit_alpha": log_uniform(1e-12, 10.0), "singular_rcond": log_uniform(1e-20, 10.0)}
LM = {"initial_bearing_deg": st.one_of(st.none(), st.floats(-720, 720)),
      "initial_distance_m": log_uniform(1e-2, 1e12), "initial_course_deg": st.floats(-720, 720),
      "initial_speed_m_s": log_uniform(1e-3, 1e6), "lambda0": log_uniform(1e-8, 1e20),
      "lambda_up": log_uniform(0.5, 1e3), "lambda_down": st.floats(0.0, 2.0),
      "f_tol_rad2": log_uniform(1e-20, 1.0), "max_iter": st.integers(0, 300),
      "lambda_max": log_uniform(1e-2, 1e30), "pd_rtol": log_uniform(1e-20, 10.0),
      "loss": st.sampled_from(["squared", "huber", "cauchy", "l1"]),
      "scale": st.sampled_from(["sigma", "mad", "iqr"]), "starts": st.integers(0, 5),
      "start_min_m": log_uniform(1e-2, 1e12), "start_max_m": log_uniform(1e-2, 1e12)}


def configs(name, fields):
    """A config of ``name`` with every field drawn, at most one of them replaced by BAD."""
    return st.tuples(st.fixed_dictionaries(fields),
                     st.one_of(st.none(), st.sampled_from(sorted(fields))),
                     st.sampled_from(BAD)).map(
        lambda draw: {"name": name, **draw[0], **({draw[1]: draw[2]} if draw[1] else {})})


def check_bearings(node):
    estimator = refused_or_built(node)
    if estimator is None:
        return
    if np.isfinite(LOG.bearing_deg).sum(axis=1).min() < estimator.config.min_bearings:
        return  # the log has too few bearings for this config: an InputError, tested elsewhere
    out = estimator.estimate(LOG)
    status = out["status"]
    assert set(status) <= set(STATUSES)
    ok = status == "ok"
    for column in (*ESTIMATE_COLUMNS, "range_sd_m", "bearing_sd_deg", "course_sd_deg",
                   "speed_sd_m_s"):
        assert np.isfinite(out[column][ok]).all(), column
    # a non-finite estimate always carries a verdict other than ok
    bad = ~np.isfinite(np.column_stack([out[c] for c in ESTIMATE_COLUMNS])).all(axis=1)
    assert (status[bad] != "ok").all()


@settings(FUZZ, max_examples=150)
@given(configs("lm", {**SHARED, **LM}))
@example({"name": "lm", "initial_distance_m": 0.0})  # LinAlgError before
@example({"name": "lm", "initial_distance_m": -5.0})  # tracks 1.8e13 m away, "converged"
@example({"name": "lm", "initial_bearing_deg": float("nan")})  # a traceback before
def test_lm_config_is_refused_or_every_track_is_finite_or_flagged(node):
    check_bearings(node)


@settings(FUZZ, max_examples=60)
@given(configs("nbearings", {**SHARED, "rcond": log_uniform(1e-20, 10.0)}))
def test_nbearings_config_is_refused_or_every_track_is_finite_or_flagged(node):
    check_bearings(node)
