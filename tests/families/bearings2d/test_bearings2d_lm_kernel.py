"""The compiled pieces of ``lm`` against independent references: atan2 against libm, the fused
F / J^T J / J^T r against the explicit Jacobian, the 4x4 Jacobi eigensolver against LAPACK,
and the whole Marquardt loop against a plain per-track Python loop (numpy residuals and
LAPACK eigh) with the same decisions: identical counters and stop reasons."""

import math

import numpy as np
import pytest

from tma.families import build_estimator
from tma.families.bearings2d.estimators.lm import initial_theta
from tma.families.bearings2d.marquardt import (
    STOP_F_TOL,
    STOP_LAMBDA_MAX,
    STOP_MAX_ITER,
    MarquardtSettings,
    fit_starts,
    scaled_eigh,
)
from tma.families.bearings2d.model import (
    BearingTerms,
    atan2,
    bearing_jacobian,
    bearing_residuals,
    predicted_bearings,
)
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.runtime.jit import njit

THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")


@njit(depends=(atan2,))
def _atan2_all(y, x, out):
    for i in range(y.size):  # a loop like the LM's (vectorised), not one call per element
        out[i] = atan2(y[i], x[i])


def test_atan2_within_one_ulp_of_libm():
    rng = np.random.default_rng(0)
    n = 200_000
    y = rng.standard_normal(n) * 10.0 ** rng.uniform(-12, 8, n)
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-12, 8, n)
    # every octant boundary and reduction interval edge: |y| / |x| near 7/16, 11/16, 1
    ratio = np.array([7 / 16, 11 / 16, 1.0])[rng.integers(0, 3, n // 4)]
    y[: n // 4] = x[: n // 4] * ratio * (1 + rng.uniform(-1e-12, 1e-12, n // 4))
    y[:8], x[:8] = [0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 0.0, 2.5], [1.0, 1.0, -1.0, -1.0, 0.0,
                                                                0.0, 3.0, -0.0]
    out = np.empty(n)
    _atan2_all(y, x, out)
    ref = np.array([math.atan2(a, b) for a, b in zip(y, x, strict=True)])
    ulps = np.abs(out - ref) / np.spacing(np.abs(ref))
    assert ulps.max() <= 1.0, ulps.max()
    np.testing.assert_array_equal(np.signbit(out[:6]), np.signbit(ref[:6]))


def _geometry(n=40, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 1201.0, 2.0)
    ox, oy = 3.0 * t, 1000.0 * np.sin(t / 200.0)
    theta = np.column_stack([rng.uniform(-20e3, 20e3, n), rng.uniform(-20e3, 20e3, n),
                             rng.uniform(-15, 15, n), rng.uniform(-15, 15, n)])
    return rng, t, ox, oy, theta


@pytest.mark.parametrize("missing", [False, True])
def test_fused_terms_equal_the_explicit_jacobian_products(missing):
    """F, H = J^T J and g = J^T r against the explicit residuals and Jacobian, at trial
    points far from and near the truth (residuals up to +-pi: every atan2 octant)."""
    rng, t, ox, oy, theta = _geometry()
    measured = predicted_bearings(theta, t, ox, oy) + rng.normal(0, 0.01, (theta.shape[0],
                                                                           t.size))
    valid = rng.random(measured.shape) > 0.3 if missing else None
    measured = np.where(valid, measured, 0.0) if missing else measured
    trial = theta + rng.normal(0, 1, theta.shape) * np.array([3e3, 3e3, 3.0, 3.0])
    trial[:5] = -theta[:5]  # the target on the other side: residuals near +-pi
    F, H, g = BearingTerms(t, ox, oy, measured, valid)(trial, np.arange(theta.shape[0]))
    r = bearing_residuals(trial, t, ox, oy, measured, valid)
    jac = bearing_jacobian(trial, t, ox, oy, valid)
    np.testing.assert_allclose(F, np.einsum("nk,nk->n", r, r), rtol=1e-12)
    np.testing.assert_allclose(H, np.einsum("nki,nkj->nij", jac, jac), rtol=1e-11)
    g_ref = np.einsum("nki,nk->ni", jac, r)
    scale = np.sqrt(np.einsum("nii->ni", H) * F[:, None])  # |g_i| <= sqrt(H_ii F)
    np.testing.assert_allclose(g, g_ref, rtol=0, atol=1e-12 * scale.max())


def _scaled(H):
    d = np.sqrt(np.einsum("nii->ni", H))
    d = np.where(d > 0, d, 1.0)
    return H / (d[:, :, None] * d[:, None, :])


@pytest.mark.parametrize("warm", [False, True])
def test_jacobi_eigensolver_equals_lapack(warm):
    """Random J^T J with columns scaled over 8 decades, rank-deficient and zero columns; warm:
    started from the eigenvectors of a perturbed matrix, as between LM steps."""
    rng = np.random.default_rng(1)
    n = 500
    J = rng.normal(size=(n, 30, 4)) * 10.0 ** rng.uniform(-8, 0, (n, 1, 4))
    J[:50, :, 3] = J[:50, :, 0]  # singular
    J[50:60, :, 2] = 0.0  # a zero column (d = 1 there)
    H = np.einsum("nki,nkj->nij", J, J)
    w, V, d = np.empty((n, 4)), np.empty((n, 4, 4)), np.empty((n, 4))
    A, B = np.empty((4, 4)), np.empty((4, 4))
    for i in range(n):
        if warm:
            E = rng.normal(size=(4, 4)) * 1e-3
            scaled_eigh(H[i] * (1 + E + E.T), w[i], V[i], d[i], False, A, B)
        scaled_eigh(H[i], w[i], V[i], d[i], warm, A, B)
    S = _scaled(H)
    ref = np.linalg.eigvalsh(S)
    np.testing.assert_allclose(np.sort(w, axis=1), ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.einsum("nij,nj,nkj->nik", V, w, V), S, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", V, V), np.broadcast_to(np.eye(4),
                                                                                V.shape),
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(d, np.sqrt(np.where(np.einsum("nii->ni", H) > 0,
                                                    np.einsum("nii->ni", H), 1.0)))


def _plain_marquardt(theta, t, ox, oy, measured, valid, cfg):
    """The documented algorithm written plainly for one track: numpy residuals and Jacobian,
    LAPACK eigh of the scaled J^T J."""

    def terms(th):
        r = bearing_residuals(th[None], t, ox, oy, measured[None], valid)[0]
        jac = bearing_jacobian(th[None], t, ox, oy, valid)[0]
        return r @ r, jac.T @ jac, jac.T @ r

    def eigh(H):
        d = np.sqrt(np.diag(H))
        d = np.where(d > 0, d, 1.0)
        w, V = np.linalg.eigh(H / np.outer(d, d))
        return w, V, d

    F, H, g = terms(theta)
    w, V, d = eigh(H)
    lam, n_f, n_acc, stop = cfg.lambda0, 1, 0, -1
    while stop < 0:
        while w[0] + lam <= cfg.pd_rtol * max(w[-1], 1.0):
            lam *= cfg.lambda_up
        step = V @ ((V.T @ (g / d)) / (w + lam)) / d
        F_trial, H_trial, g_trial = terms(theta + step)
        n_f += 1
        if F - F_trial >= 0:
            decrease = F - F_trial
            theta, F, H, g = theta + step, F_trial, H_trial, g_trial
            w, V, d = eigh(H)
            lam *= cfg.lambda_down
            n_acc += 1
            if decrease < cfg.f_tol_rad2:
                stop = STOP_F_TOL
        else:
            lam *= cfg.lambda_up
        if stop < 0 and n_acc >= cfg.max_iter:
            stop = STOP_MAX_ITER
        if stop < 0 and lam > cfg.lambda_max:
            stop = STOP_LAMBDA_MAX
    return theta, F, H, n_f, n_acc, stop


@pytest.mark.parametrize("options", [{}, {"max_iter": 4}, {"lambda_up": 1e3, "lambda_max": 20.0},
                                     {"missing": True, "initial_bearing_deg": None}])
def test_compiled_marquardt_takes_the_plain_loops_decisions(options):
    """Per track the same accepted and rejected steps (counters, stop reason) and the same
    result to round-off, including tracks stopped by max_iter or lambda_max."""
    options = dict(options)
    missing = options.pop("missing", False)
    log, _ = simulate_shard(Config(n_tracks=40, shard_size=40, sigma_deg=0.5, seed=3), 0)
    rng = np.random.default_rng(4)
    if missing:
        log.bearing_deg[rng.random(log.bearing_deg.shape) < 0.3] = np.nan
    lm = build_estimator({"name": "lm", **options})
    out = lm.estimate(log)
    t, ox, oy = log.t_s, log.own_x_m, log.own_y_m
    valid_all = np.isfinite(log.bearing_deg)
    measured = np.where(valid_all, np.deg2rad(log.bearing_deg), 0.0)
    theta0 = initial_theta(lm.config, t, ox, oy, measured, np.argmax(valid_all, axis=1))
    stops = set()
    for i in range(log.n_tracks):
        valid = valid_all[i:i + 1] if missing else None
        theta, F, H, n_f, n_acc, stop = _plain_marquardt(theta0[i], t, ox, oy, measured[i],
                                                         valid, lm.config)
        stops.add(stop)
        assert (out["n_f_evals"][i], out["n_iter"][i]) == (n_f, n_acc), i
        assert out["stop_reason"][i] == stop, i
        np.testing.assert_allclose([out[c][i] for c in THETA], theta, rtol=1e-8, atol=1e-6)
        np.testing.assert_allclose(out["cost_rad2"][i], F, rtol=1e-9)
        np.testing.assert_allclose(out["jtj_03"][i], H[0, 3], rtol=1e-8)
    expected = {"max_iter": STOP_MAX_ITER, "lambda_max": STOP_LAMBDA_MAX}
    for key, reason in expected.items():
        if key in options:
            assert reason in stops  # the case is exercised, not only converged tracks


def test_fit_starts_keeps_each_tracks_best_start_and_takes_no_track():
    """``fit_starts`` from several starts: each track keeps the start of lowest F (the
    earliest within the tolerance), n_f_evals summed over the starts; a batch of no track
    (``last_leg``'s rounds where none is left) gives empty arrays, not a division by zero."""
    log, _ = simulate_shard(Config(n_tracks=6, shard_size=6, sigma_deg=0.5, seed=2), 0)
    lm = build_estimator({"name": "lm"})
    b = lm.read(log)
    settings = MarquardtSettings.of(lm.config)
    near = initial_theta(lm.config, b.t, b.own_x, b.own_y, b.measured, b.first, 2000.0)
    far = initial_theta(lm.config, b.t, b.own_x, b.own_y, b.measured, b.first, 60000.0)
    args = (b.t, b.own_x, b.own_y, b.measured, np.empty((0, 0)), False)
    each = [fit_starts(settings, start, *args) for start in (near, far)]
    both = fit_starts(settings, np.concatenate([near, far]), *args)
    won = np.where(each[1]["cost_rad2"] < each[0]["cost_rad2"] - settings.f_tol_rad2, 1, 0)
    np.testing.assert_array_equal(both["start_won"], won)
    for key in ("theta", "cost_rad2", "n_iter", "stop_reason"):
        np.testing.assert_array_equal(both[key], np.where(
            won.reshape(-1, *[1] * (each[0][key].ndim - 1)) == 1, each[1][key], each[0][key]))
    np.testing.assert_array_equal(both["n_f_evals"], each[0]["n_f_evals"] + each[1]["n_f_evals"])
    none = fit_starts(settings, np.empty((0, 4)), b.t, b.own_x, b.own_y,
                      np.empty((0, b.t.size)), np.empty((0, b.t.size)), True)
    assert none["theta"].shape == (0, 4) and none["cost_rad2"].shape == (0,)
