"""``lm`` with ``loss=huber|cauchy`` and ``starts=K`` against independent references: the
default (squared, one start) is today's kernel call bit for bit and scipy's least squares
minimum; the robust fits reach scipy's ``least_squares(loss=huber|cauchy)`` minimum, recover
the truth under 5 % outliers where least squares fails, are ``ok`` at the nominal rate with
honest sandwich one-sigma errors; extra starts find the lower minimum where the default start
converges to a worse one."""

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.special import chdtri

from tma.families import build_estimator
from tma.families.bearings2d.estimators.lm import initial_theta
from tma.families.bearings2d.marquardt import (
    LOSS_HUBER,
    TUNING,
    marquardt,
)
from tma.families.bearings2d.model import BearingTerms, bearing_jacobian, bearing_residuals
from tma.families.bearings2d.scenario import (
    Config,
    OutlierConfig,
    PopulationConfig,
    simulate_shard,
)

THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")
SIGMA = 0.5


def _log(n, seed, prob=0.0, **kw):
    cfg = Config(n_tracks=n, shard_size=n, sigma_deg=SIGMA, seed=seed,
                 outliers=OutlierConfig(prob=prob), **kw)
    log, truth = simulate_shard(cfg, 0)
    return log, np.column_stack([truth[c].to_numpy() for c in THETA])


def _theta(out):
    return np.column_stack([out[c] for c in THETA])


def _inputs(log):
    valid = np.isfinite(log.bearing_deg)
    measured = np.where(valid, np.deg2rad(log.bearing_deg), 0.0)
    return log.t_s, log.own_x_m, log.own_y_m, measured, (None if valid.all() else valid)


def _todays_call(lm, log):
    """The pre-``loss``/``starts`` solve of ``lm``: one start, the plain kernel."""
    cfg = lm.config
    t, ox, oy, measured, valid = _inputs(log)
    first = np.zeros(log.n_tracks, dtype=int) if valid is None else np.argmax(valid, axis=1)
    terms = BearingTerms(t, ox, oy, measured, valid)
    n = log.n_tracks
    theta = initial_theta(cfg, t, ox, oy, measured, first)
    counts = [np.zeros(n, dtype=np.int64) for _ in range(2)] + [np.full(n, -1, dtype=np.int64)]
    cost, jtj = np.zeros(n), np.zeros((n, 4, 4))
    marquardt(theta, terms.t, terms.ox, terms.oy, terms.measured, terms.weight, terms.weighted,
              cfg.lambda0, cfg.lambda_up, cfg.lambda_down, cfg.f_tol_rad2, cfg.max_iter,
              cfg.lambda_max, cfg.pd_rtol, *counts, cost, jtj)
    return theta, counts, cost, jtj


@pytest.mark.parametrize("missing", [False, True])
def test_default_is_todays_kernel_call_bit_for_bit(missing):
    """loss=squared, starts=1: the same bits as the kernel called as before, and no new
    column (the estimates table keeps its bytes)."""
    log, _ = _log(60, 3)
    if missing:
        log.bearing_deg[np.random.default_rng(1).random(log.bearing_deg.shape) < 0.2] = np.nan
    lm = build_estimator({"name": "lm"})
    out = lm.estimate(log)
    theta, (n_f, n_iter, stop), cost, jtj = _todays_call(lm, log)
    np.testing.assert_array_equal(_theta(out), theta)
    np.testing.assert_array_equal(out["cost_rad2"], cost)
    np.testing.assert_array_equal(out["jtj_03"], jtj[:, 0, 3])
    for column, ref in (("n_f_evals", n_f), ("n_iter", n_iter), ("stop_reason", stop)):
        np.testing.assert_array_equal(out[column], ref)
    assert not set(out) & set(type(lm).outputs)


