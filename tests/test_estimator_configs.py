"""Fuzzed configs: every estimator (but the bearings-only ones) and every scenario of the
ranges2d, radar2d and bearing_doppler3d families either refuses a config with a ConfigError
that names a key, or runs on a small simulated log of its family and gives each track a finite
estimate or an explicit failure flag: never another exception, never a silent NaN.

Values are drawn from wide ranges around the meaningful ones plus bad values (0, negative,
NaN, +-inf, absurdly large); the ranges of the costly parameters stay small enough that each
example takes milliseconds.
"""

from dataclasses import asdict
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tma.errors import ConfigError
from tma.families import build_estimator, load_scenario
from tma.families.bearing_doppler3d import scenario as bearing_doppler3d
from tma.families.bearing_doppler3d.model import STATE_NAMES
from tma.families.radar2d import scenario as radar2d
from tma.families.ranges2d import scenario as ranges2d
from tma.families.ranges2d.estimators.base import STATUSES

FUZZ = settings(max_examples=150, deadline=None, database=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])
BAD = st.sampled_from([float("nan"), float("inf"), float("-inf"), 0.0, -1.0, -1e300, 1e300])


def real(lo, hi):
    """A float in [lo, hi] (log-uniform if lo > 0) or a bad value."""
    good = (st.floats(np.log10(lo), np.log10(hi)).map(lambda e: 10.0**e) if lo > 0
            else st.floats(lo, hi))
    return st.one_of(good, good, good, good, BAD)


def count(lo, hi, huge=True):
    """An int in [lo, hi] or a bad one (0, negative and, unless a huge count is valid but
    takes forever, 10^12)."""
    good = st.integers(lo, hi)
    return st.one_of(good, good, good, good,
                     st.sampled_from([0, -1, -(10**9)] + [10**12] * huge))


def maybe(strategy):
    return st.one_of(st.none(), strategy)


def vector(element, n):
    """Mostly ``n`` elements, sometimes another length (0 to n + 1)."""
    right = st.lists(element, min_size=n, max_size=n)
    return st.one_of(right, right, right, st.lists(element, max_size=n + 1))


def refused_or_built(node, build=build_estimator):
    """The built object, or None after checking the refusal names one of ``node``'s keys."""
    try:
        built = build(node)
    except ConfigError as exc:
        keys = [k for k in node if k not in ("name", "family")]
        assert any(k in str(exc) for k in keys), f"{exc} names none of {keys}"
        event("refused")  # --hypothesis-show-statistics: how many examples ran
        return None
    event("accepted")
    return built


# ---------------------------------------------------------------------------------- ranges2d

RANGES_LOG = ranges2d.simulate_shard(ranges2d.Config(n_tracks=2, shard_size=2), 0)[0]


def check_ranges(node):
    est = refused_or_built(node)
    if est is None:
        return
    out = est.estimate(RANGES_LOG)
    assert set(out["status"]) <= set(STATUSES)
    has = np.isin(out["status"], ["ok", "not_converged"])
    for key in ("x_m", "y_m", "se_x_m", "se_y_m"):
        assert np.isfinite(out[key][has]).all(), (key, out["status"])
    assert np.array_equal(out["reached_accuracy"], out["status"] == "ok") or node["name"] == \
        "quadrature"


def over(base):
    """Drawn keys over a cheap ``base`` (the defaults take about a second per track)."""
    return lambda drawn: {**base, **drawn}


CHEAP_SAMPLING = {"min_samples": 500, "max_samples": 3000, "batch": 500}
SAMPLING = {"n_samples": maybe(count(2, 3000, huge=False)), "accuracy_m": real(0.5, 1e4),
            "confidence": real(1e-6, 0.9999), "batch": count(1, 2000),
            "min_samples": count(2, 3000, huge=False), "max_samples": count(2, 5000, huge=False),
            "plot_points": count(0, 100), "seed": count(0, 2**40)}


@FUZZ
@given(st.fixed_dictionaries({"name": st.just("quadrature")}, optional={
    "n_panels": count(1, 20), "n_nodes": count(1, 8), "search_sd": real(0.1, 50.0),
    "search_points": count(11, 301), "log_cut": real(1.0, 1000.0)}).map(
    over({"n_panels": 10, "n_nodes": 6, "search_points": 101})))
def test_quadrature(node):
    check_ranges(node)


@FUZZ
@given(st.fixed_dictionaries({"name": st.just("prior_is")}, optional=SAMPLING).map(
    over(CHEAP_SAMPLING)))
def test_prior_is(node):
    check_ranges(node)