def test_robust_kernel_with_the_squared_loss_is_the_plain_kernel():
    """The kernel's robust branch with a quadratic loss (Huber with c = inf: omega = 1)
    takes the squared branch's decisions (counters) and reaches its result to round-off:
    the two share every step but the cost evaluation."""
    log, _ = _log(40, 4)
    lm = build_estimator({"name": "lm"})
    theta, (n_f, n_iter, stop), cost, _ = _todays_call(lm, log)
    t, ox, oy, measured, _ = _inputs(log)
    cfg = lm.config
    x = initial_theta(cfg, t, ox, oy, measured, np.zeros(log.n_tracks, dtype=int))
    out = [np.zeros(40, dtype=np.int64) for _ in range(2)] + [np.full(40, -1, dtype=np.int64),
                                                               np.zeros(40)]
    marquardt(x, t, ox, oy, measured, np.empty((0, 0)), False, cfg.lambda0, cfg.lambda_up,
              cfg.lambda_down, cfg.f_tol_rad2, cfg.max_iter, cfg.lambda_max, cfg.pd_rtol, *out,
              None, LOSS_HUBER, np.inf, np.ones(40))
    np.testing.assert_array_equal(out[0], n_f)
    np.testing.assert_array_equal(out[1], n_iter)
    np.testing.assert_array_equal(out[2], stop)
    np.testing.assert_allclose(out[3], cost, rtol=1e-9)
    np.testing.assert_allclose(x, theta, rtol=1e-8, atol=1e-6)


def _scipy_fit(log, i, x0, loss, f_scale):
    """scipy's trust-region least squares on track ``i`` (its own robust loss)."""
    t, ox, oy, measured, valid = _inputs(log)
    v = None if valid is None else valid[i:i + 1]

    def fun(th):
        return bearing_residuals(th[None], t, ox, oy, measured[i:i + 1], v)[0]

    def jac(th):
        return -bearing_jacobian(th[None], t, ox, oy, v)[0]

    return least_squares(fun, x0, jac=jac, loss=loss, f_scale=f_scale, x_scale="jac",
                         xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000).x


def _sd(out):
    return np.column_stack([np.sqrt(np.diag(np.linalg.inv(np.array(
        [[out[f"jtj_{min(a, b)}{max(a, b)}"][i] for b in range(4)] for a in range(4)]))))
        for i in range(len(out["x0_m"]))]).T * np.deg2rad(out["sigma_used_deg"])[:, None]


@pytest.mark.parametrize("loss, prob", [("squared", 0.0), ("huber", 0.05), ("cauchy", 0.05)])
def test_reaches_scipys_minimum(loss, prob):
    """scipy started from the truth (loss 'linear' for squared; f_scale = c sigma, whose rho
    is ours over 2: the same minimiser) lands where lm does, within 1e-3 one-sigma."""
    log, truth = _log(25, 5, prob)
    out = build_estimator({"name": "lm", "loss": loss}).estimate(log)
    assert (out["status"] == "ok").mean() >= 0.9
    ours, sd = _theta(out), _sd(out)
    scipy_loss = "linear" if loss == "squared" else loss
    f_scale = 1.0 if loss == "squared" else TUNING[loss] * np.deg2rad(SIGMA)
    for i in range(log.n_tracks):
        ref = _scipy_fit(log, i, truth[i], scipy_loss, f_scale)
        assert np.all(np.abs(ours[i] - ref) <= 1e-3 * sd[i]), (i, (ours[i] - ref) / sd[i])


@pytest.fixture(scope="module")
def outlier_runs():
    """300 tracks, 5 % of the bearings outliers (uniform on the circle), sigma 0.5 deg; and
    the same tracks without them."""
    clean, truth = _log(300, 9)
    dirty, _ = _log(300, 9, 0.05)
    runs = {"clean": build_estimator({"name": "lm"}).estimate(clean)}
    for loss in ("squared", "huber", "cauchy"):
        runs[loss] = build_estimator({"name": "lm", "loss": loss}).estimate(dirty)
    runs["huber_mad"] = build_estimator({"name": "lm", "loss": "huber", "scale": "mad"}
                                        ).estimate(dirty)
    return truth, runs


def _position_error(out, truth):
    return np.hypot(out["x0_m"] - truth[:, 0], out["y0_m"] - truth[:, 1])


def test_robust_fit_recovers_the_truth_under_outliers(outlier_runs):
    """Measured: median error at t = 0 ~300 m clean (least squares) and robust under
    outliers, ~14 km for least squares under outliers."""
    truth, runs = outlier_runs
    med = {k: np.median(_position_error(v, truth)) for k, v in runs.items()}
    for robust in ("huber", "cauchy", "huber_mad"):
        assert med[robust] < 1.3 * med["clean"], med
        assert med[robust] < 0.1 * med["squared"], med
    assert (runs["squared"]["status"] == "ok").mean() < 0.1  # least squares: poor_fit
    assert runs["huber"]["n_downweighted"].mean() > 0.05 * 601


def test_robust_fit_is_ok_at_the_nominal_rate_with_honest_sandwich_errors(outlier_runs):
    """Outliers do not make a robust fit poor: >= 95 % ok (the clean least-squares rate),
    and 90-99 % of the ok tracks' normalised errors within the chi-square(4) 95 % point."""
    truth, runs = outlier_runs
    bound = chdtri(4, 0.05)
    for key in ("clean", "huber", "cauchy", "huber_mad"):
        out = runs[key]
        ok = out["status"] == "ok"
        assert ok.mean() >= 0.95, (key, ok.mean())
        e = _theta(out)[ok] - truth[ok]
        info = np.array([[out[f"jtj_{min(a, b)}{max(a, b)}"][ok] for b in range(4)]
                         for a in range(4)]).transpose(2, 0, 1)
        nees = np.einsum("ni,nij,nj->n", e, info, e) / np.deg2rad(out["sigma_used_deg"][ok])**2
        assert 0.9 <= (nees <= bound).mean() <= 0.99, (key, (nees <= bound).mean())


def test_robust_fit_test_rejects_at_its_level_and_detects_a_wrong_sigma():
    """The robust fit test at fit_alpha = 0.05 rejects ~5 % of clean fits (and of fits
    under outliers); declaring sigma half the true noise fails nearly every track."""
    for prob in (0.0, 0.05):
        log, _ = _log(400, 13, prob)
        out = build_estimator({"name": "lm", "loss": "huber", "fit_alpha": 0.05}).estimate(log)
        rejected = (out["fit_p_value"] < 0.05).mean()
        assert 0.02 <= rejected <= 0.09, (prob, rejected)
    log.sigma_deg = SIGMA / 2
    out = build_estimator({"name": "lm", "loss": "cauchy"}).estimate(log)
    assert (out["status"] == "poor_fit").mean() > 0.95


def test_extra_starts_find_the_lower_minimum():
    """Targets west of own-ship, the default start north at 25 km: ~7 % of tracks converge to
    a worse local minimum (poor_fit). starts=4 finds, for those, the minimum scipy reaches
    from the truth; every other track keeps its one-start result bit for bit."""
    log, truth = _log(200, 11, population=PopulationConfig(
        initial_bearing_deg=270.0, course_min_deg=0.0, course_max_deg=360.0))
    one = build_estimator({"name": "lm"}).estimate(log)
    four = build_estimator({"name": "lm", "starts": 4}).estimate(log)
    changed = four["start_won"] > 0
    sigma2 = np.deg2rad(SIGMA) ** 2
    lower = (one["cost_rad2"] - four["cost_rad2"]) / sigma2
    assert changed.sum() >= 5
    assert np.all(lower[changed] > 10)  # chi-square units: a far lower minimum
    assert np.all(four["status"][changed] == "ok")
    assert np.all(one["status"][changed] != "ok")
    for i in np.nonzero(changed)[0]:
        ref = _scipy_fit(log, i, truth[i], "linear", 1.0)
        F_ref = np.sum(bearing_residuals(ref[None], *_inputs(log)[:3],
                                         _inputs(log)[3][i:i + 1], None) ** 2)
        assert abs(four["cost_rad2"][i] - F_ref) <= 1e-6 * F_ref, i
    for c in (*THETA, "cost_rad2", "n_iter", "stop_reason"):
        np.testing.assert_array_equal(four[c][~changed], one[c][~changed], err_msg=c)
    assert np.all(four["n_f_evals"] > one["n_f_evals"])


def test_bad_options_are_refused_naming_the_key():
    from tma.errors import ConfigError
    for key, value in (("loss", "l1"), ("scale", "iqr"), ("starts", 0),
                       ("start_min_m", 6e4)):
        with pytest.raises(ConfigError, match=key):
            build_estimator({"name": "lm", key: value})