@FUZZ
@given(st.fixed_dictionaries({"name": st.just("adaptive_is")}, optional={
    **SAMPLING, "n_bisections": count(0, 300), "shift": real(1e-8, 10.0),
    "split": st.sampled_from(["heaviest", "draw", "random"]),
    "box_m": st.one_of(vector(real(-2000.0, 2000.0), 4),  # each pair ordered, or as drawn
                       vector(real(-2000.0, 2000.0), 4).map(
                           lambda b: [*sorted(b[:2]), *sorted(b[2:])])),
    "check_samples": count(1, 2000), "max_mass_outside": real(1e-6, 2.0)}).map(
    over({**CHEAP_SAMPLING, "n_bisections": 200, "check_samples": 2000})))
def test_adaptive_is(node):
    check_ranges(node)


# ----------------------------------------------------------------------------------- radar2d

RADAR_LOG = radar2d.simulate_shard(radar2d.Config(n_tracks=3, shard_size=3, speed_m_s=20.0),
                                   0)[0]
# null, the log's period, or nonsense (a positive period that contradicts the log is an input
# error of the estimate stage: see below)
SCAN = maybe(st.one_of(st.just(3.0), BAD.filter(lambda v: not v > 0)))


def check_radar(node):
    est = refused_or_built(node)
    if est is None:
        return
    out = est.estimate(RADAR_LOG)
    assert set(out["status"]) <= {"ok", "divergent"}
    ok = out["status"] == "ok"
    for key in ("x_m", "y_m", "vx_m_s", "vy_m_s"):
        assert np.isfinite(out[key][ok]).all(), key  # every plot present: finite throughout


@FUZZ
@given(st.fixed_dictionaries({"name": st.just("alphabeta")}, optional={
    "memory": count(2, 10**6), "scan_period_s": SCAN}))
def test_alphabeta(node):
    check_radar(node)


@FUZZ
@given(st.fixed_dictionaries({"name": st.just("fuzzy_mm")}, optional={
    "memory": st.one_of(st.integers(3, 12), st.sampled_from([2, 0, -4, 201, 10**9])),
    "bad_slope": real(1e-3, 1e4), "bad_centre": real(1e-3, 10.0),
    "residual_clip": real(1e-3, 10.0), "sigma_prior_m": real(1e-6, 1e6),
    "sigma_hat_m": maybe(real(1e-6, 1e6)), "scan_period_s": SCAN}))
def test_fuzzy_mm(node):
    check_radar(node)


@FUZZ
@given(st.fixed_dictionaries({"name": st.just("imm")}, optional={
    "p_stay": real(1e-9, 1.5), "cv_accel_psd": real(1e-12, 1e6),
    "ct_accel_psd": real(1e-12, 1e6), "ct_omega_psd": real(1e-15, 10.0),
    "initial_omega_sd": real(1e-9, 10.0),
    "initial_probs": st.one_of(st.floats(0, 1).map(lambda p: [p, 1 - p]),
                               vector(real(1e-3, 2.0), 2)),
    "scan_period_s": SCAN}))
def test_imm(node):
    check_radar(node)


def test_a_period_contradicting_the_log_is_an_input_error_naming_the_key():
    """Not knowable when the config is built: the estimate stage reports it, naming it."""
    with pytest.raises(Exception, match="scan_period_s = 2 s in the config contradicts"):
        build_estimator({"name": "imm", "scan_period_s": 2.0}).estimate(RADAR_LOG)


# ------------------------------------------------------------------------- bearing_doppler3d

SMALL_AUV = {"n_tracks": 3, "shard_size": 3, "duration_s": 4.0}
MODEL = {"lam": real(1e-6, 10.0), "mu": real(1e-6, 10.0), "nu": real(-1.0, 1.0),
         "sd_angle": real(1e-6, 1.0), "sd_doppler_hz": real(1e-6, 10.0),
         "filter_step_s": st.sampled_from([0.1, 0.25, 0.3, 0.0, -0.1, float("nan")])}


def auv_log(overrides):
    """(config, log) of a small simulated dataset, or None if the scenario is refused."""
    cfg = refused_or_built({"family": "bearing_doppler3d", **SMALL_AUV, **overrides},
                           lambda node: load_scenario(node)[1])
    if cfg is None:
        return None
    try:
        return cfg, bearing_doppler3d.simulate_shard(cfg, 0)[0]
    except ConfigError as exc:  # scales valid one by one whose paths overflow together
        assert "overflow" in str(exc)
        return None


def check_auv(node, model, data_dir=None):
    est = refused_or_built(node)
    made = auv_log(model)
    if est is None or made is None:
        return
    cfg, log = made
    if node["name"] in ("cmnf", "prior_mean"):  # train (or reuse) the artefact first
        dataset = SimpleNamespace(family=cfg.family, manifest={"config": asdict(cfg)})
        est = build_estimator(type(est).prepare(asdict(est.config), dataset, data_dir),
                              data_dir)
    out = est.estimate(log)
    ok = out["filter_ok"]
    for key in (*STATE_NAMES, *[f"sd_{c}" for c in STATE_NAMES]):
        assert np.isfinite(out[key][ok]).all(), key


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("artefacts")


@FUZZ
@given(st.sampled_from(["ekf", "srekf"]),
       st.fixed_dictionaries({}, optional={"covariance_every": count(1, 20)}),
       st.fixed_dictionaries({}, optional=MODEL))
def test_kalman_filters(name, node, model):
    check_auv({"name": name, **node}, model)


@settings(FUZZ, max_examples=25)
@given(st.fixed_dictionaries({"name": st.just("cmnf")}, optional={
    "training_paths": count(100, 200), "training_seed": count(0, 3),
    "pinv_rtol": real(1e-15, 2.0), "covariance_every": count(1, 20)}),
    st.fixed_dictionaries({}, optional=MODEL))
def test_cmnf(data_dir, node, model):
    check_auv(node, model, data_dir)


@settings(FUZZ, max_examples=25)
@given(st.fixed_dictionaries({"name": st.just("prior_mean")}, optional={
    "bundle_paths": count(100, 200), "bundle_seed": count(0, 3),
    "covariance_every": count(1, 20)}),
    st.fixed_dictionaries({}, optional=MODEL))
def test_prior_mean(data_dir, node, model):
    check_auv(node, model, data_dir)


# --------------------------------------------------------------------------------- scenarios

@FUZZ
@given(st.fixed_dictionaries({"family": st.just("ranges2d"), "n_tracks": st.just(2)}, optional={
    "mode": st.sampled_from(["concrete", "population", "other"]),
    "landmarks_m": vector(vector(real(-1e4, 1e4), 2), 2),
    "ranges_m": vector(vector(real(1.0, 1e4), 3), 2),
    "n_pairs": count(1, 5), "sigma_m": real(1e-3, 1e4),
    "prior_mean_m": vector(real(-1e3, 1e3), 2), "prior_sd_m": vector(real(1e-2, 1e4), 2),
    "seed": count(0, 2**40), "shard_size": count(1, 5)}))
def test_ranges2d_scenario(node):
    made = refused_or_built(node, lambda n: load_scenario(n)[1])
    if made is not None:
        log = ranges2d.simulate_shard(made, 0)[0]
        log.validate("fuzzed")  # what the estimate stage checks when it reads the log
        out = build_estimator({"name": "prior_is", "n_samples": 200}).estimate(log)
        assert np.isfinite(out["x_m"][out["status"] != "failed"]).all()


@FUZZ
@given(st.fixed_dictionaries({"family": st.just("radar2d"), "n_tracks": st.just(2)}, optional={
    "speed_m_s": real(1e-2, 100.0), "initial_course_deg": real(-720.0, 720.0),
    "legs": st.lists(st.fixed_dictionaries({}, optional={
        "duration_s": real(1.0, 100.0), "course_deg": real(-360.0, 360.0),
        "turn_radius_m": real(1.0, 1e4), "direction": st.sampled_from(["left", "right", "up"])}),
        max_size=3),
    "scan_period_s": real(0.1, 200.0), "noise": st.sampled_from(["cartesian", "polar", "x"]),
    "sigma_m": real(1e-3, 1e3), "radar_xy_m": vector(real(-1e4, 1e4), 2),
    "range_sd_m": real(1e-3, 1e3), "bearing_sd_deg": real(1e-3, 10.0), "seed": count(0, 9)}))
def test_radar2d_scenario(node):
    made = refused_or_built(node, lambda n: load_scenario(n)[1])
    if made is not None:
        log, truth = radar2d.simulate_shard(made, 0)
        assert np.isfinite(log.plots_m).all() and log.t_s.size >= 3
        out = build_estimator({"name": "imm"}).estimate(log)
        assert np.isfinite(out["x_m"][out["status"] == "ok"]).all()


@FUZZ
@given(st.fixed_dictionaries({}, optional={
    **MODEL, "duration_s": st.sampled_from([1.0, 2.0, 2.5, 0.0, -1.0, float("inf")]),
    "obs_period_s": st.sampled_from([0.5, 1.0, 0.7, 0.0]),
    "truth_step_s": st.sampled_from([1e-2, 5e-3, 3e-3, -1e-3]),
    "omega0_hz": real(1e-2, 1e3), "sound_speed_m_s": real(1.0, 1e5),
    "sensors_m": vector(vector(real(-1e4, 1e4), 3), 2),
    "no_doppler": st.booleans(),
    "initial": st.fixed_dictionaries({}, optional={
        "speed_min_m_s": real(0.1, 20.0), "speed_max_m_s": real(0.1, 20.0),
        "position_sd_m": vector(real(1.0, 1e4), 3),
        "heading_sd_rad": real(1e-3, 10.0), "accel_min_m_s2": real(-1.0, 1.0)})}))
def test_bearing_doppler3d_scenario(node):
    made = auv_log(node)
    if made is not None:
        assert np.isfinite(made[1].obs).all()
        out = build_estimator({"name": "ekf"}).estimate(made[1])
        assert np.isfinite(out["X_m"][out["filter_ok"]]).all()
